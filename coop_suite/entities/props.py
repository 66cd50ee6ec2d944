"""Free-moving task objects: the cylinder to transport and the bridging stone.

Both are plain rigid bodies on a free joint. An Ant weighs 12.4 kg and its
legs give it at most ~120 N of traction on the floor (friction 1). The
cylinder (20 kg, friction 0.4: ~80 N to slide) barely moves for one Ant and
moves for several; the stone (12 kg: ~47 N) moves for one pusher, faster for
two. Measured with scripted pushes in `tests/test_physics.py`.
"""

from dm_control import composer
from dm_control import mjcf
import numpy as np


class _FreeProp(composer.Entity):
  """A single rigid body meant to be attached with `arena.add_free_entity`."""

  def _build(self, name, geom_kwargs):
    self._mjcf_root = mjcf.RootElement(model=name)
    self._body = self._mjcf_root.worldbody.add("body", name="body")
    # priority=1: contacts use this geom's friction instead of MuJoCo's
    # default maximum of both geoms' (the floor's 1.0 would glue it down).
    self._geom = self._body.add("geom", name="geom", group=0, priority=1,
                                **geom_kwargs)
    self._body_id = None

  @property
  def mjcf_model(self):
    return self._mjcf_root

  @property
  def geom(self):
    return self._geom

  def after_compile(self, physics, random_state):
    self._body_id = int(physics.bind(self._body).element_id)

  @property
  def body_id(self):
    """The body's id in the compiled model (after compilation)."""
    return self._body_id

  def position(self, physics):
    """Centre of the body, shape [3], world frame (metres)."""
    return physics.data.xpos[self._body_id]


class Cylinder(_FreeProp):
  """An upright cylinder (default 0.6 m radius, 0.8 m tall, 20 kg).

  Taller than an Ant's torso so that Ants push it instead of climbing it,
  and wide enough that pushing at torso height slides it before it tips.
  """

  def _build(self, name="cylinder", radius=0.6, height=0.8, mass=20.0,
             friction=0.4, rgba=(0.85, 0.2, 0.2, 1.0)):
    self.radius = radius
    self.height = height
    super()._build(name, dict(type="cylinder", size=[radius, height / 2],
                              mass=mass, friction=[friction, 0.005, 0.0001],
                              rgba=rgba))


class Stone(_FreeProp):
  """A box that fills the ravine's width and reaches the plane when inside.

  Its size is [length along the trench (y), width across it (x), height].
  """

  def _build(self, name="stone", size=(1.6, 1.9, 1.0), mass=12.0,
             friction=0.4, rgba=(0.45, 0.45, 0.5, 1.0)):
    self.size = np.asarray(size, dtype=np.float64)
    half = [size[1] / 2, size[0] / 2, size[2] / 2]
    super()._build(name, dict(type="box", size=half, mass=mass,
                              friction=[friction, 0.005, 0.0001], rgba=rgba))
