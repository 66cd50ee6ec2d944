"""Stability machinery of the hierarchy's PPO (docs/training.md, "Stability"):
value normalisation, a critic that cannot steer the policy, the KL-adaptive
learning rate, the new learner state in checkpoints and old checkpoints."""
import functools

from flax import serialization
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from agents import checkpointing
from agents import normalization
from agents.hierarchy import builder as hierarchy_builder
from agents.hierarchy import config as hierarchy_config
from agents.ppo import types
from agents.ppo import losses
from agents.ppo import returns
from agents.ppo import step_size

T, B, OBS_DIM, GLOBAL_DIM, H = 4, 4, 5, 3, 8
SMALL = dict(upper_layer_sizes=(16,), middle_layer_size=H, head_sizes=(8,),
             critic_sizes=(8,), num_minibatches=2)
POLICY_MODULES = ('upper_layer', 'middle_layer', 'command_head', 'raw_scale')


@functools.lru_cache(maxsize=None)
def _setup(agent='hrl', critic='separate', **options):
  config = hierarchy_config.HierarchyConfig(agent=agent, critic=critic,
                                            **SMALL, **options)
  builder = hierarchy_builder.HierarchyBuilder(config)
  networks = builder.make_networks(OBS_DIM, 2, GLOBAL_DIM)
  return config, builder, networks


def _learner(agent='hrl', critic='separate', **options):
  """A fresh learner (same initial state for the same arguments)."""
  _, builder, networks = _setup(agent, critic, **options)
  return builder.make_learner(networks)


def _batch(networks, seed=0, log_prob_offset=0.0):
  rng = np.random.default_rng(seed)
  f32 = lambda *shape: rng.normal(size=shape).astype(np.float32)
  discount = (rng.uniform(size=(T, B)) > 0.2).astype(np.float32)
  return types.SequenceBatch(
      observation=f32(T + 1, B, OBS_DIM) * 3 + 1,
      raw_action=f32(T, B, 2), log_prob=f32(T, B) - 2 + log_prob_offset,
      reward=f32(T, B) * 50 + 100, discount=discount,
      reset=rng.uniform(size=(T + 1, B)) < 0.3,
      initial_carry=f32(B, networks.carry_size),
      global_state=(f32(T + 1, B, GLOBAL_DIM)
                    if networks.global_state_size else None),
      truncation=((rng.uniform(size=(T, B)) > 0.9) * discount).astype(
          np.float32))


def test_value_statistics_and_targets_match_numpy():
  rng = np.random.default_rng(0)
  statistics = normalization.init(1)
  all_returns = []
  for _ in range(3):
    values = rng.normal(size=(T + 1, B)).astype(np.float32)
    rewards = rng.normal(50.0, 20.0, size=(T, B)).astype(np.float32)
    discounts = np.full((T, B), 0.99, np.float32)
    before = statistics
    targets = returns.compute_targets(values, rewards, discounts, None,
                                      statistics, gae_lambda=0.95)
    statistics = targets.value_normalizer
    # GAE in return units: the critic's outputs de-normalised with the
    # statistics it was trained against (mean + std * v).
    raw_values = (np.asarray(before.mean) + np.sqrt(np.asarray(before.var))
                  * values)
    advantages, raw_returns = losses.compute_gae(
        rewards, raw_values[:-1], discounts, raw_values[-1], 0.95)
    np.testing.assert_allclose(targets.advantage, advantages, rtol=1e-5)
    all_returns.append(np.asarray(raw_returns))
    seen = np.concatenate([r.ravel() for r in all_returns])
    np.testing.assert_allclose(statistics.count, seen.size)
    np.testing.assert_allclose(statistics.mean, [seen.mean()], rtol=1e-5)
    np.testing.assert_allclose(statistics.var, [seen.var()], rtol=1e-4)
    # Targets standardised with the statistics that include them.
    np.testing.assert_allclose(
        targets.target_value,
        (raw_returns - seen.mean()) / seen.std(), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(
        normalization.denormalize(statistics, targets.target_value[..., None])
        [..., 0], raw_returns, rtol=1e-5)
    residual = raw_returns - raw_values[:-1]
    np.testing.assert_allclose(targets.explained_variance,
                               1 - residual.var() / raw_returns.var(),
                               rtol=1e-4)


def test_without_value_normalisation_targets_are_plain_returns():
  values = np.arange((T + 1) * B, dtype=np.float32).reshape(T + 1, B)
  rewards = np.ones((T, B), np.float32)
  discounts = np.full((T, B), 0.9, np.float32)
  targets = returns.compute_targets(values, rewards, discounts, None, None,
                                    0.95)
  _, expected = losses.compute_gae(rewards, values[:-1], discounts,
                                   values[-1], 0.95)
  np.testing.assert_array_equal(targets.target_value, expected)
  np.testing.assert_array_equal(targets.behaviour_value, values[:-1])
  assert targets.value_normalizer is None


def _value_loss_gradient(agent, critic):
  _, _, networks = _setup(agent, critic)
  params = networks.init(jax.random.PRNGKey(1))
  batch = _batch(networks)
  gs = None if batch.global_state is None else batch.global_state[:-1]

  def value_loss(params):
    _, _, values = networks.unroll(params, batch.initial_carry,
                                   batch.observation[:-1], batch.reset[:-1],
                                   gs)
    return jnp.mean(jnp.square(values - 3.0))

  return jax.grad(value_loss)(params)['params']


@pytest.mark.parametrize('agent', ['hrl', 'no_memory', 'mappo'])
@pytest.mark.parametrize('critic', ['separate', 'stop_gradient'])
def test_the_value_loss_does_not_reach_the_policy(agent, critic):
  grads = _value_loss_gradient(agent, critic)
  for name in POLICY_MODULES:
    for leaf in jax.tree.leaves(grads[name]):
      np.testing.assert_array_equal(leaf, 0.0, err_msg=f'{agent} {name}')
  assert np.abs(jax.tree.leaves(grads['value_head'])[0]).max() > 0
  if critic == 'separate':
    for name in ('critic_upper_layer', 'critic_middle_layer'):
      assert all(np.abs(x).max() > 0 for x in jax.tree.leaves(grads[name]))


def test_a_shared_critic_does_reach_the_policy():
  """The check above can fail: the first run's layout trains the trunk."""
  grads = _value_loss_gradient('hrl', 'shared')
  assert np.abs(jax.tree.leaves(grads['upper_layer'])[0]).max() > 0


def test_learning_rate_follows_the_kl():
  # Hand arithmetic with target 0.01: above 0.02 -> / 1.5; below 0.005 ->
  # x 1.5; in between unchanged; never beyond the bounds.
  rate = lambda lr, kl: float(step_size.adapted_learning_rate(
      jnp.float32(lr), jnp.float32(kl), 0.01))
  np.testing.assert_allclose(rate(3e-4, 0.05), 2e-4, rtol=1e-6)
  np.testing.assert_allclose(rate(3e-4, 0.001), 4.5e-4, rtol=1e-6)
  np.testing.assert_allclose(rate(3e-4, 0.01), 3e-4, rtol=1e-6)
  assert rate(step_size.MAX_LEARNING_RATE, 0.0) == pytest.approx(
      step_size.MAX_LEARNING_RATE)
  assert rate(step_size.MIN_LEARNING_RATE, 1.0) == pytest.approx(
      step_size.MIN_LEARNING_RATE)


@pytest.mark.parametrize('target_kl, moves', [(1e-9, 'down'), (1e3, 'up')])
def test_the_learner_adapts_its_learning_rate_to_the_kl(target_kl, moves):
  initial = 1e-4  # x 1.5^8 stays below MAX_LEARNING_RATE.
  learner = _learner(target_kl=target_kl, learning_rate=initial)
  # Behaviour log-probabilities 1 nat off make the KL far above 1e-9.
  metrics = learner.step(_batch(_setup(target_kl=target_kl)[2],
                                log_prob_offset=1.0))
  assert float(metrics['approx_kl']) > 1e-3
  rate = float(step_size.learning_rate(learner.state.opt_state))
  steps = 4 * 2  # Epochs x minibatches, each adapts once.
  expected = initial * 1.5 ** (steps if moves == 'up' else -steps)
  np.testing.assert_allclose(rate, expected, rtol=1e-5)


def test_checkpoints_round_trip_the_new_state_and_resume_bit_for_bit(
    tmp_path):
  networks = _setup()[2]
  batches = [_batch(networks, seed) for seed in range(4)]
  straight = _learner()
  for batch in batches:
    straight.step(batch)

  interrupted = _learner()
  for batch in batches[:2]:
    interrupted.step(batch)
  resumed = _learner()
  resumed.restore(interrupted.save())
  saved = interrupted.state
  assert float(resumed.state.value_normalizer.count) == 2 * T * B
  np.testing.assert_array_equal(resumed.state.value_normalizer.mean,
                                saved.value_normalizer.mean)
  assert float(step_size.learning_rate(resumed.state.opt_state)) == float(
      step_size.learning_rate(saved.opt_state)) != 5e-4
  for batch in batches[2:]:
    resumed.step(batch)
  for path_, a, b in zip(
      *zip(*jax.tree_util.tree_leaves_with_path(straight.state)),
      jax.tree.leaves(resumed.state)):
    np.testing.assert_array_equal(a, b, err_msg=jax.tree_util.keystr(path_))


def _write_format_1(path, learner):
  """A file as the first layout's learner wrote it: no value statistics."""
  state = serialization.to_state_dict(jax.device_get(learner.state))
  del state['value_normalizer']
  state['step'] = state.pop('update')
  data = serialization.msgpack_serialize(
      {'format': 1, 'kind': 'hierarchy/hrl', 'state': state})
  with open(path, 'wb') as f:
    f.write(data)
  return checkpointing.read_file(path)


@pytest.mark.parametrize('critic', ['separate', 'stop_gradient'])
def test_first_layout_checkpoints_load_with_the_same_policy_and_values(
    tmp_path, critic):
  old = _learner(critic='shared', target_kl=0.0)
  old_networks = _setup(critic='shared', target_kl=0.0)[2]
  old.step(_batch(old_networks, 7))
  path = str(tmp_path / 'ant.msgpack')
  saved = _write_format_1(path, old)

  new = _learner(critic=critic)
  new.restore(saved, source=path)
  networks = _setup(critic=critic)[2]
  batch = _batch(networks, 8)
  observation = jnp.asarray(batch.observation)
  reset = jnp.asarray(batch.reset)
  _, old_dist, old_value = old_networks.unroll(
      old.state.params, old_networks.initial_carry(B), observation, reset)
  _, dist, value = networks.unroll(
      new.state.params, networks.initial_carry(B), observation, reset)
  np.testing.assert_array_equal(dist, old_dist)
  # The old head predicted returns; identity statistics read them unchanged.
  np.testing.assert_allclose(
      normalization.denormalize(new.state.value_normalizer, value[..., None])
      [..., 0], old_value, rtol=1e-6)
  assert int(new.state.update) == 1
  new.step(batch)  # And it trains on.
  saved['format'] = 99
  with pytest.raises(ValueError, match=f'{path} is a .* of format 99; this '
                     'version reads'):
    new.restore(saved, source=path)
  with pytest.raises(ValueError, match='not a hierarchy/mappo checkpoint'):
    _learner('mappo').restore(saved)
  assert checkpointing.unpack(saved, 'hierarchy/hrl', path)[0] == 99
