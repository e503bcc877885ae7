"""RSC is RSC: its causal graph drops a spurious edge, its augmentation weakens a spurious
correlation, its batches mix real and augmented rows at the ratio, its losses are SAC's.

The synthetic task `SpuriousPoint` has one true state variable, the position ``x``, and one
spurious observed feature ``y = x + noise`` (correlated with ``x`` in training, playing no part
in the dynamics or the reward): ``x' = clip(x + 0.3 a)``, ``r = −x²``. Every check can fail:
an untrained graph keeps the spurious edges; plain replay rows keep the correlation.
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

from advgame.agents.rsc.config import RSCConfig
from advgame.agents.rsc.model import CausalWorldModel, perturb_states
from advgame.agents.rsc.rsc import RSC, one_step_samples
from advgame.cli import main
from advgame.errors import ConfigError

pytestmark = pytest.mark.usefixtures("one_torch_thread")
X, Y, A = 0, 1, 2  # input columns of the graph: x, y, action
NEXT_X, REWARD = 0, 2  # output rows of the graph: x', y', reward


class SpuriousPoint(gym.Env):
    """A point at ``x`` in [-1, 1] seen with a spurious feature ``y = sign · x + noise``."""

    observation_space = spaces.Box(-5.0, 5.0, (2,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, sign: float = 1.0, noise: float = 0.3) -> None:
        self.sign, self.noise, self.x, self.t = sign, noise, 0.0, 0

    def _obs(self) -> np.ndarray:
        y = self.sign * self.x + self.noise * self.np_random.normal()
        return np.array([self.x, y], dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.x, self.t = float(self.np_random.uniform(-1, 1)), 0
        return self._obs(), {}

    def step(self, action):
        reward = -(self.x**2)
        self.x = float(np.clip(self.x + 0.3 * float(np.asarray(action).ravel()[0]), -1, 1))
        self.t += 1
        return self._obs(), reward, False, self.t >= 50, {}


def _model(**kwargs) -> RSC:
    env = DummyVecEnv([SpuriousPoint])
    options = {"net_arch": (16, 16), "batch_size": 128, "learning_starts": 2000}
    options.update(kwargs)
    return RSCConfig(**options).make_model(env, seed=0, total_steps=2000)


@pytest.fixture(scope="module")
def trained() -> RSC:
    """An RSC whose world model trained 1,400 updates on 2,000 random transitions."""
    th.set_num_threads(1)
    model = _model()
    model.learn(2000)  # learning_starts = 2000: only collects
    assert model.counts["model"] == 0
    for _ in range(1400):
        model.update_world_model(128)
    return model


def test_untrained_graph_keeps_every_edge() -> None:
    edges = _model().world_model.edge_probabilities().detach()
    assert float(edges[NEXT_X, Y]) > 0.5 and float(edges[REWARD, Y]) > 0.5


def test_learned_graph_drops_the_spurious_edges_and_keeps_the_causal_ones(trained) -> None:
    edges = trained.world_model.edge_probabilities().detach()
    assert float(edges[NEXT_X, X]) > 0.9 and float(edges[NEXT_X, A]) > 0.9
    assert float(edges[REWARD, X]) > 0.9
    assert float(edges[NEXT_X, Y]) < 0.2 and float(edges[REWARD, Y]) < 0.2
    assert float(edges[REWARD, A]) < 0.2  # r = -x² does not depend on this step's action


def test_the_generators_graph_predicts_within_twice_the_drawn_graphs_error(trained) -> None:
    th.manual_seed(2)
    pool = one_step_samples(trained.replay_buffer, 1024)
    args = (pool.observations, pool.actions, pool.next_observations, pool.rewards)
    error = trained.world_model.mode_error(*args)
    untrained = _model()
    untrained.world_model.inputs, untrained.world_model.targets = (
        trained.world_model.inputs,
        trained.world_model.targets,
    )
    assert error < 0.1 * untrained.world_model.mode_error(*args)
    drawn, _ = trained.world_model.losses(*args)  # sum over outputs / 2σ², drawn graphs
    outputs = trained.world_model.edge_probabilities().shape[0]
    assert error < 2 * float(drawn.detach()) * 2 * trained.world_model.sigma**2 / outputs


def test_augmentation_weakens_the_spurious_correlation(trained) -> None:
    th.manual_seed(1)
    pool = one_step_samples(trained.replay_buffer, 1024)
    aug = trained.augment(pool, 1024)
    real_corr = np.corrcoef(pool.observations.numpy().T)[0, 1]
    aug_corr = np.corrcoef(aug.observations.numpy().T)[0, 1]
    assert real_corr > 0.8 and aug_corr < real_corr - 0.04
    # each row moved in one dimension (plus the jitter, within `bound`)
    moved = (aug.observations - pool.observations).abs() > trained.bound + 1e-6
    assert int(moved.sum(dim=1).max()) <= 1 and int(moved.sum()) > 512
    # the outcomes are the world model's for the perturbed states: r = -x̃², x' = x̃ + 0.3 a
    x = aug.observations[:, 0]
    assert float((aug.rewards[:, 0] + x**2).abs().mean()) < 0.05
    want = th.clamp(x + 0.3 * aug.actions[:, 0], -1, 1)
    assert float((aug.next_observations[:, 0] - want).abs().mean()) < 0.05


@pytest.mark.parametrize("tau", [1.0, 0.5])
def test_graph_draws_are_the_binary_gumbel_softmax_in_distribution_and_gradient(tau) -> None:
    from torch.nn import functional as F

    model = CausalWorldModel(1, 1, temperature=tau)
    with th.no_grad():
        model.graph_logits.copy_(th.tensor([[-2.0, 0.0], [1.5, 3.0]]))
    th.manual_seed(0)
    ours = model.sample_graph(40_000)
    logits = model.graph_logits.expand(40_000, 2, 2)
    two = th.stack([logits, th.zeros_like(logits)], dim=-1)
    theirs = F.gumbel_softmax(two, tau=tau, hard=False, dim=-1)[..., 0]
    qs = th.tensor([0.1, 0.25, 0.5, 0.75, 0.9])
    for o in range(2):
        for i in range(2):  # each edge's quantiles agree to sampling error
            a = th.quantile(ours[:, o, i].detach(), qs)
            b = th.quantile(theirs[:, o, i].detach(), qs)
            th.testing.assert_close(a, b, atol=0.015, rtol=0)
    grads = []
    for draw in (ours, theirs):  # the mean edge's gradient with respect to the logits
        (grad,) = th.autograd.grad(draw.mean(0).sum(), model.graph_logits)
        grads.append(grad)
    th.testing.assert_close(grads[0], grads[1], atol=0.01, rtol=0.05)
    assert (
        0.0 <= float(ours.min().detach())
        and float(ours.max().detach()) <= 1.0
        and not ours.isnan().any()
    )


def test_perturbation_takes_the_donor_most_different_in_one_dimension_only() -> None:
    th.manual_seed(0)
    states = th.tensor([[0.0, 0.0], [0.1, 2.0], [2.0, 0.1], [1.0, 1.0]])
    for seed in range(4):  # both dimensions get drawn
        th.manual_seed(seed)
        out, dims = perturb_states(states, 1, sigma=0.0, bound=0.0)
        moved = int(dims[0])  # y: donor row 1 (far in y, near in x); x: donor row 2
        assert float(out[0, moved]) == 2.0 and float(out[0, 1 - moved]) == 0.0


def test_world_model_masks_the_inputs_an_output_has_no_edge_from() -> None:
    wm = CausalWorldModel(2, 1)
    with th.no_grad():
        wm.graph_logits[NEXT_X, Y] = -5.0
    obs, act = th.zeros(3, 2), th.zeros(3, 1)
    other = obs.clone()
    other[:, Y] = th.tensor([1.0, -2.0, 3.0])
    base, changed = wm.predict(obs, act)[0], wm.predict(other, act)[0]
    assert th.equal(base[:, NEXT_X], changed[:, NEXT_X])
    assert not th.equal(base[:, 1], changed[:, 1])  # y' still sees y
    nll, penalty = wm.losses(obs, act, obs, th.zeros(3))
    assert nll.shape == penalty.shape == () and float(penalty.detach()) > 0


def test_batches_mix_real_and_augmented_rows_at_the_ratio(trained) -> None:
    counts = dict(trained.counts)
    batch = trained.mixed_batch(128)
    assert trained.counts["augmented_rows"] - counts["augmented_rows"] == 64
    assert trained.counts["real_rows"] - counts["real_rows"] == 64
    gamma = trained.gamma
    assert th.allclose(batch.discounts[:64], th.full((64, 1), gamma))
    real = batch.discounts[64:]
    assert float(real.min()) >= gamma**4 - 1e-6 and float(real.min()) < gamma - 1e-6  # n-step 4
    assert _model().augmented_rows(128) == 0  # before warm-up: all real


def test_critic_loss_is_sac_with_per_row_discounts(trained) -> None:
    g = th.Generator().manual_seed(3)
    n = 16
    data = ReplayBufferSamples(
        th.randn(n, 2, generator=g), th.rand(n, 1, generator=g) * 2 - 1,
        th.randn(n, 2, generator=g), (th.rand(n, 1, generator=g) < 0.2).float(),
        th.randn(n, 1, generator=g), th.rand(n, 1, generator=g) * 0.5 + 0.5,
    )  # fmt: skip
    alpha = th.tensor(0.1)
    th.manual_seed(7)
    got = trained.critic_loss(data, alpha)
    th.manual_seed(7)
    with th.no_grad():
        a2, logp = trained.actor.action_log_prob(data.next_observations)
        q2 = th.min(*trained.critic_target(data.next_observations, a2))
        y = data.rewards + (1 - data.dones) * data.discounts * (q2 - 0.1 * logp.reshape(-1, 1))
        q1, q1b = trained.critic(data.observations, data.actions)
        want = 0.5 * (((q1 - y) ** 2).mean() + ((q1b - y) ** 2).mean())
    assert float(got.detach()) == pytest.approx(float(want), rel=1e-5)


def test_one_update_on_real_rows_is_sb3_sacs_update_parameter_for_parameter() -> None:
    """With no augmented rows, RSC's SAC step moves every network as SB3's `SAC.train` does."""
    from collections import defaultdict

    from stable_baselines3 import SAC
    from stable_baselines3.common.logger import Logger

    rsc = _model(n_steps=1, critic_learning_rate=3e-4, learning_starts=0)
    sac = SAC("MlpPolicy", DummyVecEnv([SpuriousPoint]), learning_rate=3e-4, ent_coef="auto_0.1",
              gamma=rsc.gamma, tau=rsc.tau, policy_kwargs={"net_arch": [16, 16]}, device="cpu",
              seed=0)  # fmt: skip
    sac.policy.load_state_dict(rsc.policy.state_dict())
    with th.no_grad():
        sac.log_ent_coef.copy_(rsc.log_ent_coef)
    g = th.Generator().manual_seed(5)
    n = 32
    data = ReplayBufferSamples(
        th.randn(n, 2, generator=g), th.rand(n, 1, generator=g) * 2 - 1,
        th.randn(n, 2, generator=g), (th.rand(n, 1, generator=g) < 0.2).float(),
        th.randn(n, 1, generator=g), None,
    )  # fmt: skip
    sac.set_logger(Logger(folder=None, output_formats=[]))
    sac.replay_buffer.sample = lambda *args, **kwargs: data  # type: ignore[method-assign]
    for model in (sac, rsc):
        model.policy.set_training_mode(True)
    start = {k: v.clone() for k, v in rsc.policy.state_dict().items()}
    th.manual_seed(9)
    sac.train(gradient_steps=1, batch_size=n)
    th.manual_seed(9)  # the same draws of pi's actions, in the same order
    rsc._sac_step(data, defaultdict(list))
    mine, theirs = rsc.policy.state_dict(), sac.policy.state_dict()
    moved = [k for k in mine if not th.equal(mine[k], start[k])]
    assert any(k.startswith("actor") for k in moved) and any("critic_target" in k for k in moved)
    for key in mine:
        assert th.allclose(mine[key], theirs[key], atol=1e-7), key
    assert th.allclose(rsc.log_ent_coef, sac.log_ent_coef, atol=1e-7)


def test_updates_are_counted_and_save_load_keeps_the_world_model(tmp_path) -> None:
    model = _model(learning_starts=100, model_warmup=50, batch_size=32)
    model.learn(300)
    steps = 300 - 100  # SB3 trains after each step once num_timesteps > learning_starts
    assert model.counts["model"] == model.counts["critic"] == model.counts["actor"] == steps
    assert model.counts["augmented_rows"] == 16 * (steps - 50 + 1)  # from the 50th update
    assert model.counts["real_rows"] == 32 * steps - model.counts["augmented_rows"]
    model.save(tmp_path / "m.zip")
    model.save_replay_buffer(tmp_path / "r.pkl")
    back = RSC.load(tmp_path / "m.zip", device="cpu")
    back.load_replay_buffer(tmp_path / "r.pkl")
    assert th.equal(back.world_model.graph_logits, model.world_model.graph_logits)
    obs, act = th.randn(5, 2), th.rand(5, 1)
    assert all(
        th.equal(a, b)
        for a, b in zip(
            back.world_model.predict(obs, act), model.world_model.predict(obs, act), strict=True
        )
    )
    assert back.counts == model.counts and back.critic_learning_rate == 1e-3
    assert back.replay_buffer.pos == model.replay_buffer.pos


def test_refuses_discrete_actions_and_bad_settings() -> None:
    env = DummyVecEnv([lambda: gym.make("CartPole-v1")])
    with pytest.raises(ConfigError, match="continuous"):
        RSCConfig().make_model(env, seed=0, total_steps=10)
    with pytest.raises(ConfigError, match="augmented_ratio"):
        RSCConfig(augmented_ratio=1.5)


TINY = {
    "batch_size": 32, "net_arch": [32, 32], "model_warmup": 50, "model_hidden": 16,
    "learning_starts": 100,
}  # fmt: skip


def _args(run: Path, scenario: str = "InvertedPendulum-v5") -> list[str]:
    return [
        "train", "--method", "rsc", "--scenario", scenario, "--preset", "default",
        "--iterations", "1", "--protagonist-steps", "200", "--eval-episodes", "1",
        "--set", f"protagonist_hparams={json.dumps(TINY)}", "--no-progress",
        "--run-dir", str(run),
    ]  # fmt: skip


def test_rsc_trains_resumes_and_evaluates_from_the_cli(tmp_path: Path) -> None:
    run = tmp_path / "rsc"
    assert main(_args(run)) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["protagonist_algo"] == "rsc" and cfg["normalize"] is False
    first = RSC.load(run / "checkpoints" / "iter_0001" / "protagonist.zip", device="cpu")
    assert first.counts["model"] == 200 - 100 and first.counts["augmented_rows"] == 16 * 51
    cfg["iterations"] = 2
    (run / "config.json").write_text(json.dumps(cfg))
    assert main(["resume", str(run), "--no-progress"]) == 0
    model = run / "checkpoints" / "iter_0002" / "protagonist.zip"
    second = RSC.load(model, device="cpu")
    assert second.counts["model"] == 400 - 100  # the counts carried on
    assert not th.equal(second.world_model.graph_logits, first.world_model.graph_logits)
    out = tmp_path / "eval"
    code = main([
        "evaluate", "--scenario", "InvertedPendulum-v5", "--checkpoint", f"rsc={model}:rsc",
        "--adversaries", "nominal", "--seeds", "1", "--budgets", "--raw-obs", "rsc",
        "--out", str(out),
    ])  # fmt: skip
    assert code == 0
    assert "rsc" in json.dumps(json.loads((out / "payoff.json").read_text()))


def test_rsc_refuses_discrete_actions_from_the_cli(tmp_path: Path, capsys) -> None:
    assert main(_args(tmp_path / "run", "LunarLander-v3")) == 2
    err = capsys.readouterr().err
    assert "continuous" in err and "Traceback" not in err
    assert not (tmp_path / "run" / "checkpoints" / "iter_0001").exists()
