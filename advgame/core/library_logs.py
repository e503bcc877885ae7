"""Other libraries' log lines that advgame's command line keeps to ``-v``.

robosuite logs an INFO line for every env it builds ("Loading controller configuration from
..."), through a console handler of its own, and passes the record on to the root logger's
handlers as well, so each line came twice. The command line calls `quiet_libraries` once; it
also sets `QUIET_VAR`, so the pool workers it starts (`advgame.runner.units.init_worker`) do the
same, where most envs of an evaluation are built.

Example:
    >>> import logging
    >>> quiet_libraries(True)
    >>> logger = logging.getLogger("robosuite_logs")
    >>> logger.propagate, logger.filter(logger.makeRecord("r", logging.INFO, "f", 1, "m", (), None))
    (False, False)
    >>> quiet_libraries(False)
    >>> bool(logger.filter(logger.makeRecord("r", logging.INFO, "f", 1, "m", (), None)))
    True

"""

from __future__ import annotations

import logging
import os

__all__ = ["CHATTY", "QUIET_VAR", "quiet_from_environment", "quiet_libraries"]

CHATTY = ("robosuite_logs",)
"""Loggers that print through a handler of their own and log INFO per env built."""

QUIET_VAR = "ADVGAME_QUIET_LIBRARIES"
"""``"1"``: drop the `CHATTY` loggers' records below WARNING; ``"0"``: keep them."""


def _below_warning(record: logging.LogRecord) -> bool:
    return record.levelno >= logging.WARNING


def quiet_libraries(quiet: bool) -> None:
    """Print `CHATTY` records once (their own handler), and below WARNING only if not `quiet`.

    The filter sits on the logger itself, so it holds whatever level the library sets when it
    is imported later. Sets `QUIET_VAR` for the worker processes started after.
    """
    os.environ[QUIET_VAR] = "1" if quiet else "0"
    for name in CHATTY:
        logger = logging.getLogger(name)
        logger.propagate = False
        if quiet and _below_warning not in logger.filters:
            logger.addFilter(_below_warning)
        elif not quiet and _below_warning in logger.filters:
            logger.removeFilter(_below_warning)


def quiet_from_environment() -> None:
    """In a worker: do what the parent's command line did (nothing if it set no `QUIET_VAR`)."""
    value = os.environ.get(QUIET_VAR)
    if value in ("0", "1"):
        quiet_libraries(value == "1")
