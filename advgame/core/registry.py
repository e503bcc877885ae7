"""The scenario registry: ids -> task bases with their disruptor presets, loaded lazily.

A scenario's task base and presets are ``"module:attr"`` entry points, imported only when the
scenario is made, so listing scenarios imports no simulator. The built-in scenarios live in
`advgame.scenarios` and register themselves when that package is first imported.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from advgame.core.moved import current
from advgame.errors import (
    AdvgameError,
    ConfigError,
    MissingExtraError,
    UnknownNameError,
    UnknownScenarioError,
    UnsupportedError,
    did_you_mean,
)

if TYPE_CHECKING:
    from advgame.core.disruptor import DisruptorSpec
    from advgame.core.game import Game

__all__ = ["Preset", "ScenarioSpec", "list_scenarios", "load", "make", "register", "scenario_spec"]

_BUILTIN = "advgame.scenarios.builtin"
_KINDS = "advgame.disruptors.kinds:from_config"
"""The built-in scenarios and disruptor kinds, reached by name (entry points), not imported:
the registry sits below the folders that fill it, as Gymnasium's registry below its tasks."""
_REGISTRY: dict[str, ScenarioSpec] = {}


@dataclass(frozen=True)
class Preset:
    """A named set-up of a scenario: its disruptors and the adversaries that suit them.

    Example:
        >>> from advgame.disruptors import ObservationDisruptor
        >>> Preset((ObservationDisruptor(eps=0.1),), description="state attack").description
        'state attack'

    """

    disruptors: tuple[DisruptorSpec, ...]
    """The disruptors, one adversary agent each."""
    adversaries: Mapping[str, Any] = field(default_factory=dict)
    """Suggested adversary policy specs by agent id (the paper's noise or schedule for it)."""
    description: str = ""
    """One line for `advgame list` and reports."""
    cost_weight: float = 0.0
    """Weight of the cost in the zero-sum payoff."""


@dataclass(frozen=True)
class ScenarioSpec:
    """A registered scenario: how to build its task base and which presets it offers."""

    id: str
    """The registry id, e.g. ``"HalfCheetah-v5"``."""
    task: str
    """``"module:attr"`` of a callable ``(**kwargs) -> TaskBase``."""
    presets: str
    """``"module:attr"`` of a callable ``(scenario_id) -> dict[str, Preset]``."""
    task_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """Keyword arguments for the task callable."""
    family: str = ""
    """Task family (``"mujoco"``, ``"box2d"``, ...), for listing."""
    description: str = ""
    """One line on the task."""
    default_preset: str = "default"
    """The preset `make` uses when given neither a preset nor disruptors."""
    extra: str = ""
    """The advgame extra that installs this scenario's simulator (``"box2d"``, ``"mamujoco"``,
    ...); empty for scenarios the core install runs."""
    requires: tuple[str, ...] = ()
    """Top-level modules the task base needs; `make` checks them first and names `extra`."""

    def missing(self) -> list[str]:
        """The modules of `requires` that are not installed (cheap: nothing is imported)."""
        return [name for name in self.requires if importlib.util.find_spec(name) is None]

    def check_installed(self) -> None:
        """Raise `MissingExtraError`, naming the extra to install, if a required module is missing."""
        absent = self.missing()
        if absent:
            raise MissingExtraError(
                f"Scenario {self.id!r} ({self.family}) needs {', '.join(map(repr, absent))}, "
                f'which is not installed. Install it with: pip install "advgame[{self.extra}]"'
            )

    def load_presets(self) -> dict[str, Preset]:
        """Import and return this scenario's presets."""
        return load(self.presets)(self.id)

    def make_task(self, **kwargs: Any) -> Any:
        """Build the task base (the caller's kwargs override the registered ones).

        Raises:
            ConfigError: the task base refused a keyword argument (unknown or a bad value);
                the message names it and, for Gymnasium tasks, the keywords it accepts.

        """
        _check_max_steps(kwargs.get("max_episode_steps"))
        try:
            task = load(self.task)(**{**self.task_kwargs, **kwargs})
        except AdvgameError:
            raise
        except Exception as exc:  # the simulator's own check of a keyword, in its own words
            if not kwargs:
                raise
            raise _task_error(self, kwargs, exc) from exc
        _check_render_mode(task, kwargs.get("render_mode"))
        return task

    def task_keywords(self) -> list[str]:
        """The keyword arguments `make` may pass to this task base, where they can be known.

        For Gymnasium tasks: `gymnasium.make`'s own and the environment class's; else the
        parameters of the task callable (empty when it only takes ``**kwargs``).
        """
        names = _parameters(load(self.task))
        env_id = self.task_kwargs.get("env_id")
        if isinstance(env_id, str):
            names |= _gym_keywords(env_id)
        return sorted(names - set(self.task_kwargs) - {"id", "self"})


def _check_max_steps(steps: Any) -> None:
    if steps is None or (isinstance(steps, int) and not isinstance(steps, bool) and steps >= 1):
        return
    raise ConfigError(
        f"max_episode_steps must be an integer >= 1 (or None for the task's own limit), got "
        f"{steps!r}; e.g. make(..., max_episode_steps=1000)."
    )


def _check_render_mode(task: Any, mode: Any) -> None:
    """Refuse a render mode the built task does not list (Gymnasium only warns; rendering fails later)."""
    if mode is None:
        return
    metadata = getattr(getattr(task, "env", None), "metadata", None)
    modes = metadata.get("render_modes") if isinstance(metadata, Mapping) else None
    if not isinstance(modes, (list, tuple)) or not modes or mode in modes:
        return
    task.close()
    hint = did_you_mean(mode, [str(m) for m in modes]) if isinstance(mode, str) else ""
    raise ConfigError(
        f"render_mode must be one of {list(modes)} or None for this task, got {mode!r}.{hint}"
    )


def _parameters(fn: Any) -> set[str]:
    """Named keyword parameters of `fn` (a class: of its ``__init__`` and its bases')."""
    out: set[str] = set()
    for target in fn.__mro__ if isinstance(fn, type) else (fn,):
        init = vars(target).get("__init__", object.__init__) if isinstance(fn, type) else target
        try:
            params = inspect.signature(init).parameters.values()
        except (TypeError, ValueError):
            continue
        out |= {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
        if isinstance(fn, type) and not any(p.kind == p.VAR_KEYWORD for p in params):
            break
    return out


def _gym_keywords(env_id: str) -> set[str]:
    import gymnasium

    from advgame.core.task import GymTask

    try:
        entry = gymnasium.spec(env_id).entry_point
        env = load(entry) if isinstance(entry, str) else entry
    except Exception:  # only for the message: an env gymnasium cannot find names no keywords
        return set()
    return _parameters(gymnasium.make) | _parameters(GymTask) | _parameters(env)


def _task_error(spec: ScenarioSpec, kwargs: Mapping[str, Any], exc: Exception) -> AdvgameError:
    known = spec.task_keywords()
    match = re.search(r"unexpected keyword argument '(\w+)'", str(exc))
    if match and match.group(1) == "render_mode":
        return UnsupportedError(
            f"make({spec.id!r}, render_mode={kwargs['render_mode']!r}): {spec.id} cannot "
            "render; its task base offers no render modes (a state-only task). Drop render_mode."
        )
    if match:
        bad = match.group(1)
        return UnknownNameError(
            f"make({spec.id!r}) got the unknown keyword argument {bad!r}."
            f"{did_you_mean(bad, known)} Keywords of this task: {known or 'see its docs'}."
        )
    return ConfigError(
        f"make({spec.id!r}) could not build the task with {dict(kwargs)!r}: "
        f"{type(exc).__name__}: {exc}. Fix or drop those keyword arguments."
        + (f" Keywords of this task: {known}." if known else "")
    )


def load(entry_point: str) -> Any:
    """Import ``"module:attr"`` (a callable, a class or a table); old module names resolve.

    A name written before its module moved (a population file's spec type, say) is looked up
    where the module is now (`advgame.core.moved`).
    """
    module, _, attr = entry_point.partition(":")
    module, _ = current(module, attr)
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"Cannot load entry point {entry_point!r}: {exc}") from exc


def register(spec: ScenarioSpec) -> None:
    """Add a scenario; registering an id twice is an error."""
    if spec.id in _REGISTRY:
        raise ConfigError(f"Scenario {spec.id!r} is already registered.")
    _REGISTRY[spec.id] = spec


def _ensure_builtin() -> None:
    importlib.import_module(_BUILTIN)


def list_scenarios(family: str | None = None) -> list[str]:
    """Every registered scenario id (optionally of one `family`), sorted."""
    _ensure_builtin()
    return sorted(k for k, s in _REGISTRY.items() if family is None or s.family == family)


def scenario_spec(scenario_id: str) -> ScenarioSpec:
    """The `ScenarioSpec` of `scenario_id`, with a "did you mean" for typos."""
    _ensure_builtin()
    if not isinstance(scenario_id, str):
        raise UnknownScenarioError(
            f"A scenario id is a string such as 'Hopper-v5', got {scenario_id!r}. "
            "advgame.list_scenarios() (or `advgame list`) shows every id."
        )
    try:
        return _REGISTRY[scenario_id]
    except KeyError:
        raise UnknownScenarioError(
            f"No scenario {scenario_id!r}.{did_you_mean(scenario_id, _REGISTRY)} "
            "advgame.list_scenarios() (or `advgame list`) shows every id."
        ) from None


def make(
    scenario_id: str,
    *,
    preset: str | None = None,
    disruptors: Sequence[DisruptorSpec] | Mapping[str, Any] | None = None,
    phase: str = "train",
    cost_weight: float | None = None,
    **task_kwargs: Any,
) -> Game:
    """Build the game of a registered scenario.

    Args:
        scenario_id: a registered id (see `list_scenarios`).
        preset: a named preset of the scenario (``"default"`` when `disruptors` is not given).
        disruptors: the disruptors instead of a preset: a list of specs, or a dict
            ``{kind: options}`` (options a dict, or a list of dicts for several of one kind).
        phase: ``"train"`` or ``"eval"`` (which schedules are live).
        cost_weight: weight of the cost in the payoff (default: the preset's, else 0).
        **task_kwargs: passed to the task base (e.g. ``render_mode``, ``max_episode_steps``).

    Example:
        >>> import advgame
        >>> game = advgame.make("Hopper-v5", disruptors={"observation": {"eps": 0.075}})
        >>> game.protagonists, game.adversaries
        (('protagonist',), ('observation_adversary',))

    """
    from advgame.core.game import Game

    _check_options(preset, phase, cost_weight)
    spec = scenario_spec(scenario_id)
    spec.check_installed()
    chosen = None
    if disruptors is not None and preset is not None:
        raise ConfigError("Give either preset=... or disruptors=..., not both.")
    if disruptors is None:
        presets = spec.load_presets()
        name = preset or spec.default_preset
        if name not in presets:
            raise UnknownNameError(
                f"Scenario {scenario_id!r} has no preset {name!r}.{did_you_mean(name, presets)} "
                f"Presets: {sorted(presets)}."
            )
        chosen = presets[name]
        specs = tuple(chosen.disruptors)
    else:
        specs = _as_specs(disruptors)
    weight = cost_weight if cost_weight is not None else (chosen.cost_weight if chosen else 0.0)
    task = spec.make_task(**task_kwargs)
    try:
        game = Game(task, specs, cost_weight=weight, phase=phase, scenario_id=scenario_id)
    except AdvgameError:
        task.close()
        raise
    except (TypeError, ValueError, KeyError, IndexError, AttributeError) as exc:
        task.close()
        raise ConfigError(
            f"The disruptors {list(specs)} do not fit {scenario_id!r}: "
            f"{type(exc).__name__}: {exc}. Check their dims, bodies, parameters and targets "
            f"against the task (advgame.make({scenario_id!r}).state_space and the docs)."
        ) from exc
    game.preset = chosen
    return game


def _check_options(preset: Any, phase: Any, cost_weight: Any) -> None:
    """Types and values of `make`'s own keywords, before anything is built."""
    if preset is not None and not isinstance(preset, str):
        raise ConfigError(f"preset must be a preset name (a string), got {preset!r}.")
    if phase not in ("train", "eval"):
        raise ConfigError(f"phase must be 'train' or 'eval', got {phase!r}.")
    if cost_weight is None:
        return
    if (
        isinstance(cost_weight, bool)
        or not isinstance(cost_weight, (int, float))
        or not 0 <= cost_weight < math.inf
    ):
        raise ConfigError(
            f"cost_weight must be a finite number >= 0 (the weight of the cost in the payoff), "
            f"got {cost_weight!r}."
        )


def _as_specs(disruptors: Sequence[DisruptorSpec] | Mapping[str, Any]) -> tuple[DisruptorSpec, ...]:
    from advgame.core.disruptor import DisruptorSpec

    from_config = load(_KINDS)
    if isinstance(disruptors, Mapping):
        out = []
        for kind, cfg in disruptors.items():
            if isinstance(cfg, (list, tuple)) and not cfg:
                raise ConfigError(
                    f"disruptors[{kind!r}] is an empty list; give a dict of options, a list of "
                    "dicts for several, or leave the kind out."
                )
            for one in cfg if isinstance(cfg, (list, tuple)) else [cfg]:
                out.append(from_config(kind, one))
        return tuple(out)
    if isinstance(disruptors, (str, bytes)) or not isinstance(disruptors, Sequence):
        raise ConfigError(
            f"disruptors must be a list of DisruptorSpec or a dict {{kind: options}}, got {disruptors!r}."
        )
    for d in disruptors:
        if not isinstance(d, DisruptorSpec):
            raise ConfigError(
                f"disruptors must hold DisruptorSpec objects (e.g. ObservationDisruptor(eps=0.1)), "
                f"got {d!r}; or pass a dict {{kind: options}}."
            )
    return tuple(disruptors)
