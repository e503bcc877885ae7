"""The ``advgame`` command line, on top of every other layer: `main` runs it.

`app` builds the parser and runs the commands; `evaluate` and `campaign` hold the sub-commands
of those names (``advgame evaluate``, ``advgame campaign`` and ``advgame zoo``).
"""

from advgame.cli.app import main

__all__ = ["main"]
