"""Single-agent locomotion tasks that train the lower layer.

Two command paradigms (paper section 5.3.1):

* `walk_to_target` (position paradigm): `command/target` is the offset to a
  target 2-6 m away, in the heading frame; reaching it (within
  `reach_radius`) draws a new one, so one episode practises many commands.
* `walk_velocity` (velocity paradigm): `command/velocity` is a planar
  velocity, fixed in the world and seen in the heading frame, redrawn every
  `command_period` seconds; with probability `p_stand` it is zero.

Both add the locomotion terms of the paper's lower-layer tables (alive, up,
action, energy and joint-limit costs) and end the episode with discount 0
when the Ant falls.
"""

import dataclasses

import numpy as np

from coop_suite import arenas
from coop_suite.tasks import base
from coop_suite.tasks import layouts
from coop_suite.tasks import exteroception
from coop_suite.tasks import rewards


@dataclasses.dataclass(frozen=True)
class LocomotionConfig(base.TaskConfig):
  """Terms shared by both paradigms (coefficients from the paper)."""

  time_limit: float = 20.0
  alive_bonus: float = 0.5
  up_bonus: float = 0.1
  action_cost: float = 0.005
  energy_cost: float = 0.05
  joint_limit_cost: float = 0.1
  fall_height: float = 0.28
  """The Ant has fallen when its torso centre is lower than this (m)."""


@dataclasses.dataclass(frozen=True)
class WalkToTargetConfig(LocomotionConfig):
  distance_scale: float = 5.0
  """Coefficient of 5 / (1 + d(agent, target))."""
  target_distance: tuple = (2.0, 6.0)
  """Range of a new target's distance from the Ant (m)."""
  reach_radius: float = 0.5
  """The target counts as reached within this distance (m)."""
  resample_on_reach: bool = True
  """Draw a new target when one is reached (False: keep it, for evaluation)."""


@dataclasses.dataclass(frozen=True)
class WalkVelocityConfig(LocomotionConfig):
  velocity_scale: float = 5.0
  """Coefficient of the velocity-tracking reward."""
  speed_range: tuple = (0.3, 1.0)
  """Range of commanded speeds (m/s)."""
  p_stand: float = 0.1
  """Probability that a drawn command is zero (stand still)."""
  command_period: float = 5.0
  """Seconds between command redraws."""


class _Locomotion(base.CoopTask):
  """One Ant on a floor; subclasses define the command and its reward."""

  MIN_AGENTS, MAX_AGENTS = 1, 1
  SHARED_EXTERO = False

  def __init__(self, n_agents, config):
    arena = arenas.Floor(size=(40.0, 40.0), target_radius=0.5,
                         physics_timestep=config.physics_timestep)
    super().__init__(arena, ["ant"] * n_agents, config)

  @property
  def walker(self):
    return self._walkers[0]

  def _initialize_layout(self, physics, random_state):
    layouts.place(self.walker, physics, [0.0, 0.0],
                  random_state.uniform(-np.pi, np.pi), random_state)
    self._random_state = random_state
    self._new_command(physics)

  def _update_status(self, physics):
    height = physics.data.xpos[self._torso_ids[0], 2]
    self._failure = bool(height < self._config.fall_height
                         or self.walker.upright(physics) < 0.0)

  def _reward_terms(self, physics):
    terms = rewards.locomotion_terms(self.features(physics, ("proprio",)),
                                     self._last_actions, self.joint_ranges,
                                     self._config)
    terms.update(self._command_terms(physics))
    return terms

  def _new_command(self, physics):
    raise NotImplementedError

  def _command_terms(self, physics):
    raise NotImplementedError

  def tracked_positions(self, physics):
    target = np.append(self._arena.target_position, 0.0)
    return np.vstack([super().tracked_positions(physics), target])


class WalkToTarget(_Locomotion):
  """Position paradigm: walk to a target given as a heading-frame offset."""

  COMMAND_FEATURES = ("target",)

  def __init__(self, n_agents=1, config=WalkToTargetConfig()):
    super().__init__(n_agents, config)
    self._reached = 0

  def _initialize_layout(self, physics, random_state):
    self._reached = 0
    super()._initialize_layout(physics, random_state)

  def _new_command(self, physics):
    distance = self._random_state.uniform(*self._config.target_distance)
    angle = self._random_state.uniform(-np.pi, np.pi)
    origin = self.walker.torso_position(physics)[:2]
    self._arena.set_target(physics, origin + distance * np.array(
        [np.cos(angle), np.sin(angle)]))

  def _commands(self, physics, frames):
    return {"target": frames.to_heading_frame(self._arena.target_position)}

  def _distance(self, physics):
    return float(rewards.planar_distance(
        self.walker.torso_position(physics)[:2], self._arena.target_position))

  def _update_status(self, physics):
    super()._update_status(physics)
    if self._distance(physics) < self._config.reach_radius:
      if self._config.resample_on_reach:
        self._reached += 1
        self._new_command(physics)
      elif self._reached == 0:
        self._reached = 1

  def _command_terms(self, physics):
    return {"distance": np.array([rewards.inverse_distance(
        self._config.distance_scale, self._distance(physics))])}

  def _progress(self, physics):
    distance = self._distance(physics)
    return {"targets_reached": self._reached,
            "target_distance": distance,
            "success": bool(self._reached > 0 or distance
                            < self._config.reach_radius)}

  def _task_state(self, physics):
    return self._arena.target_position


class WalkVelocity(_Locomotion):
  """Velocity paradigm: track a planar velocity given in the heading frame."""

  COMMAND_FEATURES = ("velocity",)

  def __init__(self, n_agents=1, config=WalkVelocityConfig()):
    super().__init__(n_agents, config)
    self._command = np.zeros(2)
    self._tracking = []

  def _initialize_layout(self, physics, random_state):
    self._tracking = []
    super()._initialize_layout(physics, random_state)

  def _new_command(self, physics):
    cfg = self._config
    rs = self._random_state
    self._command_time = physics.data.time
    if rs.uniform() < cfg.p_stand:
      self._command = np.zeros(2)
    else:
      speed = rs.uniform(*cfg.speed_range)
      angle = rs.uniform(-np.pi, np.pi)
      self._command = speed * np.array([np.cos(angle), np.sin(angle)])

  @property
  def command(self):
    """The current command, world frame (m/s)."""
    return self._command.copy()

  def set_command(self, physics, velocity_xy):
    """Overrides the command (world frame, m/s) until the next redraw."""
    self._command = np.asarray(velocity_xy, dtype=np.float64).copy()
    self._command_time = physics.data.time

  def _commands(self, physics, frames):
    return {"velocity": exteroception.rotate_to_heading(
        self._command[None], frames.cos, frames.sin)}

  def _update_status(self, physics):
    super()._update_status(physics)
    velocity = self.walker.world_velocity(physics)[:2]
    self._tracking.append(np.concatenate([velocity, self._command]))
    if (physics.data.time - self._command_time
        >= self._config.command_period - 1e-9):
      self._new_command(physics)

  def _command_terms(self, physics):
    velocity = self.walker.world_velocity(physics)[:2]
    return {"velocity": np.array([rewards.velocity_tracking(
        self._config.velocity_scale, velocity, self._command)])}

  def _progress(self, physics):
    """Tracking quality over the episode, transients after each redraw
    included. A figure is left out when the episode had no step it applies
    to (no zero command: no `mean_speed_still`), so that averages over
    episodes are not pulled towards a made-up 0."""
    if not self._tracking:
      return {}
    data = np.array(self._tracking)
    velocity, command = data[:, :2], data[:, 2:]
    speed = np.linalg.norm(command, axis=1)
    moving = speed > 0.05
    achieved = np.linalg.norm(velocity, axis=1)
    out = {}
    if np.any(~moving):
      out["mean_speed_still"] = float(np.mean(achieved[~moving]))
    if np.any(moving):
      cos = np.sum(velocity[moving] * command[moving], 1) / (
          np.maximum(achieved[moving], 1e-6) * speed[moving])
      out["velocity_cosine"] = float(np.mean(cos))
      out["speed_error"] = float(np.mean(
          np.abs(achieved[moving] - speed[moving]) / speed[moving]))
    return out

  def _task_state(self, physics):
    return self._command

