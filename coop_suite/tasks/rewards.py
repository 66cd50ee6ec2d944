"""Reward terms from the paper's reward tables, written once for all tasks.

Every function returns per-agent values, shape [n_agents], so tasks only
decide which terms to combine and with which coefficient (coefficients live
in each task's config dataclass). `inverse_distance` and `planar_norm` are
numpy ufuncs compiled by numba: they take arrays from Python, and scalars
inside a task's compiled kernel (see `transport.py`), so a formula is
written once either way.
"""

import math

import numba
import numpy as np


@numba.vectorize(["float64(float64, float64)"], cache=True)
def inverse_distance(scale, distance):
  """`scale / (1 + d)`: the paper's shaping term for a distance d (metres)."""
  return scale / (1.0 + distance)


@numba.vectorize(["float64(float64, float64)"], cache=True)
def planar_norm(dx, dy):
  """The length of a planar offset (dx, dy): sqrt(dx^2 + dy^2)."""
  return math.sqrt(dx * dx + dy * dy)


def planar_distance(a_xy, b_xy):
  """Euclidean distance over the last axis of [..., 2] arrays (metres)."""
  delta = np.subtract(a_xy, b_xy, dtype=np.float64)
  return planar_norm(delta[..., 0], delta[..., 1])


def velocity_tracking(scale, velocity_xy, command_xy, min_speed=0.05):
  """Velocity tracking: `scale * min(r, 2 - r)`, r = v . c / |c|^2.

  r is the speed along the command relative to the commanded speed. Up to
  r = 1 this is the paper's `5 * clamp(v . cmd, max=1)` (for a 1 m/s
  command; dividing by |c| makes slower commands reachable). The paper's
  clamp pays the same for any overshoot, and a controller trained on it ran
  1.5x faster than commanded (measured: mean speed error 47%), so beyond
  r = 1 the reward falls off again (a tent peaking at the commanded speed).
  A command slower than `min_speed` (m/s) means "stand still" and pays
  `scale * (1 - min(|v| / 0.5, 1))` instead.

  Args:
    scale: coefficient.
    velocity_xy: achieved planar velocity [..., 2], world frame (m/s).
    command_xy: commanded planar velocity [..., 2], world frame (m/s).
    min_speed: below this commanded speed, the stand-still reward applies.
  """
  velocity_xy = np.asarray(velocity_xy, dtype=np.float64)
  command_xy = np.asarray(command_xy, dtype=np.float64)
  vx, vy = velocity_xy[..., 0], velocity_xy[..., 1]
  cx, cy = command_xy[..., 0], command_xy[..., 1]
  speed = np.sqrt(cx * cx + cy * cy)
  safe = np.maximum(speed, min_speed)
  ratio = (vx * cx + vy * cy) / safe**2
  tracking = np.minimum(ratio, 2.0 - ratio)
  still = 1.0 - np.minimum(np.sqrt(vx * vx + vy * vy) / 0.5, 1.0)
  return scale * np.where(speed >= min_speed, tracking, still)


LOCOMOTION_TERMS = ("alive", "up", "action_cost", "energy_cost",
                    "joint_limit_cost")
"""The names of `locomotion_term_array`'s rows, in order."""


def locomotion_terms(proprio, actions, joint_ranges, config):
  """The lower layer's shared terms (alive, up, action/energy/limit costs).

  Follows Isaac Gym's Ant, which the paper's tables come from: the up bonus
  is paid while the torso's z axis is within ~21 degrees of vertical, energy
  is |action * joint velocity| with velocities scaled by 0.2, and a joint is
  "at its limit" beyond 99% of its half-range. Costs are returned negative.

  Args:
    proprio: the agents' proprioception, 'proprio/<name>' -> [n, dim], as
      `CoopTask.features(physics, ('proprio',))` returns it (computed once
      per state, shared with the observation): joint positions and
      velocities, and gravity in the torso frame, whose z is the cosine
      between the torso's z axis and the world's.
    actions: [n_agents, 8] last actions.
    joint_ranges: [n_agents, 8, 2] joint limits (rad), `CoopTask.joint_ranges`.
    config: an object with fields alive_bonus, up_bonus, action_cost,
      energy_cost, joint_limit_cost.
  Returns:
    dict of term name -> [n_agents] array.
  """
  return dict(zip(LOCOMOTION_TERMS, locomotion_term_array(
      proprio, actions, joint_ranges, config)))


def locomotion_term_array(proprio, actions, joint_ranges, config):
  """`locomotion_terms` as one float64 array [5, n_agents], its rows in
  `LOCOMOTION_TERMS` order (for code that adds them up every step)."""
  return _locomotion_terms(
      np.asarray(proprio["proprio/gravity"], np.float64),
      np.asarray(proprio["proprio/joints_pos"], np.float64),
      np.asarray(proprio["proprio/joints_vel"], np.float64),
      np.asarray(actions, np.float64),
      np.asarray(joint_ranges, np.float64), float(config.alive_bonus),
      float(config.up_bonus), float(config.action_cost),
      float(config.energy_cost), float(config.joint_limit_cost))


@numba.njit(cache=True)
def _locomotion_terms(gravity, joints_pos, joints_vel, actions, joint_ranges,
                      alive_bonus, up_bonus, action_cost, energy_cost,
                      joint_limit_cost):
  """The terms, each joint sum added in numpy's order (`_row_sum`), so
  the values are those of the same formulas in numpy, bit for bit."""
  n, joints = actions.shape
  out = np.empty((5, n))
  squares = np.empty(joints)
  energies = np.empty(joints)
  for i in range(n):
    at_limit = 0
    for j in range(joints):
      a = actions[i, j]
      squares[j] = a * a
      energies[j] = abs(a * 0.2 * joints_vel[i, j])
      low, high = joint_ranges[i, j, 0], joint_ranges[i, j, 1]
      if abs(joints_pos[i, j] - (high + low) / 2) > 0.99 * ((high - low) / 2):
        at_limit += 1
    out[0, i] = alive_bonus
    out[1, i] = up_bonus if gravity[i, 2] > 0.93 else 0.0
    out[2, i] = -action_cost * _row_sum(squares)
    out[3, i] = -energy_cost * _row_sum(energies)
    out[4, i] = -joint_limit_cost * at_limit
  return out


@numba.njit(cache=True)
def _row_sum(values):
  """`np.sum` of a contiguous float64 vector as numpy adds it (pairwise:
  eight running sums combined as a tree, then the remainder; in order
  below eight), for up to 128 values."""
  n = values.shape[0]
  if n < 8:
    total = 0.0
    for i in range(n):
      total += values[i]
    return total
  partial = values[:8].copy()
  i = 8
  while i < n - n % 8:
    for k in range(8):
      partial[k] += values[i + k]
    i += 8
  total = (((partial[0] + partial[1]) + (partial[2] + partial[3]))
           + ((partial[4] + partial[5]) + (partial[6] + partial[7])))
  while i < n:
    total += values[i]
    i += 1
  return total
