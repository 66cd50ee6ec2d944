"""The PPO learner: recurrent PPO over stored sequences (truncated BPTT).

One learner for every network: the hierarchy's variants
(`agents.hierarchy.networks`: upper and middle layer with a GRU or none, or
the 'flat' and 'lowlevel' joint policies) and plain feed-forward networks
(`agents.networks.policy_value`, a recurrent network without memory, carry
width 0). `make_update_fn` returns the pure
`update(state, batch) -> (state, metrics)`: statistics, one replay of every
sequence for values and GAE (`agents.ppo.returns`, value normalisation),
then epochs x minibatches of SGD where each minibatch re-unrolls the network
from the stored `initial_carry` (PureJaxRL `ppo_rnn`), with a KL-adaptive
learning rate (`agents.ppo.step_size`). Minibatches permute the row axis B
only, so sequences stay whole. `PPOLearner` wraps it with Acme's Learner
interface and saved states (`agents.checkpointing`).

The config is a `PPOConfig` or a `HierarchyConfig`: both have the fields
read here (`target_kl` and `normalize_values` are properties of PPOConfig).
"""
from typing import Any, Iterator, NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import optax

from agents import checkpointing
from agents import core
from agents import normalization
from agents.ppo import losses
from agents.ppo import returns
from agents.ppo import step_size
from agents.ppo import types

# 3: one state for every PPO learner, its counter named `update` (formats 1
# and 2, the feed-forward and hierarchy learners' own, named it `step`).
CHECKPOINT_FORMAT = 3
_CHECKPOINT_KIND = 'ppo'
HANDED_ON = ('params', 'normalizer', 'value_normalizer')
"""The part of a training state another run starts from (a curriculum stage,
`initialize_from`) and an evaluation needs; the rest (optimiser, update
counter, key and the global-state statistics, whose size depends on the
population) is training's own."""


def handed_on(saved: dict[str, Any]) -> dict[str, Any]:
  """A saved state (`PPOLearner.save`) with only its `HANDED_ON` part: what
  a published result keeps (`initialize_from` reads it)."""
  return {**saved, 'state': {name: value for name, value in
                             saved['state'].items() if name in HANDED_ON}}


class TrainingState(NamedTuple):
  """Everything that changes during training (and goes into checkpoints).

  Attributes:
    params: network parameters (Flax variables).
    opt_state: optax state of the optimiser chain (with the learning rate
      when it is KL-adaptive).
    normalizer: observation statistics used by the current params.
    global_state_normalizer: global-state statistics ('mappo'; otherwise
      0-dimensional and never updated).
    value_normalizer: [1]-dimensional statistics of the value targets, which
      the critic predicts standardised (never updated without
      `normalize_values`).
    update: number of updates done, int32 scalar (runners name the
      variables actors act with by it).
    key: PRNG key (raw uint32 [2]) for shuffling and entropy estimates.
  """
  params: Any
  opt_state: optax.OptState
  normalizer: normalization.NormalizerState
  global_state_normalizer: normalization.NormalizerState
  value_normalizer: normalization.NormalizerState
  update: jax.Array
  key: jax.Array


def make_initial_state(networks, optimizer: optax.GradientTransformation,
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
      update=jnp.zeros((), jnp.int32), key=key)


def _check_batch(networks, config, batch: types.SequenceBatch) -> None:
  """Shape errors at trace time, in the user's words."""
  steps, batch_size = batch.reward.shape
  expected = {
      'observation': (steps + 1, batch_size, networks.observation_size),
      'raw_action': (steps, batch_size, networks.action_size),
  }
  if batch.initial_carry is not None or networks.carry_size:
    expected['reset'] = (steps + 1, batch_size)
    expected['initial_carry'] = (batch_size, networks.carry_size)
  if networks.global_state_size is not None:
    expected['global_state'] = (steps + 1, batch_size,
                                networks.global_state_size)
  for name, shape in expected.items():
    value = getattr(batch, name)
    if value is None:
      raise ValueError(f'These networks need SequenceBatch.{name} {shape}.')
    if value.shape != shape:
      raise ValueError(f'SequenceBatch.{name} has shape {value.shape}, '
                       f'expected {shape}.')
  if batch_size % config.num_minibatches:
    raise ValueError(
        f'The batch size B={batch_size} must be divisible by '
        f'num_minibatches={config.num_minibatches}.')


def _with_empty_memory(batch: types.SequenceBatch) -> types.SequenceBatch:
  """A batch of a network without memory (no reset, no carry) with an empty
  carry [B, 0] and no resets, so it replays like any other."""
  if batch.initial_carry is not None:
    return batch
  steps, batch_size = batch.reward.shape
  return batch._replace(reset=jnp.zeros((steps + 1, batch_size), bool),
                        initial_carry=jnp.zeros((batch_size, 0)))


def make_sgd_step(loss_fn, optimizer: optax.GradientTransformation,
                  target_kl: float = 0.0):
  """One minibatch gradient step, shaped for `jax.lax.scan` over minibatches.

  `loss_fn(params, minibatch, key) -> (loss, metrics)` with an 'approx_kl'
  metric; the step's carry is `(params, opt_state)` and its input
  `(minibatch, key)`. With `target_kl > 0` (and `optimizer` from
  `step_size.make_optimizer`), the minibatch's KL sets the learning rate of
  the next step (`step_size.adapt`); the metric 'learning_rate' is the rate
  this step used.
  """
  def sgd_step(carry, minibatch_and_key):
    params, opt_state = carry
    minibatch, key = minibatch_and_key
    grads, metrics = jax.grad(loss_fn, has_aux=True)(params, minibatch, key)
    metrics['grad_norm'] = optax.tree.norm(grads)  # Before clipping.
    updates, opt_state = optimizer.update(grads, opt_state, params)
    if target_kl > 0:
      metrics['learning_rate'] = step_size.learning_rate(opt_state)
      opt_state = step_size.adapt(opt_state, metrics['approx_kl'], target_kl)
    return (optax.apply_updates(params, updates), opt_state), metrics
  return sgd_step


def make_update_fn(networks, config, optimizer: optax.GradientTransformation):
  """Builds the pure `update(state, batch) -> (state, metrics)`; jit it.

  Args:
    networks: `HierarchyNetworks` or `PolicyValueNetworks` (their `unroll`,
      sizes and `distribution`).
    config: `PPOConfig` or `HierarchyConfig`.
    optimizer: `step_size.make_optimizer(config)`.

  `batch` is a `types.SequenceBatch` of T steps of B rows (B divisible by
  `config.num_minibatches`). Metrics are means over all SGD steps (see
  `agents.ppo.losses.ppo_loss`), plus 'learning_rate' (mean rate of the
  steps) and 'explained_variance' of the values that made the targets.
  """
  preprocess = normalization.make_preprocess_fn(
      config.normalize_observations, config.observation_clip)
  uses_global_state = networks.global_state_size is not None
  loss_options = dict(
      clip_epsilon=config.clip_epsilon, clip_value_loss=config.clip_value_loss,
      entropy_cost=config.entropy_cost, value_cost=config.value_cost,
      normalize_advantages=config.normalize_advantages)

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
    steps = types.TrainingBatch(
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
                           networks.distribution, key, **loss_options)

  sgd_step = make_sgd_step(loss_fn, optimizer, config.target_kl)

  def epoch(carry, key, batch: types.SequenceTrainingBatch):
    permutation_key, loss_key = jax.random.split(key)
    permutation = jax.random.permutation(
        permutation_key, batch.initial_carry.shape[0])
    m = config.num_minibatches

    def split(x, axis):  # Shuffle B, then [.., B, ..] -> [M, .., B / M, ..].
      x = jnp.take(x, permutation, axis=axis)
      x = x.reshape(*x.shape[:axis], m, x.shape[axis] // m,
                    *x.shape[axis + 1:])
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
    batch = _with_empty_memory(batch)
    # Statistics first, as in Brax: the SGD then fits the parameters to the
    # statistics that the next rollout's actor will use. The behaviour
    # log-probabilities were computed with the old statistics, and the
    # probability ratio accounts for the difference. The bootstrap row is
    # the next batch's first row, so it is counted once, there.
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
                         value_normalizer, state.update + 1, key), metrics

  return update


class PPOLearner(core.Learner):
  """Trains one policy (one species); publishes params and statistics.

  `save()` returns an `agents.checkpointing` saved state of kind
  `checkpoint_kind` ('ppo'; the hierarchy's learner names its variant).
  `_upgrade` converts the `older_formats` of that kind.
  """

  checkpoint_kind = _CHECKPOINT_KIND
  older_formats = (1,)

  def __init__(self,
               networks,
               config,
               batches: Optional[Iterator[types.SequenceBatch]] = None,
               key: Optional[jax.Array] = None):
    """Args:
      networks: the networks to train (`HierarchyNetworks` or
        `PolicyValueNetworks`).
      config: hyper-parameters (`HierarchyConfig` or `PPOConfig`).
      batches: where `step()` takes data from when it is given none.
      key: PRNG key; defaults to `PRNGKey(config.seed)`.
    """
    self._optimizer = step_size.make_optimizer(config)
    if key is None:
      key = jax.random.PRNGKey(config.seed)
    self._state = make_initial_state(networks, self._optimizer, key)
    self._update = jax.jit(make_update_fn(networks, config, self._optimizer))
    self._batches = batches

  @property
  def state(self) -> TrainingState:
    """The current training state (a pytree of arrays)."""
    return self._state

  def step(self,
           batch: Optional[types.SequenceBatch] = None) -> dict[str, Any]:
    """One PPO update on `batch`, or on the iterator's next one.

    Returns the update's metrics (device scalars; `float()` them to log).
    """
    if batch is None:
      if self._batches is None:
        raise ValueError(f'{type(self).__name__}.step() needs a batch: pass '
                         'one or give the learner a `batches` iterator.')
      batch = next(self._batches)
    self._state, metrics = self._update(self._state, batch)
    return metrics

  def get_variables(self, names: Sequence[str]) -> list[Any]:
    """Variables by name: 'params', 'normalizer', 'global_state_normalizer'
    or 'update'."""
    state = self._state
    variables = {'params': state.params, 'normalizer': state.normalizer,
                 'global_state_normalizer': state.global_state_normalizer,
                 'update': state.update}
    unknown = [name for name in names if name not in variables]
    if unknown:
      raise ValueError(f'Unknown variable names {unknown}; expected some of '
                       f'{sorted(variables)}.')
    return [variables[name] for name in names]

  def save(self) -> dict[str, Any]:
    """The full training state (params, optimiser, statistics, update
    counter, PRNG key) as a saved state of host arrays."""
    return checkpointing.saved_state(self._state, self.checkpoint_kind,
                                     CHECKPOINT_FORMAT)

  def _upgrade(self, file_format: int,
               state_dict: dict[str, Any]) -> dict[str, Any]:
    """A state dict of one of the `older_formats` in today's layout (the
    counter may keep its old name, `step`)."""
    del file_format  # Format 1, the feed-forward learner's first layout.
    # It had no value or global-state statistics: they start as identities.
    return {**checkpointing.to_state_dict(self._state), **state_dict}

  def _state_dict(self, saved: dict[str, Any], source: str
                  ) -> dict[str, Any]:
    """The state dict of a saved state, in today's layout."""
    file_format, state_dict = checkpointing.unpack(
        saved, self.checkpoint_kind, source)
    if file_format != CHECKPOINT_FORMAT:
      if file_format not in self.older_formats:
        raise ValueError(
            f'{source} is a {self.checkpoint_kind} checkpoint of format '
            f'{file_format}; this version reads formats '
            f'{[*self.older_formats, CHECKPOINT_FORMAT]}.')
      state_dict = self._upgrade(file_format, state_dict)
      if 'step' in state_dict:
        state_dict = {**state_dict, 'update': state_dict['step']}
        del state_dict['step']
    return state_dict

  def restore(self, saved: dict[str, Any], source: str = 'checkpoint'
              ) -> None:
    """Continues from a state returned by `save` with the same networks and
    config (or an older format that `_upgrade` reads); errors name
    `source`."""
    self._state = checkpointing.from_state_dict(
        source, self._state, self._state_dict(saved, source))

  def initialize_from(self, saved: dict[str, Any],
                      source: str = 'checkpoint') -> None:
    """Starts from another run's saved state (e.g. a curriculum stage): its
    parameters and its observation and value statistics, with this
    learner's fresh optimiser, update counter and PRNG key.

    Raises:
      ValueError: the state is of another kind (variant), or its networks
        differ from this learner's (naming `source`).
    """
    state_dict = self._state_dict(saved, source)
    template = {name: getattr(self._state, name) for name in HANDED_ON}
    loaded = checkpointing.from_state_dict(
        source, template, {name: state_dict[name] for name in HANDED_ON})
    self._state = self._state._replace(**loaded)
