"""Corridor crossing: everybody through a slit that fits one Ant at a time.

Agents start on an arc, all at the same distance from the slit's entrance,
so that rushing together jams the slit. Each agent that crosses the finish
line pays every agent a bonus; success when all have crossed.
`start_heading_error` records the episode's start (the Ants' mean angle
away from facing the entrance, rad), so that `coop-compare` can check that
two evaluations played the same episodes.
"""

import dataclasses
from typing import NamedTuple

import numba
import numpy as np

from coop_suite import arenas
from coop_suite import kernels
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
    self._start_heading_error = 0.0  # See `_progress`.
    # `measure`'s arguments after the frames (the arena does not move).
    self._geometry = (float(arena.finish_x), arena.slit_entrance,
                      arena.slit_exit, float(arena.slit_width), self._target,
                      float(config.agent_target_scale))

  def _exteroception(self, physics, frames):
    offsets = self._measure(physics).offsets
    return {
        "slit": offsets[:, :5],
        "target": offsets[:, 5:],
        "crossed": self._crossed[:, None].astype(np.float64),
    }

  def _measure(self, physics):
    """`measure` of this physics state (computed once per state)."""
    return self.per_state("measure", lambda: measure(
        self.frames(physics).packed, *self._geometry))

  def _initialize_layout(self, physics, random_state):
    cfg = self._config
    self._crossed = np.zeros(self.n_agents, dtype=bool)
    self._new_crossings = 0
    entrance = self._arena.slit_entrance
    starts = layouts.arc(self.n_agents, entrance, cfg.start_distance,
                         facing=np.pi)
    turns = random_state.uniform(-0.3, 0.3, self.n_agents)
    yaws = layouts.face(starts, entrance) + turns
    self._start_heading_error = float(np.mean(np.abs(turns)))
    for walker, xy, yaw in zip(self._walkers, starts, yaws):
      layouts.place(walker, physics, xy, yaw, random_state)

  def _update_status(self, physics):
    # Past the line, not crossed before.
    newly = self._measure(physics).past_finish > self._crossed
    self._new_crossings = int(np.count_nonzero(newly))
    self._crossed |= newly
    self._success = bool(self._crossed.all())

  def _reward_terms(self, physics):
    return {
        "crossing": self.each_agent(
            self._config.crossing_bonus * self._new_crossings),
        "agent_target": self._measure(physics).agent_target,
    }

  def _progress(self, physics):
    return {"crossed": int(np.sum(self._crossed)),
            "fraction_crossed": float(np.mean(self._crossed)),
            "start_heading_error": self._start_heading_error}

  def _task_state(self, physics):
    return self._crossed.astype(np.float64)

  def tracked_positions(self, physics):
    slit = np.append(self._arena.slit_exit, 0.0)
    return np.vstack([super().tracked_positions(physics), slit])


class Measurement(NamedTuple):
  """What the corridor reads from one state (`measure`)."""

  past_finish: np.ndarray
  """[n] whether each agent's torso is past the finish line."""
  agent_target: np.ndarray
  """[n] `rewards.inverse_distance` of d(agent, target)."""
  offsets: np.ndarray
  """[n, 7] the slit's entrance and exit in each agent's heading frame, the
  slit's width, the target in the heading frame (m)."""


@numba.njit(cache=True)
def measure(frames, finish_x, entrance, exit_, slit_width, target,
            target_scale):
  """What the corridor reads from one state, for all agents in one compiled
  call (see `transport.measure` for why).

  Args:
    frames: [n, >= 5] the agents' x, y, z, cos, sin (`AgentFrames.packed`).
    finish_x: the finish line's x (m).
    entrance, exit_: [2] the slit's entrance and exit centres (m).
    slit_width: the slit's width (m).
    target: [2] the point of the finish line in front of the slit (m).
    target_scale: coefficient of 1 / (1 + d(agent, target)).
  Returns:
    A `Measurement`.
  """
  n = frames.shape[0]
  past_finish = np.empty(n, dtype=np.bool_)
  agent_target = np.empty(n)
  offsets = np.empty((n, 7))
  tx, ty = target[0], target[1]
  for i in range(n):
    x, y, cos, sin = frames[i, 0], frames[i, 1], frames[i, 3], frames[i, 4]
    past_finish[i] = x > finish_x
    agent_target[i] = rewards.inverse_distance(
        target_scale, rewards.planar_norm(x - tx, y - ty))
    offsets[i, 0], offsets[i, 1] = kernels.to_heading(
        cos, sin, entrance[0] - x, entrance[1] - y)
    offsets[i, 2], offsets[i, 3] = kernels.to_heading(
        cos, sin, exit_[0] - x, exit_[1] - y)
    offsets[i, 4] = slit_width
    offsets[i, 5], offsets[i, 6] = kernels.to_heading(cos, sin, tx - x,
                                                      ty - y)
  return Measurement(past_finish, agent_target, offsets)
