"""The threat model of a table: the preset whose budgets every attack column plays in.

`default_threat` is the scenario's ATLA preset where it has one; `observation_agent` names the
preset's bounded observation adversary, the one agent that attacks and learned adversaries
play.
"""

from __future__ import annotations

from advgame.errors import ConfigError, UnknownNameError, did_you_mean

__all__ = ["default_threat", "observation_agent"]


def default_threat(scenario: str) -> str:
    """The shared threat model of a table: ATLA's budgets where the scenario has them."""
    from advgame.core.registry import scenario_spec

    return "atla" if "atla" in scenario_spec(scenario).load_presets() else "default"


def observation_agent(scenario: str, preset: str) -> str:
    """The adversary of `preset`'s bounded observation disruptor (what attacks play)."""
    from advgame.core.registry import scenario_spec

    presets = scenario_spec(scenario).load_presets()
    if preset not in presets:
        hint = did_you_mean(preset, presets)
        raise UnknownNameError(f"Scenario {scenario!r} has no preset {preset!r}.{hint}")
    found = [
        d.agent
        for d in presets[preset].disruptors
        if d.kind == "observation" and getattr(d, "bounded", False)
    ]
    if not found:
        raise ConfigError(
            f"The threat model {preset!r} of {scenario} has no bounded observation disruptor, "
            "so attack columns have no budget to search; choose one that has (e.g. atla or "
            "default) with --threat / threat=."
        )
    return found[0]
