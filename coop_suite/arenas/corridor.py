"""Two walls that leave one slit, wide enough for exactly one Ant.

Layout (world frame): the walls stand on the line x = `wall_x`, `thickness`
deep along x, with a slit of `slit_width` centred on y = 0. Agents start on
the side x < wall_x; the finish line is the line x = `finish_x`.
"""

from coop_suite.arenas import floor
import numpy as np


class CorridorArena(floor.Floor):
  """A floor divided by two walls with a one-ant slit and a finish line."""

  def _build(self, name="corridor", size=(16.0, 16.0), slit_width=1.7,
             wall_thickness=1.0, wall_height=1.0, wall_x=0.0,
             finish_distance=2.0, **kwargs):
    """Builds the corridor.

    Args:
      name: model name.
      size: floor half-extents (metres).
      slit_width: gap between the walls (metres). An upright Ant spans about
        1.3 m, so 1.7 m passes one and blocks two abreast.
      wall_thickness: extent of the walls along x (metres): the corridor's
        length.
      wall_height: metres; high enough that no Ant climbs over.
      wall_x: x of the walls' centre line (metres).
      finish_distance: distance from the slit's exit to the finish line.
      **kwargs: passed to `Floor`.
    """
    self.slit_width = slit_width
    self.wall_thickness = wall_thickness
    self.wall_height = wall_height
    self.wall_x = wall_x
    self.finish_x = wall_x + wall_thickness / 2 + finish_distance
    super()._build(name=name, size=size, **kwargs)
    wall_length = size[1] - slit_width / 2
    for side, sign in (("left", 1.0), ("right", -1.0)):
      self._mjcf_root.worldbody.add(
          "geom", name=f"wall_{side}", type="box",
          size=(wall_thickness / 2, wall_length / 2, wall_height / 2),
          pos=(wall_x, sign * (slit_width / 2 + wall_length / 2),
               wall_height / 2),
          rgba=(0.6, 0.6, 0.65, 1), group=floor.TERRAIN_GROUP)
    self.finish_site = self._mjcf_root.worldbody.add(
        "site", name="finish_line", type="box",
        size=(0.05, size[1], 0.005), pos=(self.finish_x, 0, 0.005),
        rgba=(0.1, 0.9, 0.2, 0.8), group=0)
    self.target_site.rgba = (0, 0, 0, 0)

  @property
  def slit_entrance(self):
    """World xy of the slit's entrance (metres)."""
    return np.array([self.wall_x - self.wall_thickness / 2, 0.0])

  @property
  def slit_exit(self):
    """World xy of the slit's exit (metres)."""
    return np.array([self.wall_x + self.wall_thickness / 2, 0.0])
