"""Who is evaluated: fixed policies from anywhere as protagonist specs, checked before they play.

A protagonist of a payoff table is any policy spec: a run's final protagonist
(`run_protagonist`), an SB3 model trained elsewhere with its observation normalizer
(`sb3_protagonist`), a MAPPO/IPPO team file (`team_protagonist`) or a plain function.
`check_protagonists` builds each once against the scenario's spaces (and asks it for one
action), so a wrong checkpoint or function fails with both spaces named before any job runs. `cli_protagonists` reads the ``advgame
evaluate`` options into the same specs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from advgame.agents.common.checkpoint import ALGOS, SB3Checkpoint
from advgame.errors import AdvgameError, ConfigError, did_you_mean

__all__ = [
    "check_protagonists",
    "cli_protagonists",
    "run_protagonist",
    "sb3_protagonist",
    "team_protagonist",
]

ACTOR_SPEC = "advgame.agents.marl.nets:TorchActorCheckpoint"
"""The spec class of one protagonist's actor in a MAPPO/IPPO actors file."""
NORMALIZER_NAMES = ("vecnormalize.pkl", "vec_normalize.pkl", "protagonist_vecnormalize.pkl")
"""Files beside a model that an error about a missing normalizer suggests."""


def run_protagonist(run_dir: Path) -> tuple[Any, Any]:
    """A finished (or interrupted) run's `TrainConfig` and its last protagonist(s) as a spec.

    Team runs (MAPPO/IPPO) give ``{protagonist id: spec}``, one actor per protagonist.
    """
    from advgame.core.config import load_json
    from advgame.training import TEAM_ALGOS, TrainConfig
    from advgame.training.loop import read_state

    state_path = run_dir / "state.json"
    if not state_path.exists():
        raise ConfigError(
            f"{run_dir} has no finished iteration (no state.json); train or resume it."
        )
    cfg = load_json(TrainConfig, run_dir / "config.json")
    folder = run_dir / read_state(run_dir)["checkpoint"]
    if cfg.protagonist_algo in TEAM_ALGOS:
        path = folder / f"{cfg.protagonist_algo}_actors.pt"
        return cfg, team_protagonist(cfg.scenario, path, preset=cfg.preset)
    norm = folder / "protagonist_obs_norm.npz"
    from advgame.training import learner_config

    spec = SB3Checkpoint(
        str(folder / "protagonist.zip"),
        learner_config(cfg.protagonist_algo, cfg.protagonist_hparams).algo,  # its file's format
        str(norm) if norm.exists() else None,
        deterministic=True,
    )
    return cfg, spec


def sb3_protagonist(
    path: str | Path,
    algo: str = "ppo",
    *,
    normalizer: str | Path | None = None,
    raw_observations: bool = False,
    deterministic: bool = True,
) -> SB3Checkpoint:
    """An SB3 model saved anywhere as a protagonist spec, behind its observation normalizer.

    Give `normalizer` (the `VecNormalize.save` pickle or an ``.npz`` with ``mean``/``var``),
    or say ``raw_observations=True`` if the model was trained without one: a model trained
    behind `VecNormalize` and played on raw observations sees the wrong inputs, so neither
    is refused.
    """
    if algo not in ALGOS:
        raise ConfigError(f"Unknown algorithm {algo!r} for {path}; expected one of {ALGOS}.")
    if not Path(path).is_file():
        raise ConfigError(f"No model file at {str(path)!r}; give the .zip saved by model.save().")
    if normalizer is not None and raw_observations:
        raise ConfigError(f"{path}: give a normalizer or raw_observations=True, not both.")
    if normalizer is None and not raw_observations:
        beside = [p.name for p in Path(path).parent.iterdir() if _looks_like_normalizer(p)]
        hint = f" Found beside the model: {sorted(beside)}." if beside else ""
        raise ConfigError(
            f"No normalizer given for {path}: pass normalizer=PATH (its VecNormalize pickle "
            f"or obs-norm .npz), or raw_observations=True if it was trained on raw "
            f"observations.{hint}"
        )
    if normalizer is not None:
        from advgame.agents.common.checkpoint import load_normalizer

        load_normalizer(str(normalizer))  # a missing or unreadable file fails here
    norm = None if normalizer is None else str(normalizer)
    return SB3Checkpoint(str(path), algo, norm, deterministic=deterministic)


def _looks_like_normalizer(path: Path) -> bool:
    return path.name in NORMALIZER_NAMES or path.name.endswith(("_obs_norm.npz", "norm.pkl"))


def team_protagonist(
    scenario: str, path: str | Path, preset: str | None = None, deterministic: bool = True
) -> dict[str, Any]:
    """A MAPPO/IPPO actors file (``<algo>_actors.pt``) as ``{protagonist id: spec}``."""
    from advgame.core.registry import load, make

    if not Path(path).is_file():
        raise ConfigError(f"No team actors file at {str(path)!r}; expected <algo>_actors.pt.")
    game = make(scenario, preset=preset) if preset else make(scenario, disruptors={})
    game.close()
    actor = load(ACTOR_SPEC)
    return {p: actor(str(path), p, deterministic=deterministic) for p in game.protagonists}


def _first_action(policy: Any, game: Any, agent: str) -> Any:
    """The policy's action on the first observation; its own failure is a `ConfigError`."""
    try:
        return policy.act(game.observe(agent))
    except AdvgameError:
        raise
    except Exception as exc:
        raise ConfigError(
            f"it fails on an observation of shape {np.shape(game.observe(agent))} "
            f"({type(exc).__name__}: {exc}); fix the policy or give the scenario it was made for."
        ) from exc


def check_protagonists(scenario: str, protagonists: Mapping[str, Any]) -> dict[str, Any]:
    """Build every protagonist once on `scenario`'s nominal game; return the built policies.

    A checkpoint whose spaces (or normalizer) do not fit fails here, naming both sides, before
    any evaluation job is queued.
    """
    from advgame.core.episodes import build_policies
    from advgame.core.registry import make

    game = make(scenario, disruptors={})
    built = {}
    try:
        game.reset(seed=0)
        for name, spec in protagonists.items():
            specs = spec if isinstance(spec, Mapping) else dict.fromkeys(game.protagonists, spec)
            try:
                built[name] = build_policies(game, specs)
                for agent in game.protagonists:
                    _check_action(game, agent, _first_action(built[name][agent], game, agent))
            except ConfigError as exc:
                raise type(exc)(f"Protagonist {name!r} on {scenario}: {exc}") from None
    finally:
        game.close()
    return built


def _check_action(game: Any, agent: str, action: Any) -> None:
    """A Box action of the wrong shape fails here, not deep inside the simulator."""
    space = game.action_space(agent)
    shape = np.shape(action)
    if isinstance(space, spaces.Box) and shape != space.shape:
        raise ConfigError(
            f"it answers the first observation of {agent!r} with an action of shape {shape}, "
            f"but {agent!r} acts in {space}."
        )


def _named(items: Sequence[str], option: str, form: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not name or not sep or not value:
            raise ConfigError(f"{option} takes {form}, got {item!r}.")
        if name in out:
            raise ConfigError(f"{option} names {name!r} twice; give each name once.")
        out[name] = value
    return out


def cli_protagonists(
    scenario: str,
    *,
    checkpoints: Sequence[str] = (),
    normalizers: Sequence[str] = (),
    raw_obs: Sequence[str] = (),
    callables: Sequence[str] = (),
    teams: Sequence[str] = (),
) -> dict[str, Any]:
    """Protagonist specs from ``advgame evaluate`` options (``NAME=...`` strings)."""
    from advgame.core.registry import load

    models = _named(checkpoints, "--checkpoint", "NAME=PATH[:ALGO]")
    norms = _named(normalizers, "--normalizer", "NAME=PATH")
    for name in [*norms, *raw_obs]:
        if name not in models:
            hint = did_you_mean(name, models)
            raise ConfigError(f"No --checkpoint named {name!r}.{hint} Checkpoints: {list(models)}")
    out: dict[str, Any] = {}
    for name, value in models.items():
        path, algo = _path_algo(value)
        try:
            out[name] = sb3_protagonist(
                path, algo, normalizer=norms.get(name), raw_observations=name in raw_obs
            )
        except ConfigError as exc:
            msg = str(exc).replace("pass normalizer=PATH", f"pass --normalizer {name}=PATH")
            msg = msg.replace("raw_observations=True", f"--raw-obs {name}")
            raise ConfigError(f"--checkpoint {name}: {msg}") from None
    for name, target in _named(callables, "--callable", "NAME=MODULE:FUNCTION").items():
        out[name] = load(target)
    for name, path in _named(teams, "--team", "NAME=PATH").items():
        out[name] = team_protagonist(scenario, path)
    return out


def _path_algo(value: str) -> tuple[str, str]:
    head, sep, tail = value.rpartition(":")
    if sep and tail in ALGOS:
        return head, tail
    if sep and "/" not in tail and "\\" not in tail and not Path(value).exists():
        raise ConfigError(f"Unknown algorithm {tail!r} in {value!r}; expected one of {ALGOS}.")
    return value, "ppo"
