"""Bad input gets a clear error, and the environment stays usable after it."""

import numpy as np
import pytest

import coop_suite


def test_unknown_task_names_the_choices():
  with pytest.raises(ValueError, match="transport"):
    coop_suite.load("tranport", 4)


@pytest.mark.parametrize("task,n_agents", [
    ("transport", 0), ("transport", 17), ("corridor", -1), ("ravine", 9),
    ("walk_to_target", 2), ("walk_velocity", 0)])
def test_agent_count_out_of_range(task, n_agents):
  low, high = coop_suite.agent_range(task)
  with pytest.raises(ValueError, match=f"{low} to {high}"):
    coop_suite.load(task, n_agents)


@pytest.mark.parametrize("n_agents", [2.0, "4", True, 4.5])
def test_agent_count_must_be_an_integer(n_agents):
  with pytest.raises(TypeError, match="integer"):
    coop_suite.load("transport", n_agents)


def test_numpy_integer_agent_count_is_fine():
  assert coop_suite.load("transport", np.int64(2)).n_agents == 2


def test_unknown_option_names_the_allowed_ones():
  with pytest.raises(ValueError, match="target_radius"):
    coop_suite.load("transport", 2, target_radious=2.0)
  with pytest.raises(ValueError, match="stage"):
    coop_suite.load("ravine", 2, stage="bridge")
  with pytest.raises(ValueError, match="n_pushers"):
    coop_suite.load("ravine", 2, n_pushers=0)
  with pytest.raises(TypeError, match="seed"):
    coop_suite.load("transport", 2, seed=1.5)


def test_a_ravine_the_arena_cannot_hold_is_refused():
  with pytest.raises(ValueError, match="ravine's length"):
    coop_suite.load("ravine", 2, length=24.0)  # Open ends.
  with pytest.raises(ValueError, match="before the finish line"):
    coop_suite.load("ravine", 2, stage="crossers", width=1.0)
  # Where no stone start is drawn, its range does not matter.
  coop_suite.load("ravine", 2, width=1.0).close()
  coop_suite.load("ravine", 2, stage="crossers", width=1.0,
                  stone_start_probability=0.0).close()


@pytest.mark.parametrize("args,kwargs,error", [
    (("tranport", 4), {}, ValueError), (("ravine", 9), {}, ValueError),
    (("transport", 2.0), {}, TypeError),
    (("transport", 2), {"stage": "pushers"}, ValueError),
    (("ravine", 2), {"n_pushers": 0}, ValueError),
    (("transport", 2), {"time_limit": -1.0}, ValueError),
    (("transport", 2), {"seed": 1.5}, TypeError),
    # Longer than the plane: once clipped silently, the layout using it.
    (("ravine", 2), {"length": 30.0}, ValueError)])
def test_check_options_raises_what_load_raises(args, kwargs, error):
  with pytest.raises(error) as from_load:
    coop_suite.load(*args, **kwargs)
  with pytest.raises(error) as from_check:
    coop_suite.check_options(*args, **kwargs)
  assert str(from_check.value) == str(from_load.value)
  coop_suite.check_options("ravine", 3, stage="crossers", n_pushers=1)


@pytest.fixture(name="env")
def env_fixture():
  env = coop_suite.load("transport", 3, seed=0)
  env.reset()
  return env


@pytest.mark.parametrize("action,error,match", [
    (np.zeros((2, 8)), ValueError, "3 agents"),
    ([np.zeros(8)] * 4, ValueError, "3 agents"),
    (np.zeros((3, 7)), ValueError, r"shape \(7,\)"),
    ([np.zeros(8), np.zeros(8), np.zeros(9)], ValueError, "agent 2"),
    (np.full((3, 8), np.nan), ValueError, "NaN"),
    ([np.zeros(8), np.zeros(8), [0.0] * 7 + [np.inf]], ValueError, "NaN"),
    ([np.zeros(8), np.zeros(8), ["a"] * 8], TypeError, "agent 2"),
    ("left", TypeError, "list of 3 arrays"),
    (3.0, TypeError, "list of 3 arrays"),
])
def test_bad_actions_raise_and_leave_env_usable(env, action, error, match):
  before = env.physics.data.qpos.copy()
  with pytest.raises(error, match=match):
    env.step(action)
  np.testing.assert_array_equal(env.physics.data.qpos, before)
  timestep = env.step(np.zeros((3, 8)))
  assert timestep.mid()


def test_out_of_bounds_actions_are_clipped(env):
  env.step(np.full((3, 8), 5.0))
  np.testing.assert_array_equal(env.physics.data.ctrl, 1.0)


def test_physics_divergence_ends_episode_not_process(env):
  env.physics.data.qvel[:] = 1e30
  timestep = env.step(np.zeros((3, 8)))
  assert timestep.last()
  assert float(timestep.discount) == 0.0
  assert len(timestep.reward) == 3
  assert env.physics_diverged
  assert env.episode_metrics()["physics_diverged"]
  timestep = env.step(np.zeros((3, 8)))  # Starts a fresh episode.
  assert timestep.first()
  assert not env.physics_diverged
  assert env.step(np.zeros((3, 8))).mid()
