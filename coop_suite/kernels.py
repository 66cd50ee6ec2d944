"""Compiled kernels (numba) for what every task computes at each step.

Why compiled: for transport with four Ants the physics of one control step
costs ~400-500 us on our 2-core machine, and each numpy call on these tiny
arrays costs ~1 us hot and several times that right after the physics,
which leaves the caches cold. The proprioception, heading frames, nearest
teammates and ray-cast heights of all agents took ~100 such calls, i.e. a
third of the step. Each kernel below does one of them for all agents in one
call, with the same floating-point operations in the same order as the numpy
expressions in their docstrings, so the features are bit-identical to the
numpy versions they replace (`tests/test_kernels.py` checks it on real
states). The same holds for each task's own `measure` kernel (its geometry,
status and shaping terms, next to the task in `tasks/`), the reward sums
(`add_rewards`) and the action check (`clip_finite`).

Arrays are MuJoCo's own (`physics.data.xpos` etc., never copied in Python);
every kernel returns a new array, so observations built from it stay valid
after later steps. Compiled once per machine and cached on disk
(`cache=True`); the first import in a fresh checkout takes a few seconds.
"""

import math

import numba
import numpy as np

from coop_suite.fast import raycast

# Column layout of the proprioception (`agent_state`'s columns 5 onwards).
PROPRIO_LAYOUT = (("joints_pos", 8), ("joints_vel", 8), ("torso_height", 1),
                  ("gravity", 3), ("velocity", 3), ("angular_velocity", 3),
                  ("prev_action", 8))
PROPRIO_SIZE = sum(size for _, size in PROPRIO_LAYOUT)


def proprio_columns(offset=0, prefix=""):
  """((prefix + name, slice of its columns), ...) in PROPRIO_LAYOUT order,
  for the proprioception at column `offset` of a packed array."""
  columns, start = [], offset
  for name, size in PROPRIO_LAYOUT:
    columns.append((prefix + name, slice(start, start + size)))
    start += size
  return tuple(columns)


@numba.njit(cache=True)
def rotate(cos, sin, x, y):
  """The planar vector (x, y) turned by the angle of cosine `cos` and sine
  `sin`: (cos x - sin y, sin x + cos y).

  The suite's one 2-D rotation: a heading-frame vector into the world frame
  with an agent's (cos, sin) of its yaw, a world offset into the heading
  frame with (cos, -sin) (`to_heading`). Compiled for the kernels;
  `rotate.py_func` is the same formula for numpy arrays (broadcast).
  """
  return cos * x - sin * y, sin * x + cos * y


@numba.njit(cache=True)
def to_heading(cos, sin, dx, dy):
  """A world-frame offset (dx, dy) seen in the heading frame of yaw (cos,
  sin): `rotate` by -yaw, (cos dx + sin dy, cos dy - sin dx) bit for bit
  (negation is exact)."""
  return rotate(cos, -sin, dx, dy)


@numba.njit(cache=True)
def _write_frame(xpos, xmat, b, out, i, col):
  """Body b's x, y, z, cos, sin into out[i, col:col + 5] (`heading_frames`)."""
  out[i, col] = xpos[b, 0]
  out[i, col + 1] = xpos[b, 1]
  out[i, col + 2] = xpos[b, 2]
  cos, sin = xmat[b, 0], xmat[b, 3]
  norm = math.hypot(cos, sin)
  if norm == 0.0:
    norm = 1.0
  out[i, col + 3] = cos / norm
  out[i, col + 4] = sin / norm


@numba.njit(cache=True)
def _write_proprioception(xpos, xmat, qpos, qvel, b, qpos_adr, dof_adr, free,
                          prev_action, out, i, col):
  """One Ant's proprioception into out[i, col:col + PROPRIO_SIZE], in
  PROPRIO_LAYOUT order; b is its torso body, qpos_adr, dof_adr and
  prev_action are its rows, free its free joint's first dof.

  joints_pos = qpos[qpos_adr], joints_vel = qvel[dof_adr], torso_height =
  xpos[b, 2], gravity = the last row of the torso's xmat (the world's z axis
  in the torso frame), velocity = v^T R (the free joint's world linear
  velocity in the torso frame), angular_velocity = the free joint's (already
  local) angular velocity, prev_action = the last action.
  """
  joints = qpos_adr.shape[0]
  for j in range(joints):
    out[i, col + j] = qpos[qpos_adr[j]]
  col += joints
  for j in range(joints):
    out[i, col + j] = qvel[dof_adr[j]]
  col += joints
  out[i, col] = xpos[b, 2]
  col += 1
  for j in range(3):
    out[i, col + j] = xmat[b, 6 + j]
  col += 3
  v0, v1, v2 = qvel[free], qvel[free + 1], qvel[free + 2]
  for j in range(3):
    out[i, col + j] = v0 * xmat[b, j] + v1 * xmat[b, 3 + j] + v2 * xmat[
        b, 6 + j]
  col += 3
  for j in range(3):
    out[i, col + j] = qvel[free + 3 + j]
  col += 3
  for j in range(prev_action.shape[0]):
    out[i, col + j] = prev_action[j]


@numba.njit(cache=True)
def add_rewards(terms, sums, returns):
  """Every agent's reward from its terms ([terms, n]): the total, summed in
  term order, as float32 [n]; adds the terms to `sums` ([terms, n]) and the
  total to `returns` ([n]) in place."""
  n = terms.shape[1]
  total = np.zeros(n)
  for t in range(terms.shape[0]):
    for i in range(n):
      sums[t, i] += terms[t, i]
      total[i] += terms[t, i]
  out = np.empty(n, dtype=np.float32)
  for i in range(n):
    returns[i] += total[i]
    out[i] = total[i]
  return out


@numba.njit(cache=True)
def clip_finite(values, low, high):
  """`values` [n, d] clipped to [low[j], high[j]] in column j, as a new
  float array; None if any value is NaN or infinite."""
  out = np.empty(values.shape)
  for i in range(values.shape[0]):
    for j in range(values.shape[1]):
      value = values[i, j]
      if not math.isfinite(value):
        return None
      out[i, j] = min(max(value, low[j]), high[j])
  return out


@numba.njit(cache=True)
def heading_frames(xpos, xmat, bodies):
  """Positions and headings of `bodies`: [n, 5] = x, y, z, cos, sin.

  The heading is the yaw of the body's x axis: (xmat[0], xmat[3]) divided by
  np.hypot of both (by 1 where that is 0).
  """
  n = bodies.shape[0]
  out = np.empty((n, 5))
  for i in range(n):
    _write_frame(xpos, xmat, bodies[i], out, i, 0)
  return out


@numba.njit(cache=True)
def agent_state(xpos, xmat, qpos, qvel, torso, qpos_adr, dof_adr, free_adr,
                prev_action):
  """Every Ant's torso frame (x, y, z, cos, sin as `heading_frames`) and
  proprioception (`_write_proprioception`) side by side, [n, 5 +
  PROPRIO_SIZE]: what every task reads at every control step, in one call."""
  n = torso.shape[0]
  out = np.empty((n, 5 + PROPRIO_SIZE))
  for i in range(n):
    _write_frame(xpos, xmat, torso[i], out, i, 0)
    _write_proprioception(xpos, xmat, qpos, qvel, torso[i], qpos_adr[i],
                          dof_adr[i], free_adr[i], prev_action[i], out, i, 5)
  return out


@numba.njit(cache=True)
def nearest_teammates(frames, k, species, out, column):
  """Writes each agent's k nearest teammates into out[:, column:].

  `frames` is `heading_frames`' [n, 5]; `species` [n] ints: agent i's
  teammates are the other agents of its species. Columns: 2k heading-frame
  offsets (nearest first, zero padding), then k mask values (1 real, 0
  padding). Offsets to j from i: d = xy[j] - xy[i], then `to_heading` with
  agent i's heading. Ties keep the lower index.
  """
  n = frames.shape[0]
  dist2 = np.empty(n)
  for i in range(n):
    xi, yi = frames[i, 0], frames[i, 1]
    cos, sin = frames[i, 3], frames[i, 4]
    for j in range(n):
      dx, dy = frames[j, 0] - xi, frames[j, 1] - yi
      # -1 marks an agent that is not (or no longer) a candidate.
      dist2[j] = dx * dx + dy * dy if species[j] == species[i] else -1.0
    dist2[i] = np.inf  # Nobody is their own teammate.
    for slot in range(k):
      best = -1
      if slot < n - 1:
        for j in range(n):
          if dist2[j] != -1.0 and (best < 0 or dist2[j] < dist2[best]):
            best = j
      if best < 0 or best == i:
        out[i, column + 2 * slot] = 0.0
        out[i, column + 2 * slot + 1] = 0.0
        out[i, column + 2 * k + slot] = 0.0
        continue
      out[i, column + 2 * slot], out[i, column + 2 * slot + 1] = to_heading(
          cos, sin, frames[best, 0] - xi, frames[best, 1] - yi)
      out[i, column + 2 * k + slot] = 1.0
      dist2[best] = -1.0  # Taken.


@numba.vectorize(["float64(float64, float64, float64, float64)"], cache=True)
def ray_height(dist, scale, origin_height, no_hit):
  """The height (world z, m) a downward ray from `origin_height` met after
  `dist` (`scale` = its length per metre of drop): origin_height - dist /
  scale, never below `no_hit`, which is also the answer where it met nothing
  (dist < 0). A numpy ufunc, and a scalar function inside kernels."""
  if dist < 0:
    return no_hit
  return max(origin_height - dist / scale, no_hit)


@numba.njit(cache=True)
def terrain_heights(geom_xpos, geom_xmat, geom_size, geom_type, candidates,
                    frames, local_dirs, scale, origin_height, no_hit, out,
                    column):
  """Writes ray-cast terrain heights into out[:, column:column + m].

  Per agent m rays from (x, y, origin_height) along the `local_dirs` ([m, 3],
  heading frame) turned by its yaw (`rotate`; lz unchanged), each
  against the `candidates` geoms (`raycast.nearest_hit`), the distance
  turned into a height by `ray_height`.
  """
  n, m = frames.shape[0], local_dirs.shape[0]
  origin = np.empty(3)
  direction = np.empty(3)
  for i in range(n):
    cos, sin = frames[i, 3], frames[i, 4]
    origin[0], origin[1], origin[2] = frames[i, 0], frames[i, 1], origin_height
    for r in range(m):
      direction[0], direction[1] = rotate(cos, sin, local_dirs[r, 0],
                                          local_dirs[r, 1])
      direction[2] = local_dirs[r, 2]
      dist = raycast.nearest_hit(geom_xpos, geom_xmat, geom_size, geom_type,
                                 candidates, origin, direction)
      out[i, column + r] = ray_height(dist, scale[r], origin_height, no_hit)


@numba.njit(cache=True)
def shared_exteroception(frames, k, species, geom_xpos, geom_xmat, geom_size,
                         geom_type, candidates, local_dirs, scale,
                         origin_height, no_hit):
  """Features every cooperative task shows each agent, [n, 4 + 3k + m]:
  self_pose (x, y, cos, sin), `nearest_teammates` (2k offsets, k mask; of
  the agent's own `species`) and `terrain_heights` (m samples), in one
  call."""
  n, m = frames.shape[0], local_dirs.shape[0]
  out = np.empty((n, 4 + 3 * k + m))
  for i in range(n):
    out[i, 0] = frames[i, 0]
    out[i, 1] = frames[i, 1]
    out[i, 2] = frames[i, 3]
    out[i, 3] = frames[i, 4]
  nearest_teammates(frames, k, species, out, 4)
  terrain_heights(geom_xpos, geom_xmat, geom_size, geom_type, candidates,
                  frames, local_dirs, scale, origin_height, no_hit, out,
                  4 + 3 * k)
  return out


@numba.njit(cache=True)
def command_input(frames, proprioception, world, velocity, source, columns,
                  command_columns, out):
  """The lower layer's input rows, written into `out` [n, d] in one call.

  Row i gets agent i's `proprioception[i, source]` in `out[i, columns]` and
  its command in `out[i, command_columns]` (2 columns): the world-frame
  command `world[i]` seen in the agent's heading frame (`frames`, [n, >= 5]
  x, y, z, cos, sin), as an offset from the agent to that point (position
  paradigm) or as it is (`velocity`), through `to_heading`. The same
  operations as `heading_offsets` and numpy's `rotate.py_func(cos, -sin,
  ...)`, so the same numbers (cast to `out`'s dtype as numpy assigns).
  """
  for i in range(out.shape[0]):
    dx, dy = world[i, 0], world[i, 1]
    if not velocity:
      dx, dy = dx - frames[i, 0], dy - frames[i, 1]
    x, y = to_heading(frames[i, 3], frames[i, 4], dx, dy)
    out[i, command_columns[0]] = x
    out[i, command_columns[1]] = y
    for k in range(source.shape[0]):
      out[i, columns[k]] = proprioception[i, source[k]]


@numba.njit(cache=True)
def heading_offsets(frames, world_xy):
  """Offsets from each agent to world points, in its heading frame.

  `world_xy` is [m, 2] (the same m points for every agent) or [n, m, 2] (m
  points per agent); returns [n, m, 2]: d = p - xy, then `to_heading` with
  the agent's heading.
  """
  n = frames.shape[0]
  m = world_xy.shape[-2]
  out = np.empty((n, m, 2))
  for i in range(n):
    x, y, cos, sin = frames[i, 0], frames[i, 1], frames[i, 3], frames[i, 4]
    for j in range(m):
      if world_xy.ndim == 2:
        dx, dy = world_xy[j, 0] - x, world_xy[j, 1] - y
      else:
        dx, dy = world_xy[i, j, 0] - x, world_xy[i, j, 1] - y
      out[i, j, 0], out[i, j, 1] = to_heading(cos, sin, dx, dy)
  return out
