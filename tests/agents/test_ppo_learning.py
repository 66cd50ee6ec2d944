"""PPOLearner on feed-forward networks: one update, checkpoints, and a bandit
the lower layer's variant must solve."""
import collections

from flax import serialization
import jax
import numpy as np
import pytest

from agents import checkpointing
from agents.hierarchy import builder as hierarchy_builder
from agents.hierarchy import config as hierarchy_config
from agents.networks import policy_value
from agents.ppo import config as ppo_config
from agents.ppo import learning
from agents.ppo import types

OBS_DIM, ACTION_DIM, T, B = 3, 2, 5, 8
SMALL = dict(policy_hidden=(16,), value_hidden=(16,))


def _random_rollout(seed=0, with_truncation=True):
  rng = np.random.default_rng(seed)
  f32 = lambda *shape: rng.normal(size=shape).astype(np.float32)
  discount = (rng.uniform(size=(T, B)) > 0.2).astype(np.float32)
  truncation = ((rng.uniform(size=(T, B)) > 0.9) * discount).astype(np.float32)
  return types.SequenceBatch(
      observation=f32(T + 1, B, OBS_DIM) * 3 + 1,
      raw_action=f32(T, B, ACTION_DIM),
      log_prob=f32(T, B) - 2, reward=f32(T, B), discount=discount,
      truncation=truncation if with_truncation else None)


def _make_learner(seed=0, rollouts=None, **overrides):
  config = ppo_config.PPOConfig(seed=seed, **{**SMALL, **overrides})
  networks = policy_value.make_policy_value_networks(
      OBS_DIM, ACTION_DIM, config.policy_hidden, config.value_hidden)
  return learning.PPOLearner(networks, config, rollouts)


def test_one_update_is_finite_and_changes_parameters():
  learner = _make_learner(
      rollouts=iter([_random_rollout(with_truncation=False)]))
  before = learner.get_variables(['params'])[0]
  metrics = learner.step()  # Takes the iterator's rollout.
  for name, value in metrics.items():
    assert np.isfinite(value), name
  after, normalizer, update = learner.get_variables(
      ['params', 'normalizer', 'update'])
  changed = jax.tree.map(lambda a, b: not np.array_equal(a, b), before, after)
  assert all(jax.tree.leaves(changed))
  assert int(update) == 1 and float(normalizer.count) == T * B


def test_bad_requests_are_rejected_with_clear_errors():
  learner = _make_learner()
  with pytest.raises(ValueError, match='divisible by num_minibatches=3'):
    _make_learner(num_minibatches=3).step(_random_rollout())
  with pytest.raises(ValueError, match='Unknown variable'):
    learner.get_variables(['weights'])
  with pytest.raises(ValueError, match='needs a batch'):
    learner.step()


def test_save_restore_round_trips_exactly(tmp_path):
  learner = _make_learner()
  learner.step(_random_rollout(0))
  saved = jax.device_get(learner.state)
  # Through a learner file of the msgpack layout, as runs before orbax
  # wrote them (runners.checkpoints writes orbax; tests/test_run_safety.py).
  path = str(tmp_path / 'learner.msgpack')
  with open(path, 'wb') as f:
    f.write(serialization.msgpack_serialize(learner.save()))
  learner.step(_random_rollout(1))
  after_saved = jax.device_get(learner.state)

  learner.restore(checkpointing.read_file(path))
  for a, b in zip(jax.tree.leaves(saved), jax.tree.leaves(learner.state)):
    np.testing.assert_array_equal(a, b)
  assert int(learner.state.update) == 1
  # Restored state, same data: training continues identically.
  learner.step(_random_rollout(1))
  for a, b in zip(jax.tree.leaves(after_saved), jax.tree.leaves(learner.state)):
    np.testing.assert_array_equal(a, b)

  other = _make_learner(seed=1)  # A fresh process restoring the file.
  other.restore(checkpointing.read_file(path))
  for a, b in zip(jax.tree.leaves(saved), jax.tree.leaves(other.state)):
    np.testing.assert_array_equal(a, b)
  with pytest.raises(ValueError, match='other shapes'):
    _make_learner(policy_hidden=(8,)).restore(checkpointing.read_file(path))

  # Format 1, the feed-forward learner's own: no value or global-state
  # statistics, the counter named `step`.
  state = serialization.to_state_dict(saved)
  state['step'] = state.pop('update')
  del state['value_normalizer'], state['global_state_normalizer']
  other.restore({'format': 1, 'kind': 'ppo', 'state': state})
  for a, b in zip(jax.tree.leaves(saved), jax.tree.leaves(other.state)):
    np.testing.assert_array_equal(a, b)


TimeStep = collections.namedtuple(
    'TimeStep', ['step_type', 'reward', 'discount', 'observation'])


def test_the_lower_layer_variant_solves_a_one_step_bandit():
  # Constant observation, reward -|a - 0.5|: the policy's mean must move from
  # tanh(~0) = 0 to about 0.5. Each episode is one step and terminates.
  # The lower layer's settings (coop-pretrain-lowlevel): constant rate, raw
  # value targets, the distribution's own std floor.
  num_envs = 64
  config = hierarchy_config.HierarchyConfig(
      agent='lowlevel', learning_rate=3e-3, entropy_cost=1e-3, num_epochs=2,
      num_minibatches=2, flat_sizes=(8,), target_kl=0.0,
      normalize_values=False, reward_scaling=1.0, min_action_std=1e-3,
      max_grad_norm=0.5)
  builder = hierarchy_builder.HierarchyBuilder(config)
  networks = builder.make_networks(1, 1)
  learner = builder.make_learner(networks)
  actor = builder.make_actor(networks, learner)
  evaluator = builder.make_actor(networks, learner, deterministic=True)
  observation = np.ones((num_envs, 1), np.float32)
  first = np.ones(num_envs, bool)  # Every step starts an episode.
  last = TimeStep(np.full(num_envs, 2), None, np.zeros(num_envs), observation)
  mean = lambda: float(evaluator.select_action(observation[:1],
                                               first[:1])[0][0, 0])

  initial_mean = mean()
  actor.observe_first()
  for _ in range(60):
    action, _ = actor.select_action(observation, first)
    actor.observe(action, last._replace(reward=-np.abs(action[:, 0] - 0.5)))
    learner.step(actor.take_rollout())
    actor.update()
  evaluator.update()
  final_mean = mean()

  assert abs(initial_mean) < 0.1
  assert abs(final_mean - 0.5) < 0.05, final_mean
