"""The Game's contract: move order, whose action counts, true payoffs, determinism, clear errors.

All on real simulators (MuJoCo Hopper-v5, Box2D LunarLander-v3); see `advgame.core.game` for the
sense/act moves these tests pin down.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import advgame
from advgame.adversaries import GaussianAdversary
from advgame.core.episodes import filler_action, rollout
from advgame.core.policy import AgentInfo
from advgame.core.schedule import Schedule
from advgame.disruptors import (
    ActionDisruptor,
    DynamicsDisruptor,
    ForceDisruptor,
    ObservationDisruptor,
    Param,
    RewardDisruptor,
)
from advgame.errors import (
    ActionError,
    AdvgameError,
    BudgetError,
    ConfigError,
    UnknownNameError,
    UnknownScenarioError,
)

P = "protagonist"
OBS, ACT, REW, DYN, FORCE = (
    "observation_adversary",
    "action_adversary",
    "reward_adversary",
    "dynamics_adversary",
    "force_adversary",
)


# -- helpers ---------------------------------------------------------------------------------
def hopper(disruptors: Any, steps: int = 30, **kwargs: Any) -> advgame.Game:
    return advgame.make("Hopper-v5", disruptors=disruptors, max_episode_steps=steps, **kwargs)


def fillers(game: advgame.Game, **given: Any) -> dict[str, Any]:
    """A valid action for every agent, with `given` overriding some of them."""
    out = {a: filler_action(game.action_space(a)) for a in game.possible_agents}
    out.update(given)
    return out


def sign_attack(s: np.ndarray) -> np.ndarray:
    """The observation adversary's deterministic choice: δ = f(s) = 0.05·sign(s), raw units."""
    return 0.05 * np.sign(s)


class ProtagonistRng:
    """Uniformly random protagonist actions from a generator of its own."""

    def __init__(self, game: advgame.Game, seed: int) -> None:
        self.space = game.action_space(P)
        self.rng = np.random.default_rng(seed)

    def __call__(self) -> np.ndarray:
        return self.rng.uniform(self.space.low, self.space.high).astype(self.space.dtype)


# -- (a) order within a step (invariant 3) ------------------------------------------------------
@pytest.mark.parametrize(("eps", "clipped_per_dim"), [(0.1, 0), (0.03, 1)])
def test_sense_move_perturbs_the_true_state_of_the_same_step(
    eps: float, clipped_per_dim: int
) -> None:
    game = hopper([ObservationDisruptor(eps=eps)], steps=40)
    encode = game.disruptors[OBS].encode
    act = ProtagonistRng(game, 1)
    obs, _ = game.reset(seed=0)
    previous: np.ndarray | None = None
    fresh_differs_from_stale = 0
    steps = 0
    while game.agents:
        # before the sense move: everyone sees the true state s_t, the simulator's own state
        s_t = obs[OBS]
        assert game.move == "sense" and game.next_movers == {OBS}
        assert np.array_equal(s_t, game.state())
        assert np.array_equal(s_t, game.task.env.unwrapped._get_obs())
        assert np.array_equal(obs[P], s_t)

        obs, rewards, terms, truncs, infos = game.step(
            fillers(game, **{OBS: encode(sign_attack(s_t))})
        )
        delta = np.clip(sign_attack(s_t), -eps, eps)
        assert np.array_equal(obs[P], s_t + delta), (obs[P] - s_t, delta)
        assert np.array_equal(obs[OBS], s_t) and np.array_equal(game.state(), s_t)
        assert infos[OBS] == {
            "acted": True,
            "clipped": clipped_per_dim * int(np.count_nonzero(s_t)),
        }
        assert not infos[P]["acted"] and all(r == 0.0 for r in rewards.values())
        assert not any(terms.values()) and not any(truncs.values())
        if previous is not None and not np.array_equal(
            obs[P], s_t + np.clip(sign_attack(previous), -eps, eps)
        ):
            fresh_differs_from_stale += 1

        assert game.move == "act" and game.next_movers == {P}
        previous = s_t
        obs, *_ = game.step(fillers(game, **{P: act()}))
        steps += 1
    assert steps >= 5
    # the test discriminates: a one-step-stale δ_{t-1} would have shown something else
    assert fresh_differs_from_stale >= 1


def test_stale_timing_lands_on_the_next_observation() -> None:
    game = hopper([ObservationDisruptor(eps=0.1, timing="stale")], steps=40)
    encode = game.disruptors[OBS].encode
    act = ProtagonistRng(game, 2)
    obs, _ = game.reset(seed=0)
    assert game.move == "act" and game.next_movers == {P, OBS}  # no sense move
    assert np.array_equal(obs[P], obs[OBS])  # nothing chosen yet at t = 0
    differs_from_fresh = 0
    steps = 0
    while True:
        s_t = obs[OBS]
        obs, rewards, _, _, infos = game.step({P: act(), OBS: encode(sign_attack(s_t))})
        steps += 1
        assert infos[OBS]["acted"] and infos[P]["acted"]
        assert rewards[OBS] == -infos[P]["payoff"]
        if not game.agents:
            break
        s_next = obs[OBS]
        assert np.array_equal(s_next, game.state())
        assert np.array_equal(obs[P], s_next + sign_attack(s_t)), (obs[P] - s_next, s_t)
        if not np.array_equal(obs[P], s_next + sign_attack(s_next)):
            differs_from_fresh += 1
    assert steps >= 5
    assert differs_from_fresh >= 1


# -- (b) who moves: next_movers and infos["acted"] --------------------------------------------
ALL_KINDS = (
    ObservationDisruptor(eps=0.1),
    ObservationDisruptor(eps=0.1, timing="stale", name="stale_adversary"),
    ActionDisruptor(eps=0.1),
    RewardDisruptor(eps=0.1),
    DynamicsDisruptor(params=[Param("mass", 0.8, 1.2, relative=True)]),
    ForceDisruptor(bodies=("foot",), axes="xz", max_force=3.0),
)


def _play(
    game: advgame.Game,
    seed: int,
    adversary_action: Callable[[str, int], Any],
    protagonist: Callable[[], Any],
) -> list[tuple[int, str, frozenset, dict]]:
    """Play one episode; return (t, move, next_movers, infos) of every move."""
    game.reset(seed=seed)
    for i, agent in enumerate(game.adversaries):  # reproducible .sample() for adversaries
        game.action_space(agent).seed(seed + i)
    log = []
    while game.agents:
        t, move, movers = game.t, game.move, game.next_movers
        actions = {a: adversary_action(a, t) for a in game.adversaries}
        actions[P] = protagonist()
        *_, infos = game.step(actions)
        log.append((t, move, movers, infos))
    return log


def test_sense_move_uses_only_observation_adversaries_and_act_move_the_rest() -> None:
    game = hopper(ALL_KINDS, steps=12)
    rng = ProtagonistRng(game, 3)
    log = _play(game, 0, lambda a, t: game.action_space(a).sample(), rng)
    act_movers = {P, "stale_adversary", ACT, REW, DYN, FORCE}
    assert [m for _, m, _, _ in log] == ["sense", "act"] * 12
    for t, move, movers, infos in log:
        expected = {OBS} if move == "sense" else act_movers
        assert movers == expected, (t, move, movers)
        assert {a for a, i in infos.items() if i["acted"]} == expected, (t, move, infos)


def test_every_n_and_per_episode_schedules_say_who_moves() -> None:
    disruptors = [
        ObservationDisruptor(eps=0.1, schedule=Schedule.every_n(3)),
        ActionDisruptor(eps=0.1, schedule=Schedule.every_n(3)),
        DynamicsDisruptor(params=[Param("gravity", 8.0, 12.0)], schedule=Schedule.per_episode()),
    ]
    game = hopper(disruptors, steps=10)
    log = _play(game, 0, lambda a, t: game.action_space(a).sample(), ProtagonistRng(game, 4))
    expected = []
    for t in range(10):
        if t % 3 == 0:
            expected.append((t, "sense", frozenset({OBS})))
        act = {P} | ({ACT} if t % 3 == 0 else set()) | ({DYN} if t == 0 else set())
        expected.append((t, "act", frozenset(act)))
    assert [(t, m, movers) for t, m, movers, _ in log] == expected
    for _, _, movers, infos in log:
        assert {a for a, i in infos.items() if i["acted"]} == movers


def test_action_of_an_inactive_adversary_does_not_count() -> None:
    """Off-schedule garbage from an every-3 action adversary changes nothing; on-schedule counts."""

    def run(off_schedule: float, on_schedule: float) -> list[np.ndarray]:
        game = hopper([ActionDisruptor(eps=0.5, schedule=Schedule.every_n(3))], steps=15)
        act = ProtagonistRng(game, 5)
        obs, _ = game.reset(seed=0)
        seen = [obs[P]]
        while game.agents:
            u = on_schedule if game.t % 3 == 0 else off_schedule
            obs, _, _, _, infos = game.step({P: act(), ACT: np.full(3, u, dtype=np.float32)})
            assert infos[ACT]["clipped"] == (3 if infos[ACT]["acted"] and abs(u) > 1 else 0)
            seen.append(obs[P])
        return seen

    base = run(off_schedule=1.0, on_schedule=1.0)
    off = run(off_schedule=-7.0, on_schedule=1.0)
    on = run(off_schedule=1.0, on_schedule=-1.0)
    assert len(base) == len(off)
    assert all(np.array_equal(a, b) for a, b in zip(base, off, strict=True))
    assert not all(np.array_equal(a, b) for a, b in zip(base, on, strict=False))


def test_phase_schedules_and_reset_option_switch() -> None:
    disruptors = [
        ObservationDisruptor(eps=0.1, schedule=Schedule(phase="eval")),
        ActionDisruptor(eps=0.1, schedule=Schedule(phase="train")),
    ]
    game = hopper(disruptors, steps=6)
    assert game.phase == "train"
    ones = lambda a, t: np.ones(game.action_space(a).shape, dtype=np.float32)  # noqa: E731

    obs, _ = game.reset(seed=0)
    assert game.move == "act" and game.next_movers == {P, ACT}
    log = _play(game, 0, ones, ProtagonistRng(game, 6))
    assert all(move == "act" and movers == {P, ACT} for _, move, movers, _ in log)
    assert all(not infos[OBS]["acted"] and infos[ACT]["acted"] for *_, infos in log)

    obs, _ = game.reset(seed=0, options={"phase": "eval"})
    assert game.phase == "eval"
    assert game.move == "sense" and game.next_movers == {OBS}
    obs, *_ = game.step(fillers(game, **{OBS: np.ones(11, dtype=np.float32)}))
    assert np.array_equal(obs[P], game.state() + 0.1)
    assert game.next_movers == {P}
    game.reset(seed=0)  # no options: the phase stays
    assert game.phase == "eval" and game.next_movers == {OBS}
    log = _play(game, 0, ones, ProtagonistRng(game, 6))
    assert [(m, movers) for _, m, movers, _ in log] == [("sense", {OBS}), ("act", {P})] * (
        len(log) // 2
    )

    game.reset(seed=0, options={"phase": "train"})
    assert game.phase == "train" and game.next_movers == {P, ACT}
    with pytest.raises(ConfigError, match="'test'"):
        game.reset(options={"phase": "test"})


def test_observation_adversary_inactive_in_train_phase_leaves_the_state_alone() -> None:
    game = hopper([ObservationDisruptor(eps=0.1, schedule=Schedule(phase="eval"))], steps=10)
    act = ProtagonistRng(game, 7)
    obs, _ = game.reset(seed=0)
    while game.agents:
        assert np.array_equal(obs[P], game.state())
        obs, *_ = game.step({P: act(), OBS: np.ones(11, dtype=np.float32)})


# -- (c) reward disruptor vs true reward, zero-sum on the true payoff ---------------------------
def test_reward_disruptor_changes_only_what_the_protagonist_observes() -> None:
    game = hopper([RewardDisruptor(eps=0.5)], steps=25)
    nominal = hopper([], steps=25)
    act_a, act_b = ProtagonistRng(game, 8), ProtagonistRng(nominal, 8)
    game.reset(seed=3)
    nominal.reset(seed=3)
    changed = steps = 0
    while game.agents:
        steps += 1
        u = 1.0 if game.t % 2 == 0 else -4.0  # -4 is clipped to -1
        _, rewards, _, _, infos = game.step({P: act_a(), REW: np.array([u], dtype=np.float32)})
        _, nom_rewards, _, _, nom_infos = nominal.step({P: act_b()})
        true = nom_rewards[P]
        assert infos[P]["true_reward"] == true == nom_infos[P]["true_reward"]
        assert rewards[P] == true + 0.5 * max(u, -1.0)
        assert infos[P]["payoff"] == true
        assert rewards[REW] == -true  # paid on the true payoff, not the observed reward
        assert infos[REW]["clipped"] == (1 if u < -1 else 0)
        changed += rewards[P] != true
    assert not nominal.agents
    assert steps >= 5 and changed == steps


def test_cost_disruptor_and_weighted_payoff() -> None:
    game = hopper(
        [RewardDisruptor(eps=0.25, signal="cost")], steps=20, cost_key="x_velocity", cost_weight=0.5
    )
    assert game.adversaries == ("cost_adversary",) and game.cost_weight == 0.5
    act = ProtagonistRng(game, 9)
    game.reset(seed=1)
    nonzero = 0
    while game.agents:
        _, rewards, _, _, infos = game.step({P: act(), "cost_adversary": np.ones(1, np.float32)})
        info = infos[P]
        assert info["true_cost"] == info["x_velocity"]
        assert info["cost"] == info["true_cost"] + 0.25
        assert rewards[P] == info["true_reward"]
        assert info["payoff"] == info["true_reward"] - 0.5 * info["true_cost"]
        assert rewards["cost_adversary"] == -info["payoff"]
        nonzero += info["true_cost"] != 0.0
    assert nonzero > 0


# -- (d) determinism (invariant 5) ----------------------------------------------------------
class _Recorder:
    def __init__(self, inner: Any, log: list[np.ndarray]) -> None:
        self.inner, self.log = inner, log

    def reset(self, seed: int | None = None) -> None:
        self.inner.reset(seed)

    def act(self, observation: Any) -> Any:
        self.log.append(np.array(observation, copy=True))
        return self.inner.act(observation)


class _Recording:
    """A PolicySpec wrapping another, recording every observation its policy acts on."""

    def __init__(self, spec: Any, log: list[np.ndarray]) -> None:
        self.spec, self.log = spec, log

    def build(self, info: AgentInfo) -> _Recorder:
        return _Recorder(self.spec.build(info), self.log)


class _RandomProtagonist:
    def __init__(self, space: Any, log: list[np.ndarray]) -> None:
        self.space, self.log = space, log
        self.rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, observation: Any) -> np.ndarray:
        self.log.append(np.array(observation, copy=True))
        return self.rng.uniform(self.space.low, self.space.high).astype(self.space.dtype)


ADVERSARY_NOISE = {
    OBS: GaussianAdversary(std=0.05),
    REW: GaussianAdversary(std=0.05),
    ACT: GaussianAdversary(std=0.05),
    DYN: GaussianAdversary(mean=1.0, std=0.1),  # relative factors around nominal
    FORCE: GaussianAdversary(std=2.0),
}


def _seeded_rollout(game: advgame.Game, seed: int) -> tuple[list, dict[str, list[np.ndarray]]]:
    logs: dict[str, list[np.ndarray]] = {a: [] for a in game.possible_agents}
    policies: dict[str, Any] = {a: _Recording(s, logs[a]) for a, s in ADVERSARY_NOISE.items()}
    policies[P] = _RandomProtagonist(game.action_space(P), logs[P])
    return rollout(game, policies, seed=seed, episodes=2), logs


def _same_logs(a: dict[str, list[np.ndarray]], b: dict[str, list[np.ndarray]]) -> bool:
    return a.keys() == b.keys() and all(
        len(a[k]) == len(b[k])
        and all(np.array_equal(x, y) for x, y in zip(a[k], b[k], strict=True))
        for k in a
    )


def test_seeded_rollouts_are_identical_step_by_step() -> None:
    game1 = advgame.make("Hopper-v5", preset="full", max_episode_steps=60)
    game2 = advgame.make("Hopper-v5", preset="full", max_episode_steps=60)
    assert set(game1.adversaries) == set(ADVERSARY_NOISE)
    res1, logs1 = _seeded_rollout(game1, 11)
    res2, logs2 = _seeded_rollout(game2, 11)
    assert res1 == res2
    assert all(r.length > 0 for r in res1)
    assert len(logs1[P]) == sum(r.length for r in res1)
    assert len(logs1[OBS]) == len(logs1[P])  # a sense move before every protagonist step
    assert len(logs1[DYN]) == 2  # per-episode schedule: once per episode
    assert _same_logs(logs1, logs2)
    # the protagonist acted on perturbed observations (the noise is live)
    assert not all(np.array_equal(p, s) for p, s in zip(logs1[P], logs1[OBS], strict=True))

    # the same game played again from the same seed: nothing leaks across episodes
    res3, logs3 = _seeded_rollout(game1, 11)
    assert res3 == res1 and _same_logs(logs3, logs1)

    res4, logs4 = _seeded_rollout(game2, 12)
    assert res4 != res1
    assert not np.array_equal(logs4[P][0], logs1[P][0])
    assert not _same_logs(logs4, logs1)


# -- (e) clear errors -----------------------------------------------------------------------
def _raises(fn: Callable[[], Any], exc: type[Exception], *fragments: str) -> AdvgameError:
    with pytest.raises(exc) as info:
        fn()
    err = info.value
    assert isinstance(err, AdvgameError), f"{type(err).__name__} is not an AdvgameError: {err}"
    for fragment in fragments:
        assert fragment in str(err), f"{fragment!r} not in {str(err)!r}"
    return err


@pytest.mark.parametrize(
    ("bad", "good"), [("HalfCheetah-v4", "HalfCheetah-v5"), ("Hoper-v5", "Hopper-v5")]
)
def test_unknown_scenario_suggests_the_nearest_id(bad: str, good: str) -> None:
    err = _raises(
        lambda: advgame.make(bad), UnknownScenarioError, repr(bad), f'Did you mean "{good}"?'
    )
    assert str(err).startswith("No scenario")  # not a KeyError repr
    _raises(lambda: advgame.core.registry.scenario_spec(bad), UnknownScenarioError, f'"{good}"')


CONFIG_ERRORS: list[Any] = [
    pytest.param(
        lambda: advgame.make("Hopper-v5", preset="atlas"),
        UnknownNameError,
        ("'atlas'", 'Did you mean "atla"?'),
        id="unknown-preset",
    ),
    pytest.param(
        lambda: advgame.make("Hopper-v5", disruptors={"observaton": {"eps": 0.1}}),
        UnknownNameError,
        ("'observaton'", 'Did you mean "observation"?'),
        id="unknown-kind",
    ),
    pytest.param(
        lambda: advgame.make("Hopper-v5", disruptors=[ForceDisruptor(bodies=("torsoo",))]),
        UnknownNameError,
        ("'torsoo'", 'Did you mean "torso"?'),
        id="force-unknown-body",
    ),
    pytest.param(
        lambda: advgame.make("Hopper-v5", disruptors={"force": {"bodies": ["fot"]}}),
        UnknownNameError,
        ("'fot'", 'Did you mean "foot"?'),
        id="force-unknown-body-dict",
    ),
    pytest.param(
        lambda: hopper([DynamicsDisruptor(params=[Param("mass", 0.5, 1.5, names=("thig",))])]),
        UnknownNameError,
        ("'thig'", 'Did you mean "thigh"?'),
        id="param-unknown-body",
    ),
    pytest.param(
        lambda: Param("masss", 0.5, 1.5),
        UnknownNameError,
        ("'masss'", '"mass"'),
        id="param-unknown-kind",
    ),
    pytest.param(
        lambda: advgame.make("Hopper-v5", preset="default", disruptors=[]),
        ConfigError,
        ("preset", "disruptors"),
        id="preset-and-disruptors",
    ),
    pytest.param(
        lambda: advgame.make("Hopper-v5", phase="test"), ConfigError, ("'test'",), id="bad-phase"
    ),
    pytest.param(
        lambda: advgame.make("Hopper-v5", cost_weight=-1.0),
        ConfigError,
        ("-1.0",),
        id="negative-cost-weight",
    ),
]

BUDGET_ERRORS: list[Any] = [
    pytest.param(lambda: ObservationDisruptor(eps=-0.1), ("-0.1",), id="obs-negative"),
    pytest.param(lambda: ObservationDisruptor(eps=math.nan), ("nan",), id="obs-nan"),
    pytest.param(
        lambda: ObservationDisruptor(eps=math.inf), ("inf", "bounded=False"), id="obs-inf"
    ),
    pytest.param(
        lambda: hopper([ObservationDisruptor(eps=[0.1, 0.2])]), ("(2,)", "11"), id="obs-wrong-shape"
    ),
    pytest.param(lambda: ObservationDisruptor(eps=[[0.1]]), ("(1, 1)",), id="obs-2d"),
    pytest.param(
        lambda: advgame.make("Hopper-v5", disruptors={"observation": {"eps": -0.5}}),
        ("-0.5",),
        id="obs-negative-dict",
    ),
    pytest.param(lambda: ActionDisruptor(eps=-1.0), ("-1.0",), id="action-negative"),
    pytest.param(lambda: ActionDisruptor(eps=[0.1, math.nan]), ("nan",), id="action-nan"),
    pytest.param(
        lambda: hopper([ActionDisruptor(eps=[0.1, 0.2])]), ("(2,)", "3"), id="action-wrong-shape"
    ),
    pytest.param(lambda: ActionDisruptor(mode="noisy", alpha=1.5), ("1.5",), id="action-alpha"),
    pytest.param(lambda: RewardDisruptor(eps=math.nan), ("nan",), id="reward-nan"),
    pytest.param(lambda: RewardDisruptor(eps=-0.2), ("-0.2",), id="reward-negative"),
    pytest.param(lambda: RewardDisruptor(eps=[0.1, 0.2]), ("(2,)",), id="reward-wrong-shape"),
    pytest.param(lambda: ForceDisruptor(max_force=-3.0), ("-3.0",), id="force-negative"),
    pytest.param(lambda: ForceDisruptor(max_force=math.nan), ("nan",), id="force-nan"),
    pytest.param(
        lambda: ForceDisruptor(bodies=("torso",), max_force=[1.0, 2.0]),
        ("(2,)",),
        id="force-wrong-shape",
    ),
    pytest.param(lambda: Param("mass", 2.0, 1.0), ("2.0", "1.0"), id="param-low-above-high"),
    pytest.param(lambda: Param("gravity", math.nan, 1.0), ("nan",), id="param-nan"),
    pytest.param(lambda: Param("friction", -0.5, 1.0), ("-0.5",), id="param-negative"),
]


@pytest.mark.parametrize(("fn", "exc", "fragments"), CONFIG_ERRORS)
def test_config_errors_name_the_bad_value(
    fn: Callable[[], Any], exc: type[Exception], fragments: tuple[str, ...]
) -> None:
    _raises(fn, exc, *fragments)


@pytest.mark.parametrize(("fn", "fragments"), BUDGET_ERRORS)
def test_bad_budgets_are_budget_errors(fn: Callable[[], Any], fragments: tuple[str, ...]) -> None:
    assert issubclass(BudgetError, AdvgameError)
    _raises(fn, BudgetError, *fragments)


@pytest.fixture
def game() -> advgame.Game:
    """Hopper with an observation (sense) and an action adversary, reset; next is a sense move."""
    g = hopper([ObservationDisruptor(eps=0.1), ActionDisruptor(eps=0.1)], steps=5)
    g.reset(seed=0)
    assert g.move == "sense"
    return g


def _to_act_move(game: advgame.Game) -> None:
    game.step(fillers(game))
    assert game.move == "act"


@pytest.mark.parametrize("move", ["sense", "act"])
def test_missing_and_unknown_agents(game: advgame.Game, move: str) -> None:
    if move == "act":
        _to_act_move(game)
    actions = fillers(game)
    del actions[ACT]
    _raises(lambda: game.step(actions), ActionError, "missing", repr(ACT))
    actions = fillers(game, action_adversry=np.zeros(3, np.float32))
    _raises(lambda: game.step(actions), ActionError, "'action_adversry'", f'Did you mean "{ACT}"?')
    _raises(lambda: game.action_space("protagonst"), ActionError, "'protagonst'", '"protagonist"')
    _raises(lambda: game.observation_space("nobody"), ActionError, "'nobody'")


@pytest.mark.parametrize(
    ("agent", "value", "fragments"),
    [
        (P, np.zeros(4), ("(4,)", "(3,)")),
        (P, np.array([0.0, math.nan, 0.0]), ("NaN",)),
        (P, np.array([0.0, math.inf, 0.0]), ("inf",)),
        (ACT, np.zeros(2), ("(2,)", "(3,)")),
        (ACT, np.array([math.nan, 0.0, 0.0]), ("NaN",)),
        (P, "0.1 0.2 0.3", ()),  # text, e.g. from a language-model controller
        (ACT, "0.1 0.2 0.3", ()),  # invariant 1: an LLM adversary's text is an error, clearly
    ],
    ids=["p-shape", "p-nan", "p-inf", "adv-shape", "adv-nan", "p-text", "adv-text"],
)
def test_bad_actions_on_the_act_move_name_the_agent(
    game: advgame.Game, agent: str, value: Any, fragments: tuple[str, ...]
) -> None:
    _to_act_move(game)
    _raises(
        lambda: game.step(fillers(game, **{agent: value})), ActionError, repr(agent), *fragments
    )


@pytest.mark.parametrize("value", [np.full(11, math.nan), np.zeros(10)], ids=["nan", "shape"])
def test_bad_observation_adversary_action_on_the_sense_move(game: advgame.Game, value: Any) -> None:
    _raises(lambda: game.step(fillers(game, **{OBS: value})), ActionError, repr(OBS))


@pytest.mark.parametrize("bad", [7, 1.5, -1, [1], None, "left", math.nan, math.inf])
def test_bad_discrete_protagonist_action(bad: Any) -> None:
    pytest.importorskip("Box2D", reason="LunarLander-v3 needs the box2d extra")
    game = advgame.make("LunarLander-v3")
    game.reset(seed=0)
    game.step(fillers(game))  # the default preset's observation adversary senses first
    assert game.next_movers == {P, ACT}  # then the probabilistic action adversary acts
    _raises(lambda: game.step(fillers(game, **{P: bad})), ActionError, repr(P), repr(bad))


def test_rejected_step_leaves_the_game_unchanged() -> None:
    def build() -> advgame.Game:
        g = advgame.make("Hopper-v5", preset="full", max_episode_steps=10)
        g.reset(seed=4)
        g.step(fillers(g))  # sense move
        return g

    game, twin = build(), build()
    before = (game.t, game.move, game.next_movers)
    good = fillers(
        game, **{a: np.full(game.action_space(a).shape, 0.5, np.float32) for a in game.next_movers}
    )
    bad = dict(good, protagonist=np.array([0.0, math.nan, 0.0]))
    _raises(lambda: game.step(bad), ActionError, repr(P))
    assert (game.t, game.move, game.next_movers) == before
    out, twin_out = game.step(good), twin.step(good)
    for a in game.possible_agents:
        assert np.array_equal(out[0][a], twin_out[0][a])
        assert out[1][a] == twin_out[1][a]


def test_step_after_the_episode_ends() -> None:
    game = hopper([ActionDisruptor(eps=0.1)], steps=3)
    game.reset(seed=0)
    for _ in range(3):
        _, _, _, truncs, _ = game.step(fillers(game))
    assert all(truncs.values()) and game.agents == [] and game.next_movers == frozenset()
    _raises(lambda: game.step(fillers(game)), ActionError, "reset()")
    game.reset(seed=0)  # and reset brings it back
    assert game.agents == [P, ACT]
