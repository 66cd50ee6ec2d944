"""Step-size control for PPO: Adam whose learning rate follows the KL.

The clipped objective bounds the policy's step only loosely: a constant
learning rate moved the hierarchy's policy by KL 0.06-0.17 per iteration
late in the first transport run and it collapsed (docs/training.md). As in
the paper's rl_games (`schedule: adaptive`, `kl_threshold: 0.008`), the
learning rate is divided by 1.5 after a minibatch whose approximate KL to
the behaviour policy exceeds twice the target and multiplied by 1.5 after
one below half of it, within [`MIN_LEARNING_RATE`, `MAX_LEARNING_RATE`].

The rate lives in the optimiser state (`optax.inject_hyperparams`), so it
goes into checkpoints with the Adam moments and a resumed run continues at
the rate it had. With `target_kl = 0` the optimiser is plain Adam at a
constant rate (the lower layer's Brax settings).
"""
import jax
import jax.numpy as jnp
import optax

MIN_LEARNING_RATE = 1e-6  # rl_games' bounds.
MAX_LEARNING_RATE = 1e-2
_FACTOR = 1.5


def make_optimizer(config) -> optax.GradientTransformation:
  """Adam after global-norm gradient clipping.

  `config` is a PPO-style config (`learning_rate`, `adam_epsilon`,
  `max_grad_norm`, optional `target_kl`); with `target_kl > 0` the learning
  rate is a state that `adapt` changes.
  """
  if getattr(config, 'target_kl', 0.0) > 0:
    adam = optax.inject_hyperparams(optax.adam)(
        learning_rate=config.learning_rate, eps=config.adam_epsilon)
  else:
    adam = optax.adam(config.learning_rate, eps=config.adam_epsilon)
  return optax.chain(optax.clip_by_global_norm(config.max_grad_norm), adam)


def adapted_learning_rate(learning_rate: jax.Array, kl: jax.Array,
                          target_kl: float) -> jax.Array:
  """The next learning rate (scalar) after a step whose KL was `kl`.

  Down by 1.5 above 2 x target, up by 1.5 below target / 2, unchanged in
  between (the dead band keeps it from oscillating), then clipped to
  [MIN_LEARNING_RATE, MAX_LEARNING_RATE].
  """
  learning_rate = jnp.where(kl > 2.0 * target_kl, learning_rate / _FACTOR,
                            learning_rate)
  learning_rate = jnp.where(kl < 0.5 * target_kl, learning_rate * _FACTOR,
                            learning_rate)
  return jnp.clip(learning_rate, MIN_LEARNING_RATE, MAX_LEARNING_RATE)


def learning_rate(opt_state: optax.OptState) -> jax.Array:
  """The current learning rate of a `make_optimizer(config)` state whose
  config has `target_kl > 0`."""
  return opt_state[1].hyperparams['learning_rate']


def adapt(opt_state: optax.OptState, kl: jax.Array,
          target_kl: float) -> optax.OptState:
  """`opt_state` with its learning rate adapted to `kl` (see
  `adapted_learning_rate`); for `make_optimizer` with `target_kl > 0`."""
  adam_state = opt_state[1]
  rate = adapted_learning_rate(learning_rate(opt_state), kl, target_kl)
  hyperparams = {**adam_state.hyperparams,
                 'learning_rate': rate.astype(jnp.float32)}
  return (opt_state[0], adam_state._replace(hyperparams=hyperparams),
          *opt_state[2:])
