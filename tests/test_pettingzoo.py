"""The PettingZoo adapter: API conformance, seeding, termination vs truncation.

Short time limits keep every test fast: PettingZoo's checkers run whole
episodes.
"""

import os
import re
import warnings

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

# pylint: disable=g-import-not-at-top,wrong-import-position
from pettingzoo.test import parallel_api_test
from pettingzoo.test import parallel_seed_test

import coop_suite
import coop_suite.pettingzoo

_DOC = os.path.join(os.path.dirname(__file__), "..", "docs", "pettingzoo.md")

# (task, n_agents, load options): every task at two population sizes where
# it has two (the locomotion tasks take one agent).
_CASES = [
    ("transport", 1, {}), ("transport", 3, {}),
    ("corridor", 1, {}), ("corridor", 3, {}),
    ("ravine", 1, {"stage": "joint"}), ("ravine", 2, {"stage": "joint"}),
    ("ravine", 2, {"stage": "pushers"}), ("ravine", 2, {"stage": "crossers"}),
    ("walk_to_target", 1, {}), ("walk_velocity", 1, {}),
]


def _zeros(env):
  return {agent: np.zeros(8, np.float32) for agent in env.agents}


def _rollout(env, seed, n_steps=8):
  """Observations, rewards and states of `n_steps` fixed random actions."""
  observations, _ = env.reset(seed=seed)
  trace = [observations]
  rng = np.random.RandomState(123)
  for _ in range(n_steps):
    actions = {a: rng.uniform(-1, 1, 8) for a in env.possible_agents}
    observations, rewards, _, _, _ = env.step(actions)
    trace += [observations, rewards, env.state()]
  return trace


def _assert_same(a, b):
  if isinstance(a, dict):
    assert a.keys() == b.keys()
    for key in a:
      _assert_same(a[key], b[key])
  elif isinstance(a, list):
    assert len(a) == len(b)
    for x, y in zip(a, b):
      _assert_same(x, y)
  else:
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("task,n_agents,options", _CASES)
def test_pettingzoo_parallel_api_test(task, n_agents, options):
  env = coop_suite.pettingzoo_env(task, n_agents, time_limit=1.0, **options)
  with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    parallel_api_test(env, num_cycles=25)  # 20 steps reach the time limit.
  assert not [str(w.message) for w in caught]


def test_parallel_api_test_flat_observations():
  env = coop_suite.pettingzoo.ParallelEnv(
      coop_suite.load("transport", 3, time_limit=1.0), flatten=True)
  parallel_api_test(env, num_cycles=25)


@pytest.mark.parametrize("task,n_agents", [("transport", 3), ("ravine", 2)])
def test_pettingzoo_parallel_seed_test(task, n_agents):
  parallel_seed_test(
      lambda: coop_suite.pettingzoo_env(task, n_agents, time_limit=1.0))


def test_agent_ids_say_species_and_index():
  env = coop_suite.pettingzoo_env("ravine", 2, n_pushers=3)
  assert env.possible_agents == ["crosser_0", "crosser_1", "pusher_0",
                                 "pusher_1", "pusher_2"]
  assert coop_suite.pettingzoo_env("transport", 2).possible_agents == [
      "ant_0", "ant_1"]
  assert env.agents == []  # Until reset().


def test_same_seed_same_episode():
  env = coop_suite.pettingzoo_env("ravine", 2)
  first = _rollout(env, seed=7)
  _rollout(env, seed=8)  # Moves the random stream on.
  _assert_same(first, _rollout(env, seed=7))
  _assert_same(first, _rollout(coop_suite.pettingzoo_env("ravine", 2), 7))
  # The load seed and the reset seed are the same seed.
  loaded = coop_suite.pettingzoo_env("ravine", 2, seed=7)
  _assert_same(first[0], loaded.reset()[0])


def test_different_seeds_different_episodes():
  env = coop_suite.pettingzoo_env("transport", 3)
  a, _ = env.reset(seed=1)
  b, _ = env.reset(seed=2)
  assert not np.array_equal(a["ant_0"]["extero/target"],
                            b["ant_0"]["extero/target"])


def _place_cylinder_on_target(env):
  task, physics = env.env.task, env.env.physics
  task.cylinder.set_pose(physics,
                         position=[*task.arena.target_position, 0.25])
  task.cylinder.set_velocity(physics, velocity=np.zeros(3),
                             angular_velocity=np.zeros(3))


def test_hand_made_success_is_termination_not_truncation():
  # hold_time=0: the success counts on the step the cylinder rests inside.
  env = coop_suite.pettingzoo_env("transport", 3, time_limit=0.5,
                                  end_on_success=True, hold_time=0.0)
  env.reset(seed=0)
  _place_cylinder_on_target(env)
  _, rewards, terminations, truncations, infos = env.step(_zeros(env))
  assert all(terminations.values()) and not any(truncations.values())
  assert min(rewards.values()) > 50.0  # Bonus plus the shaping terms.
  assert all(info["episode_metrics"]["success"] for info in infos.values())
  assert env.agents == []


def test_success_runs_on_to_the_time_limit_by_default():
  env = coop_suite.pettingzoo_env("transport", 3, time_limit=0.5,
                                  hold_time=0.0)
  env.reset(seed=0)
  _place_cylinder_on_target(env)
  _, rewards, terminations, truncations, _ = env.step(_zeros(env))
  assert not any(terminations.values()) and not any(truncations.values())
  assert min(rewards.values()) > 50.0
  for _ in range(9):
    _, _, terminations, truncations, infos = env.step(_zeros(env))
  assert all(truncations.values()) and not any(terminations.values())
  assert infos["ant_0"]["episode_metrics"]["success"]


def test_time_limit_is_truncation_not_termination():
  env = coop_suite.pettingzoo_env("transport", 3, time_limit=0.5)
  env.reset(seed=0)
  for _ in range(9):  # 0.5 s is 10 control steps of 0.05 s.
    _, _, terminations, truncations, infos = env.step(_zeros(env))
    assert not any(terminations.values()) and not any(truncations.values())
    assert infos == {agent: {} for agent in env.possible_agents}
  _, _, terminations, truncations, infos = env.step(_zeros(env))
  assert all(truncations.values()) and not any(terminations.values())
  assert not infos["ant_0"]["episode_metrics"]["success"]
  assert env.agents == []
  with pytest.raises(RuntimeError, match="reset"):
    env.step({agent: np.zeros(8) for agent in env.possible_agents})
  env.reset()
  assert env.agents == env.possible_agents


def test_physics_divergence_is_termination():
  env = coop_suite.pettingzoo_env("transport", 2)
  env.reset(seed=0)
  env.env.physics.data.qvel[:] = 1e30
  _, _, terminations, truncations, infos = env.step(_zeros(env))
  assert all(terminations.values()) and not any(truncations.values())
  assert infos["ant_1"]["episode_metrics"]["physics_diverged"]


def test_spaces_and_state():
  env = coop_suite.pettingzoo_env("ravine", 2)
  observations, infos = env.reset(seed=0)
  assert infos == {agent: {} for agent in env.possible_agents}
  for agent in env.possible_agents:
    assert env.observation_space(agent) is env.observation_space(agent)
    assert env.action_space(agent) is env.action_space(agent)
    space = env.action_space(agent)
    assert space.dtype == np.float32 and space.shape == (8,)
    assert np.all(space.low == -1.0) and np.all(space.high == 1.0)
    for box in env.observation_space(agent).values():
      assert box.dtype == np.float32 and np.all(np.isinf(box.low))
    assert all(v.dtype == np.float32 for v in observations[agent].values())
    assert env.observation_space(agent).contains(observations[agent])
  state = env.state()
  assert state.dtype == np.float32 and env.state_space.contains(state)
  assert state.shape == (7 * 4 + 4,)  # Four Ants, then stone and crosser xy.
  with pytest.raises(ValueError, match="crosser_0"):
    env.observation_space("ant_0")


def test_flat_layout_is_the_sorted_dict_concatenated():
  flat = coop_suite.pettingzoo.ParallelEnv(coop_suite.load("corridor", 2),
                                           flatten=True)
  nested = coop_suite.pettingzoo_env("corridor", 2)
  flat_obs, _ = flat.reset(seed=3)
  nested_obs, _ = nested.reset(seed=3)
  layout = flat.observation_keys("ant_1")
  assert list(layout) == sorted(nested_obs["ant_1"])
  for key, where in layout.items():
    np.testing.assert_array_equal(flat_obs["ant_1"][where],
                                  nested_obs["ant_1"][key])
  assert flat.observation_space("ant_1").shape == flat_obs["ant_1"].shape
  assert flat_obs["ant_1"].dtype == np.float32


def test_actions_are_matched_by_id_not_dict_order():
  env = coop_suite.pettingzoo_env("transport", 3)
  actions = {a: np.full(8, 0.1 * i) for i, a in enumerate(env.possible_agents)}
  env.reset(seed=0)
  forward = env.step(actions)
  env.reset(seed=0)
  backward = env.step(dict(reversed(list(actions.items()))))
  _assert_same(forward[0], backward[0])


@pytest.mark.parametrize("make_actions,error,match", [
    (lambda ids: [np.zeros(8)] * 3, TypeError, "dict agent id"),
    (lambda ids: {a: np.zeros(8) for a in ids[:2]}, ValueError,
     r"Missing .*'ant_2'"),
    (lambda ids: {**{a: np.zeros(8) for a in ids}, "ant_9": np.zeros(8)},
     ValueError, r"Unknown .*'ant_9'.*'ant_0', 'ant_1', 'ant_2'"),
    (lambda ids: {**{a: np.zeros(8) for a in ids}, "ant_1": np.zeros(7)},
     ValueError, r"'ant_1' has shape \(7,\); expected \(8,\)"),
    (lambda ids: {**{a: np.zeros(8) for a in ids}, "ant_2": [np.nan] * 8},
     ValueError, "'ant_2' contains NaN"),
    (lambda ids: {**{a: np.zeros(8) for a in ids}, "ant_0": ["a"] * 8},
     TypeError, "'ant_0' is not numeric"),
])
def test_bad_actions_raise_and_leave_env_usable(make_actions, error, match):
  env = coop_suite.pettingzoo_env("transport", 3)
  env.reset(seed=0)
  before = env.env.physics.data.qpos.copy()
  with pytest.raises(error, match=match):
    env.step(make_actions(list(env.possible_agents)))
  np.testing.assert_array_equal(env.env.physics.data.qpos, before)
  _, _, terminations, _, _ = env.step(_zeros(env))
  assert not any(terminations.values())


def test_bad_reset_and_step_before_reset():
  env = coop_suite.pettingzoo_env("walk_velocity", 1)
  with pytest.raises(RuntimeError, match="reset"):
    env.step({"ant_0": np.zeros(8)})
  with pytest.raises(TypeError, match="seed"):
    env.reset(seed=1.5)
  with pytest.raises(ValueError, match="seed"):
    env.reset(seed=-1)
  with pytest.raises(ValueError, match="render_mode"):
    coop_suite.pettingzoo.ParallelEnv(env.env, render_mode="human")


def test_render_rgb_array():
  env = coop_suite.pettingzoo.ParallelEnv(coop_suite.load("transport", 2),
                                          render_mode="rgb_array",
                                          render_size=(48, 64))
  env.reset(seed=0)
  frame = env.render()
  assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
  env.close()
  assert env.agents == []


def test_docs_example_runs(capsys):
  with open(_DOC) as f:
    blocks = re.findall(r"```python\n(.*?)```", f.read(), re.S)
  assert len(blocks) == 1
  exec(compile(blocks[0], _DOC, "exec"), {})  # pylint: disable=exec-used
  assert "episode 1: ended by" in capsys.readouterr().out


def test_pettingzoo_env_passes_adapter_options():
  env = coop_suite.pettingzoo_env("transport", 2, flatten=True,
                                  render_mode="rgb_array", render_size=(60, 80),
                                  time_limit=1.0)
  observations, _ = env.reset(seed=0)
  assert observations["ant_0"].ndim == 1
  assert env.render().shape == (60, 80, 3)
  env.close()
