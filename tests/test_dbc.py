"""DBC is DBC: its losses against hand computations, where its gradients go, what it learns.

Every check here can fail: the losses are recomputed from the formulas of the authors' code
(``facebookresearch/deep_bisim4control``: ``agent/bisim_agent.py``, ``transition_model.py``)
with the networks' own layers but none of `advgame.agents.dbc.dbc`'s code; each loss must reach
exactly the networks the authors let it train; on a task with a distractor observation the
trained encoder must shrink the distractor (an untrained one does not), and the bisimulation
loss must shrink it further than the model losses alone.
"""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3.common.type_aliases import ReplayBufferSamples
from stable_baselines3.common.vec_env import DummyVecEnv
from torch import nn

from advgame.agents.dbc.config import DBCConfig
from advgame.agents.dbc.dbc import DBC
from advgame.cli import main
from advgame.errors import ConfigError

GAMMA = 0.99
SMALL = {"net_arch": (32, 32), "feature_dim": 8, "encoder_arch": (16,), "model_width": 16}
pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _model(**kwargs) -> DBC:
    env = DummyVecEnv([lambda: gym.make("InvertedPendulum-v5")])
    cfg = DBCConfig(**{**SMALL, "learning_starts": 50, "batch_size": 16, **kwargs})
    return cfg.make_model(env, seed=0, total_steps=1000)


def _batch(n: int = 10, seed: int = 0) -> ReplayBufferSamples:
    g = th.Generator().manual_seed(seed)
    obs, nxt = th.randn(n, 4, generator=g), th.randn(n, 4, generator=g)
    act = th.rand(n, 1, generator=g) * 2 - 1
    rew = th.randn(n, 1, generator=g) * 2  # reward gaps beyond 1: Huber's linear branch
    done = (th.rand(n, 1, generator=g) < 0.3).float()
    return ReplayBufferSamples(obs, act, nxt, done, rew)


def _jiggle(model: DBC, seed: int = 1) -> None:
    """Move every weight off its initial value (LayerNorm's gains and biases are 1 and 0)."""
    g = th.Generator().manual_seed(seed)
    with th.no_grad():
        for p in model.policy.parameters():
            p.add_(0.2 * th.randn(p.shape, generator=g))


def _norm(x: th.Tensor, ln: nn.LayerNorm) -> th.Tensor:
    centred = x - x.mean(dim=1, keepdim=True)
    var = centred.pow(2).mean(dim=1, keepdim=True)
    return centred / th.sqrt(var + ln.eps) * ln.weight + ln.bias


def _lin(x: th.Tensor, layer: nn.Linear) -> th.Tensor:
    return x @ layer.weight.T + layer.bias


def _huber(x: th.Tensor) -> th.Tensor:
    return th.where(x.abs() < 1, 0.5 * x.pow(2), x.abs() - 0.5)


def _hand(model: DBC, data, perm: th.Tensor, noise: th.Tensor) -> tuple[th.Tensor, ...]:
    """J_bisim, J_transition, J_reward from the layers' weights and the authors' formulas."""
    flat = [m for m in model.policy.encoder.net if isinstance(m, (nn.Linear, nn.LayerNorm))]
    first, last, ln = flat

    def phi(obs: th.Tensor) -> th.Tensor:
        return _norm(_lin(th.relu(_lin(obs, first)), last), ln)

    z, next_z = phi(data.observations), phi(data.next_observations)
    tm = model.policy.transition_model
    hidden = th.relu(_norm(_lin(th.cat([z, data.actions], 1), tm.trunk[0]), tm.trunk[1]))
    mu = _lin(hidden, tm.mu)
    sigma = 1e-4 + (10.0 - 1e-4) * th.sigmoid(_lin(hidden, tm.sigma))
    dec = model.policy.reward_decoder
    pred = _lin(th.relu(_norm(_lin(mu + sigma * noise, dec[0]), dec[1])), dec[3])
    w2 = th.sqrt((mu - mu[perm]).pow(2) + (sigma - sigma[perm]).pow(2))
    target = _huber(data.rewards - data.rewards[perm]) + GAMMA * w2
    bisim = (_huber(z - z[perm]) - target).pow(2).mean()
    trans = (0.5 * ((mu - next_z) / sigma).pow(2) + th.log(sigma)).mean()
    return bisim, trans, (pred - data.rewards).pow(2).mean()


def test_model_losses_are_the_formulas() -> None:
    model = _model()
    _jiggle(model)
    data = _batch()
    perm = th.tensor([3, 7, 0, 9, 1, 8, 2, 5, 4, 6])
    noise = th.randn(10, 8, generator=th.Generator().manual_seed(2))
    got = model.model_losses(data, perm, noise)
    with th.no_grad():
        want = _hand(model, data, perm, noise)
    for a, b in zip(got, want, strict=True):
        assert float(a.detach()) == pytest.approx(float(b), rel=1e-5)
    assert float(got[0].detach()) > 0.01  # not a vacuous zero


def _grads(loss: th.Tensor, module: nn.Module) -> float:
    params = list(module.parameters())
    grads = th.autograd.grad(loss, params, retain_graph=True, allow_unused=True)
    return sum(0.0 if g is None else float(g.abs().sum()) for g in grads)


def test_each_loss_trains_what_the_authors_let_it() -> None:
    model = _model()
    _jiggle(model)
    data, policy = _batch(), model.policy
    bisim, trans, reward = model.model_losses(data)
    assert _grads(bisim, policy.encoder) > 0  # through z and z_pi
    assert _grads(bisim, policy.transition_model) == 0  # mu and sigma are taken as given
    assert _grads(trans, policy.encoder) > 0 and _grads(trans, policy.transition_model) > 0
    assert _grads(reward, policy.reward_decoder) > 0 and _grads(reward, policy.encoder) > 0
    assert _grads(model.critic_loss(data, th.tensor(0.1)), policy.encoder) > 0
    actions, _ = model.actor.action_log_prob(data.observations)
    assert _grads(actions.sum(), policy.encoder) == 0  # the actor reads the encoding detached
    # one encoder, shared; the target encoder is a copy; the optimizers hold the right weights
    assert model.actor.features_extractor is policy.encoder is model.critic.features_extractor
    assert policy.target_encoder is not policy.encoder
    held = {id(p) for g in model.actor.optimizer.param_groups for p in g["params"]}
    assert not held & {id(p) for p in policy.encoder.parameters()}
    held = {id(p) for g in model.critic.optimizer.param_groups for p in g["params"]}
    assert {id(p) for p in policy.encoder.parameters()} <= held
    # the actor's log std stays in the paper's [-10, 2] however far its layer is pushed
    for bias, bound in ((1e4, 2.0), (-1e4, -10.0)):
        with th.no_grad():
            model.actor.log_std.bias.fill_(bias)
        _, log_std, _ = model.actor.get_action_dist_params(data.observations)
        assert th.allclose(log_std, th.full_like(log_std, bound))


def test_the_next_encoding_is_a_target_of_the_transition_model_not_trained_by_it() -> None:
    model = _model()
    _jiggle(model)
    data = _batch()
    nxt = data.next_observations.clone().requires_grad_(True)
    _, trans, _ = model.model_losses(data._replace(next_observations=nxt))
    (grad,) = th.autograd.grad(trans, nxt, allow_unused=True)
    assert grad is None  # the authors detach phi(s'); only phi(s) (through mu) is trained
    # the same loss without the detach would reach s': the check can tell the two apart
    policy = model.policy
    mu, sigma = policy.transition_model(policy.encode(data.observations), data.actions)
    undetached = (0.5 * ((mu - policy.encode(nxt)) / sigma).pow(2) + th.log(sigma)).mean()
    assert float(th.autograd.grad(undetached, nxt)[0].abs().sum()) > 0


def test_critic_target_reads_the_target_encoder_and_the_lower_target_q() -> None:
    model = _model()
    _jiggle(model)
    with th.no_grad():  # a target encoder and target Q networks unlike the online ones
        for p in model.critic_target.parameters():
            p.add_(0.3 * th.randn(p.shape, generator=th.Generator().manual_seed(3)))
    data, alpha = _batch(), th.tensor(0.1)
    th.manual_seed(4)
    got = model.critic_loss(data, alpha)
    th.manual_seed(4)  # the same sampled next actions
    with th.no_grad():
        next_a, next_logp = model.actor.action_log_prob(data.next_observations)
        z_next = model.policy.target_encoder(data.next_observations)
        qs = [q(th.cat([z_next, next_a], 1)) for q in model.critic_target.q_networks]
        soft = th.min(qs[0], qs[1]) - alpha * next_logp.reshape(-1, 1)
        y = data.rewards + (1 - data.dones) * GAMMA * soft
        z = model.policy.encoder(data.observations)
        want = sum(
            ((q(th.cat([z, data.actions], 1)) - y) ** 2).mean() for q in model.critic.q_networks
        )
    assert float(got.detach()) == pytest.approx(float(want), rel=1e-5)


def test_schedule_targets_and_save_load_keep_every_network(tmp_path: Path) -> None:
    model = _model(tau=0.01, encoder_tau=0.05)  # two rates, so a swap of them would show
    model.learn(150)
    updates = 150 - 50  # SB3 trains after each step once num_timesteps > learning_starts
    assert model.counts == {"critic": updates, "model": updates, "actor": 50, "target": 50}
    pairs = [
        (model.policy.encoder, model.policy.target_encoder, 0.05),
        *zip(model.critic.q_networks, model.critic_target.q_networks, (0.01, 0.01), strict=True),
    ]
    before = [[p.clone() for p in target.parameters()] for _, target, _ in pairs]
    model._update_targets()
    for (online, target, rate), old in zip(pairs, before, strict=True):
        for was, new, now in zip(old, target.parameters(), online.parameters(), strict=True):
            assert th.allclose(new, (1 - rate) * was + rate * now)
    model.save(tmp_path / "m.zip")
    back = DBC.load(tmp_path / "m.zip", device="cpu")
    mine, theirs = model.policy.state_dict(), back.policy.state_dict()
    assert mine.keys() == theirs.keys() and any("transition_model" in k for k in mine)
    assert all(th.equal(mine[k], theirs[k]) for k in mine)
    for name in ("encoder_optimizer", "decoder_optimizer"):
        a, b = getattr(model.policy, name).state_dict(), getattr(back.policy, name).state_dict()
        assert a["state"] and all(
            th.equal(a["state"][i]["exp_avg"], b["state"][i]["exp_avg"]) for i in a["state"]
        )
    assert back.counts == model.counts and back.bisim_coef == 0.5
    assert back.actor.features_extractor is back.policy.encoder  # still one shared encoder


class PointWithDistractor(gym.Env):
    """A point on [-1, 1] steered towards 0 (reward −|x|), observed with fresh N(0, 1) noise."""

    observation_space = spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.t = float(self.np_random.uniform(-1, 1)), 0
        return self._obs(), {}

    def _obs(self) -> np.ndarray:
        return np.array([self.x, self.np_random.normal()], np.float32)

    def step(self, action):
        self.x = float(np.clip(self.x + 0.25 * float(action[0]), -1.0, 1.0))
        self.t += 1
        return self._obs(), -abs(self.x), False, self.t >= 50, {}


def _distractor_ratio(model: DBC) -> tuple[float, float]:
    """(encoded, raw) ratio: mean distance of pairs differing only in the distractor over the
    mean distance of pairs differing only in the position (Euclidean norms, 500 pairs each)."""
    rng = np.random.default_rng(123)
    x, d1, d2 = rng.uniform(-1, 1, 500), rng.normal(size=500), rng.normal(size=500)
    x1, x2, d = rng.uniform(-1, 1, 500), rng.uniform(-1, 1, 500), rng.normal(size=500)

    def gap(a: tuple, b: tuple) -> float:
        with th.no_grad():
            za, zb = (model.policy.encode(th.as_tensor(np.stack(s, 1)).float()) for s in (a, b))
        return float((za - zb).norm(dim=1).mean())

    raw = float(np.abs(d1 - d2).mean() / np.abs(x1 - x2).mean())
    return gap((x, d1), (x, d2)) / gap((x1, d), (x2, d)), raw


def _point_model(**kwargs) -> DBC:
    cfg = DBCConfig(**{**SMALL, "net_arch": (64, 64), "feature_dim": 16, "encoder_arch": (64,),
                       "model_width": 64, "batch_size": 64, **kwargs})  # fmt: skip
    return cfg.make_model(DummyVecEnv([PointWithDistractor]), seed=0, total_steps=1000)


def test_trained_encoder_shrinks_a_distractor_an_untrained_one_keeps() -> None:
    model = _point_model(learning_starts=200)
    untrained, raw = _distractor_ratio(model)
    assert raw > 1.5  # the distractor moves the raw observation more than the position does
    model.learn(500)  # DBC as configured: the paper's rates, tiny networks, 300 updates
    trained, _ = _distractor_ratio(model)
    assert trained < 0.5 * raw < untrained


def test_the_bisimulation_loss_itself_shrinks_the_distractor() -> None:
    """Only the model step (no critic), 500 updates at 1e-3, with and without J_bisim."""
    ratios = {}
    for coef in (0.5, 0.0):
        model = _point_model(learning_starts=10**6, bisim_coef=coef, encoder_lr=1e-3,
                             decoder_lr=1e-3)  # fmt: skip
        model.learn(400)  # random transitions only: learning never starts
        for _ in range(500):
            model.model_step(model.replay_buffer.sample(64))
        ratios[coef] = _distractor_ratio(model)[0]
    assert ratios[0.5] < 0.6 * ratios[0.0]


def _train_args(run: Path, scenario: str = "InvertedPendulum-v5") -> list[str]:
    tiny = {"learning_starts": 100, "batch_size": 32, **SMALL, "model_width": 32}
    return [
        "train", "--method", "dbc", "--scenario", scenario, "--iterations", "1",
        "--protagonist-steps", "200", "--eval-episodes", "1", "--no-progress",
        "--set", f"protagonist_hparams={json.dumps(tiny)}", "--run-dir", str(run),
    ]  # fmt: skip


def test_dbc_trains_resumes_and_is_evaluated_from_the_command_line(tmp_path: Path) -> None:
    run = tmp_path / "dbc"
    assert main(_train_args(run)) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["protagonist_algo"] == "dbc" and cfg["normalize"] is False
    first = DBC.load(run / "checkpoints" / "iter_0001" / "protagonist.zip", device="cpu")
    assert first.counts["critic"] == 200 - 100
    cfg["iterations"] = 2
    (run / "config.json").write_text(json.dumps(cfg))
    assert main(["resume", str(run), "--no-progress"]) == 0
    model = run / "checkpoints" / "iter_0002" / "protagonist.zip"
    second = DBC.load(model, device="cpu")
    assert second.counts["critic"] == 400 - 100  # the update count carried on
    assert second.policy.encoder_optimizer.state_dict()["state"]
    out = tmp_path / "eval"
    code = main([
        "evaluate", "--scenario", "InvertedPendulum-v5", "--checkpoint", f"dbc={model}:dbc",
        "--adversaries", "nominal", "--seeds", "1", "--raw-obs", "dbc", "--workers", "1",
        "--out", str(out),
    ])  # fmt: skip
    assert code == 0
    assert "dbc" in (out / "payoff.json").read_text()


@pytest.mark.parametrize(
    ("scenario", "says"), [("LunarLander-v3", "continuous"), ("MA-Ant-2x4", "dbc")]
)
def test_dbc_refuses_what_it_cannot_serve_before_training(
    tmp_path: Path, capsys, scenario: str, says: str
) -> None:
    assert main(_train_args(tmp_path / "run", scenario)) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err
    assert not (tmp_path / "run" / "checkpoints" / "iter_0001").exists()


def test_config_refuses_bad_values_and_non_flat_observations() -> None:
    with pytest.raises(ConfigError, match="bisim_coef"):
        DBCConfig(bisim_coef=-1.0)
    with pytest.raises(ConfigError, match="log_std_min"):
        DBCConfig(log_std_min=3.0)
    env = DummyVecEnv([lambda: gym.make("CartPole-v1")])
    with pytest.raises(ConfigError, match="continuous"):
        DBCConfig().make_model(env, seed=0, total_steps=10)
