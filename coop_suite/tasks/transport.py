"""Cooperative transport: push a heavy cylinder into a target zone together.

The cylinder starts at the origin, agents start at random places and headings
over a wide annulus around it, the target is drawn at random each episode.
Success ("accurately and stably") when the cylinder's centre has stayed at
rest inside the target zone for `hold_time` seconds; `reached` reports
whether it ever entered the zone, and `start_agent_cylinder` /
`start_cylinder_target` where the episode started (the Ants' mean distance
from the cylinder and the target's distance from it, m: the paper's
success-by-start-position figure, appendix A.2). The physics is calibrated
so that the task is cooperative (docs/tasks.md, docs/baselines.md).

Rewards are the paper's table: 10 / (1 + d(cylinder, target)),
5 / (1 + d(agent, cylinder)), 5 / (1 + d(agent, target)) per agent and step,
+50 to all on success. Training goes through a curriculum of two stages (the
paper's "training curricula ... dense rewards in the early stages"),
selected with `stage`:

* 'push': the agent-target term is off, so the only way to more reward is
  to gather at the cylinder and move it to the target. With the term on
  from the start, a policy can settle its Ants on the target instead, an
  optimum of the shaping as rewarding as early pushing that some seeds
  never leave (docs/results.md, "Seed 1").
* 'joint': every term of the paper's table (the default; evaluation).
"""

import dataclasses
from typing import NamedTuple

import numba
import numpy as np

from coop_suite import arenas
from coop_suite import kernels
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
  hold_time: float = 2.0
  """...for this long without a break (s) to count as a success."""
  start_distance: tuple = (2.0, 8.0)
  """Range of the agents' start distance from the cylinder's centre (m);
  positions are uniform over this annulus, at least 1.7 m apart."""
  cylinder_mass: float = 40.0
  """Cylinder mass (kg): one Ant cannot move it far, two barely, four at a
  slow walk (docs/tasks.md gives the measurements that chose it)."""
  cylinder_radius: float = 0.6
  """Cylinder radius (m); it is 0.8 m tall."""
  cylinder_friction: float = 0.4
  """Sliding friction of the cylinder on the floor (and on the Ants)."""


STAGES = ("joint", "push")


class Transport(base.CoopTask):
  """Push the cylinder into the target zone."""

  MIN_AGENTS, MAX_AGENTS = 1, 16
  TASK_OPTIONS = ("stage",)
  EXTERO_FEATURES = ("cylinder", "target")

  def __init__(self, n_agents, config=TransportConfig(), stage="joint"):
    if stage not in STAGES:
      raise ValueError(f"Unknown stage {stage!r}; choose one of {STAGES}.")
    self.stage = stage
    arena = arenas.Floor(target_radius=config.target_radius,
                         physics_timestep=config.physics_timestep)
    self.cylinder = Cylinder(radius=config.cylinder_radius,
                             mass=config.cylinder_mass,
                             friction=config.cylinder_friction)
    arena.add_free_entity(self.cylinder)
    super().__init__(arena, ["ant"] * n_agents, config)
    self._held, self._reached = 0.0, False  # See `_update_status`.
    self._start = (0.0, 0.0)  # See `_progress`.
    agent_target = 0.0 if stage == "push" else config.agent_target_scale
    self._scales = (float(config.cylinder_target_scale),
                    float(config.agent_cylinder_scale), float(agent_target))

  def _exteroception(self, physics, frames):
    offsets = self._measure(physics).offsets
    return {"cylinder": offsets[:, :2], "target": offsets[:, 2:]}

  def _initialize_layout(self, physics, random_state):
    cfg = self._config
    layouts.place_prop(self.cylinder, physics,
                       [0.0, 0.0, self.cylinder.height / 2])
    distance = random_state.uniform(*cfg.target_distance)
    angle = random_state.uniform(-np.pi, np.pi)
    self._arena.set_target(physics, distance * np.array(
        [np.cos(angle), np.sin(angle)]))
    self._held = 0.0
    self._reached = False
    starts = layouts.annulus(self.n_agents, [0.0, 0.0], cfg.start_distance,
                             random_state)
    # The cylinder starts at the origin.
    self._start = (float(np.mean(np.linalg.norm(starts, axis=1))),
                   float(distance))
    yaws = random_state.uniform(-np.pi, np.pi, self.n_agents)
    for walker, xy, yaw in zip(self._walkers, starts, yaws):
      layouts.place(walker, physics, xy, yaw, random_state)

  def _measure(self, physics):
    """`measure` of this physics state (computed once per state)."""
    def compute():
      data = physics.data.ptr
      return measure(self.frames(physics).packed, data.xpos, data.cvel,
                     self.cylinder.body_id, self._arena.target_position,
                     self._scales)
    return self.per_state("measure", compute)

  def _update_status(self, physics):
    measured = self._measure(physics)
    inside = measured.cylinder_target < self._config.target_radius
    self._reached |= inside
    if inside and measured.cylinder_speed < self._config.rest_speed:
      self._held += self.control_timestep
    else:
      self._held = 0.0
    # Half a control step of slack against float sums of the timestep.
    if self._held >= self._config.hold_time - 0.5 * self.control_timestep:
      self._success = True

  def _reward_terms(self, physics):
    shaping = self._measure(physics).shaping
    bonus = self._config.success_bonus if self._success_event else 0.0
    return {
        "cylinder_target": shaping[0],
        "agent_cylinder": shaping[1],
        "agent_target": shaping[2],
        "success": self.each_agent(bonus),
    }

  def _progress(self, physics):
    return {"cylinder_target_distance": float(
                self._measure(physics).cylinder_target),
            "reached": bool(self._reached),
            "start_agent_cylinder": self._start[0],
            "start_cylinder_target": self._start[1]}

  def _task_state(self, physics):
    return np.concatenate([self.cylinder.position(physics)[:2],
                           self._arena.target_position])

  def tracked_positions(self, physics):
    target = np.append(self._arena.target_position, 0.0)
    return np.vstack([super().tracked_positions(physics),
                      self.cylinder.position(physics), target])


class Measurement(NamedTuple):
  """What transport reads from one state (`measure`)."""

  cylinder_target: float
  """d(cylinder, target), planar (m)."""
  cylinder_speed: float
  """The cylinder's planar speed (m/s)."""
  shaping: np.ndarray
  """[3, n] `rewards.inverse_distance` of d(cylinder, target),
  d(agent, cylinder) and d(agent, target)."""
  offsets: np.ndarray
  """[n, 4] the cylinder's and the target's offsets in each agent's heading
  frame (m)."""


@numba.njit(cache=True)
def measure(frames, xpos, cvel, cylinder, target, scales):
  """Everything transport reads from one state, for all agents in one
  compiled call (in numpy it was ~30 small-array calls, each paying for the
  caches the physics has just flushed).

  Args:
    frames: [n, >= 5] the agents' x, y, z, cos, sin (`AgentFrames.packed`).
    xpos: [nbody, 3] and cvel: [nbody, 6], MuJoCo's body positions and
      velocities (`physics.data`).
    cylinder: the cylinder's body id.
    target: [2] the target's centre (m).
    scales: coefficients of 1 / (1 + d) for d(cylinder, target),
      d(agent, cylinder) and d(agent, target).
  Returns:
    A `Measurement`.
  """
  n = frames.shape[0]
  cx, cy = xpos[cylinder, 0], xpos[cylinder, 1]
  tx, ty = target[0], target[1]
  cylinder_target = rewards.planar_norm(cx - tx, cy - ty)
  # cvel is [angular, linear] at the subtree's centre of mass: the body's own
  # for a single free body.
  cylinder_speed = rewards.planar_norm(cvel[cylinder, 3], cvel[cylinder, 4])
  shaping = np.empty((3, n))
  offsets = np.empty((n, 4))
  for i in range(n):
    x, y, cos, sin = frames[i, 0], frames[i, 1], frames[i, 3], frames[i, 4]
    shaping[0, i] = rewards.inverse_distance(scales[0], cylinder_target)
    shaping[1, i] = rewards.inverse_distance(
        scales[1], rewards.planar_norm(x - cx, y - cy))
    shaping[2, i] = rewards.inverse_distance(
        scales[2], rewards.planar_norm(x - tx, y - ty))
    offsets[i, 0], offsets[i, 1] = kernels.to_heading(cos, sin, cx - x, cy - y)
    offsets[i, 2], offsets[i, 3] = kernels.to_heading(cos, sin, tx - x, ty - y)
  return Measurement(cylinder_target, cylinder_speed, shaping, offsets)
