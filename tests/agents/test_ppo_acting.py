"""PPOActor records rollouts the learner can use, one parameter version each."""
import collections

import numpy as np
import pytest

from agents import normalization
from agents.ppo import builder as ppo_builder
from agents.ppo import config as ppo_config

TimeStep = collections.namedtuple(
    'TimeStep', ['step_type', 'reward', 'discount', 'observation'])
OBS_DIM, ACTION_DIM, B = 4, 2, 4


_BUILDER = ppo_builder.PPOBuilder(ppo_config.PPOConfig(
    policy_hidden=(16,), value_hidden=(16,), num_minibatches=2))
_NETWORKS = _BUILDER.make_networks(OBS_DIM, ACTION_DIM)


@pytest.fixture(scope='module')
def learner():
  """Shared so that its update compiles once for all tests of this module."""
  return _BUILDER.make_learner(_NETWORKS)


def _setup(learner, **actor_kwargs):
  return _NETWORKS, learner, _BUILDER.make_actor(_NETWORKS, learner,
                                                 **actor_kwargs)


def _timestep(step, step_type=1, discount=1.0):
  obs = np.full((B, OBS_DIM), float(step), np.float32)
  return TimeStep(np.full(B, step_type), np.full(B, 0.1 * step, np.float32),
                  np.full(B, discount, np.float32), obs)


def test_records_a_rollout_with_terminations_and_truncations(learner):
  networks, learner, actor = _setup(learner, action_bounds=(-2.0, 2.0))
  actor.observe_first(_timestep(0, step_type=0))
  for step in range(1, 4):
    action = actor.select_action(_timestep(step - 1).observation)
    assert action.shape == (B, ACTION_DIM) and np.all(np.abs(action) <= 2.0)
    ts = _timestep(step)
    if step == 2:  # Env 0 terminates, env 1 hits its time limit.
      ts = ts._replace(step_type=np.array([2, 2, 1, 1]),
                       discount=np.array([0.0, 1.0, 1.0, 1.0], np.float32))
    actor.observe(action, ts)
  rollout = actor.take_rollout()

  assert rollout.observation.shape == (4, B, OBS_DIM)
  assert rollout.raw_action.shape == (3, B, ACTION_DIM)
  np.testing.assert_array_equal(rollout.discount[1], [0, 1, 1, 1])
  np.testing.assert_array_equal(rollout.truncation[1], [0, 1, 0, 0])
  assert rollout.truncation.sum() == 1
  # Log-probabilities are those of the stored raw actions.
  params, normalizer = learner.get_variables(['params', 'normalizer'])
  dist_params = networks.apply_policy(
      params, normalization.normalize(normalizer, rollout.observation[:-1]))
  np.testing.assert_allclose(
      rollout.log_prob,
      networks.distribution.log_prob(dist_params, rollout.raw_action),
      rtol=1e-5)
  assert np.isfinite(learner.step(rollout)['total_loss'])
  # The next segment continues from the last observation.
  actor.observe(actor.select_action(rollout.observation[-1]), _timestep(4))
  np.testing.assert_array_equal(actor.take_rollout().observation[0],
                                rollout.observation[-1])


def test_new_parameters_wait_for_the_next_segment(learner):
  _, learner, actor = _setup(learner, deterministic=True)
  obs = _timestep(1).observation
  actor.observe_first(_timestep(0, step_type=0))
  old_action = actor.select_action(obs)
  for step in range(1, 4):  # T = 3 like the other test: no recompilation.
    actor.observe(actor.select_action(obs), _timestep(step))
  learner.step(actor.take_rollout())  # Changes params and statistics.

  actor.observe(actor.select_action(obs), _timestep(2))
  actor.update()  # Mid-segment: deferred.
  np.testing.assert_array_equal(actor.select_action(obs), old_action)
  actor.observe(old_action, _timestep(3))
  actor.take_rollout()
  assert not np.allclose(actor.select_action(obs), old_action)


def test_observe_before_select_action_is_an_error(learner):
  _, _, actor = _setup(learner)
  actor.observe_first(_timestep(0, step_type=0))
  with pytest.raises(RuntimeError, match='select_action'):
    actor.observe(None, _timestep(1))
