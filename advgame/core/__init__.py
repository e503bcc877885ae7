"""The game core: the registry, the `Game` (a PettingZoo ParallelEnv), moves, tasks and views.

Also the team wrapper, policies, schedules and episodes. `advgame` re-exports the public names
lazily; import submodules directly (``from advgame.core.game import Game``).
"""
