"""Exteroception shared by every task: what the upper layer sees.

`AgentFrames` (where each agent is and which way it faces),
`rotate_to_heading`, `nearest_teammates` and `HeightSampler` (ray-cast
terrain heights); the tasks' observables are built in `base.py`.

Features are computed for all agents at once (arrays with a leading agent
axis [n, ...]) because composer's per-observable overhead, paid once per
agent and feature, would otherwise cost more than the physics itself; the
shared ones (frames, teammates, heights) in compiled kernels (`kernels.py`).

Planar vectors are expressed in each agent's heading frame: the world frame
rotated by the torso's yaw (x ahead, y to the left), in metres. Sizes never
depend on the number of agents, so one policy runs in any population.
"""

import mujoco
import numpy as np

from coop_suite.arenas import TERRAIN_GROUP
from coop_suite import kernels
from coop_suite.fast import raycast

# Height-sample rays start this far above the agent's torso (metres). The
# rays fan out from one point per agent, so a high origin keeps them close to
# vertical: within 6 degrees for the default grid.
_RAY_ORIGIN_HEIGHT = 8.0
# Height reported where a ray hits nothing within its range (metres).
_NO_HIT_HEIGHT = -3.0


class AgentFrames:
  """Where every agent is and which way it faces, for one physics state.

  Fields: `position` [n, 3] torso centres, world frame (m); `cos`, `sin` [n]
  of the heading (yaw); `packed` [n, >= 5] whose first five columns are x,
  y, z, cos, sin, the array the compiled kernels read (None for frames built
  by hand, see `as_packed`). Built from a kernel's output, the other fields
  are views of `packed`, made on first use: most steps need none of them.
  """

  __slots__ = ("_position", "_cos", "_sin", "packed")

  def __init__(self, position=None, cos=None, sin=None, packed=None):
    if packed is None and (position is None or cos is None or sin is None):
      raise ValueError("AgentFrames needs position, cos and sin, or packed.")
    self._position, self._cos, self._sin = position, cos, sin
    self.packed = packed

  @property
  def position(self):
    if self._position is None:
      self._position = self.packed[:, :3]
    return self._position

  @property
  def cos(self):
    if self._cos is None:
      self._cos = self.packed[:, 3]
    return self._cos

  @property
  def sin(self):
    if self._sin is None:
      self._sin = self.packed[:, 4]
    return self._sin

  @classmethod
  def from_walkers(cls, walkers, physics):
    ids = np.array([w._torso_id for w in walkers])  # pylint: disable=protected-access
    return cls.from_bodies(physics, ids)

  @classmethod
  def from_bodies(cls, physics, body_ids):
    """Frames of the bodies `body_ids` (the agents' torsos)."""
    return cls(packed=kernels.heading_frames(
        physics.data.xpos, physics.data.xmat, body_ids))

  @classmethod
  def from_packed(cls, packed):
    """Frames of `packed` ([n, >= 5], first columns x, y, z, cos, sin, e.g.
    `kernels.heading_frames` or `kernels.agent_state`), not copied."""
    return cls(packed=packed)

  def as_packed(self):
    """The [n, >= 5] array the kernels read, built if the frames lack one."""
    if self.packed is not None:
      return self.packed
    return np.column_stack([self.position, self.cos, self.sin]).astype(
        np.float64)

  def to_heading_frame(self, world_xy):
    """Offsets from each agent to world points, in its heading frame.

    Args:
      world_xy: [2] (one point for all), [n, 2] (one per agent) or
        [n, m, 2] (m per agent), world frame (m).
    Returns:
      [n, 2] or [n, m, 2] offsets, heading frame (m).
    """
    world_xy = np.asarray(world_xy, dtype=np.float64)
    shape = world_xy.shape
    if (not 1 <= len(shape) <= 3 or shape[-1] != 2
        or (len(shape) > 1 and shape[0] != len(self.cos))):
      raise ValueError(f"Expected world points of shape [2], [{len(self.cos)}"
                       f", 2] or [{len(self.cos)}, m, 2]; got {shape}.")
    if world_xy.ndim == 1:  # One point for all: [1, 2].
      return kernels.heading_offsets(self.as_packed(), world_xy[None])[:, 0]
    if world_xy.ndim == 2:  # One point per agent: [n, 1, 2].
      return kernels.heading_offsets(self.as_packed(), world_xy[:, None])[:, 0]
    return kernels.heading_offsets(self.as_packed(), world_xy)


def rotate_to_heading(delta, cos, sin):
  """World-frame offsets [..., 2] in the heading frame of yaw (cos, sin),
  broadcast: `kernels.rotate` by -yaw, on numpy arrays."""
  x, y = kernels.rotate.py_func(cos, -np.asarray(sin), delta[..., 0],
                                delta[..., 1])
  return np.stack([x, y], -1)


def nearest_teammates(frames, k, species=None):
  """Offsets to each agent's k nearest teammates and a validity mask.

  Args:
    frames: the agents' `AgentFrames`.
    k: teammates per agent.
    species: [n] ints, the agents' species: teammates are the other agents
      of one's own species (None: one species).

  Returns:
    offsets: [n, k * 2], heading frame (m), nearest first, zero padding.
    mask: [n, k], 1.0 for a real teammate and 0.0 for padding.
  """
  n = len(frames.cos)
  if species is None:
    species = np.zeros(n, np.int64)
  else:
    species = np.asarray(species)
    if species.shape != (n,) or species.dtype.kind not in "iu":
      raise ValueError(f"species must be {n} integers, one per agent; got "
                       f"{species.dtype} {species.shape}.")
    species = species.astype(np.int64)
  out = np.empty((n, 3 * k))
  kernels.nearest_teammates(frames.as_packed(), k, species, out, 0)
  return out[:, :2 * k], out[:, 2 * k:]


class HeightSampler:
  """Terrain heights on a `grid` x `grid` square around each agent.

  The square is centred on the torso, aligned with its heading frame,
  `spacing` metres between samples, row-major from back-right to front-left.
  Each value is the world z (m) of the first terrain or prop surface a ray
  meets on its way down; Ants are invisible to the rays (geom group 1).

  Calling it casts the rays from compiled code against the terrain geoms
  only (`coop_suite.fast.raycast`); `multi_ray` casts them with MuJoCo's
  own `mj_multiRay`, the plain path: the same heights, bit for bit.
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
    self._bound = (None, None)  # (the mjData, its geom arguments).

  @property
  def size(self):
    return self._num

  @property
  def geom_group(self):
    """The `geomgroup` mask of `mj_ray` that selects the terrain."""
    return self._group

  @property
  def ray_args(self):
    """The rays' arguments of `kernels.terrain_heights` (after `geom_args`
    and `frames`): directions, scales, origin height, no-hit height."""
    return (self._local_dirs, self._scale, _RAY_ORIGIN_HEIGHT, _NO_HIT_HEIGHT)

  def geom_args(self, physics):
    """The geoms' arguments of `kernels.terrain_heights`: MuJoCo's geom
    arrays of `physics` and the terrain geoms' ids
    (`raycast.terrain_geoms`)."""
    data = physics.data.ptr
    if self._bound[0] is not data:  # Views into this mjData, kept with it.
      model = physics.model.ptr
      self._bound = (data, (data.geom_xpos, data.geom_xmat, model.geom_size,
                            model.geom_type.astype(np.int32),
                            raycast.terrain_geoms(model, self._group)))
    return self._bound[1]

  def __call__(self, physics, frames):
    """Returns [n, grid * grid] heights (m, world z)."""
    out = np.empty((len(frames.cos), self._num))
    kernels.terrain_heights(*self.geom_args(physics), frames.as_packed(),
                            *self.ray_args, out, 0)
    return out

  def multi_ray(self, physics, frames):
    """`self(physics, frames)` through MuJoCo's `mj_multiRay` (every geom,
    `mj_ray`'s filters), one call per agent: the plain path."""
    model, data = physics.model.ptr, physics.data.ptr
    out = np.empty((len(frames.cos), self._num))
    dist = np.empty(self._num)
    geom_ids = np.zeros(self._num, np.int32)
    lx, ly, lz = self._local_dirs.T
    for i, (x, y) in enumerate(frames.position[:, :2]):
      dx, dy = kernels.rotate.py_func(frames.cos[i], frames.sin[i], lx, ly)
      directions = np.stack([dx, dy, lz], -1)
      mujoco.mj_multiRay(model, data, np.array([x, y, _RAY_ORIGIN_HEIGHT]),
                         directions.ravel(), self._group, 1, -1, geom_ids,
                         dist, None, self._num, mujoco.mjMAXVAL)
      out[i] = kernels.ray_height(dist, self._scale, _RAY_ORIGIN_HEIGHT,
                                  _NO_HIT_HEIGHT)
    return out
