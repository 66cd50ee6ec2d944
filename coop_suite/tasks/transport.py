"""Cooperative transport: push a heavy cylinder into a target zone together.

The cylinder starts at the origin, agents start on a ring around it (one per
quadrant with four), the target is drawn at random each episode. Success when
the cylinder's centre rests inside the target zone.
"""

import dataclasses

import numpy as np

from coop_suite import arenas
from coop_suite.entities import Cylinder
from coop_suite.tasks import base
from coop_suite.tasks import layouts
from coop_suite.tasks import rewards


@dataclasses.dataclass(frozen=True)
class TransportConfig(base.TaskConfig):
  """Transport settings; reward coefficients follow the paper's table."""

  time_limit: float = 40.0
  cylinder_target_scale: float = 10.0
  """Coefficient of 10 / (1 + d(cylinder, target))."""
  agent_cylinder_scale: float = 5.0
  """Coefficient of 5 / (1 + d(agent, cylinder))."""
  agent_target_scale: float = 5.0
  """Coefficient of 5 / (1 + d(agent, target))."""
  success_bonus: float = 50.0
  """Paid to every agent once, on success."""
  target_distance: tuple = (3.0, 6.0)
  """Range of the target's distance from the cylinder's start (m)."""
  target_radius: float = 1.0
  """The cylinder's centre must be this close to the target (m)."""
  rest_speed: float = 0.3
  """...and move slower than this (m/s) to count as resting."""
  start_radius: float = 3.0
  """Minimum distance of the agents' start ring from the cylinder (m)."""
  cylinder_mass: float = 20.0
  """Cylinder mass (kg): heavy enough to need more than one Ant."""
  cylinder_radius: float = 0.6
  """Cylinder radius (m); it is 0.8 m tall."""


class Transport(base.CoopTask):
  """Push the cylinder into the target zone."""

  MIN_AGENTS, MAX_AGENTS = 1, 16
  EXTERO_FEATURES = ("cylinder", "target")

  def __init__(self, n_agents, config=TransportConfig()):
    arena = arenas.Floor(target_radius=config.target_radius,
                         physics_timestep=config.physics_timestep)
    self.cylinder = Cylinder(radius=config.cylinder_radius,
                             mass=config.cylinder_mass)
    arena.add_free_entity(self.cylinder)
    super().__init__(arena, ["ant"] * n_agents, config)

  def _exteroception(self, physics, frames):
    return {
        "cylinder": frames.to_heading_frame(
            self.cylinder.position(physics)[:2]),
        "target": frames.to_heading_frame(self._arena.target_position),
    }

  def _initialize_layout(self, physics, random_state):
    cfg = self._config
    layouts.place_prop(self.cylinder, physics,
                       [0.0, 0.0, self.cylinder.height / 2])
    distance = random_state.uniform(*cfg.target_distance)
    angle = random_state.uniform(-np.pi, np.pi)
    self._arena.set_target(physics, distance * np.array(
        [np.cos(angle), np.sin(angle)]))
    starts = layouts.ring(self.n_agents, [0.0, 0.0], cfg.start_radius,
                          random_state)
    yaws = random_state.uniform(-np.pi, np.pi, self.n_agents)
    for walker, xy, yaw in zip(self._walkers, starts, yaws):
      layouts.place(walker, physics, xy, yaw, random_state)

  def _distances(self, physics):
    """d(cylinder, target) [], d(agent, cylinder) [n], d(agent, target) [n]."""
    def compute():
      goals = np.empty((2, 2))  # The cylinder and the target.
      goals[0] = self.cylinder.position(physics)[:2]
      goals[1] = self._arena.target_position
      agents = self.frames(physics).position[:, None, :2]
      to_goals = rewards.planar_distance(agents, goals)
      return (rewards.planar_distance(goals[0], goals[1]), to_goals[:, 0],
              to_goals[:, 1])
    return self.per_state("distances", physics, compute)

  def _update_status(self, physics):
    cylinder_target, _, _ = self._distances(physics)
    if (cylinder_target < self._config.target_radius
        and self.cylinder.planar_speed(physics) < self._config.rest_speed):
      self._success = True

  def _reward_terms(self, physics):
    cfg = self._config
    cylinder_target, agent_cylinder, agent_target = self._distances(physics)
    return {
        "cylinder_target": rewards.inverse_distance(
            cfg.cylinder_target_scale, np.full(self.n_agents, cylinder_target)),
        "agent_cylinder": rewards.inverse_distance(cfg.agent_cylinder_scale,
                                                   agent_cylinder),
        "agent_target": rewards.inverse_distance(cfg.agent_target_scale,
                                                 agent_target),
        "success": np.full(self.n_agents,
                           cfg.success_bonus if self._success_event else 0.0),
    }

  def _progress(self, physics):
    cylinder_target, _, _ = self._distances(physics)
    return {"cylinder_target_distance": float(cylinder_target)}

  def _task_state(self, physics):
    return np.concatenate([self.cylinder.position(physics)[:2],
                           self._arena.target_position])

  def tracked_positions(self, physics):
    target = np.append(self._arena.target_position, 0.0)
    return np.vstack([super().tracked_positions(physics),
                      self.cylinder.position(physics), target])

