"""A camera that keeps every agent and the task object in view, headless.

Every arena has a fixed camera named `framing`; `FramingCamera` moves it
before each frame so that it looks down at the bounding box of
`task.tracked_positions(physics)` from a fixed azimuth and elevation, far
enough back to fit the box. Rendering goes through MuJoCo's offscreen
context (`MUJOCO_GL=egl` on a machine without a display): no viewer needed.
"""

import mujoco
import numpy as np

CAMERA_NAME = "framing"


class FramingCamera:
  """Moves the `framing` camera to frame the task; smooths its motion."""

  def __init__(self, azimuth_deg=90.0, elevation_deg=-55.0, margin=2.0,
               min_extent=4.0, smoothing=0.85):
    """Args:
      azimuth_deg: horizontal direction the camera looks along, degrees
        from +x (90: it looks along +y, standing on the -y side).
      elevation_deg: pitch below the horizon (negative looks down).
      margin: metres added around the tracked box.
      min_extent: smallest box side considered (m), so a lone ant is not
        filmed from a few centimetres.
      smoothing: 0 follows instantly; closer to 1 moves more gently.
    """
    self._azimuth = np.deg2rad(azimuth_deg)
    self._elevation = np.deg2rad(elevation_deg)
    self._margin = margin
    self._min_extent = min_extent
    self._smoothing = smoothing
    self._state = None

  def reset(self):
    self._state = None

  def update(self, physics, task):
    """Places the camera for the current state of `task`."""
    points = np.asarray(task.tracked_positions(physics), dtype=np.float64)
    low, high = points.min(0), points.max(0)
    center = (low + high) / 2
    extent = max(np.max(high[:2] - low[:2]) + 2 * self._margin,
                 self._min_extent)
    camera = physics.model.camera(CAMERA_NAME)
    fovy = np.deg2rad(camera.fovy[0])
    distance = 0.6 * extent / np.tan(fovy / 2)
    target = np.array([center[0], center[1], center[2], distance])
    if self._state is None:
      self._state = target
    else:
      self._state = self._smoothing * self._state + (
          1 - self._smoothing) * target
    center, distance = self._state[:3], self._state[3]
    forward = np.array([np.cos(self._elevation) * np.cos(self._azimuth),
                        np.cos(self._elevation) * np.sin(self._azimuth),
                        np.sin(self._elevation)])
    position = center - distance * forward
    # MuJoCo cameras look along their -z axis with +y up.
    z_axis = -forward
    x_axis = np.cross(np.array([0.0, 0.0, 1.0]), z_axis)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    quaternion = np.zeros(4)
    mujoco.mju_mat2Quat(quaternion,
                        np.stack([x_axis, y_axis, z_axis], 1).ravel())
    camera.pos[:] = position
    camera.quat[:] = quaternion


def render(env, camera, width=640, height=480):
  """One RGB frame [height, width, 3] uint8 of `env` through `camera`."""
  camera.update(env.physics, env.task)
  return env.physics.render(height=height, width=width,
                            camera_id=CAMERA_NAME)
