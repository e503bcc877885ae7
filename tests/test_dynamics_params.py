"""Dynamics disruptors on real MuJoCo tasks, one parameter kind at a time: they change the
physics, and nothing leaks.

For each dynamics parameter kind (mass, gravity, wind, friction, damping, gear, length):

* a shifted value really changes the simulated trajectory compared with the nominal model, from
  the same seeded state under the same protagonist actions;
* a zero-width interval at the nominal value is the identity: the game plays exactly the plain
  Gymnasium trajectory;
* a length shift (a recompiled model) is reproducible across episodes;
* ``game.reset()`` restores the nominal model exactly (design invariant 4).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from advgame.disruptors import Param
from tests._dynamics_helpers import (
    DYN,
    VX,
    VZ,
    P,
    changed_keys,
    make_game,
    model_snapshot,
    play_gym,
)


@dataclass(frozen=True)
class Case:
    """One parameter kind: a shift with its interval end, and the zero-width nominal interval."""

    env_id: str
    shift: Param
    end: float  # adversary action selecting an end of the shift's interval
    nominal: Param  # low == high == nominal value
    steps: int  # act moves after which the states are compared
    touches: frozenset[str]  # model arrays the shift must change
    check: Callable[[Any, dict[str, np.ndarray]], None]  # the live model holds the shifted value


def _torso(sim) -> int:
    return sim.body_id("torso")


def _check_mass(sim, nom):
    t = _torso(sim)
    assert sim.model.body_mass[t] == 3.0 * nom["body_mass"][t]
    np.testing.assert_allclose(sim.model.body_inertia[t], 3.0 * nom["body_inertia"][t])


def _check_gravity(sim, nom):
    assert np.array_equal(sim.model.opt.gravity, [0.0, 0.0, -19.62])


def _check_wind(sim, nom):
    assert np.array_equal(sim.model.opt.wind, [10.0, 0.0, 0.0])
    assert sim.model.opt.density == 1.2  # the Param's air density: wind needs a medium


def _check_friction(sim, nom):
    assert np.all(sim.model.geom_friction[:, 0] == 0.05)


def _check_damping(sim, nom):
    assert np.array_equal(sim.model.dof_damping, 10.0 * nom["dof_damping"])
    assert np.any(nom["dof_damping"] > 0)


def _check_gear(sim, nom):
    assert np.array_equal(sim.model.actuator_gear[:, 0], 1.5 * nom["actuator_gear"][:, 0])


def _check_length(full: float, nominal_full: float):
    def check(sim, nom):
        geom = sim.model.body_geomadr[_torso(sim)]
        assert sim.model.geom_size[geom, 1] == pytest.approx(full / 2, rel=1e-12)
        # The capsule was rebuilt, so its mass follows its length (a longer capsule is heavier).
        t = _torso(sim)
        assert (sim.model.body_mass[t] > nom["body_mass"][t]) == (full > nominal_full)

    return check


CASES = {
    "mass": Case(
        "Hopper-v5",
        Param("mass", 0.5, 3.0, names=("torso",), relative=True),
        1.0,
        Param("mass", 1.0, 1.0, names=("torso",), relative=True),
        1,
        frozenset({"body_mass", "body_inertia"}),
        _check_mass,
    ),
    "gravity": Case(
        "Hopper-v5",
        Param("gravity", 9.81, 19.62),
        1.0,
        Param("gravity", 9.81, 9.81),
        1,
        frozenset({"gravity"}),
        _check_gravity,
    ),
    "wind": Case(
        "Hopper-v5",
        Param("wind", 0.0, 10.0),
        1.0,
        Param("wind", 0.0, 0.0),
        1,
        frozenset({"wind", "density"}),
        _check_wind,
    ),
    # Friction acts only through contacts; Hopper's foot first touches the floor ~8 steps in.
    "friction": Case(
        "Hopper-v5",
        Param("friction", 0.05, 1.0),
        -1.0,
        Param("friction", 1.0, 1.0, relative=True),
        15,
        frozenset({"geom_friction"}),
        _check_friction,
    ),
    "damping": Case(
        "Hopper-v5",
        Param("damping", 1.0, 10.0, relative=True),
        1.0,
        Param("damping", 1.0, 1.0, relative=True),
        1,
        frozenset({"dof_damping"}),
        _check_damping,
    ),
    "gear": Case(
        "Hopper-v5",
        Param("gear", 0.5, 1.5, relative=True),
        1.0,
        Param("gear", 1.0, 1.0, relative=True),
        1,
        frozenset({"actuator_gear"}),
        _check_gear,
    ),
    "length-hopper": Case(
        "Hopper-v5",
        Param("length", 0.3, 0.5, names=("torso",)),
        1.0,
        Param("length", 0.4, 0.4, names=("torso",)),
        1,
        frozenset({"geom_size", "body_mass", "body_inertia"}),
        _check_length(0.5, 0.4),
    ),
    "length-walker": Case(
        "Walker2d-v5",
        Param("length", 0.2, 0.6, names=("torso",)),
        -1.0,
        Param("length", 0.4, 0.4, names=("torso",)),
        1,
        frozenset({"geom_size", "body_mass", "body_inertia"}),
        _check_length(0.2, 0.4),
    ),
}


def protagonist_actions(game, n: int, seed: int, scale: float = 1.0) -> list[np.ndarray]:
    space = game.action_space(P)
    rng = np.random.default_rng(seed)
    return [(scale * rng.uniform(space.low, space.high)).astype(space.dtype) for _ in range(n)]


def play(
    game,
    seed: int,
    actions: list[np.ndarray],
    adversary: float,
    on_step: Callable[[Any], None] | None = None,
) -> list[np.ndarray]:
    """Reset with `seed` and play the protagonist actions; return the observations after each."""
    game.reset(seed=seed)
    out = []
    adv = np.full(game.action_space(DYN).shape, adversary, dtype=np.float32)
    for a in actions:
        assert game.next_movers == {P, DYN}
        obs, _, term, trunc, _ = game.step({P: a, DYN: adv})
        out.append(np.array(obs[P]))
        if on_step is not None:
            on_step(game)
        if term[P] or trunc[P]:
            break
    return out


@pytest.mark.parametrize("kind", list(CASES))
def test_shift_changes_the_next_state(kind):
    case = CASES[kind]
    shifted, nominal = make_game(case.env_id, case.shift), make_game(case.env_id, case.nominal)
    try:
        nom_model = model_snapshot(shifted.task.sim)
        # Moderate actions keep the hopper healthy (no early termination) for all steps.
        actions = protagonist_actions(shifted, case.steps, seed=11, scale=0.3)
        contacts: list[int] = []

        def watch(game):
            case.check(game.task.sim, nom_model)
            contacts.append(game.task.sim.data.ncon)

        obs_shift = play(shifted, 7, actions, case.end, on_step=watch)
        obs_nom = play(nominal, 7, actions, 0.0)
        assert len(obs_shift) == len(obs_nom) == case.steps
        # The earlier states are identical when the parameter cannot act before contact ...
        if kind == "friction":
            assert max(contacts) > 0, "the hopper never touched the floor: friction untested"
            first = contacts.index(next(c for c in contacts if c > 0))
            for k in range(first):
                assert np.array_equal(obs_shift[k], obs_nom[k])
        # ... and the final state is clearly different (MuJoCo is deterministic, so an unused
        # parameter would give bit-identical states).
        diff = np.abs(obs_shift[-1] - obs_nom[-1])
        assert diff.max() > 1e-6, diff
        if kind == "gravity":  # twice the gravity: the hopper falls faster
            assert obs_shift[-1][VZ] < obs_nom[-1][VZ]
        if kind == "wind":  # a +x wind drags the hopper forward
            assert obs_shift[-1][VX] > obs_nom[-1][VX]
    finally:
        shifted.close()
        nominal.close()


@pytest.mark.parametrize("kind", list(CASES))
def test_zero_width_interval_at_nominal_plays_the_plain_task(kind):
    """A nominal-valued shift is the identity: the trajectory of the plain Gymnasium env.

    Checked in two consecutive episodes, since MuJoCo keeps model edits across resets. Length
    changes recompile the model from its XML; the recompiled capsule's half-length (0.2) may
    differ from the XML's fromto-derived one in the last bit, so lengths get a 1e-9 tolerance.
    """
    case = CASES[kind]
    game = make_game(case.env_id, case.nominal)
    try:
        actions = protagonist_actions(game, 25, seed=3)
        for episode in range(2):
            seed = 100 + episode
            got = play(game, seed, actions, 0.0)
            want = play_gym(case.env_id, seed, actions)
            assert len(got) == len(want), f"episode {episode}: episode lengths differ"
            atol = 1e-9 if case.shift.kind == "length" else 0.0
            for t, (g, w) in enumerate(zip(got, want, strict=True)):
                np.testing.assert_allclose(
                    g, w, rtol=0, atol=atol, err_msg=f"{kind}: episode {episode}, step {t}"
                )
    finally:
        game.close()


@pytest.mark.parametrize("kind", ["length-hopper", "length-walker"])
def test_length_shift_is_reproducible_across_episodes(kind):
    """Same seed, same actions, same length shift: the same trajectory in every episode.

    A length shift recompiles the model during the step; the simulation must carry on from the
    seeded initial state in the first episode exactly as in later ones (design invariant 5).
    """
    case = CASES[kind]
    game = make_game(case.env_id, case.shift)
    try:
        actions = protagonist_actions(game, 10, seed=5, scale=0.3)
        episodes = [play(game, 9, actions, case.end) for _ in range(3)]
        for later in episodes[1:]:
            assert len(later) == len(episodes[0])
            for t, (a, b) in enumerate(zip(episodes[0], later, strict=True)):
                np.testing.assert_array_equal(a, b, err_msg=f"{kind}: step {t}")
    finally:
        game.close()


@pytest.mark.parametrize("kind", list(CASES))
def test_reset_restores_the_nominal_model_exactly(kind):
    case = CASES[kind]
    game = make_game(case.env_id, case.shift)
    try:
        sim = game.task.sim
        model0 = sim.model
        before = model_snapshot(sim)  # before any reset or step
        game.reset(seed=0)
        assert not changed_keys(before, model_snapshot(sim))
        rng = np.random.default_rng(0)
        for episode, adversary in enumerate([case.end, None, -0.5 * case.end]):
            game.reset(seed=episode)
            assert not changed_keys(before, model_snapshot(sim)), f"episode {episode} began shifted"
            for t in range(4):
                u = rng.uniform(-1, 1) if adversary is None else adversary
                game.step(
                    {
                        P: np.zeros(game.action_space(P).shape, np.float32),
                        DYN: np.array([u], dtype=np.float32),
                    }
                )
                if t == 0:
                    assert changed_keys(before, model_snapshot(sim)) & case.touches, (
                        "the shift did not reach the model: this test would prove nothing"
                    )
            game.reset()
            after = model_snapshot(sim)
            assert not changed_keys(before, after), changed_keys(before, after)
            if case.shift.kind == "length":
                assert sim.model is model0  # the nominal compiled model is back, not a rebuild
    finally:
        game.close()
