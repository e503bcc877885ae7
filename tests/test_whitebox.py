"""White-box observation attacks (MAD, critic, PGD): in budget, stronger than random search by
their own objective, never touching the protagonist's parameters, on single agents and teams."""

from __future__ import annotations

import io

import numpy as np
import pytest
import torch

import advgame
from advgame.adversaries.whitebox import CriticAttack, MADAttack, PGDAttack
from advgame.agents.common.checkpoint import SB3Policy
from advgame.core.episodes import build_policies, rollout
from advgame.disruptors import ActionDisruptor, ObservationDisruptor
from advgame.errors import ConfigError

ADV = "observation_adversary"


class KnownVictim:
    """A known differentiable protagonist: a = tanh(W s), V(s) = sin(v·s), std 0.5.

    W is small enough that tanh is not saturated (a saturated action has no gradient to follow).
    """

    def __init__(self, n_obs: int, n_act: int, seed: int = 0) -> None:
        gen = torch.Generator().manual_seed(seed)
        self.w = 0.5 * torch.randn(n_act, n_obs, generator=gen) / n_obs**0.5
        self.v = torch.randn(n_obs, generator=gen)

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, observation: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            obs = torch.as_tensor(np.asarray(observation, dtype=np.float32))[None]
            return self.action_mean(obs)[0].numpy()

    def action_mean(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.tanh(obs @ self.w.T)

    def action_std(self) -> torch.Tensor:
        return torch.full((self.w.shape[0],), 0.5)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.sin(obs @ self.v)

    def q_value(self, obs: torch.Tensor, action: torch.Tensor) -> None:
        return None


def _random_in_budget(rng: np.random.Generator, n: int, norm: str) -> np.ndarray:
    if norm == "linf":
        return rng.uniform(-1, 1, n)
    direction = rng.standard_normal(n)
    return direction / np.linalg.norm(direction) * rng.uniform() ** (1 / n)


def _game_at_a_sense_move(norm: str, space: str, victim: KnownVictim, attack: object):
    game = advgame.make(
        "Hopper-v5", disruptors=[ObservationDisruptor(eps=0.05, norm=norm, space=space)]
    )
    pols = build_policies(game, {"protagonist": victim, ADV: attack})
    if space == "normalized":
        game.set_observation_scale("protagonist", np.linspace(0.5, 2.0, 11))
    game.reset(seed=3)
    noop = game.agent_info(ADV).noop_action
    for _ in range(4):  # away from the initial pose (unattacked), to a state with some structure
        game.play({a: noop if a == ADV else pols[a].act(game.observe(a)) for a in game.next_movers})
    assert game.move == "sense"
    return game, pols


@pytest.mark.parametrize("attack_cls", [MADAttack, CriticAttack])
@pytest.mark.parametrize("norm", ["linf", "l2"])
@pytest.mark.parametrize("space", ["raw", "normalized"])
def test_attack_stays_in_budget_and_beats_random_search(
    attack_cls: type, norm: str, space: str
) -> None:
    victim = KnownVictim(11, 3)
    game, pols = _game_at_a_sense_move(norm, space, victim, attack_cls(steps=20, restarts=1))
    attack = pols[ADV]
    attack.reset(0)
    u = attack.act(game.observe(ADV))
    assert np.abs(u).max() <= 1.0 + 1e-6 and (norm == "linf" or np.linalg.norm(u) <= 1 + 1e-5)
    found = attack.objective_of("protagonist", u)
    rng = np.random.default_rng(0)
    randoms = [
        attack.objective_of("protagonist", _random_in_budget(rng, 11, norm)) for _ in range(300)
    ]
    assert found >= max(randoms), (found, max(randoms))
    # what the protagonist sees moved by at most the budget, and the disruptor clipped nothing
    unit = game.disruptors[ADV].unit
    true_obs = np.array(game.true_observation("protagonist"), dtype=np.float64)
    move = game.play({ADV: u})
    assert move.clipped[ADV] == 0
    delta = (np.asarray(game.observe("protagonist")) - true_obs) / unit
    if norm == "linf":
        assert np.abs(delta).max() <= 1 + 1e-6
    else:
        assert np.linalg.norm(delta) <= 1 + 1e-5
    assert np.abs(delta).max() > 0.1  # it did attack


def test_pgd_maximises_a_user_objective() -> None:
    victim = KnownVictim(11, 3, seed=1)
    attack = PGDAttack(objective_fn=_first_action, steps=15)
    game, pols = _game_at_a_sense_move("linf", "raw", victim, attack)
    pols[ADV].reset(0)
    u = pols[ADV].act(game.observe(ADV))
    with torch.no_grad():
        clean = victim.action_mean(
            torch.as_tensor(np.asarray(game.true_observation("protagonist"), dtype=np.float32))[
                None
            ]
        )[0, 0]
    assert pols[ADV].objective_of("protagonist", u) > float(clean)


def _first_action(victim, clean, attacked):
    return victim.action_mean(attacked)[0, 0]


def _state_bytes(module: torch.nn.Module) -> bytes:
    buffer = io.BytesIO()
    torch.save(module.state_dict(), buffer)
    return buffer.getvalue()


@pytest.mark.usefixtures("one_torch_thread")
@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_sb3_policies_are_attacked_without_being_modified(algo: str) -> None:
    import gymnasium as gym
    from stable_baselines3 import PPO, SAC

    env = gym.make("Hopper-v5")
    if algo == "ppo":
        model = PPO("MlpPolicy", env, n_steps=64, batch_size=32, seed=0, device="cpu")
        model.learn(64)
    else:
        model = SAC("MlpPolicy", env, learning_starts=0, seed=0, device="cpu")
        model.learn(8)
    rng = np.random.default_rng(0)
    victim = SB3Policy(model, rng.normal(size=11), rng.uniform(0.5, 2.0, 11))
    before = _state_bytes(model.policy)
    grads_before = _grads(model.policy)
    optimizer_before = [_state_bytes_of(opt) for opt in _optimizers(model)]
    game = advgame.make(
        "Hopper-v5",
        disruptors=[ObservationDisruptor(eps=0.1, space="normalized")],
        max_episode_steps=15,
    )
    for attack in (MADAttack(steps=5), CriticAttack(steps=5)):
        [result] = rollout(game, {"protagonist": victim, ADV: attack}, seed=0)
        assert result.length > 0 and result.clipped[ADV] == 0
    assert _state_bytes(model.policy) == before
    assert _grads(model.policy) == grads_before  # no gradient reached the parameters
    assert [_state_bytes_of(opt) for opt in _optimizers(model)] == optimizer_before


@pytest.mark.usefixtures("one_torch_thread")
def test_the_lean_ppo_mean_is_sb3s_distribution_mean_bit_for_bit() -> None:
    import gymnasium as gym
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", gym.make("Hopper-v5"), n_steps=64, batch_size=32, seed=0, device="cpu")
    model.learn(64)  # leaves the policy in training mode; the attack must evaluate it in eval
    rng = np.random.default_rng(0)
    victim = SB3Policy(model, rng.normal(size=11), rng.uniform(0.5, 2.0, 11))
    obs = torch.as_tensor(rng.normal(size=(7, 11)), dtype=torch.float32).requires_grad_(True)
    lean = victim.action_mean(obs)
    assert not model.policy.training
    (lean_grad,) = torch.autograd.grad(lean.square().sum(), obs)
    sb3 = model.policy.get_distribution(victim._features(obs)).distribution.mean
    (sb3_grad,) = torch.autograd.grad(sb3.square().sum(), obs)
    assert torch.equal(lean, sb3) and torch.equal(lean_grad, sb3_grad)

    class Shifted(type(model.policy)):  # overrides the distribution: the lean path steps aside
        def get_distribution(self, obs):  # type: ignore[no-untyped-def]
            dist = super().get_distribution(obs)
            dist.distribution.loc = dist.distribution.loc + 1.0
            return dist

    model.policy.__class__ = Shifted
    assert torch.equal(victim.action_mean(obs.detach()), lean.detach() + 1.0)


def _grads(module: torch.nn.Module) -> list[bytes | None]:
    return [None if p.grad is None else p.grad.numpy().tobytes() for p in module.parameters()]


def _optimizers(model: object) -> list[torch.optim.Optimizer]:
    policy = model.policy  # type: ignore[attr-defined]
    found = [getattr(policy, "optimizer", None)]
    found += [getattr(getattr(policy, n, None), "optimizer", None) for n in ("actor", "critic")]
    return [opt for opt in found if opt is not None]


def _state_bytes_of(optimizer: torch.optim.Optimizer) -> bytes:
    buffer = io.BytesIO()
    torch.save(optimizer.state_dict(), buffer)
    return buffer.getvalue()


def test_mad_attacks_a_team_of_actors() -> None:
    from advgame.agents.marl.nets import GaussianActor, TorchActorPolicy, actor_record

    pytest.importorskip("gymnasium_robotics", reason="MA-HalfCheetah-2x3 needs the mamujoco extra")
    game = advgame.make(
        "MA-HalfCheetah-2x3", disruptors=[ObservationDisruptor(eps=0.1)], max_episode_steps=8
    )
    team = {}
    for i, agent in enumerate(game.protagonists):
        n_obs = game.observation_space(agent).shape[0]
        space = game.action_space(agent)
        actor = GaussianActor(
            n_obs, space.shape[0], [16], generator=torch.Generator().manual_seed(i)
        )
        team[agent] = TorchActorPolicy(actor_record(actor, None, space.low, space.high))
    [attacked] = rollout(game, {**team, ADV: MADAttack(steps=3)}, seed=0)
    [nominal] = rollout(game, team, seed=0)
    assert attacked.length == nominal.length == 8
    assert attacked.clipped[ADV] == 0
    assert attacked.true_return != nominal.true_return
    with pytest.raises(ConfigError, match="needs a critic"):
        rollout(game, {**team, ADV: CriticAttack()}, seed=0)


def test_bad_uses_are_clear_errors() -> None:
    victim = KnownVictim(11, 3)
    game = advgame.make("Hopper-v5", disruptors=[ActionDisruptor(eps=0.1)])
    with pytest.raises(ConfigError, match="attacks observations"):
        build_policies(game, {"protagonist": victim, "action_adversary": MADAttack()})
    game = advgame.make("Hopper-v5", disruptors=[ObservationDisruptor(bounded=False)])
    with pytest.raises(ConfigError, match="needs a budget"):
        build_policies(game, {"protagonist": victim, ADV: MADAttack()})
    game = advgame.make("Hopper-v5", disruptors=[ObservationDisruptor(eps=0.1)])
    with pytest.raises(ConfigError, match="white-box access"):
        build_policies(game, {"protagonist": lambda obs: [0.0] * 3, ADV: MADAttack()})
    for bad in ({"steps": 0}, {"restarts": -1}, {"step_size": float("nan")}):
        with pytest.raises(ConfigError):
            MADAttack(**bad)  # type: ignore[arg-type]
