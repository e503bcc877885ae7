"""OMPO's non-stationary tasks as presets of Hopper-v5, Walker2d-v5, Ant-v5 and Humanoid-v5.

The numbers and the geometry are those of the code of OMPO's authors (Luo et al., "OMPO: A
Unified Framework for RL under Policy and Dynamics Shifts", ICML 2024; github.com/Roythuly/OMPO):
``main_non_stationary.py`` sets each training episode's dynamics before its reset, in episode
``i = 1, 2, ...`` (line 84: ``itertools.count(1)``), and ``Non_stationary_env/*_random.py``
writes them into the model. Presets of each task:

* ``ompo-nonstationary``: OMPO's per-episode sinusoid, ``base + amplitude·sin(ω·i)``, played by
  `SinusoidAdversary` with ``start=1`` (the first episode a policy plays is OMPO's first).
* ``ompo-low``, ``ompo-mid``, ``ompo-high``: the range's lower end, centre and upper end held
  constant in every episode (``base - amplitude``, ``base``, ``base + amplitude``), for
  evaluation columns at fixed points of the range.

Per task (value: formula; OMPO's line):

* Hopper-v5: torso, foot capsule half-lengths ``(0.4, 0.39) + (0.1, 0.1)·sin(0.2·i)``
  (``main_non_stationary.py`` lines 85-88; geometry ``hopper_random.py`` lines 26-30).
* Walker2d-v5: torso, both feet half-lengths ``(0.2, 0.1) + (0.1, 0.05)·sin(0.3·i)``
  (lines 89-92; ``walker2d_random.py`` lines 27-33).
* Ant-v5: gravity, wind ``(14.715, 1.0) + (4.905, 0.2)·sin(0.5·i)`` (lines 93-96;
  ``ant_random.py`` lines 21-22 and 37-38).
* Humanoid-v5: gravity, wind ``(14.715, 1.0) + (4.905, 0.5)·sin(0.5·i)`` (lines 97-100;
  ``humanoid_random.py`` lines 21-22 and 37-38).

Mapping to Gymnasium v5 (OMPO edits gym's v3 models by index; the v5 models compile to the same
arrays, and the names are used here). OMPO's torso edit, ``body_pos[1][2] = 1.05 + L``,
``body_pos[2][2] = -L`` (``body_pos[5][2] = -L`` too on Walker2d), ``geom_size[1][1] = L``,
gives the torso capsule (``torso_geom``, nominal half-length 0.2) the half-length ``L`` and
moves the ``torso`` body up by ``L - 0.2`` while ``thigh`` (and ``thigh_left``) move down by as
much in its frame: the torso grows upward from the hip, the legs are unchanged
(`Param` ``"capsule"`` with ``anchor="base"``). ``geom_size[4][1]`` (``[7][1]``) is the half-
length of ``foot_geom`` (``foot_left_geom``), nominal 0.195 on Hopper and 0.1 on Walker2d,
which grows at both ends (``anchor="centre"``). So Hopper's torso and foot are 1.5-2.5 times
their nominal half-lengths (OMPO's numbers are half-lengths, not full lengths centred on the
nominal model), and Walker2d's are centred on nominal. Ant and Humanoid: OMPO sets
``opt.viscosity = 0.00002`` and ``opt.density = 1.2`` at construction and, per episode,
``opt.gravity = [0, 0, -g]`` and ``opt.wind = [-w, 0, 0]``: a wind of speed ``w`` blowing
along -x, against the Ant's forward direction (``Param("wind", axis=(-1, 0, 0),
air_viscosity=0.00002)``, density 1.2 while it blows, which is always: ``w >= 0.5``).

Deviations, each chosen: the shapes are OMPO's in-place edits (masses and inertias stay
nominal, as in OMPO), but the collision bounds MuJoCo computes at compile time are updated with
them (OMPO's stay stale, so a lengthened foot's tips can pass through the floor; see
`advgame.disruptors.capsule`). The dynamics are set by the dynamics adversary's move at the
start of the episode, before the first simulator step, where OMPO sets them before the reset;
the reset state is the same (Gymnasium's reset draws joint positions, which the shapes do not
change). OMPO evaluates Hopper on the nominal body (``env.reset()`` without lengths, line 169):
a quirk not copied; these presets play the shifted body in evaluation too.
"""

from __future__ import annotations

from dataclasses import dataclass

from advgame.adversaries import ConstantAdversary, SinusoidAdversary
from advgame.core.registry import Preset
from advgame.core.schedule import Schedule
from advgame.disruptors import DynamicsDisruptor, Param

__all__ = ["OMPO_TASKS", "OmpoTask", "ompo_presets"]

_REPO = "Roythuly/OMPO"


@dataclass(frozen=True)
class OmpoTask:
    """One of OMPO's non-stationary tasks: its parameters and its sinusoid."""

    params: tuple[Param, ...]
    """The dynamics parameters, in the order of `base` and `amplitude`."""
    base: tuple[float, ...]
    """The sinusoid's centre per parameter."""
    amplitude: tuple[float, ...]
    """Its amplitude per parameter."""
    frequency: float
    """``ω`` per episode index."""
    what: str
    """The parameters in words."""
    source: str
    """Where in OMPO's code the numbers and the edits are."""

    def value(self, sign: float) -> tuple[float, ...]:
        """``base + sign·amplitude``: the range's low end (-1), centre (0) or high end (1).

        Rounded to 12 decimals, so that the ends are the intervals' ends exactly (9.81, not
        14.715 - 4.905 = 9.809999999999999, which the disruptor would clip).
        """
        pairs = zip(self.base, self.amplitude, strict=True)
        return tuple(round(b + sign * a, 12) for b, a in pairs)


def _gravity_wind(wind_amplitude: float, lines: str, file: str) -> OmpoTask:
    wind = Param(
        "wind", 1.0 - wind_amplitude, 1.0 + wind_amplitude,
        axis=(-1.0, 0.0, 0.0), air_density=1.2, air_viscosity=0.00002,
    )  # fmt: skip
    return OmpoTask(
        params=(Param("gravity", 9.81, 19.62), wind),
        base=(14.715, 1.0),
        amplitude=(4.905, wind_amplitude),
        frequency=0.5,
        what="gravity, wind along -x (density 1.2, viscosity 2e-5)",
        source=f"main_non_stationary.py L{lines}, {file} L21-22, L37-38",
    )


OMPO_TASKS: dict[str, OmpoTask] = {
    "Hopper-v5": OmpoTask(
        params=(
            Param("capsule", 0.3, 0.5, names=("torso",), anchor="base"),
            Param("capsule", 0.29, 0.49, names=("foot",)),
        ),
        base=(0.4, 0.39),
        amplitude=(0.1, 0.1),
        frequency=0.2,
        what="torso, foot capsule half-lengths (torso up from the hip, masses nominal)",
        source="main_non_stationary.py L85-88, Non_stationary_env/hopper_random.py L26-30",
    ),
    "Walker2d-v5": OmpoTask(
        params=(
            Param("capsule", 0.1, 0.3, names=("torso",), anchor="base"),
            Param("capsule", 0.05, 0.15, names=("foot", "foot_left")),
        ),
        base=(0.2, 0.1),
        amplitude=(0.1, 0.05),
        frequency=0.3,
        what="torso, feet capsule half-lengths (torso up from the hip, masses nominal)",
        source="main_non_stationary.py L89-92, Non_stationary_env/walker2d_random.py L27-33",
    ),
    "Ant-v5": _gravity_wind(0.2, "93-96", "Non_stationary_env/ant_random.py"),
    "Humanoid-v5": _gravity_wind(0.5, "97-100", "Non_stationary_env/humanoid_random.py"),
}
"""OMPO's non-stationary tasks by scenario id (see the module docstring)."""


def ompo_presets(env_id: str) -> dict[str, Preset]:
    """The ``ompo-*`` presets of `env_id` (empty if OMPO has no non-stationary task for it)."""
    task = OMPO_TASKS.get(env_id)
    if task is None:
        return {}
    spec = DynamicsDisruptor(params=task.params, schedule=Schedule.per_episode())
    where = f"OMPO ({_REPO} {task.source})"
    wave = SinusoidAdversary(task.base, task.amplitude, task.frequency, start=1)
    out = {
        "ompo-nonstationary": Preset(
            (spec,),
            {"dynamics_adversary": wave},
            f"{where}: {task.what} = {task.base} + {task.amplitude}·sin({task.frequency}·i), "
            "episode i = 1, 2, ...",
        )
    }
    for name, sign in (("low", -1.0), ("mid", 0.0), ("high", 1.0)):
        value = task.value(sign)
        out[f"ompo-{name}"] = Preset(
            (spec,),
            {"dynamics_adversary": ConstantAdversary(value)},
            f"{where}: {task.what} held at {value} "
            f"(the range's {'centre' if sign == 0 else name + ' end'})",
        )
    return out
