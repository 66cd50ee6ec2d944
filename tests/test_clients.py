"""What clients do to an environment: pickle it, copy it, close it twice,
send any float dtype, import dm_control first, pass odd settings."""
import copy
import os
import pickle
import subprocess
import sys

import cloudpickle
import numpy as np
import pytest

import coop_suite

COOPERATIVE = ("transport", "corridor", "ravine")


def _first_observation(env):
  return env.reset().observation


@pytest.mark.parametrize("task", COOPERATIVE)
def test_environment_pickles_and_copies_as_its_load_call(task):
  env = coop_suite.load(task, 2, seed=3, time_limit=2.0)
  expected = _first_observation(env)
  env.step(np.zeros((env.n_agents, 8)))  # Mid-episode: not carried over.
  for clone in (pickle.loads(pickle.dumps(env)), copy.deepcopy(env),
                cloudpickle.loads(cloudpickle.dumps(env))):
    assert clone is not env and clone.task is not env.task
    assert clone.task.config == env.task.config
    assert clone.task.species == env.task.species
    observation = _first_observation(clone)  # Same seed, same episode.
    for mine, theirs in zip(observation, expected):
      for key in theirs:
        np.testing.assert_array_equal(mine[key], theirs[key], err_msg=key)
    assert clone.step(np.zeros((clone.n_agents, 8))).mid()
    clone.close()
  env.close()


def test_environment_not_from_load_says_to_use_a_factory():
  env = coop_suite.load("corridor", 2)
  bare = coop_suite.CoopEnvironment(env.task, time_limit=1.0,
                                    random_state=np.random.RandomState(0))
  with pytest.raises(TypeError, match="factory"):
    pickle.dumps(bare)


def test_pettingzoo_adapter_pickles_with_its_options():
  env = coop_suite.pettingzoo_env("ravine", 1, n_pushers=1, flatten=True,
                                  seed=0, render_size=(24, 32))
  expected, _ = env.reset(seed=5)
  for clone in (pickle.loads(pickle.dumps(env)), copy.deepcopy(env),
                cloudpickle.loads(cloudpickle.dumps(env))):
    assert clone.possible_agents == ["crosser_0", "pusher_0"]
    assert clone.flatten and clone._render_size == (24, 32)  # pylint: disable=protected-access
    observations, _ = clone.reset(seed=5)
    for agent in expected:
      np.testing.assert_array_equal(observations[agent], expected[agent])
    clone.close()
  env.close()


def test_close_twice_does_nothing():
  env = coop_suite.load("corridor", 2)
  env.reset()
  env.close()
  env.close()
  adapter = coop_suite.pettingzoo_env("corridor", 2)
  adapter.reset(seed=0)
  adapter.close()
  adapter.close()


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.longdouble,
                                   np.dtype(">f4"), np.dtype(">f8")],
                         ids=["float16", "float32", "longdouble",
                              "float32_big_endian", "float64_big_endian"])
def test_any_real_float_dtype_steps_like_float64(dtype):
  actions = np.random.RandomState(0).uniform(-1.2, 1.2, (2, 8))
  actions = actions.astype(dtype).astype(np.float64)  # Representable.
  results = []
  for as_dtype in (np.float64, dtype):
    env = coop_suite.load("transport", 2, seed=0)
    env.reset()
    timestep = env.step(actions.astype(as_dtype))
    results.append((timestep.observation[0]["proprio/joints_pos"],
                    timestep.reward))
    env.close()
  np.testing.assert_array_equal(results[0][0], results[1][0])
  np.testing.assert_array_equal(results[0][1], results[1][1])


def test_complex_actions_are_rejected():
  env = coop_suite.load("transport", 2, seed=0)
  env.reset()
  with pytest.raises(TypeError, match="complex"):
    env.step(np.zeros((2, 8), np.complex128))
  env.close()


@pytest.mark.parametrize("time_limit", [0, -1, float("nan"), float("inf")])
def test_bad_time_limits_are_rejected(time_limit):
  with pytest.raises(ValueError, match="time_limit"):
    coop_suite.load("transport", 2, time_limit=time_limit)
  with pytest.raises(TypeError, match="time_limit"):
    coop_suite.load("transport", 2, time_limit="30")


@pytest.mark.parametrize("task,options,message", [
    ("transport", dict(physics_timestep=0), "physics_timestep must be > 0"),
    ("transport", dict(control_timestep=0.033), "whole multiple"),
    ("transport", dict(cylinder_radius=-0.5), "cylinder_radius must be > 0"),
    ("transport", dict(cylinder_mass=float("nan")), "cylinder_mass must be "
     "finite"),
    ("transport", dict(target_distance=(6.0, 3.0)), "low <= high"),
    ("corridor", dict(slit_width=0.0), "slit_width must be > 0"),
    ("corridor", dict(k_neighbours=1.5), "k_neighbours must be an integer"),
    ("ravine", dict(depth=-1.0), "depth must be > 0"),
    ("ravine", dict(stone_in_path_probability=1.5),
     r"stone_in_path_probability must be in \[0, 1\]"),
    ("ravine", dict(stone_in_path_distance=-0.1),
     "stone_in_path_distance must be >= 0"),
    ("ravine", dict(end_on_success="yes"), "end_on_success must be True or "
     "False"),
    ("walk_velocity", dict(speed_range=(-1.0, 1.0)), "speed_range must be "
     ">= 0"),
])
def test_task_config_is_checked_before_mujoco_compiles(task, options,
                                                       message):
  with pytest.raises((ValueError, TypeError), match=message):
    coop_suite.load(task, **options)


def test_ravine_accepts_numpy_integers():
  env = coop_suite.load("ravine", np.int64(1), n_pushers=np.int32(2))
  assert env.task.species == ("crosser", "pusher", "pusher")
  env.close()


def test_renders_when_dm_control_was_imported_first_without_mujoco_gl():
  # What `import ray.rllib` before coop_suite does: dm_control chooses GLFW,
  # which cannot render without a display.
  script = (
      "import dm_control.mujoco\n"
      "import coop_suite\n"
      "env = coop_suite.pettingzoo_env('corridor', 2, render_mode='rgb_array',"
      " render_size=(24, 32))\n"
      "env.reset(seed=0)\n"
      "print(env.render().shape)\n")
  environ = {k: v for k, v in os.environ.items()
             if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY",
                          "WAYLAND_DISPLAY")}
  result = subprocess.run([sys.executable, "-c", script], env=environ,
                          capture_output=True, text=True, timeout=120,
                          check=False)
  assert result.returncode == 0, result.stderr[-2000:]
  assert result.stdout.strip().endswith("(24, 32, 3)")


def test_target_zone_is_not_the_cylinders_colour():
  env = coop_suite.load("transport", 2)
  model = env.physics.model
  target = model.site("target").rgba[:3]
  cylinder = model.geom_rgba[model.body_geomadr[
      model.body(env.task.cylinder.mjcf_model.find_all("body")[0]
                 .full_identifier).id]][:3]
  assert np.abs(target - cylinder).max() > 0.5  # Tells them apart.
  env.close()
