"""MuJoCo's ray casts from compiled code, against the terrain geoms only.

`mj_multiRay` (MuJoCo's own, the plain path) tests every geom of the model,
the Ants' 50 included, which the height rays must ignore: it cost more than
all other features together. The height kernel (`kernels.terrain_heights`)
instead calls `mju_rayGeom`, the function `mj_ray` uses per geom, on the
geoms `terrain_geoms` selects once per model with `mj_ray`'s own filters:
the same distances, bit for bit (`tests/test_kernels.py`).
"""

import mujoco
import numba
import numpy as np

from coop_suite.fast import libmujoco

# One ray against one primitive geom. The last argument (an optional surface
# normal, NULL here) is absent in older MuJoCo versions, where the C calling
# convention ignores it.
_mju_ray_geom = libmujoco.function("mju_rayGeom", numba.types.float64(
    *(libmujoco.POINTER,) * 5, numba.types.int32, libmujoco.POINTER))


@numba.njit(cache=True)
def nearest_hit(geom_xpos, geom_xmat, geom_size, geom_type, candidates,
                origin, direction):
  """Distance along one ray to the nearest of the `candidates` geoms, -1 if
  it meets none: what `mj_ray` returns with those geoms left after its
  filters (the same `mju_rayGeom` per geom, the same minimum)."""
  nearest = -1.0
  for g in candidates:
    dist = _mju_ray_geom(geom_xpos.ctypes.data + 24 * g,
                         geom_xmat.ctypes.data + 72 * g,
                         geom_size.ctypes.data + 24 * g, origin.ctypes.data,
                         direction.ctypes.data, geom_type[g], 0)
    if dist >= 0 and (dist < nearest or nearest < 0):
      nearest = dist
  return nearest


# Geom types `mju_rayGeom` handles; meshes, height fields and SDFs need
# MuJoCo's own ray functions.
_PRIMITIVE_GEOMS = frozenset(int(t) for t in (
    mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_SPHERE,
    mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_BOX))


def terrain_geoms(model, geom_group):
  """Ids of the geoms a ray sees with `mj_ray`'s filters (no excluded body,
  static geoms included): visible (alpha of the geom, or of its material,
  above 0) and in a group enabled in `geom_group`.

  Raises:
    ValueError: if one of them is not a primitive (a mesh, height field or
      SDF), which the compiled height kernel cannot ray-cast.
  """
  alpha = np.where(model.geom_matid >= 0,
                   model.mat_rgba[np.maximum(model.geom_matid, 0), 3]
                   if model.nmat else 1.0, model.geom_rgba[:, 3])
  group = np.clip(model.geom_group, 0, len(geom_group) - 1)
  ids = np.flatnonzero((alpha != 0) & (geom_group[group] != 0))
  for g in ids:
    if int(model.geom_type[g]) not in _PRIMITIVE_GEOMS:
      name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
      raise ValueError(
          f"Terrain geom {name or g!r} is a "
          f"{mujoco.mjtGeom(model.geom_type[g]).name}; height samples support "
          "primitive geoms only (plane, sphere, capsule, ellipsoid, cylinder, "
          "box).")
  return ids.astype(np.int64)
