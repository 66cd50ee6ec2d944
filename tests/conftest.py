"""Shared fixtures and helpers for the suite's tests."""

import os
import secrets

os.environ.setdefault("MUJOCO_GL", "egl")
# Ray's local instances authenticate with a token; without one Ray writes a
# new ~/.ray/auth_token on its first start, and two test processes
# (`pytest -n 2`) starting Ray at once could each write their own. Each
# process's instances take this one from the environment instead.
os.environ.setdefault("RAY_AUTH_TOKEN", secrets.token_hex(32))

import numpy as np  # pylint: disable=g-import-not-at-top
import pytest  # pylint: disable=g-import-not-at-top


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config):
  """With -n (pytest-xdist, README's test command) each module runs whole on
  one process unless --dist says otherwise: its module fixtures (a tiny
  training, a Ray instance) are built once. Set here, not in pytest.ini's
  addopts, so that a pytest without xdist still runs the suite."""
  option = config.option
  if getattr(option, "numprocesses", None) and option.dist == "no":
    option.dist = "loadfile"


@pytest.fixture(scope="session", autouse=True)
def _compilation_cache(tmp_path_factory):
  """One persistent XLA compilation cache for the whole suite: every
  `train` / `evaluate` call builds new learners and actors whose programs
  earlier tests compiled already (a resumed tiny run: 19 s -> 5 s on the
  2-core machine). The suite's own folder; the settings are restored."""
  import jax  # pylint: disable=g-import-not-at-top
  from jax.experimental.compilation_cache import compilation_cache  # pylint: disable=g-import-not-at-top
  settings = {"jax_compilation_cache_dir": str(tmp_path_factory.mktemp("xla")),
              "jax_persistent_cache_min_compile_time_secs": 0,
              "jax_persistent_cache_min_entry_size_bytes": 0}
  saved = {name: getattr(jax.config, name) for name in settings}
  for name, value in settings.items():
    jax.config.update(name, value)
  compilation_cache.reset_cache()
  yield
  for name, value in saved.items():
    jax.config.update(name, value)
  compilation_cache.reset_cache()


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
