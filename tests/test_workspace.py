"""The workspace disruptor on a Gymnasium MuJoCo task: a setup move, then the nominal model back.

The robosuite presets (table, door-shift, lift-shift) are tested in tests/test_robosuite.py;
here the disruptor itself runs on Pusher-v5, whose observation shows the goal's position.
"""

from __future__ import annotations

import numpy as np
import pytest

import advgame
from advgame.disruptors import Shift, WorkspaceDisruptor
from advgame.errors import ConfigError, UnknownNameError

GOAL = Shift("goal", bodies=["goal"], offset=(0.1, -0.05, 0.0), geoms=["table"])


def test_setup_move_moves_the_goal_before_the_protagonist_sees_it() -> None:
    game = advgame.make("Pusher-v5", disruptors=[WorkspaceDisruptor(shifts=[GOAL])])
    first, _ = game.reset(seed=0)
    assert game.move == "sense" and game.next_movers == frozenset({"workspace_adversary"})
    rgba0 = game.task.sim.model.geom_rgba.copy()
    move = game.play({"workspace_adversary": np.array([0.5], dtype=np.float32)})
    assert move.kind == "sense" and move.clipped == {"workspace_adversary": 0}
    shown = game.observe("protagonist")
    np.testing.assert_allclose(shown[20:23] - first["protagonist"][20:23], [0.05, -0.025, 0.0])
    assert game.state() is not None and np.array_equal(game.state(), shown)
    table = game.task.sim.geom_id("table")
    np.testing.assert_allclose(
        game.task.sim.model.geom_rgba[table], rgba0[table] + 0.5 * ([0, 0, 1, 1] - rgba0[table])
    )
    assert game.next_movers >= {"protagonist"}
    while game.agents:  # the rest of the episode is ordinary: no second setup move
        game.play({a: game.action_space(a).sample() * 0 for a in game.next_movers})
        assert "workspace_adversary" not in game.next_movers
    again, _ = game.reset(seed=0)
    np.testing.assert_array_equal(again["protagonist"], first["protagonist"])
    np.testing.assert_array_equal(game.task.sim.model.geom_rgba, rgba0)


def test_eval_only_schedule_skips_the_setup_move_in_training() -> None:
    from advgame.core.schedule import Schedule

    spec = WorkspaceDisruptor(shifts=[GOAL], schedule=Schedule(phase="eval"))
    game = advgame.make("Pusher-v5", disruptors=[spec])
    game.reset(seed=0)
    assert "protagonist" in game.next_movers  # no setup move in the training phase
    game.reset(seed=0, options={"phase": "eval"})
    assert game.next_movers == frozenset({"workspace_adversary"})


def test_bad_workspace_specs_say_what_is_wrong() -> None:
    with pytest.raises(UnknownNameError, match="goal"):
        advgame.make(
            "Pusher-v5", disruptors=[WorkspaceDisruptor(shifts=[Shift("g", bodies=["gaol"])])]
        )
    with pytest.raises(ConfigError, match="moves and recolours nothing"):
        Shift("nothing")
    with pytest.raises(ConfigError, match="persist"):
        from advgame.core.schedule import Schedule

        WorkspaceDisruptor(shifts=[GOAL], schedule=Schedule(persist=True))
