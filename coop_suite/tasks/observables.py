"""Exteroception shared by every task: what the upper layer sees.

Features are computed for all agents at once (arrays with a leading agent
axis [n, ...]) because composer's per-observable overhead, paid once per
agent and feature, would otherwise cost more than the physics itself.

Planar vectors are expressed in each agent's heading frame: the world frame
rotated by the torso's yaw (x ahead, y to the left), in metres. Sizes never
depend on the number of agents, so one policy runs in any population.
"""

import typing

import mujoco
import numpy as np

from coop_suite.arenas import TERRAIN_GROUP

# Height-sample rays start this far above the agent's torso (metres). The
# rays fan out from one point (one `mj_multiRay` call per agent), so a high
# origin keeps them close to vertical: within 6 degrees for the default grid.
_RAY_ORIGIN_HEIGHT = 8.0
# Height reported where a ray hits nothing within its range (metres).
_NO_HIT_HEIGHT = -3.0


class AgentFrames(typing.NamedTuple):
  """Where every agent is and which way it faces, for one physics state."""

  position: np.ndarray  # [n, 3] torso centres, world frame (m).
  cos: np.ndarray  # [n] cosine of the heading (yaw).
  sin: np.ndarray  # [n] sine of the heading (yaw).

  @classmethod
  def from_walkers(cls, walkers, physics):
    ids = [w._torso_id for w in walkers]  # pylint: disable=protected-access
    xmat = physics.data.xmat[ids]
    cos, sin = xmat[:, 0], xmat[:, 3]
    norm = np.hypot(cos, sin)
    norm[norm == 0] = 1.0
    return cls(physics.data.xpos[ids].copy(), cos / norm, sin / norm)

  def to_heading_frame(self, world_xy):
    """Offsets from each agent to world points, in its heading frame.

    Args:
      world_xy: [2] (one point for all), [n, 2] (one per agent) or
        [n, m, 2] (m per agent), world frame (m).
    Returns:
      [n, 2] or [n, m, 2] offsets, heading frame (m).
    """
    world_xy = np.asarray(world_xy, dtype=np.float64)
    origin, cos, sin = self.position[:, :2], self.cos, self.sin
    if world_xy.ndim == 3:
      origin, cos, sin = origin[:, None], cos[:, None], sin[:, None]
    return rotate_to_heading(world_xy - origin, cos, sin)


def rotate_to_heading(delta, cos, sin):
  """Rotates world-frame offsets [..., 2] by -yaw (cos, sin broadcast)."""
  dx, dy = delta[..., 0], delta[..., 1]
  out = np.empty(np.broadcast_shapes(dx.shape, np.shape(cos)) + (2,))
  out[..., 0] = cos * dx + sin * dy
  out[..., 1] = cos * dy - sin * dx
  return out


def self_pose(frames):
  """World pose [x, y, cos(yaw), sin(yaw)] per agent, shape [n, 4]."""
  out = np.empty((len(frames.cos), 4))
  out[:, :2] = frames.position[:, :2]
  out[:, 2] = frames.cos
  out[:, 3] = frames.sin
  return out


def nearest_teammates(frames, k):
  """Offsets to each agent's k nearest teammates and a validity mask.

  Returns:
    offsets: [n, k * 2], heading frame (m), nearest first, zero padding.
    mask: [n, k], 1.0 for a real teammate and 0.0 for padding.
  """
  n = len(frames.cos)
  offsets = np.zeros((n, k, 2))
  mask = np.zeros((n, k))
  m = min(k, n - 1)
  if m > 0:
    xy = frames.position[:, :2]
    delta = xy[None, :, :] - xy[:, None, :]  # [i, j]: from agent i to j.
    dist2 = np.einsum("ijk,ijk->ij", delta, delta)
    np.fill_diagonal(dist2, np.inf)
    if m == 1:
      order = np.argmin(dist2, axis=1)[:, None]
    else:
      order = np.argsort(dist2, axis=1)[:, :m]
    nearest = delta[np.arange(n)[:, None], order]  # [n, m, 2]
    offsets[:, :m] = rotate_to_heading(nearest, frames.cos[:, None],
                                       frames.sin[:, None])
    mask[:, :m] = 1.0
  return offsets.reshape(n, -1), mask


class HeightSampler:
  """Terrain heights on a `grid` x `grid` square around each agent.

  The square is centred on the torso, aligned with its heading frame,
  `spacing` metres between samples, row-major from back-right to front-left.
  Each value is the world z (m) of the first terrain or prop surface a ray
  meets on its way down; Ants are invisible to the rays (geom group 1).
  """

  def __init__(self, grid, spacing):
    ticks = (np.arange(grid) - (grid - 1) / 2) * spacing
    local = np.stack(np.meshgrid(ticks, ticks, indexing="ij"),
                     -1).reshape(-1, 2)
    self._num = len(local)
    # Unit directions from the ray origin to each sample point at z = 0, in
    # the heading frame; rotating them by the yaw keeps them unit length.
    rays = np.concatenate([local, np.full((self._num, 1),
                                          -_RAY_ORIGIN_HEIGHT)], axis=1)
    self._scale = np.linalg.norm(rays, axis=1) / _RAY_ORIGIN_HEIGHT
    self._local_dirs = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    self._group = np.zeros(6, dtype=np.uint8)
    self._group[TERRAIN_GROUP] = 1
    self._geom_id = np.zeros(self._num, dtype=np.int32)

  @property
  def size(self):
    return self._num

  def __call__(self, physics, frames):
    """Returns [n, grid * grid] heights (m, world z)."""
    n = len(frames.cos)
    lx, ly, lz = self._local_dirs.T
    c, s = frames.cos[:, None], frames.sin[:, None]
    dirs = np.empty((n, self._num, 3))
    dirs[..., 0] = c * lx - s * ly
    dirs[..., 1] = s * lx + c * ly
    dirs[..., 2] = lz
    origins = frames.position.copy()
    origins[:, 2] = _RAY_ORIGIN_HEIGHT
    dist = np.empty((n, self._num))
    model, data = physics.model.ptr, physics.data.ptr
    for i in range(n):
      mujoco.mj_multiRay(model, data, origins[i], dirs[i].ravel(),
                         self._group, 1, -1, self._geom_id, dist[i], None,
                         self._num, 100.0)
    heights = _RAY_ORIGIN_HEIGHT - dist / self._scale
    return np.where(dist >= 0, np.maximum(heights, _NO_HIT_HEIGHT),
                    _NO_HIT_HEIGHT)
