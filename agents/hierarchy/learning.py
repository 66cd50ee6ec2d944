"""Recurrent PPO for the hierarchy: truncated BPTT over stored sequences.

`make_update_fn` returns the pure `update(state, batch) -> (state, metrics)`:
statistics, one replay of every sequence for values and GAE, then epochs x
minibatches of SGD where each minibatch re-unrolls the ML from the stored
`initial_carry` (PureJaxRL `ppo_rnn`). Minibatches permute the batch axis B
only, so sequences stay whole. Value targets come from `agents.ppo.returns`
(value normalisation), the step size from `agents.ppo.step_size`
(KL-adaptive learning rate). `HierarchyLearner` wraps it with Acme's Learner
interface and checkpoint files; it mirrors `agents.ppo.learning`.
"""
from typing import Any, Iterator, NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import optax

from agents import checkpointing
from agents import core
from agents import normalization
from agents.hierarchy import config as hierarchy_config
from agents.hierarchy import legacy
from agents.hierarchy import networks as hierarchy_networks
from agents.hierarchy import types
from agents.ppo import learning as ppo_learning
from agents.ppo import losses
from agents.ppo import returns
from agents.ppo import step_size
from agents.ppo import types as ppo_types

# 2: value normaliser and adaptive learning rate in the state, critic layouts
# (format 1 files are converted by `agents.hierarchy.legacy`).
_CHECKPOINT_FORMAT = 2


class TrainingState(NamedTuple):
  """Everything that changes during training (and goes into checkpoints).

  Attributes:
    params: network parameters (Flax variables).
    opt_state: optax state of the optimiser chain (with the adapted
      learning rate when `target_kl > 0`).
    normalizer: observation statistics used by the current params.
    global_state_normalizer: global-state statistics ('mappo'; for the other
      variants 0-dimensional and never updated).
    value_normalizer: [1]-dimensional statistics of the value targets, which
      the critic predicts standardised (never updated without
      `normalize_values`).
    step: number of updates done, int32 scalar.
    key: PRNG key (raw uint32 [2]) for shuffling and entropy estimates.
  """
  params: Any
  opt_state: optax.OptState
  normalizer: normalization.NormalizerState
  global_state_normalizer: normalization.NormalizerState
  value_normalizer: normalization.NormalizerState
  step: jax.Array
  key: jax.Array


def make_optimizer(
    config: hierarchy_config.HierarchyConfig) -> optax.GradientTransformation:
  """Adam after global-norm gradient clipping, KL-adaptive learning rate."""
  return step_size.make_optimizer(config)


def make_initial_state(networks: hierarchy_networks.HierarchyNetworks,
                       optimizer: optax.GradientTransformation,
                       key: jax.Array) -> TrainingState:
  """Fresh parameters, optimiser state and empty statistics."""
  init_key, key = jax.random.split(key)
  params = networks.init(init_key)
  return TrainingState(
      params=params, opt_state=optimizer.init(params),
      normalizer=normalization.init(networks.observation_size),
      global_state_normalizer=normalization.init(
          networks.global_state_size or 0),
      value_normalizer=normalization.init(1),
      step=jnp.zeros((), jnp.int32), key=key)


def _check_batch(networks, config, batch: types.SequenceBatch) -> None:
  """Shape errors at trace time, in the user's words."""
  steps, batch_size = batch.reward.shape
  expected = {
      'observation': (steps + 1, batch_size, networks.observation_size),
      'raw_action': (steps, batch_size, networks.action_size),
      'reset': (steps + 1, batch_size),
      'initial_carry': (batch_size, networks.carry_size),
  }
  if networks.global_state_size is not None:
    if batch.global_state is None:
      raise ValueError("agent='mappo' needs SequenceBatch.global_state.")
    expected['global_state'] = (steps + 1, batch_size,
                                networks.global_state_size)
  for name, shape in expected.items():
    if getattr(batch, name).shape != shape:
      raise ValueError(f'SequenceBatch.{name} has shape '
                       f'{getattr(batch, name).shape}, expected {shape}.')
  if batch_size % config.num_minibatches:
    raise ValueError(
        f'The batch size B={batch_size} must be divisible by '
        f'num_minibatches={config.num_minibatches}.')


def make_update_fn(networks: hierarchy_networks.HierarchyNetworks,
                   config: hierarchy_config.HierarchyConfig,
                   optimizer: optax.GradientTransformation):
  """Builds the pure `update(state, batch) -> (state, metrics)`; jit it.

  `batch` is a `types.SequenceBatch` of T commands of B agents. Metrics are
  means over all SGD steps (see `agents.ppo.losses.ppo_loss`), plus
  'learning_rate' (mean rate of the steps) and 'explained_variance' of the
  values that made the targets.
  """
  preprocess = normalization.make_preprocess_fn(
      config.normalize_observations, config.observation_clip)
  uses_global_state = networks.global_state_size is not None

  def make_training_batch(params, normalizer, gs_normalizer,
                          value_normalizer, batch):
    """(SequenceTrainingBatch, returns.Targets) of `batch`."""
    observation = preprocess(normalizer, batch.observation)  # [T+1, B, D]
    global_state = (preprocess(gs_normalizer, batch.global_state)
                    if uses_global_state else None)
    # One replay of T + 1 steps gives the values and the bootstrap value.
    _, _, values = networks.unroll(params, batch.initial_carry, observation,
                                   batch.reset, global_state)  # [T+1, B]
    targets = returns.compute_targets(
        values, batch.reward * config.reward_scaling,
        config.discount * batch.discount, batch.truncation,
        value_normalizer if config.normalize_values else None,
        config.gae_lambda)
    steps = ppo_types.TrainingBatch(
        observation=observation[:-1], raw_action=batch.raw_action,
        behaviour_log_prob=batch.log_prob,
        behaviour_value=targets.behaviour_value,
        advantage=targets.advantage, target_value=targets.target_value)
    return types.SequenceTrainingBatch(
        steps=steps, reset=batch.reset[:-1],
        initial_carry=batch.initial_carry,
        global_state=None if global_state is None else global_state[:-1]
    ), targets

  def loss_fn(params, minibatch: types.SequenceTrainingBatch, key):
    # Truncated BPTT: gradients flow through the T steps of the sequence but
    # not into the stored initial carry, which is data.
    _, dist_params, values = networks.unroll(
        params, minibatch.initial_carry, minibatch.steps.observation,
        minibatch.reset, minibatch.global_state)
    return losses.ppo_loss(dist_params, values, minibatch.steps,
                           networks.distribution, key,
                           **ppo_learning.loss_options(config))

  sgd_step = ppo_learning.make_sgd_step(loss_fn, optimizer, config.target_kl)

  def epoch(carry, key, batch: types.SequenceTrainingBatch):
    permutation_key, loss_key = jax.random.split(key)
    permutation = jax.random.permutation(
        permutation_key, batch.initial_carry.shape[0])
    m = config.num_minibatches

    def split(x, axis):  # Shuffle B, then [.., B, ..] -> [M, .., B / M, ..].
      x = jnp.take(x, permutation, axis=axis)
      x = x.reshape(*x.shape[:axis], m, -1, *x.shape[axis + 1:])
      return jnp.moveaxis(x, axis, 0)

    minibatches = types.SequenceTrainingBatch(
        steps=jax.tree.map(lambda x: split(x, 1), batch.steps),
        reset=split(batch.reset, 1),
        initial_carry=split(batch.initial_carry, 0),
        global_state=jax.tree.map(lambda x: split(x, 1), batch.global_state))
    keys = jax.random.split(loss_key, m)
    return jax.lax.scan(sgd_step, carry, (minibatches, keys))

  def update(state: TrainingState, batch: types.SequenceBatch):
    _check_batch(networks, config, batch)
    # Statistics first (as in agents.ppo.learning); the bootstrap row is the
    # next batch's first row, so it is counted once, there.
    normalizer = state.normalizer
    gs_normalizer = state.global_state_normalizer
    if config.normalize_observations:
      normalizer = normalization.update(normalizer, batch.observation[:-1])
      if uses_global_state:
        gs_normalizer = normalization.update(gs_normalizer,
                                             batch.global_state[:-1])
    key, epochs_key = jax.random.split(state.key)
    training_batch, targets = make_training_batch(
        state.params, normalizer, gs_normalizer, state.value_normalizer,
        batch)
    (params, opt_state), metrics = jax.lax.scan(
        lambda carry, key: epoch(carry, key, training_batch),
        (state.params, state.opt_state),
        jax.random.split(epochs_key, config.num_epochs))
    metrics = jax.tree.map(jnp.mean, metrics)
    metrics['explained_variance'] = targets.explained_variance
    if 'learning_rate' not in metrics:  # Constant rate (target_kl = 0).
      metrics['learning_rate'] = jnp.float32(config.learning_rate)
    value_normalizer = (targets.value_normalizer if config.normalize_values
                        else state.value_normalizer)
    return TrainingState(params, opt_state, normalizer, gs_normalizer,
                         value_normalizer, state.step + 1, key), metrics

  return update


class HierarchyLearner(core.Learner):
  """Trains one species' hierarchy; publishes params and statistics."""

  def __init__(self,
               networks: hierarchy_networks.HierarchyNetworks,
               config: hierarchy_config.HierarchyConfig,
               batches: Optional[Iterator[types.SequenceBatch]] = None,
               key: Optional[jax.Array] = None):
    """Args:
      networks: the networks to train.
      config: hyper-parameters.
      batches: where `step()` takes data from when it is given none.
      key: PRNG key; defaults to `PRNGKey(config.seed)`.
    """
    optimizer = make_optimizer(config)
    if key is None:
      key = jax.random.PRNGKey(config.seed)
    self._state = make_initial_state(networks, optimizer, key)
    self._optimizer = optimizer
    self._update = jax.jit(make_update_fn(networks, config, optimizer))
    self._batches = batches
    # The variant is part of the file's kind: an 'hrl' file never loads into
    # a 'mappo' learner, even where the shapes would allow it.
    self._checkpoint_kind = f'hierarchy/{networks.agent}'

  @property
  def state(self) -> TrainingState:
    """The current training state (a pytree of arrays)."""
    return self._state

  def step(self,
           batch: Optional[types.SequenceBatch] = None) -> dict[str, Any]:
    """One PPO iteration on `batch`, or on the iterator's next one.

    Returns the update's metrics (device scalars; `float()` them to log).
    """
    if batch is None:
      if self._batches is None:
        raise ValueError('HierarchyLearner.step() needs a batch: pass one or '
                         'give the learner a `batches` iterator.')
      batch = next(self._batches)
    self._state, metrics = self._update(self._state, batch)
    return metrics

  def get_variables(self, names: Sequence[str]) -> list[Any]:
    """Variables by name: 'params', 'normalizer', 'global_state_normalizer'
    or 'step'."""
    state = self._state
    variables = {'params': state.params, 'normalizer': state.normalizer,
                 'global_state_normalizer': state.global_state_normalizer,
                 'step': state.step}
    unknown = [name for name in names if name not in variables]
    if unknown:
      raise ValueError(f'Unknown variable names {unknown}; expected some of '
                       f'{sorted(variables)}.')
    return [variables[name] for name in names]

  def save(self, path: str) -> None:
    """Writes the full training state to `path`, atomically."""
    checkpointing.save_state(path, self._state, self._checkpoint_kind,
                             _CHECKPOINT_FORMAT)

  def _read_state_dict(self, path: str) -> dict[str, Any]:
    """The state dict of a file written by `save`, in today's layout."""
    file_format, state_dict = checkpointing.read(path, self._checkpoint_kind)
    if file_format == legacy.FORMAT:
      return legacy.convert(state_dict, self._state, self._optimizer)
    if file_format != _CHECKPOINT_FORMAT:
      raise ValueError(f'{path} is a {self._checkpoint_kind} checkpoint of '
                       f'format {file_format}; this version reads formats '
                       f'{legacy.FORMAT} and {_CHECKPOINT_FORMAT}.')
    return state_dict

  # What a curriculum stage hands on (`initialize_from`); the rest (optimiser,
  # update step, key and the global-state statistics, whose size depends on
  # the population) starts fresh.
  _HANDED_ON = ('params', 'normalizer', 'value_normalizer')

  def initialize_from(self, path: str) -> None:
    """Starts from another run's file written by `save` (e.g. a curriculum
    stage): its parameters and its observation and value statistics, with
    this learner's fresh optimiser, update step and PRNG key.

    Raises:
      ValueError: the file is of another variant, or its networks differ
        from this learner's (naming the file).
    """
    state_dict = self._read_state_dict(path)
    template = {name: getattr(self._state, name) for name in self._HANDED_ON}
    loaded = checkpointing.from_state_dict(
        path, template, {name: state_dict[name] for name in self._HANDED_ON})
    self._state = self._state._replace(**loaded)

  def restore(self, path: str) -> None:
    """Loads a file written by `save` with the same networks and config.

    Files of the first layout (format 1: shared critic, no value statistics)
    are converted (`agents.hierarchy.legacy`): the policy exactly, a
    separate critic as a copy of the shared trunk, a fresh optimiser.
    """
    state_dict = self._read_state_dict(path)
    self._state = checkpointing.from_state_dict(path, self._state,
                                                state_dict)
