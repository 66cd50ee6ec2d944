"""The hierarchical agent: variants learn, GRU resets, actor == learner."""
import collections
import functools
import gc

from flax import serialization
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from agents import normalization
from agents.hierarchy import builder as hierarchy_builder
from agents.hierarchy import config as hierarchy_config
from agents.ppo import types

TimeStep = collections.namedtuple(
    'TimeStep', ['step_type', 'reward', 'discount', 'observation'])
T, B, OBS_DIM, GLOBAL_DIM, H = 4, 4, 5, 3, 8
SMALL = dict(upper_layer_sizes=(16,), middle_layer_size=H, head_sizes=(8,),
             critic_sizes=(8,), flat_sizes=(16,), num_minibatches=2)


def _config(agent):
  return hierarchy_config.HierarchyConfig(agent=agent, **SMALL)


def _action_dim(agent):
  # The 2-D command, or joint actions (a variant without the lower layer).
  return 2 if _config(agent).uses_commands else 8


@functools.lru_cache(maxsize=None)
def _setup(agent):
  """Builder, networks and learner per variant, shared so each compiles once."""
  builder = hierarchy_builder.HierarchyBuilder(_config(agent))
  networks = builder.make_networks(OBS_DIM, _action_dim(agent), GLOBAL_DIM)
  return builder, networks, builder.make_learner(networks)


def _random_batch(agent, seed=0):
  rng = np.random.default_rng(seed)
  f32 = lambda *shape: rng.normal(size=shape).astype(np.float32)
  discount = (rng.uniform(size=(T, B)) > 0.2).astype(np.float32)
  return types.SequenceBatch(
      observation=f32(T + 1, B, OBS_DIM) * 3 + 1,
      raw_action=f32(T, B, _action_dim(agent)), log_prob=f32(T, B) - 2,
      reward=f32(T, B), discount=discount,
      reset=rng.uniform(size=(T + 1, B)) < 0.3,
      initial_carry=f32(B, _setup(agent)[1].carry_size),
      global_state=(f32(T + 1, B, GLOBAL_DIM)
                    if _config(agent).uses_global_state else None),
      truncation=((rng.uniform(size=(T, B)) > 0.9) * discount).astype(
          np.float32))


@pytest.mark.parametrize('agent', hierarchy_config.AGENTS)
def test_updates_move_every_parameter_and_stay_finite(agent):
  _, _, learner = _setup(agent)
  before, update = learner.get_variables(['params', 'update'])
  for seed in range(2):
    metrics = learner.step(_random_batch(agent, seed))
    for name, value in metrics.items():
      assert np.isfinite(value), (agent, name)
  after, normalizer, gs_normalizer, update_after = learner.get_variables(
      ['params', 'normalizer', 'global_state_normalizer', 'update'])
  unchanged = [jax.tree_util.keystr(path) for path, a, b in zip(
      *zip(*jax.tree_util.tree_leaves_with_path(before)),
      jax.tree.leaves(after)) if np.array_equal(a, b)]
  assert not unchanged, unchanged
  assert int(update_after) == int(update) + 2
  assert float(normalizer.count) >= 2 * T * B
  assert float(gs_normalizer.count) == (
      float(normalizer.count) if _config(agent).uses_global_state else 0.0)


@pytest.mark.parametrize('agent', ['hrl', 'mappo'])
def test_gru_carry_is_reset_where_an_episode_starts(agent):
  _, networks, learner = _setup(agent)
  params, = learner.get_variables(['params'])
  rng = np.random.default_rng(1)
  obs = jnp.asarray(rng.normal(size=(6, B, OBS_DIM)), jnp.float32)
  gs = jnp.asarray(rng.normal(size=(6, B, GLOBAL_DIM)), jnp.float32)
  carry = jnp.asarray(rng.normal(size=(B, networks.carry_size)),
                      jnp.float32)
  reset = np.zeros((6, B), bool)
  reset[3, :2] = True  # Rows 0 and 1 start a new episode at t = 3.
  _, dist, value = networks.unroll(params, carry, obs, reset, gs)
  # A fresh sequence starting at t = 3 from the initial carry.
  _, fresh_dist, fresh_value = networks.unroll(
      params, networks.initial_carry(B), obs[3:], np.zeros((3, B), bool),
      gs[3:])
  np.testing.assert_allclose(dist[3:, :2], fresh_dist[:, :2], atol=1e-6)
  np.testing.assert_allclose(value[3:, :2], fresh_value[:, :2], atol=1e-6)
  # Rows without a reset remember the earlier steps: the memory is real.
  assert not np.allclose(dist[3:, 2:], fresh_dist[:, 2:], atol=1e-4)


def test_actor_steps_compute_the_function_the_learner_replays():
  builder, networks, learner = _setup('hrl')
  learner.step(_random_batch('hrl', 2))  # Non-trivial statistics.
  actor = builder.make_actor(networks, learner, action_bounds=(-3.0, 3.0))
  rng = np.random.default_rng(3)
  actor.observe_first()
  carries, values = [], []
  for t in range(T):
    obs = rng.normal(size=(B, OBS_DIM)).astype(np.float32)
    reset = np.zeros(B, bool) if t else np.ones(B, bool)
    if t == 2:
      reset[1] = True  # Agent 1's episode ended after command 1.
    actions, extras = actor.select_action(obs, reset)
    assert actions.shape == (B, 2) and np.all(np.abs(actions) <= 3.0)
    carries.append(extras['carry_before'])
    values.append(extras['value'])
    step_type = np.where(np.arange(B) == 1, 2 if t == 1 else 1, 1)
    actor.observe(actions, TimeStep(step_type, np.ones(B, np.float32),
                                    np.ones(B, np.float32), obs + 1))
  final_carry = actor.carry
  batch = actor.take_rollout()
  assert batch.observation.shape == (T + 1, B, OBS_DIM)
  np.testing.assert_array_equal(batch.reset[2], [0, 1, 0, 0])
  np.testing.assert_array_equal(batch.reset[-1], [0, 0, 0, 0])
  np.testing.assert_array_equal(batch.initial_carry, carries[0])
  np.testing.assert_array_equal(batch.truncation[1], [0, 1, 0, 0])

  # The learner's replay of the stored sequence: same log-probs and values.
  params, normalizer = learner.get_variables(['params', 'normalizer'])
  carry, dist, value = networks.unroll(
      params, batch.initial_carry,
      normalization.normalize(normalizer, batch.observation[:-1]),
      batch.reset[:-1])
  log_prob = networks.distribution.log_prob(dist, batch.raw_action)
  np.testing.assert_allclose(log_prob, batch.log_prob, rtol=1e-5, atol=1e-5)
  np.testing.assert_allclose(value, np.stack(values), rtol=1e-5, atol=1e-5)
  np.testing.assert_allclose(carry, final_carry, atol=1e-6)
  # The learner accepts the actor's batch as it is.
  assert np.isfinite(float(learner.step(batch)['total_loss']))


def test_actor_keeps_one_parameter_version_per_segment():
  builder, networks, learner = _setup('no_memory')
  actor = builder.make_actor(networks, learner)
  obs = np.zeros((B, OBS_DIM), np.float32)
  timestep = TimeStep(np.ones(B, int), np.zeros(B, np.float32),
                      np.ones(B, np.float32), obs)
  actor.observe_first()
  actor.select_action(obs, np.ones(B, bool))
  actor.observe(None, timestep)
  # pylint: disable=protected-access
  old_params = actor._variables[0]
  learner.step(_random_batch('no_memory'))
  actor.update()  # Mid-segment: deferred.
  assert actor._variables[0] is old_params
  actor.take_rollout()
  assert actor._variables[0] is not old_params
  # pylint: enable=protected-access
  with pytest.raises(RuntimeError, match='observe after each'):
    actor.select_action(obs, np.zeros(B, bool))
    actor.select_action(obs, np.zeros(B, bool))


def test_mappo_critic_reads_the_global_state_and_the_policy_does_not():
  _, networks, learner = _setup('mappo')
  params, = learner.get_variables(['params'])
  rng = np.random.default_rng(4)
  obs = jnp.asarray(rng.normal(size=(2, B, OBS_DIM)), jnp.float32)
  gs = jnp.asarray(rng.normal(size=(2, B, GLOBAL_DIM)), jnp.float32)
  carry, reset = networks.initial_carry(B), np.zeros((2, B), bool)
  _, dist, value = networks.unroll(params, carry, obs, reset, gs)
  _, other_dist, _ = networks.unroll(params, carry, -obs, reset, gs)
  _, same_dist, other_value = networks.unroll(params, carry, obs, reset, -gs)
  np.testing.assert_array_equal(dist, same_dist)
  assert not np.allclose(value, other_value)
  assert not np.allclose(dist, other_dist)
  with pytest.raises(ValueError, match='needs global_state_dim'):
    hierarchy_builder.HierarchyBuilder(hierarchy_config.HierarchyConfig(
        agent='mappo')).make_networks(OBS_DIM, 2)


@pytest.mark.parametrize('agent, other', [('mappo', 'hrl'), ('hrl', 'flat')])
def test_save_restore_round_trips_and_the_update_counter_continues(
    agent, other):
  _, _, learner = _setup(agent)
  learner.step(_random_batch(agent, 5))
  saved = jax.device_get(learner.state)
  saved_state = learner.save()
  learner.step(_random_batch(agent, 6))
  after_saved = jax.device_get(learner.state)

  learner.restore(saved_state)
  for a, b in zip(jax.tree.leaves(saved), jax.tree.leaves(learner.state)):
    np.testing.assert_array_equal(a, b)
  learner.step(_random_batch(agent, 6))  # Same data: same result.
  for a, b in zip(jax.tree.leaves(after_saved),
                  jax.tree.leaves(learner.state)):
    np.testing.assert_array_equal(a, b)
  assert int(learner.state.update) == int(saved.update) + 1
  with pytest.raises(ValueError, match=f'not a hierarchy/{other} checkpoint'):
    _setup(other)[2].restore(saved_state)
  # Format 2, the hierarchy learner's own: the counter named `step`.
  state = serialization.to_state_dict(saved)
  state['step'] = state.pop('update')
  learner.restore({'format': 2, 'kind': f'hierarchy/{agent}', 'state': state})
  for a, b in zip(jax.tree.leaves(saved), jax.tree.leaves(learner.state)):
    np.testing.assert_array_equal(a, b)


def test_bad_batches_and_configs_are_rejected_with_clear_errors():
  _, _, learner = _setup('hrl')
  batch = _random_batch('hrl')
  with pytest.raises(ValueError, match='initial_carry has shape'):
    learner.step(batch._replace(initial_carry=batch.initial_carry[:, :2]))
  with pytest.raises(ValueError, match='must be one of'):
    hierarchy_config.HierarchyConfig(agent='feudal')
  with pytest.raises(ValueError, match='needs a batch'):
    learner.step()


@pytest.mark.parametrize('initial_std', [0.0, 0.25])
def test_the_command_std_starts_where_the_config_says(initial_std):
  config = hierarchy_config.HierarchyConfig(
      **SMALL, initial_action_std=initial_std)
  networks = hierarchy_builder.HierarchyBuilder(config).make_networks(
      OBS_DIM, 2, GLOBAL_DIM)
  params = networks.init(jax.random.PRNGKey(3))
  observation = jnp.asarray(np.random.default_rng(0).normal(
      size=(T, B, OBS_DIM)), jnp.float32)
  _, dist_params, _ = networks.unroll(
      params, networks.initial_carry(B), observation,
      jnp.zeros((T, B), bool))
  _, scale = networks.distribution.loc_and_scale(dist_params)
  # 0 keeps the default: a zero pre-softplus scale, softplus(0) + floor.
  expected = initial_std or np.log(2) + config.min_action_std
  np.testing.assert_allclose(scale, expected, rtol=1e-6)
  if not initial_std:
    assert not np.any(params['params']['raw_scale'])


def test_an_initial_std_the_config_cannot_start_from_is_refused():
  with pytest.raises(ValueError, match='must be > --min-action-std'):
    hierarchy_config.HierarchyConfig(initial_action_std=0.05)
  with pytest.raises(ValueError, match='needs a state-independent std'):
    hierarchy_config.HierarchyConfig(initial_action_std=0.5,
                                     state_dependent_std=True)
  with pytest.raises(ValueError, match='initial-action-std'):
    hierarchy_config.HierarchyConfig(initial_action_std=-1.0)


def test_hrl_remembers_a_cue_it_no_longer_sees():
  """Memory sanity check: a cue shown at the first of 3 commands is rewarded
  at the last, when the observation is 0. A memoryless policy earns 0 in
  expectation; the GRU must carry the cue (reward 1 = command * cue)."""
  builder = hierarchy_builder.HierarchyBuilder(hierarchy_config.HierarchyConfig(
      upper_layer_sizes=(16,), middle_layer_size=16, head_sizes=(),
      learning_rate=1e-2, num_minibatches=1, entropy_cost=0.0,
      reward_scaling=1.0))  # Rewards here are already of order 1.
  networks = builder.make_networks(obs_dim=1, action_dim=1)
  learner = builder.make_learner(networks)
  actor = builder.make_actor(networks, learner)
  rng = np.random.default_rng(0)
  batch_size, returns = 64, []
  actor.observe_first()
  for _ in range(20):
    cue = rng.choice([-1.0, 1.0], size=(batch_size, 1)).astype(np.float32)
    observations = [cue, 0 * cue, 0 * cue, cue]  # Then the next episode.
    for t in range(3):
      actions, _ = actor.select_action(observations[t],
                                       np.full(batch_size, t == 0))
      last = t == 2
      reward = (actions * cue)[:, 0] if last else np.zeros(batch_size)
      actor.observe(actions, TimeStep(
          np.full(batch_size, 2 if last else 1), reward,
          np.full(batch_size, 0.0 if last else 1.0), observations[t + 1]))
    returns.append(reward.mean())
    learner.step(actor.take_rollout())
    actor.update()
  assert np.mean(returns[-5:]) > 0.9, returns


def _module_classes():
  found, stack = set(), [nn.Module]
  while stack:
    for sub in stack.pop().__subclasses__():
      if sub not in found:
        found.add(sub)
        stack.append(sub)
  return found


# The variants with a middle-layer GRU: the others trace no flax transform.
@pytest.mark.parametrize('agent', [
    a for a in hierarchy_config.AGENTS
    if _config(a).uses_commands and _config(a).recurrent])
def test_tracing_an_update_makes_no_module_class(agent):
  """Species' learners trace their updates at once in threads
  (`runners.learner_loop.step_learners`); flax makes a lifted class (the
  scanned GRU) by editing its bases' dataclass fields in place, which races.
  So no class may be made while tracing: a fresh learner's first (tracing)
  update and its actor's first step leave the set of Module classes as it
  was."""
  builder, networks, _ = _setup(agent)
  learner = builder.make_learner(networks)  # Its own jit: traces anew.
  actor = builder.make_actor(networks, learner)
  gc.disable()  # A class made and dropped would otherwise go unseen.
  try:
    before = _module_classes()
    learner.step(_random_batch(agent))
    actor.observe_first()
    actor.select_action(
        np.zeros((B, OBS_DIM), np.float32), np.ones(B, bool),
        global_state=np.zeros((B, GLOBAL_DIM), np.float32))
    made = _module_classes() - before
  finally:
    gc.enable()
  assert not made, made
