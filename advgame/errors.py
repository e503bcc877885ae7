"""The advgame error hierarchy: one root, every message says what was wrong and how to fix it."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = [
    "ActionError",
    "AdvgameError",
    "BudgetError",
    "ConfigError",
    "FileFormatError",
    "MissingExtraError",
    "UnknownNameError",
    "UnknownScenarioError",
    "UnsupportedError",
    "did_you_mean",
]


class AdvgameError(Exception):
    """Root of every error advgame raises on purpose; catch this to catch them all."""


class ConfigError(AdvgameError, ValueError):
    """A configuration value (disruptor, schedule, preset, learner) is invalid."""


class FileFormatError(AdvgameError, ValueError):
    """A file advgame wrote (run, checkpoint, normalizer, population, results) cannot be read.

    The message names the file, says whether it looks empty, truncated, not of its format or
    written by another version, and how to recover (rerun the step that wrote it, or delete
    the folder). Bad *values* a user typed raise `ConfigError` instead.
    """

    def __init__(self, message: str, path: str | None = None) -> None:
        super().__init__(message)
        self.path = path
        """The file that failed to load."""


class BudgetError(ConfigError):
    """A budget is negative, non-finite or of the wrong shape."""


class UnknownNameError(ConfigError, KeyError):
    """A name (disruptor kind, body, parameter, agent, preset) does not exist."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class UnknownScenarioError(UnknownNameError):
    """`make` was given a scenario id that is not registered."""


class MissingExtraError(AdvgameError, ImportError):
    """An optional package a scenario needs is not installed.

    The message names the advgame extra that brings it (``pip install "advgame[box2d]"``).
    """


class ActionError(AdvgameError, ValueError):
    """An action dict passed to `Game.step` is missing agents, names unknown ones, or is malformed."""


class UnsupportedError(AdvgameError, NotImplementedError):
    """A client asked a game for something it does not have (a render on a state-only task).

    The message names the scenario and what it offers instead. A subclass of
    `NotImplementedError`, as Gymnasium's and PettingZoo's base ``render`` raise.
    """


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """Return ' Did you mean "x"?' for the closest choice, or '' if none is close."""
    close = difflib.get_close_matches(str(name), list(choices), n=1, cutoff=0.5)
    return f' Did you mean "{close[0]}"?' if close else ""
