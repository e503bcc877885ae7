"""Where moved modules went: old names in files written before a move keep loading.

advgame writes class paths into files: part files of campaigns are pickles, populations store a
spec's ``"module:qualname"``, and a part file is named by the digest of its unit's pickle, which
spells the module of every class in the unit. When a module moves, `MOVED` maps its old name to
its new one (`MOVED_NAMES` does the same for a single class), and the readers and the one
writer of such names go through this module:

* `current` turns an old name into the one that holds the class now: for ``"module:attr"``
  names (`advgame.core.registry.load`) and for pickles (`Unpickler`, `load_pickle`: part
  files);
* `stable_pickle` writes a value as it would have been pickled before every move (old module
  names), so a unit's digest, and with it the name of its part file, does not change when the
  code is reorganised;
* files this module does not read, Stable-Baselines3's zips above all (their ``data`` holds
  cloudpickled classes such as ``advgame.agents.dbc_nets.DBCPolicy``), import the old name
  itself: `advgame.agents.common.aliases` makes every old ``advgame.agents.*`` name in `MOVED`
  import as the module that replaced it.

Add a line to `MOVED` for every module that moves (a module that moves again gets a second line,
from its last name: `current` and `former` follow the chain); never remove one while a file in
the wild may name it (tests/test_layers.py loads the committed part files and populations through it).
"""

from __future__ import annotations

import io
import pickle
from typing import IO, Any

__all__ = ["MOVED", "Unpickler", "current", "former", "load_pickle", "stable_pickle"]

MOVED: dict[str, str] = {
    # 27 Nov 2026 (issue 35): one direction of imports; evaluation split into rooms
    "advgame.disruptors.base": "advgame.core.disruptor",
    "advgame.training.checkpoint": "advgame.agents.checkpoint",
    "advgame.training.forward": "advgame.agents.forward",
    "advgame.training.learning": "advgame.agents.side",
    "advgame.evaluation.jobs": "advgame.evaluation.table.jobs",
    "advgame.evaluation.columns": "advgame.evaluation.table.columns",
    "advgame.evaluation.protagonists": "advgame.evaluation.table.protagonists",
    "advgame.evaluation.applicable": "advgame.evaluation.table.applicable",
    "advgame.evaluation.batched": "advgame.evaluation.table.batched",
    "advgame.evaluation.running": "advgame.evaluation.table.running",
    "advgame.evaluation.payoff": "advgame.evaluation.table.payoff",
    "advgame.evaluation.snapshots": "advgame.evaluation.table.snapshots",
    "advgame.evaluation.optimal": "advgame.evaluation.attacks.optimal",
    "advgame.evaluation.exploit": "advgame.evaluation.attacks.exploit",
    "advgame.evaluation.executor": "advgame.runner.run",
    "advgame.evaluation._local": "advgame.runner.local",
    "advgame.evaluation._ray": "advgame.runner.ray",
    "advgame.evaluation.units": "advgame.runner.units",
    "advgame.evaluation.report": "advgame.reports.report",
    "advgame.evaluation.plots": "advgame.reports.plots",
    "advgame.campaign_report": "advgame.reports.campaign",
    "advgame.evaluation.suite": "advgame.workflows.suite",
    "advgame.evaluation.demo": "advgame.workflows.demo",
    "advgame.evaluation.metasolver": "advgame.workflows.metasolver",
    "advgame.campaign": "advgame.workflows.campaign",
    "advgame.zoo": "advgame.workflows.zoo",
    "advgame.psro": "advgame.workflows.psro",
    "advgame.cli_campaign": "advgame.cli.campaign",
    # 6 Dec 2026 (issue 71): agents/ as rooms, one folder per learner family and agents/common.
    # An old module whose name is now its family's folder (sb3, marl, safe, ompo, rsc, dbc,
    # recurrent) is that package, which exposes the old module's public names; the other old
    # names import as the new module (advgame.agents.common.aliases), so SB3 zips load.
    "advgame.agents.checkpoint": "advgame.agents.common.checkpoint",
    "advgame.agents.forward": "advgame.agents.common.forward",
    "advgame.agents.normalizer": "advgame.agents.common.normalizer",
    "advgame.agents.replay_store": "advgame.agents.common.replay_store",
    "advgame.agents.side": "advgame.agents.common.side",
    "advgame.agents.stats": "advgame.agents.common.stats",
    "advgame.agents.sb3_policy": "advgame.agents.common.sb3_policy",
    "advgame.agents.recurrent_policy": "advgame.agents.common.recurrent_policy",
    "advgame.agents.sb3": "advgame.agents.sb3.config",
    "advgame.agents.her": "advgame.agents.sb3.her",
    "advgame.agents.sa_ppo": "advgame.agents.sa.ppo",
    "advgame.agents.sa_recurrent": "advgame.agents.sa.recurrent",
    "advgame.agents.sa_recurrent_config": "advgame.agents.sa.config",
    "advgame.agents.recurrent": "advgame.agents.recurrent.config",
    "advgame.agents.recurrent_ppo": "advgame.agents.recurrent.ppo",
    "advgame.agents.marl": "advgame.agents.marl.marl",
    "advgame.agents.marl_nets": "advgame.agents.marl.nets",
    "advgame.agents.marl_shared": "advgame.agents.marl.shared",
    "advgame.agents.marl_collect": "advgame.agents.marl.collect",
    "advgame.agents.marl_ppo": "advgame.agents.marl.ppo",
    "advgame.agents.marl_norm": "advgame.agents.marl.norm",
    "advgame.agents.safe": "advgame.agents.safe.safe",
    "advgame.agents.safe_ppo": "advgame.agents.safe.ppo",
    "advgame.agents.ompo": "advgame.agents.ompo.ompo",
    "advgame.agents.ompo_nets": "advgame.agents.ompo.nets",
    "advgame.agents.ompo_config": "advgame.agents.ompo.config",
    "advgame.agents.rsc": "advgame.agents.rsc.rsc",
    "advgame.agents.rsc_model": "advgame.agents.rsc.model",
    "advgame.agents.rsc_config": "advgame.agents.rsc.config",
    "advgame.agents.dbc": "advgame.agents.dbc.dbc",
    "advgame.agents.dbc_nets": "advgame.agents.dbc.nets",
    "advgame.agents.dbc_config": "advgame.agents.dbc.config",
}
"""Old module name -> the module that holds its classes and functions now."""

MOVED_NAMES: dict[tuple[str, str], tuple[str, str]] = {
    # 6 Dec 2026 (issue 71): SA-PPO's config joined its family (agents/sb3 is below agents/sa)
    ("advgame.agents.sb3", "SAPPOConfig"): ("advgame.agents.sa.config", "SAPPOConfig"),
}
"""Single classes moved out of a module that stayed: (module, name) -> (module, name)."""

_FORMER = {new: old for old, new in MOVED.items()}
_FORMER_NAMES = {new: old for old, new in MOVED_NAMES.items()}


def current(module: str, name: str | None = None) -> tuple[str, str | None]:
    """The (module, name) that an old `module` (and attribute `name`) refer to today.

    A module that moved twice is followed to its last place.

    Example:
        >>> current("advgame.evaluation.jobs", "EvalJob")
        ('advgame.evaluation.table.jobs', 'EvalJob')
        >>> current("advgame.training.checkpoint", "SB3Checkpoint")
        ('advgame.agents.common.checkpoint', 'SB3Checkpoint')
        >>> current("advgame.core.game", "Game")
        ('advgame.core.game', 'Game')

    """
    return _follow(module, name, MOVED, MOVED_NAMES)


def former(module: str, name: str) -> tuple[str, str]:
    """The (module, name) a class had before every move (what `stable_pickle` writes).

    Example:
        >>> former("advgame.runner.units", "UnitRecord")
        ('advgame.evaluation.units', 'UnitRecord')
        >>> former("advgame.agents.common.checkpoint", "SB3Checkpoint")
        ('advgame.training.checkpoint', 'SB3Checkpoint')

    """
    old_module, old_name = _follow(module, name, _FORMER, _FORMER_NAMES)
    return old_module, old_name or name


def _follow(
    module: str,
    name: str | None,
    modules: dict[str, str],
    names: dict[tuple[str, str], tuple[str, str]],
) -> tuple[str, str | None]:
    """Follow a chain of moves (forward or back) from `module` and `name` to its end."""
    for _ in range(len(MOVED) + len(MOVED_NAMES) + 1):  # a chain of moves, never a circle
        if name is not None and (module, name) in names:
            module, name = names[module, name]
        elif module in modules:
            module = modules[module]
        else:
            return module, name
    raise RuntimeError(f"advgame.core.moved: the moves of {module!r} form a circle")


class Unpickler(pickle.Unpickler):
    """A pickle reader that finds classes under their old module names too."""

    def find_class(self, module: str, name: str) -> Any:
        """The class or function `module.name`, looked up where it lives now."""
        new_module, new_name = current(module, name)
        return super().find_class(new_module, new_name or name)


def load_pickle(file: IO[bytes]) -> Any:
    """Read one pickle from an open binary `file` (old module names resolved)."""
    return Unpickler(file).load()


_PurePickler: Any = vars(pickle)["_Pickler"]
"""The pure-Python pickler (the C one cannot rename a global)."""
_whichmodule: Any = vars(pickle)["whichmodule"]


class _FormerNames(_PurePickler):
    """Pickles as `pickle.Pickler` does, but writes each class under its `former` name.

    The C pickler cannot rename a global; the pure-Python one writes the same bytes otherwise
    (tests/test_layers.py checks both on the units of a committed campaign).
    """

    def save_global(self, obj: Any, name: str | None = None) -> None:
        qualname = name or getattr(obj, "__qualname__", None) or obj.__name__
        module = _whichmodule(obj, qualname)
        old_module, old_name = former(module, qualname)
        if (old_module, old_name) == (module, qualname):
            super().save_global(obj, name)
            return
        self.save(old_module)  # protocol >= 4: module and name, then STACK_GLOBAL
        self.save(old_name)
        self.write(pickle.STACK_GLOBAL)
        self.memoize(obj)


def stable_pickle(obj: Any) -> bytes:
    """`obj` pickled without a memo, every class under its module name before the moves.

    The bytes depend on the values alone (no memo: a shared string and two equal copies
    pickle alike) and not on where the code lives now; a value holding a cycle needs the memo
    and is pickled with it.
    """
    buf = io.BytesIO()
    pickler = _FormerNames(buf, protocol=pickle.HIGHEST_PROTOCOL)
    pickler.fast = True  # no memo: every occurrence of a value is written out in full
    try:
        pickler.dump(obj)
    except ValueError:  # a cycle: only the memo can write it
        buf = io.BytesIO()
        _FormerNames(buf, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
    return buf.getvalue()
