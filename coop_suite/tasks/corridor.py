"""Corridor crossing: everybody through a slit that fits one Ant at a time.

Agents start on an arc, all at the same distance from the slit's entrance,
so that rushing together jams the slit. Each agent that crosses the finish
line pays every agent a bonus; success when all have crossed.
"""

import dataclasses

import numpy as np

from coop_suite import arenas
from coop_suite.tasks import base
from coop_suite.tasks import layouts
from coop_suite.tasks import rewards


@dataclasses.dataclass(frozen=True)
class CorridorConfig(base.TaskConfig):
  """Corridor settings; reward coefficients follow the paper's table."""

  time_limit: float = 40.0
  crossing_bonus: float = 50.0
  """Paid to every agent each time one agent crosses the finish line."""
  agent_target_scale: float = 5.0
  """Coefficient of 5 / (1 + d(agent, target)); the target is the point of
  the finish line in front of the slit."""
  slit_width: float = 1.7
  """Gap between the walls (m): passes one upright Ant, not two abreast."""
  wall_thickness: float = 1.0
  """Length of the slit along x (m)."""
  start_distance: float = 4.0
  """Minimum distance from the agents to the slit's entrance (m)."""


class Corridor(base.CoopTask):
  """File through the slit one by one."""

  MIN_AGENTS, MAX_AGENTS = 1, 16
  EXTERO_FEATURES = ("slit", "target", "crossed")

  def __init__(self, n_agents, config=CorridorConfig()):
    arena = arenas.CorridorArena(slit_width=config.slit_width,
                                 wall_thickness=config.wall_thickness,
                                 physics_timestep=config.physics_timestep)
    self._target = np.array([arena.finish_x, 0.0])
    super().__init__(arena, ["ant"] * n_agents, config)
    self._crossed = np.zeros(n_agents, dtype=bool)

  def _exteroception(self, physics, frames):
    arena = self._arena
    n = self.n_agents
    slit = np.empty((n, 5))
    slit[:, 0:2] = frames.to_heading_frame(arena.slit_entrance)
    slit[:, 2:4] = frames.to_heading_frame(arena.slit_exit)
    slit[:, 4] = arena.slit_width
    return {
        "slit": slit,
        "target": frames.to_heading_frame(self._target),
        "crossed": self._crossed[:, None].astype(np.float64),
    }

  def _initialize_layout(self, physics, random_state):
    cfg = self._config
    self._crossed = np.zeros(self.n_agents, dtype=bool)
    self._new_crossings = 0
    entrance = self._arena.slit_entrance
    starts = layouts.arc(self.n_agents, entrance, cfg.start_distance,
                         facing=np.pi)
    yaws = layouts.face(starts, entrance) + random_state.uniform(
        -0.3, 0.3, self.n_agents)
    for walker, xy, yaw in zip(self._walkers, starts, yaws):
      layouts.place(walker, physics, xy, yaw, random_state)

  def _update_status(self, physics):
    x = physics.data.xpos[self._torso_ids, 0]
    newly = (x > self._arena.finish_x) & ~self._crossed
    self._new_crossings = int(np.sum(newly))
    self._crossed |= newly
    self._success = bool(np.all(self._crossed))

  def _reward_terms(self, physics):
    cfg = self._config
    agents = physics.data.xpos[self._torso_ids, :2]
    return {
        "crossing": np.full(self.n_agents,
                            cfg.crossing_bonus * self._new_crossings),
        "agent_target": rewards.inverse_distance(
            cfg.agent_target_scale, rewards.planar_distance(agents,
                                                            self._target)),
    }

  def _progress(self, physics):
    return {"crossed": int(np.sum(self._crossed)),
            "fraction_crossed": float(np.mean(self._crossed))}

  def _task_state(self, physics):
    return self._crossed.astype(np.float64)

  def tracked_positions(self, physics):
    slit = np.append(self._arena.slit_exit, 0.0)
    return np.vstack([super().tracked_positions(physics), slit])
