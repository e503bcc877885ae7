"""Adversary specs from text or dicts, as config files and the command line write them.

``adversary_spec("gauss:0.1")`` is ``GaussianAdversary(std=0.1)``; a dict names the kind and
its fields: ``{"kind": "uniform", "low": -0.2, "high": 0.2}``. The kinds:

==============  ====================================================  ======================
text            spec                                                  argument
==============  ====================================================  ======================
``zero``        `ZeroAdversary` (the disruptor's no-op)
``random``      `RandomAdversary` (uniform over the whole budget)
``gauss:S``     `GaussianAdversary(std=S)`                            the std (default 0.1)
``uniform:W``   `UniformAdversary(low=-W, high=W)`                    the half-width
``constant:V``  `ConstantAdversary(value=V)`                          the raw value
``mad``         `MADAttack` (white-box)
``critic``      `CriticAttack` (white-box)
``rs``          `RobustSarsaAttack` (white-box, learned critic)
``max-cost``    `MaxCostAttack` (white-box, learned cost critic;
                safe scenarios)
``pa-ad``       `PAADAttack` (white-box, learned director)
``llm``         `LLMAdversary` (the offline local model; a dict
                may give ``backend``: ``{"kind": "openai", ...}``)
==============  ====================================================  ======================
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from advgame.errors import AdvgameError, ConfigError, UnknownNameError, did_you_mean

__all__ = ["KINDS", "adversary_spec"]

KINDS = (
    "zero", "random", "gauss", "uniform", "constant", "mad", "critic", "rs", "max-cost", "pa-ad",
    "llm",
)  # fmt: skip
"""The kind names `adversary_spec` knows."""


def _classes() -> dict[str, Any]:
    from advgame import adversaries as a

    return {
        "zero": a.ZeroAdversary, "random": a.RandomAdversary, "gauss": a.GaussianAdversary,
        "uniform": a.UniformAdversary, "constant": a.ConstantAdversary, "mad": a.MADAttack,
        "critic": a.CriticAttack, "rs": a.RobustSarsaAttack, "max-cost": a.MaxCostAttack,
        "pa-ad": a.PAADAttack, "llm": a.LLMAdversary,
    }  # fmt: skip


def _from_text(text: str) -> tuple[str, dict[str, Any]]:
    """``KIND[:NUMBER]`` -> the kind and its fields."""
    kind, _, arg = text.partition(":")
    if not arg or kind not in KINDS:
        return kind, {}
    try:
        x = float(arg)
    except ValueError:
        raise ConfigError(f"In adversary spec {text!r}, {arg!r} is not a number.") from None
    fields = {"gauss": {"std": x}, "uniform": {"low": -x, "high": x}, "constant": {"value": x}}
    if kind not in fields:
        raise ConfigError(
            f"Adversary spec {text!r}: {kind!r} takes no argument (only gauss:STD, uniform:W, "
            "constant:V do); use a dict for its fields."
        )
    return kind, fields[kind]


def adversary_spec(value: str | Mapping[str, Any]) -> Any:
    """The adversary spec that `value` (text or ``{"kind": ..., fields}``) names."""
    if isinstance(value, str):
        kind, fields = _from_text(value.strip())
    elif isinstance(value, Mapping):
        fields = {k: v for k, v in value.items() if k != "kind"}
        kind = value.get("kind", "")
    else:
        raise ConfigError(
            f"An adversary spec is text (e.g. 'gauss:0.1', 'mad') or a dict with 'kind', got "
            f"{value!r}."
        )
    if kind not in KINDS:
        raise UnknownNameError(
            f"Unknown adversary kind {kind!r}.{did_you_mean(str(kind), KINDS)} Kinds: {list(KINDS)}."
        )
    cls = _classes()[kind]
    if kind == "llm":
        fields = _llm_fields(fields)
    try:
        return cls(**fields)
    except AdvgameError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"Bad fields for a {kind!r} adversary {fields!r}: {exc}.") from None


def _llm_fields(fields: dict[str, Any]) -> dict[str, Any]:
    """An LLM adversary's fields from JSON (nested backend dict, region pair) as objects.

    ``backend`` is a dict with ``kind`` ``"local"`` (the offline model, the default) or
    ``"openai"`` (an OpenAI-compatible server) and that backend's fields.
    """
    from advgame.adversaries import LocalModel, OpenAIEndpoint

    out = dict(fields)
    backend = out.get("backend")
    if isinstance(backend, Mapping):
        opts = {k: v for k, v in backend.items() if k != "kind"}
        kinds = {"local": LocalModel, "openai": OpenAIEndpoint}
        kind = backend.get("kind", "local")
        if kind not in kinds:
            raise ConfigError(f"An LLM backend's kind is 'local' or 'openai', got {kind!r}.")
        try:
            out["backend"] = kinds[kind](**opts)
        except TypeError as exc:
            raise ConfigError(f"Bad fields for an {kind!r} LLM backend {opts!r}: {exc}.") from None
    if isinstance(out.get("region"), list):
        out["region"] = tuple(out["region"])
    return out
