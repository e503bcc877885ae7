"""The Game's contract, part three: clear errors.

Unknown scenarios, presets, kinds, bodies and parameters suggest the nearest name; bad budgets are
`BudgetError`s naming the value; bad, missing or unknown agents' actions are `ActionError`s naming
the agent, on either move, and a rejected step leaves the game unchanged. On real simulators
(MuJoCo Hopper-v5, Box2D LunarLander-v3).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import advgame
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
from tests._game_helpers import ACT, OBS, P, fillers, hopper


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
