"""A flat floor with a visible target zone and global physics settings.

Every arena of the suite derives from `Floor`, so the physics options that
matter for speed live here once: a 10 ms physics step, pyramidal friction
cones and no noslip pass (composer's base arena asks for elliptic cones and
five noslip iterations, which roughly halves the step rate with many ants).
"""

from dm_control import composer
import numpy as np

# Geoms in this group are terrain: ray casts for height samples only see it.
TERRAIN_GROUP = 0


TARGET_RGBA = (0.1, 0.9, 0.2, 0.5)
"""Where to go is green (the target zone, like the finish lines); the
object to move is red (`props.Cylinder`): docs/tasks.md's colour code."""


class Floor(composer.Arena):
  """A square floor, a target zone marker and a framing camera."""

  def _build(self, name="floor", size=(15.0, 15.0), target_radius=1.0,
             physics_timestep=0.01, memory_mb=8):
    """Builds the floor.

    Args:
      name: model name.
      size: half-extents of the floor in x and y (metres).
      target_radius: radius of the target zone disc (metres); purely visual,
        the task decides what "inside" means.
      physics_timestep: MuJoCo timestep (seconds).
      memory_mb: MuJoCo arena memory for contacts and constraints (MiB); the
        task sizes it for its agent count.
    """
    super()._build(name=name)
    root = self._mjcf_root
    self.size = np.asarray(size, dtype=np.float64)
    root.option.timestep = physics_timestep
    root.option.cone = "pyramidal"
    root.option.noslip_iterations = 0
    root.option.iterations = 20
    root.option.ls_iterations = 10
    root.size.memory = f"{int(memory_mb)}M"
    root.visual.headlight.ambient = (0.4, 0.4, 0.4)
    root.visual.headlight.diffuse = (0.6, 0.6, 0.6)
    root.visual.quality.shadowsize = 2048

    root.asset.add("texture", name="skybox", type="skybox", builtin="gradient",
                   rgb1=(0.4, 0.6, 0.8), rgb2=(0, 0, 0), width=200,
                   height=200)
    root.asset.add("texture", name="grid", type="2d", builtin="checker",
                   rgb1=(0.2, 0.3, 0.4), rgb2=(0.1, 0.2, 0.3), width=300,
                   height=300, mark="edge", markrgb=(0.2, 0.3, 0.4))
    self.ground_material = root.asset.add(
        "material", name="grid", texture="grid", texrepeat=(1, 1),
        texuniform=True, reflectance=0.1)
    root.worldbody.add("light", name="sun", pos=(0, 0, 20), dir=(0, 0, -1),
                       directional=True, diffuse=(0.5, 0.5, 0.5),
                       castshadow=False)
    self._build_ground()

    self.target_radius = target_radius
    self.target_position = np.zeros(2)
    self.target_site = root.worldbody.add(
        "site", name="target", type="cylinder", size=(target_radius, 0.005),
        pos=(0, 0, 0.005), rgba=TARGET_RGBA, group=0)
    # A fixed camera whose pose `runners.video` sets each frame to frame the
    # agents and the task object.
    self.framing_camera = root.worldbody.add(
        "camera", name="framing", pos=(0, -10, 10), xyaxes=(1, 0, 0, 0, 0.7, 0.7),
        fovy=45)

  def _build_ground(self):
    """Adds the ground. Subclasses with terrain override this."""
    self._mjcf_root.worldbody.add(
        "geom", name="ground", type="plane", size=(*self.size, 0.1),
        material=self.ground_material, group=TERRAIN_GROUP)

  def ground_height(self, xy):
    """Height of the static terrain at world points `xy` [N, 2] (metres).

    An analytic counterpart of the ray casts, used to place agents.
    """
    return np.zeros(np.asarray(xy).shape[:-1])

  def set_target(self, physics, xy):
    """Moves the target zone marker to world position `xy` (metres)."""
    physics.bind(self.target_site).pos[:2] = xy
    self.target_position = np.asarray(xy, dtype=np.float64)
