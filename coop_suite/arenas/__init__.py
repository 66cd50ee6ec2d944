"""Arenas: static terrain, markers and the physics options shared by all tasks."""

from coop_suite.arenas.corridor import CorridorArena
from coop_suite.arenas.floor import Floor
from coop_suite.arenas.floor import TERRAIN_GROUP
from coop_suite.arenas.ravine import RavineArena

__all__ = ["Floor", "CorridorArena", "RavineArena", "TERRAIN_GROUP"]
