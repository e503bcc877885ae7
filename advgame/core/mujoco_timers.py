"""MuJoCo's profiling timers, switched off where the games step their simulators.

MuJoCo times every stage of ``mj_step`` (about 16 readings of a clock a step) whenever its
global callback ``mjcb_time`` is set, and MuJoCo's Python bindings set it to a steady-clock
reader each time an ``MjData`` is made while it is unset. Only ``MjData.timer`` (profiling
statistics) reads what it measures: no state, force or contact depends on it, and neither
Gymnasium, robosuite nor advgame reads ``timer``. On the 2-core VM the readings cost about a
tenth of a HalfCheetah-v5 substep (``benchmarks/bench_array_game.py`` prints the measurement).

`quiet_timers` unsets the callback. The games call it when an episode starts (`Game.reset`,
after the task's reset, which may have made an ``MjData``), when a dynamics disruptor
recompiles the model, and `advgame.core.physics.ThreadedStepper` before every batched step;
since the callback is global to the process, simulators stepped outside the games (a raw
``gymnasium.make`` env beside them) then run without it too, until the bindings make another
``MjData``. Set the environment variable `TIMERS_VAR` to ``1`` to keep MuJoCo's timers (to
profile with ``MjData.timer``). Clearing the callback while another thread steps is safe:
MuJoCo reads the pointer once for each reading, tests it and calls what it read (``mj_step``
in the 3.9 library, disassembled).
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os
import sys
from typing import Any

__all__ = ["TIMERS_VAR", "mujoco_library", "quiet_timers", "timer_slot"]

TIMERS_VAR = "ADVGAME_MUJOCO_TIMERS"
"""Environment variable: ``1`` keeps MuJoCo's profiling timers on (`quiet_timers` does nothing)."""


@functools.cache
def mujoco_library() -> Any:
    """MuJoCo's shared library as the bindings loaded it (the same file, so the same handle).

    ``None`` where no such file sits next to the bindings (macOS and Windows wheels name it
    otherwise).
    """
    import mujoco

    folder = os.path.dirname(mujoco.__file__)
    found = sorted(glob.glob(os.path.join(folder, f"libmujoco.so.{mujoco.__version__}")))
    found = found or sorted(glob.glob(os.path.join(folder, "libmujoco*.so*")))
    return ctypes.CDLL(found[0]) if found else None


@functools.cache
def timer_slot() -> ctypes.c_void_p | None:
    """MuJoCo's global ``mjcb_time`` as a ctypes pointer; ``None`` where it is not reachable."""
    library = mujoco_library()
    if library is None:
        return None
    try:
        return ctypes.c_void_p.in_dll(library, "mjcb_time")
    except ValueError:  # a build that does not export it
        return None


def quiet_timers() -> None:
    """Unset MuJoCo's timer callback, unless `TIMERS_VAR` is ``1`` or MuJoCo is not loaded."""
    if "mujoco" not in sys.modules or os.environ.get(TIMERS_VAR) == "1":
        return
    slot = timer_slot()
    if slot is not None and slot.value:
        slot.value = None
