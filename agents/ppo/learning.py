"""PPO learner: a NamedTuple training state and one jit-compiled update.

`make_update_fn` returns the pure `update(state, rollout) -> (state, metrics)`
(the whole PPO iteration: statistics, GAE, epochs x minibatches of SGD);
`PPOLearner` wraps it with Acme's Learner interface and checkpoint files.

Minibatches are drawn by permuting the batch axis B and keeping time whole
(PureJaxRL's recurrent layout), so a recurrent learner can reuse this scheme
with sequences that start from stored hidden states.
"""
from typing import Any, Iterator, NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import optax

from agents import checkpointing
from agents import core
from agents import normalization
from agents.networks import policy_value
from agents.ppo import config as ppo_config
from agents.ppo import losses
from agents.ppo import returns
from agents.ppo import step_size
from agents.ppo import types

_CHECKPOINT_FORMAT = 1
_CHECKPOINT_KIND = 'ppo'


class TrainingState(NamedTuple):
  """Everything that changes during training (and goes into checkpoints).

  Attributes:
    params: network parameters, {'policy': ..., 'value': ...}.
    opt_state: optax state of the optimiser chain.
    normalizer: observation statistics used by the current params.
    step: number of updates done, int32 scalar.
    key: PRNG key (raw uint32 [2]) for shuffling and entropy estimates.
  """
  params: Any
  opt_state: optax.OptState
  normalizer: normalization.NormalizerState
  step: jax.Array
  key: jax.Array


def make_optimizer(
    config: ppo_config.PPOConfig) -> optax.GradientTransformation:
  """Adam after global-norm gradient clipping (`step_size.make_optimizer`)."""
  return step_size.make_optimizer(config)


def loss_options(config) -> dict:
  """The keyword options of `losses.ppo_loss` taken from a PPO-style config
  (shared by this learner and `agents.hierarchy`)."""
  return dict(clip_epsilon=config.clip_epsilon,
              clip_value_loss=config.clip_value_loss,
              entropy_cost=config.entropy_cost, value_cost=config.value_cost,
              normalize_advantages=config.normalize_advantages)


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


def make_initial_state(networks: policy_value.PolicyValueNetworks,
                       optimizer: optax.GradientTransformation,
                       key: jax.Array) -> TrainingState:
  """Fresh parameters, optimiser state and empty observation statistics."""
  init_key, key = jax.random.split(key)
  params = networks.init(init_key)
  return TrainingState(
      params=params,
      opt_state=optimizer.init(params),
      normalizer=normalization.init(networks.observation_size),
      step=jnp.zeros((), jnp.int32),
      key=key)


def make_update_fn(networks: policy_value.PolicyValueNetworks,
                   config: ppo_config.PPOConfig,
                   optimizer: optax.GradientTransformation):
  """Builds the pure `update(state, rollout) -> (state, metrics)`; jit it.

  The rollout is a `types.Rollout` with T steps of B environments; B must be
  divisible by `config.num_minibatches`. Metrics are means over all SGD steps.
  """
  preprocess = normalization.make_preprocess_fn(
      config.normalize_observations, config.observation_clip)

  def make_training_batch(params, normalizer, rollout) -> types.TrainingBatch:
    observation = preprocess(normalizer, rollout.observation)  # [T+1, B, D]
    values = networks.apply_value(params, observation)  # [T+1, B]
    targets = returns.compute_targets(
        values, rollout.reward * config.reward_scaling,
        config.discount * rollout.discount, rollout.truncation, None,
        config.gae_lambda)
    return types.TrainingBatch(
        observation=observation[:-1], raw_action=rollout.raw_action,
        behaviour_log_prob=rollout.log_prob,
        behaviour_value=targets.behaviour_value,
        advantage=targets.advantage, target_value=targets.target_value)

  def loss_fn(params, batch, key):
    dist_params = networks.apply_policy(params, batch.observation)
    values = networks.apply_value(params, batch.observation)
    return losses.ppo_loss(dist_params, values, batch, networks.distribution,
                           key, **loss_options(config))

  sgd_step = make_sgd_step(loss_fn, optimizer)

  def epoch(carry, key, batch):
    permutation_key, loss_key = jax.random.split(key)
    batch_size = batch.advantage.shape[1]
    permutation = jax.random.permutation(permutation_key, batch_size)

    def to_minibatches(x):  # [T, B, ...] -> [M, T, B / M, ...], shuffled on B.
      x = jnp.take(x, permutation, axis=1)
      x = x.reshape(x.shape[0], config.num_minibatches, -1, *x.shape[2:])
      return jnp.swapaxes(x, 0, 1)

    minibatches = jax.tree.map(to_minibatches, batch)
    keys = jax.random.split(loss_key, config.num_minibatches)
    return jax.lax.scan(sgd_step, carry, (minibatches, keys))

  def update(state: TrainingState, rollout: types.Rollout):
    batch_size = rollout.reward.shape[1]
    if batch_size % config.num_minibatches:
      raise ValueError(
          f'The rollout batch size B={batch_size} must be divisible by '
          f'num_minibatches={config.num_minibatches}.')
    # Statistics first, as in Brax: the SGD then fits the parameters to the
    # statistics that the next rollout's actor will use. The behaviour
    # log-probabilities were computed with the old statistics, and the
    # probability ratio accounts for the difference.
    normalizer = state.normalizer
    if config.normalize_observations:
      # The bootstrap row is the next rollout's first row: count it once.
      normalizer = normalization.update(normalizer, rollout.observation[:-1])
    key, epochs_key = jax.random.split(state.key)
    batch = make_training_batch(state.params, normalizer, rollout)
    (params, opt_state), metrics = jax.lax.scan(
        lambda carry, key: epoch(carry, key, batch),
        (state.params, state.opt_state),
        jax.random.split(epochs_key, config.num_epochs))
    metrics = jax.tree.map(jnp.mean, metrics)
    return TrainingState(params, opt_state, normalizer, state.step + 1,
                         key), metrics

  return update


class PPOLearner(core.Learner):
  """Trains PPO on rollouts; publishes `params` and `normalizer`."""

  def __init__(self,
               networks: policy_value.PolicyValueNetworks,
               config: ppo_config.PPOConfig,
               rollouts: Optional[Iterator[types.Rollout]] = None,
               key: Optional[jax.Array] = None):
    """Args:
      networks: the policy/value networks to train.
      config: hyper-parameters.
      rollouts: where `step()` takes data from when it is given none.
      key: PRNG key; defaults to `PRNGKey(config.seed)`.
    """
    optimizer = make_optimizer(config)
    if key is None:
      key = jax.random.PRNGKey(config.seed)
    self._state = make_initial_state(networks, optimizer, key)
    self._update = jax.jit(make_update_fn(networks, config, optimizer))
    self._rollouts = rollouts

  @property
  def state(self) -> TrainingState:
    """The current training state (a pytree of arrays)."""
    return self._state

  def step(self, rollout: Optional[types.Rollout] = None) -> dict[str, Any]:
    """One PPO iteration on `rollout`, or on the iterator's next one.

    Returns the update's metrics (device scalars; `float()` them to log).
    """
    if rollout is None:
      if self._rollouts is None:
        raise ValueError('PPOLearner.step() needs a rollout: pass one or '
                         'give the learner a `rollouts` iterator.')
      rollout = next(self._rollouts)
    self._state, metrics = self._update(self._state, rollout)
    return metrics

  def get_variables(self, names: Sequence[str]) -> list[Any]:
    """Variables by name: 'params', 'normalizer' or 'step'."""
    variables = {'params': self._state.params,
                 'normalizer': self._state.normalizer,
                 'step': self._state.step}
    unknown = [name for name in names if name not in variables]
    if unknown:
      raise ValueError(f'Unknown variable names {unknown}; expected some of '
                       f'{sorted(variables)}.')
    return [variables[name] for name in names]

  def save(self, path: str) -> None:
    """Writes the full training state to `path`, atomically (see
    `agents.checkpointing`)."""
    checkpointing.save_state(path, self._state, _CHECKPOINT_KIND,
                             _CHECKPOINT_FORMAT)

  def restore(self, path: str) -> None:
    """Loads a file written by `save` with the same networks and config."""
    self._state = checkpointing.restore_state(path, self._state,
                                              _CHECKPOINT_KIND,
                                              _CHECKPOINT_FORMAT)
