"""A plane cut by a trench (the ravine) with a finish line beyond it.

Layout (world frame): the trench runs along y, spans x in
[ravine_x - width/2, ravine_x + width/2], is `depth` deep and `length` long
(closed at both ends). The plane is at z = 0, the trench floor at z = -depth.
Crossers start at x < ravine_x - width/2; the finish line is x = `finish_x`.
An Ant cannot climb the trench walls (its torso rides ~0.55 m high), so a
crosser needs the stone, which fills the trench's width and reaches the plane.
"""

from coop_suite.arenas import floor
import numpy as np


class RavineArena(floor.Floor):
  """A plane with a closed trench across it and a finish line."""

  def _build(self, name="ravine", size=(12.0, 12.0), width=2.0, depth=1.0,
             length=16.0, ravine_x=0.0, finish_distance=2.0, **kwargs):
    """Builds the ravine.

    Args:
      name: model name.
      size: half-extents of the plane (metres).
      width: trench width along x (metres); fits one Ant across.
      depth: trench depth (metres); equals the stone's height.
      length: trench length along y (metres), less than 2 * size[1].
      ravine_x: x of the trench's centre line (metres).
      finish_distance: distance from the far edge to the finish line.
      **kwargs: passed to `Floor`.
    """
    self.width = width
    self.depth = depth
    if not 0 < length < 2 * size[1]:
      # Clipping it would leave the task's layout (stone, pushers) using
      # the length asked for, beyond the trench's closed ends; at the
      # plane's extent the ends would be open.
      raise ValueError(f"The ravine's length must be in (0, {2 * size[1]:g}) "
                       f"(shorter than the plane along y, so that its ends "
                       f"are closed), got {length!r}.")
    self.length = length
    self.ravine_x = ravine_x
    self.near_edge_x = ravine_x - width / 2
    self.far_edge_x = ravine_x + width / 2
    self.finish_x = self.far_edge_x + finish_distance
    super()._build(name=name, size=size, **kwargs)
    self.finish_site = self._mjcf_root.worldbody.add(
        "site", name="finish_line", type="box", size=(0.05, size[1], 0.005),
        pos=(self.finish_x, 0, 0.005), rgba=(0.1, 0.9, 0.2, 0.8), group=0)
    self.target_site.rgba = (0, 0, 0, 0)

  def _build_ground(self):
    worldbody = self._mjcf_root.worldbody
    sx, sy = self.size
    d = self.depth
    dark = self._mjcf_root.asset.add("material", name="trench",
                                     rgba=(0.12, 0.1, 0.08, 1))
    worldbody.add("geom", name="trench_floor", type="plane",
                  size=(sx, sy, 0.1), pos=(0, 0, -d), material=dark,
                  group=floor.TERRAIN_GROUP)
    # Two platforms on either side of the trench, their tops at z = 0.
    near_len = self.near_edge_x + sx
    far_len = sx - self.far_edge_x
    platform = dict(type="box", material=self.ground_material,
                    group=floor.TERRAIN_GROUP, friction=(1, 0.005, 0.0001))
    worldbody.add("geom", name="platform_near",
                  size=(near_len / 2, sy, d / 2),
                  pos=(-sx + near_len / 2, 0, -d / 2), **platform)
    worldbody.add("geom", name="platform_far",
                  size=(far_len / 2, sy, d / 2),
                  pos=(sx - far_len / 2, 0, -d / 2), **platform)
    # Caps close the trench's ends so pushers and stone stay inside.
    cap_len = sy - self.length / 2
    if cap_len > 0:
      for side, sign in (("north", 1.0), ("south", -1.0)):
        worldbody.add("geom", name=f"cap_{side}",
                      size=(self.width / 2, cap_len / 2, d / 2),
                      pos=(self.ravine_x, sign * (sy - cap_len / 2), -d / 2),
                      **platform)

  def in_trench(self, xy):
    """Whether world points `xy` [..., 2] lie over the trench."""
    xy = np.asarray(xy)
    return ((np.abs(xy[..., 0] - self.ravine_x) < self.width / 2)
            & (np.abs(xy[..., 1]) < self.length / 2))

  def ground_height(self, xy):
    return np.where(self.in_trench(xy), -self.depth, 0.0)
