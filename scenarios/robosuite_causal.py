"""The paper's causal robosuite tasks, LiftCausal and DoorCausal, as games with spurious features.

Robust Gymnasium's Figure 3 (c-d) trains RSC, ATLA and DBC on two tasks whose workspace has a
*causal* feature (what the task needs) and a *spurious* one (what merely goes with it in
training); the correlation holds in training and breaks at test (RSC: Ding et al., NeurIPS
2023). The authors' ``robust_gymnasium/envs/robosuite/environments/causal/lift_causal.py`` and
``door_causal.py`` draw both features inside the environment's reset, tied by a
``spurious_type``. Here the two features are the two dimensions of a `WorkspaceDisruptor`, so
an adversary chooses them once per episode; the paper's correlations are an adversary of their
own, `SpuriousCorrelation`, and a learned or scheduled adversary can drive the same dimensions.

* **LiftCausal** (scenario ``RS-LiftCausal``): dimension 0 is the cube's *side* (``+1``: y > 0,
  ``-1``: y < 0, 5 to 10 cm off the centre line as in the paper); dimension 1 its colour
  (``+1`` red, ``-1`` green), which the protagonist observes: the last three numbers of
  ``object-state`` are the cube's RGB (the paper's ``cube_color`` sensor). ``xnr``: red when
  y <= 0; ``xpr``: red when y > 0.
* **DoorCausal** (scenario ``RS-DoorCausal``): dimension 0 turns the door (``+1``: the paper's
  ``left``, yaw -pi/2 - 0.325 ± 0.025 rad; ``-1``: ``right``, -pi/2 + 0.325 ± 0.025), dimension
  1 sets the handle's height on the door (``+1``: high, 0.2 m; ``-1``: low, -0.1 m); the
  protagonist observes it in ``handle_pos``. ``hhl``: high handle when the door turns left;
  ``hhr``: high when it turns right.

Presets of both scenarios: ``spurious-<type>`` for the paper's two ``spurious_type`` values
(each the other one reversed), ``spurious-none`` (the features drawn independently: the correlation absent),
``adversarial`` (the two dimensions with no suggested adversary: the loop learns one),
``default`` (the paper's default ``spurious_type``: ``xnr``, ``hhl``), ``full`` (the
training correlation plus observation, reward, action and dynamics adversaries) and ``atla``
(the training correlation plus ATLA's observation attack, ε = `ATLA_EPS` in normalized units:
what ``--method atla`` trains against here).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from advgame.core.policy import AgentInfo, Policy
from advgame.core.registry import Preset
from advgame.disruptors import ObservationDisruptor, Shift, WorkspaceDisruptor
from advgame.errors import ConfigError

__all__ = [
    "ATLA_EPS",
    "CAUSAL_TASKS",
    "CUBE_NOMINAL_RGBA",
    "DOOR_HANDLE",
    "DOOR_JITTER",
    "DOOR_TABLE_OFFSET",
    "DOOR_TURN",
    "GREEN",
    "LIFT_BAND",
    "LIFT_SIDE",
    "RED",
    "SPURIOUS_TYPES",
    "SpuriousCorrelation",
    "causal_presets",
    "door_features",
    "lift_features",
]

RED = (1.0, 0.0, 0.0, 1.0)
"""The cube's colour at feature value ``+1`` (the paper's ``red``)."""
GREEN = (0.0, 1.0, 0.0, 1.0)
"""The cube's colour at feature value ``-1`` (the paper's ``green``)."""
CUBE_NOMINAL_RGBA = (0.5, 0.5, 0.0, 1.0)
"""The cube's colour with no disturbance (feature value 0): half way from green to red."""
LIFT_SIDE = 0.075
"""How far (m, along y) the side feature moves the cube from its centre band."""
LIFT_BAND = (0.1, 0.025)
"""Half-widths (m) of the cube's own draw around the table centre, in x and in y."""
DOOR_TURN = 0.325
"""How far (rad) the door-side feature turns the door from -pi/2; ``+1`` turns it by -0.325."""
DOOR_JITTER = 0.025
"""Half-width (rad) of the door's own yaw draw around -pi/2."""
DOOR_HANDLE = (-0.175, 0.05, 0.15)
"""The handle (latch body) on the door: x, its nominal height, and the height change at ±1."""
DOOR_TABLE_OFFSET = (-0.3, -0.5, 0.8)
"""DoorCausal's table offset (robosuite's Door: (-0.2, -0.35, 0.8))."""

ATLA_EPS = 0.01
"""The observation budget of ATLA on the causal tasks (the Robust Gymnasium paper's RSC table
caption: "for ATLA ... adv eps is 0.01"), in the protagonist's normalized units as ATLA's."""

SPURIOUS_TYPES = {
    "RS-LiftCausal": {"xnr": 0.0, "xpr": 1.0},
    "RS-DoorCausal": {"hhl": 1.0, "hhr": 0.0},
}
"""Each causal scenario's ``spurious_type`` values -> P(spurious sign = causal sign)."""

CAUSAL_TASKS = tuple(SPURIOUS_TYPES)
"""The causal scenarios' ids."""


def lift_features() -> WorkspaceDisruptor:
    """LiftCausal's two features: the cube's side (dimension 0) and its colour (dimension 1)."""
    return WorkspaceDisruptor(
        shifts=(
            Shift("cube_side", bodies=("cube_main",), offset=(0.0, LIFT_SIDE, 0.0)),
            Shift("cube_colour", geoms=("cube_g0_vis",), rgba_high=RED, rgba_low=GREEN),
        )
    )


def door_features() -> WorkspaceDisruptor:
    """DoorCausal's two features: the door's turn (dimension 0) and the handle's height (1)."""
    return WorkspaceDisruptor(
        shifts=(
            Shift("door_side", bodies=("Door_main",), yaw=-DOOR_TURN),
            Shift("handle_height", body_offsets=(("Door_latch", (0.0, 0.0, DOOR_HANDLE[2])),)),
        )
    )


class _CorrelatedSigns:
    """Draws (causal, spurious) signs per call: two uniforms each, whatever `agree` is."""

    def __init__(self, info: AgentInfo, agree: float, causal: int, spurious: int) -> None:
        self.info, self.agree, self.causal, self.spurious = info, agree, causal, spurious
        self.rng = np.random.default_rng()

    def reset(self, seed: int | None = None) -> None:
        """Reseed (when a seed is given)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def act(self, observation: Any) -> np.ndarray:
        """A fresh draw: the causal sign uniform, the spurious one agreeing with P(`agree`)."""
        side, same = self.rng.random(2)
        u = np.zeros(self.info.action_size)
        u[self.causal] = 1.0 if side < 0.5 else -1.0
        u[self.spurious] = u[self.causal] if same < self.agree else -u[self.causal]
        return self.info.encode(u)


@dataclass(frozen=True)
class SpuriousCorrelation:
    """A causal and a spurious feature drawn per episode (each ±1) with a declared correlation.

    The causal feature's sign is uniform; the spurious one equals it with probability `agree`
    (1: always, the features agree; 0: never, the reversed correlation; 0.5: independent, the
    correlation absent). Other dimensions stay 0. With the same seed, two values of `agree`
    draw the same causal features.

    Example:
        >>> import advgame
        >>> game = advgame.make("RS-LiftCausal", preset="spurious-xpr", max_episode_steps=2)
        >>> pol = SpuriousCorrelation(agree=1.0).build(game.agent_info("workspace_adversary"))
        >>> pol.reset(seed=0)
        >>> side, colour = pol.act(None)
        >>> bool(side == colour)
        True

    """

    agree: float = 1.0
    """P(spurious sign = causal sign): 1 or 0 for a ``spurious_type``, 0.5 for none."""
    causal: int = 0
    """The causal feature's dimension of the adversary's action."""
    spurious: int = 1
    """The spurious feature's dimension."""

    def __post_init__(self) -> None:
        if not (isinstance(self.agree, (int, float)) and 0.0 <= float(self.agree) <= 1.0):
            raise ConfigError(
                f"SpuriousCorrelation.agree is a probability in [0, 1], got {self.agree!r}."
            )
        dims = (self.causal, self.spurious)
        if not all(isinstance(d, int) and d >= 0 for d in dims) or self.causal == self.spurious:
            raise ConfigError(
                f"SpuriousCorrelation needs two different dimensions >= 0, got causal="
                f"{self.causal!r}, spurious={self.spurious!r}."
            )

    def build(self, info: AgentInfo) -> Policy:
        """A seeded sampler for `info`'s (workspace) disruptor."""
        if max(self.causal, self.spurious) >= info.action_size:
            raise ConfigError(
                f"SpuriousCorrelation uses dimensions {self.causal} and {self.spurious}, but "
                f"{info.agent!r} has {info.action_size}; give it a two-feature disruptor "
                "(e.g. advgame.scenarios.robosuite_causal.lift_features())."
            )
        return _CorrelatedSigns(info, float(self.agree), self.causal, self.spurious)


def causal_presets(scenario_id: str, full: tuple[Any, ...]) -> dict[str, Preset]:
    """The presets of causal scenario `scenario_id`; `full` are the family's ``full`` disruptors."""
    if scenario_id not in SPURIOUS_TYPES:
        raise ConfigError(f"{scenario_id!r} is not a causal task; they are {list(CAUSAL_TASKS)}.")
    lift = scenario_id == "RS-LiftCausal"
    spec = lift_features() if lift else door_features()
    what = "cube colour vs side" if lift else "handle height vs door side"
    out: dict[str, Preset] = {}
    for name, agree in SPURIOUS_TYPES[scenario_id].items():
        adversary = {spec.agent: SpuriousCorrelation(agree=agree)}
        out[f"spurious-{name}"] = Preset((spec,), adversary, f"{what}: spurious_type {name}")
    first = next(iter(SPURIOUS_TYPES[scenario_id]))
    out["spurious-none"] = Preset(
        (spec,), {spec.agent: SpuriousCorrelation(agree=0.5)}, f"{what}: independent (test)"
    )
    out["adversarial"] = Preset((spec,), description=f"{what}: chosen by a learned adversary")
    train = out[f"spurious-{first}"]
    out["default"] = Preset(train.disruptors, train.adversaries, f"spurious-{first} (the paper's)")
    out["full"] = Preset(
        (spec, *full), train.adversaries, f"spurious-{first} plus observation to dynamics"
    )
    out["atla"] = Preset(
        (spec, ObservationDisruptor(eps=ATLA_EPS, space="normalized")),
        train.adversaries,
        f"spurious-{first} plus ATLA's L-inf observation attack, eps {ATLA_EPS} (normalized units)",
    )
    return out
