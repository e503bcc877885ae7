"""DBC (bisimulation representations) on SB3's SAC: its config, algorithm and networks."""

from advgame.agents.dbc.config import DBCConfig

__all__ = ["DBCConfig"]
