"""Shared fixtures and helpers for the suite's tests."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # pylint: disable=g-import-not-at-top


def drive(env, indices, velocity_xy, seconds, gain=150.0, max_force=120.0,
          lift=0.5):
  """Scripted locomotion: pushes the torsos of agents `indices`.

  A stand-in for a walking controller in physics tests. A P-controller on
  `xfrc_applied` drives each torso towards `velocity_xy` (world, m/s), the
  horizontal force capped at `max_force` N (about what an Ant's legs can
  push with), while `lift` carries that fraction of its weight so its legs
  slide instead of digging in. Returns the last timestep.
  """
  physics = env.physics
  timestep = None
  for _ in range(int(round(seconds / env.control_timestep()))):
    for i in indices:
      walker = env.task.walkers[i]
      body = walker._torso_id  # pylint: disable=protected-access
      velocity = walker.world_velocity(physics)[:2]
      force = np.clip(gain * (np.asarray(velocity_xy) - velocity),
                      -max_force, max_force)
      physics.data.xfrc_applied[body, :2] = force
      physics.data.xfrc_applied[body, 2] = (
          lift * 9.81 * physics.model.body_subtreemass[body])
    timestep = env.step(np.zeros((env.n_agents, 8)))
    if timestep.last():
      break
  physics.data.xfrc_applied[:] = 0.0
  return timestep
