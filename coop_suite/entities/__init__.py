"""Entities: the Ant walker and the free props the tasks are built from."""

from coop_suite.entities.ant import Ant
from coop_suite.entities.ant import STANDING_HEIGHT
from coop_suite.entities.props import Cylinder
from coop_suite.entities.props import Stone

__all__ = ["Ant", "Cylinder", "Stone", "STANDING_HEIGHT"]
