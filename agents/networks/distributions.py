"""Tanh-squashed diagonal Gaussian policy distribution (as in Brax and SAC).

A network outputs `dist_params` [..., 2A]: A means and A pre-softplus scales.
The policy samples a *raw* action u ~ N(loc, scale) and acts with
a = tanh(u) in [-1, 1] (then optionally rescaled to an environment's bounds).

Agents store the raw u, not a: log-probabilities are evaluated at u, with the
change-of-variables term log|da/du| = log(1 - tanh(u)^2) subtracted, which
stays finite where atanh(a) would overflow for |a| -> 1.

All methods are pure functions of arrays, so feed-forward and recurrent
networks (and the PPO loss) share this one object; it is a frozen dataclass,
hence hashable and safe to close over in `jax.jit`.
"""
import dataclasses
import math

import jax
import jax.numpy as jnp


def _log_det_jacobian(raw_action: jax.Array) -> jax.Array:
  """Elementwise log|d tanh(u)/du| = log(1 - tanh(u)^2), stable form.

  Uses 1 - tanh(u)^2 = 4 / (e^u + e^-u)^2, i.e. 2 * (log 2 - u - softplus(-2u)).
  """
  return 2.0 * (math.log(2.0) - raw_action - jax.nn.softplus(-2.0 * raw_action))


@dataclasses.dataclass(frozen=True)
class NormalTanhDistribution:
  """Diagonal Gaussian over raw actions, squashed by tanh.

  Attributes:
    action_size: A, number of action dimensions.
    min_std: floor on the standard deviation, so the policy never collapses
      to a point where log-probabilities blow up.
  """
  action_size: int
  min_std: float = 1e-3

  @property
  def param_size(self) -> int:
    """Width of the network output that parameterises the distribution."""
    return 2 * self.action_size

  def loc_and_scale(self,
                    dist_params: jax.Array) -> tuple[jax.Array, jax.Array]:
    """[..., 2A] network output -> (loc [..., A], scale [..., A] > 0)."""
    loc, raw_scale = jnp.split(dist_params, 2, axis=-1)
    return loc, jax.nn.softplus(raw_scale) + self.min_std

  def sample_raw(self, dist_params: jax.Array, key: jax.Array) -> jax.Array:
    """Raw (pre-tanh) action u [..., A]; reparameterised."""
    loc, scale = self.loc_and_scale(dist_params)
    return loc + scale * jax.random.normal(key, loc.shape, loc.dtype)

  def mode_raw(self, dist_params: jax.Array) -> jax.Array:
    """The Gaussian's mean as a raw action [..., A] (deterministic policy)."""
    return self.loc_and_scale(dist_params)[0]

  @staticmethod
  def squash(raw_action: jax.Array) -> jax.Array:
    """Raw action u -> environment action tanh(u) in [-1, 1]."""
    return jnp.tanh(raw_action)

  def log_prob(self, dist_params: jax.Array,
               raw_action: jax.Array) -> jax.Array:
    """log density [...] of the squashed action tanh(u), evaluated at raw u.

    log p(a) = sum_i [log N(u_i; loc_i, scale_i) - log(1 - tanh(u_i)^2)].
    """
    loc, scale = self.loc_and_scale(dist_params)
    z = (raw_action - loc) / scale
    gaussian = (-0.5 * jnp.square(z) - jnp.log(scale)
                - 0.5 * math.log(2 * math.pi))
    return jnp.sum(gaussian - _log_det_jacobian(raw_action), axis=-1)

  def entropy(self, dist_params: jax.Array, key: jax.Array) -> jax.Array:
    """One-sample estimate [...] of the squashed action's entropy.

    H(tanh(U)) = H(U) + E[log(1 - tanh(U)^2)]; the Gaussian part is exact, the
    expectation is estimated with one reparameterised sample (as in Brax).
    """
    _, scale = self.loc_and_scale(dist_params)
    gaussian = 0.5 + 0.5 * math.log(2 * math.pi) + jnp.log(scale)
    raw = self.sample_raw(dist_params, key)
    return jnp.sum(gaussian + _log_det_jacobian(raw), axis=-1)


def rescale(action: jax.Array, low, high) -> jax.Array:
  """Maps actions in [-1, 1] affinely onto a Box spec's [low, high].

  Log-probabilities stay those of the [-1, 1] action: the affine map only adds
  a constant, which cancels in PPO's probability ratios.
  """
  low = jnp.asarray(low, action.dtype)
  high = jnp.asarray(high, action.dtype)
  return low + 0.5 * (action + 1.0) * (high - low)
