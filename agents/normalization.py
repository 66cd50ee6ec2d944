"""Running mean / variance of observations, for input normalisation (and of
value targets, for value normalisation: `agents.ppo.returns`).

Observations of a walker mix metres, radians and m/s, so networks train much
better on standardised inputs. The statistics are a NamedTuple with pure
functions (jit-friendly, as in Brax's `running_statistics`), merged batch by
batch with Chan et al.'s parallel form of Welford's algorithm: exact for any
batch sizes and stable for long runs because it never subtracts two large sums.

Statistics belong to the weights: a policy is only meaningful together with the
normaliser it was trained with, so `to_dict` / `from_dict` turn them into numpy
arrays that `np.savez` stores next to the parameters.
"""
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# Keeps constant features (variance 0) from being divided by zero.
_EPSILON = 1e-8


class NormalizerState(NamedTuple):
  """Statistics of everything seen so far.

  Attributes:
    count: number of observations merged, scalar float32. float32 counts stay
      exact up to 2**24 and only lose relative precision ~1e-7 beyond, which
      is harmless for a weight.
    mean: [dim] running mean.
    var: [dim] running (population) variance; 1 before any data, so that
      normalising with fresh statistics is the identity.
  """
  count: jax.Array
  mean: jax.Array
  var: jax.Array


def init(dim: int) -> NormalizerState:
  """Statistics for `dim`-dimensional observations with no data yet."""
  return NormalizerState(
      count=jnp.zeros((), jnp.float32),
      mean=jnp.zeros((dim,), jnp.float32),
      var=jnp.ones((dim,), jnp.float32))


def update(state: NormalizerState, batch: jax.Array) -> NormalizerState:
  """Merges a batch of observations into the statistics.

  Args:
    state: current statistics.
    batch: [..., dim] observations; all leading axes (e.g. [T, B]) are samples.

  Returns:
    Statistics over the old samples and the batch together.
  """
  batch = jnp.reshape(batch, (-1, state.mean.shape[-1])).astype(jnp.float32)
  batch_count = jnp.asarray(batch.shape[0], jnp.float32)
  batch_mean = jnp.mean(batch, axis=0)
  batch_var = jnp.var(batch, axis=0)

  count = state.count + batch_count
  delta = batch_mean - state.mean
  mean = state.mean + delta * batch_count / count
  # Sum of squared deviations of the union (Chan et al. 1979); the old `var`
  # is weighted by its count, so the initial var = 1 contributes nothing.
  m2 = (state.var * state.count + batch_var * batch_count
        + jnp.square(delta) * state.count * batch_count / count)
  return NormalizerState(count=count, mean=mean, var=m2 / count)


def normalize(state: NormalizerState, x: jax.Array,
              clip: float = 5.0) -> jax.Array:
  """Standardises `x` [..., dim] and clips it to [-clip, clip].

  Clipping bounds the inputs the network sees when a rare state lies many
  standard deviations out (e.g. an ant flipping over).
  """
  normalized = (x - state.mean) / jnp.sqrt(state.var + _EPSILON)
  return jnp.clip(normalized, -clip, clip)


def denormalize(state: NormalizerState, x: jax.Array) -> jax.Array:
  """The inverse of an unclipped `normalize`: x * std + mean, [..., dim].

  Value normalisation (`agents.ppo.returns`) reads a critic that predicts
  standardised returns back in return units with it.
  """
  return x * jnp.sqrt(state.var + _EPSILON) + state.mean


def make_preprocess_fn(
    enabled: bool, clip: float = 5.0
) -> Callable[[NormalizerState, jax.Array], jax.Array]:
  """The observation preprocessing shared by an agent's actor and learner.

  Returns `normalize` when `enabled`, else a function that passes observations
  through untouched (in particular unclipped).
  """
  if enabled:
    return lambda state, x: normalize(state, x, clip)
  return lambda state, x: x


def to_dict(state: NormalizerState,
            prefix: str = '') -> dict[str, np.ndarray]:
  """Statistics as numpy arrays, e.g. for `np.savez(path, **to_dict(s))`.

  `prefix` (e.g. `'normalizer/'`) lets the statistics share one `.npz` file
  with the network weights.
  """
  return {prefix + name: np.asarray(value)
          for name, value in state._asdict().items()}


def from_dict(arrays, prefix: str = '') -> NormalizerState:
  """Inverse of `to_dict`; accepts a dict or an opened `.npz` file."""
  return NormalizerState(**{
      name: jnp.asarray(arrays[prefix + name], jnp.float32)
      for name in NormalizerState._fields})
