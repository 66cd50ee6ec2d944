"""The tasks: one module each, built from shared observables, rewards, layouts.

`TASKS` maps a task name to (task class, config class, default agent count).
"""

from coop_suite.tasks.corridor import Corridor, CorridorConfig
from coop_suite.tasks.locomotion import WalkToTarget, WalkToTargetConfig
from coop_suite.tasks.locomotion import WalkVelocity, WalkVelocityConfig
from coop_suite.tasks.ravine import Ravine, RavineConfig
from coop_suite.tasks.transport import Transport, TransportConfig

TASKS = {
    "transport": (Transport, TransportConfig, 4),
    "corridor": (Corridor, CorridorConfig, 4),
    "ravine": (Ravine, RavineConfig, 2),
    "walk_to_target": (WalkToTarget, WalkToTargetConfig, 1),
    "walk_velocity": (WalkVelocity, WalkVelocityConfig, 1),
}
