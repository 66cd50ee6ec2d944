"""The RLlib adapter, checked by RLlib's own environment checker."""
import pickle

import numpy as np
import pytest

import coop_suite

# ray.rllib ships inside ray but imports only with the [rllib] extra.
pytest.importorskip("ray.rllib", reason="RLlib is the optional [rllib] extra",
                    exc_type=ImportError)
# pylint: disable=g-import-not-at-top,wrong-import-position
from ray.rllib.env import multi_agent_env
from ray.rllib.utils.pre_checks import env as rllib_checks


@pytest.mark.parametrize("task,n_agents", [("transport", 2), ("ravine", 1)])
def test_rllib_checker_passes(task, n_agents):
  env = coop_suite.rllib_env(task, n_agents, time_limit=1.0)
  assert isinstance(env, multi_agent_env.MultiAgentEnv)
  rllib_checks.check_multiagent_environments(env)
  agent = env.possible_agents[0]
  assert env.get_observation_space(agent).shape == (
      env.observation_spaces[agent].shape)
  assert env.get_action_space(agent).shape == (8,)
  env.close()
  env.close()


def test_time_limit_is_truncation_not_termination_in_all():
  env = coop_suite.rllib_env("corridor", 2, time_limit=0.5)
  observations, _ = env.reset(seed=0)
  assert sorted(observations) == ["ant_0", "ant_1"]
  assert all(o.dtype == np.float32 and o.ndim == 1
             for o in observations.values())
  steps = 0
  while True:
    _, rewards, terminateds, truncateds, infos = env.step(
        {agent: np.zeros(8, np.float32) for agent in env.agents})
    steps += 1
    assert set(terminateds) == set(truncateds) == {"ant_0", "ant_1", "__all__"}
    assert set(rewards) == {"ant_0", "ant_1"}
    if truncateds["__all__"] or terminateds["__all__"]:
      break
  assert steps == 10  # 0.5 s of 0.05 s control steps.
  assert truncateds["__all__"] and not terminateds["__all__"]
  assert "episode_metrics" in infos["ant_0"]
  assert env.agents == []


def test_same_seed_same_episode_and_pickles_for_workers():
  env = coop_suite.rllib_env("ravine", 2, stage="joint")
  first, _ = env.reset(seed=4)
  clone = pickle.loads(pickle.dumps(env))
  again, _ = clone.reset(seed=4)
  assert clone.possible_agents == ["crosser_0", "crosser_1", "pusher_0",
                                   "pusher_1"]
  for agent in first:
    np.testing.assert_array_equal(first[agent], again[agent])
