"""Feed-forward policy and value networks as a dataclass of pure functions.

Acme / Brax style: the networks object holds no parameters. `init(key)` creates
them and every other field is a pure function of `(params, inputs)`, so the
learner can `jax.jit` and `jax.grad` through them and an actor can run them
with any update's parameters it pulled.

Observations arrive already normalised (see `agents.normalization`); shapes
are [..., obs_dim] with any leading axes ([B], [T, B], ...).

`unroll` gives these networks the interface of the recurrent ones
(`agents.hierarchy.networks`) with an empty carry, so one PPO learner
(`agents.ppo.learning`) trains both: a feed-forward network is a recurrent
one without memory.
"""
import dataclasses
from typing import Any, Callable, Optional, Sequence

import jax
import jax.numpy as jnp

from agents.networks import distributions
from agents.networks import mlp

Params = Any  # A pytree: {'policy': ..., 'value': ...} of Flax variables.


@dataclasses.dataclass(frozen=True)
class PolicyValueNetworks:
  """Actor-critic networks for PPO.

  Attributes:
    init: key -> params.
    apply_policy: (params, obs [..., obs_dim]) -> dist_params [..., 2A].
    apply_value: (params, obs [..., obs_dim]) -> value [...].
    unroll: (params, carry [B, 0], observation [T, B, obs_dim], reset, global
      state) -> (carry, dist_params [T, B, 2A], value [T, B]); reset and
      global state are ignored (`agents.hierarchy.networks` has the same
      signature).
    distribution: how to read `dist_params` (sample, log_prob, entropy).
    observation_size: obs_dim the networks expect.
    action_size: A.
    carry_size: 0, no memory.
    global_state_size: None, no global state.
  """
  init: Callable[[jax.Array], Params]
  apply_policy: Callable[[Params, jax.Array], jax.Array]
  apply_value: Callable[[Params, jax.Array], jax.Array]
  unroll: Callable[..., tuple[jax.Array, jax.Array, jax.Array]]
  distribution: distributions.NormalTanhDistribution
  observation_size: int
  action_size: int
  carry_size: int = 0
  global_state_size: Optional[int] = None


def make_policy_value_networks(
    obs_dim: int,
    action_dim: int,
    policy_hidden: Sequence[int] = (256, 256),
    value_hidden: Sequence[int] = (256, 256),
    activation: str = 'swish',
) -> PolicyValueNetworks:
  """Separate policy and value MLPs (no shared torso, as in Brax PPO).

  Separate torsos keep the value loss's large gradients away from the policy
  features; the policy head starts with small weights so that the initial
  policy is close to N(0, softplus(0)) in raw-action space, whatever the input.
  """
  distribution = distributions.NormalTanhDistribution(action_dim)
  policy_module = mlp.MLP(
      layer_sizes=(*policy_hidden, distribution.param_size),
      activation=activation, final_kernel_scale=0.01)
  value_module = mlp.MLP(layer_sizes=(*value_hidden, 1), activation=activation)
  dummy_obs = jnp.zeros((1, obs_dim), jnp.float32)

  def init(key: jax.Array) -> Params:
    policy_key, value_key = jax.random.split(key)
    return {'policy': policy_module.init(policy_key, dummy_obs),
            'value': value_module.init(value_key, dummy_obs)}

  def apply_policy(params: Params, obs: jax.Array) -> jax.Array:
    return policy_module.apply(params['policy'], obs)

  def apply_value(params: Params, obs: jax.Array) -> jax.Array:
    return jnp.squeeze(value_module.apply(params['value'], obs), axis=-1)

  def unroll(params, carry, observation, reset=None, global_state=None):
    del reset, global_state  # No memory, no global state.
    return (carry, apply_policy(params, observation),
            apply_value(params, observation))

  return PolicyValueNetworks(
      init=init, apply_policy=apply_policy, apply_value=apply_value,
      unroll=unroll, distribution=distribution, observation_size=obs_dim,
      action_size=action_dim)

