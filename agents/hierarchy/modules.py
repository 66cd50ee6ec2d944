"""Flax modules of the hierarchy: upper layer, middle layer and heads.

Everything is time-major: inputs [T, B, ...] and a carry [B, H]. An actor
steps with T = 1; the learner replays whole sequences with T > 1. Because
both run this one module, acting and learning see the same function.
"""
import functools
import math
from typing import Optional

import flax.linen as nn
import jax
import jax.numpy as jnp

from agents.hierarchy import config as hierarchy_config
from agents.networks import mlp

# A small last layer starts the policy close to its prior, whatever the input
# (as `agents.networks.policy_value` does for the lower layer).
_POLICY_HEAD_SCALE = 0.01


def _raw_scale_init(config: hierarchy_config.HierarchyConfig):
  """Initialiser of the state-independent pre-softplus scale: zeros, or the
  inverse softplus of `initial_action_std - min_action_std`."""
  if not config.initial_action_std:
    return nn.initializers.zeros
  excess = config.initial_action_std - config.min_action_std
  return nn.initializers.constant(math.log(math.expm1(excess)))


class ResettingGRUCell(nn.Module):
  """One GRU step that first resets the carry of rows starting an episode.

  Scanned over time by `MiddleLayer`. The initial carry is zeros (PureJaxRL);
  a reset replaces the carried state by it, so a new episode never sees the
  previous one's memory.
  """
  hidden_size: int

  @nn.compact
  def __call__(self, carry: jax.Array, inputs: tuple[jax.Array, jax.Array]):
    """(carry [B, H], (features [B, F], reset [B])) -> (carry, out [B, H])."""
    features, reset = inputs
    carry = jnp.where(reset[:, None], jnp.zeros_like(carry), carry)
    return nn.GRUCell(features=self.hidden_size, name='gru')(carry, features)


# The scanned cell is a Module class of its own: made once, here, and not
# while tracing. Flax builds a lifted class by editing its bases'
# `__dataclass_fields__` in place, which is not thread-safe, and the
# species' learners trace at the same time in threads
# (`runners.learner_loop.step_learners`).
_ScannedGRUCell = nn.scan(ResettingGRUCell, variable_broadcast='params',
                          split_rngs={'params': False}, in_axes=0, out_axes=0)


class MiddleLayer(nn.Module):
  """The ML: a GRU scanned over the T commands of a sequence.

  `recurrent=False` (`HierarchyConfig.recurrent`, 'no_memory') replaces the
  GRU by one Dense layer of the same width and passes the carry through untouched, so the interface (and
  the learner's code path) stays the same.
  """
  hidden_size: int
  recurrent: bool = True
  activation: str = 'swish'

  @nn.compact
  def __call__(self, carry, features, reset):
    """(carry [B, H], features [T, B, F], reset [T, B]) -> (carry, [T, B, H]).

    The carry returned is the one after the last step.
    """
    if not self.recurrent:
      out = mlp.MLP((self.hidden_size,), self.activation, activate_final=True,
                    name='mlp')(features)
      return carry, out
    return _ScannedGRUCell(self.hidden_size, name='scan')(
        carry, (features, reset))


class HierarchyPolicyValue(nn.Module):
  """Policy (command) and value of one species, all variants in one module.

  'hrl' / 'no_memory' / 'mappo': observation (exteroception) -> UL MLP ->
  ML -> command head. The critic (`critic`, see `HierarchyConfig.critic`)
  reads, by the value head, either features of an UL and ML of its own
  ('separate'; its ML state is the second half of the carry), the policy's
  ML features through a stop-gradient ('stop_gradient') or the policy's ML
  features ('shared'). 'mappo' adds features of the global state to the
  critic's. 'flat': observation (proprio + extero; 'lowlevel': proprio +
  command) -> policy MLP and a separate value MLP (Brax's layout for the
  lower layer); the carry passes through.

  The policy's parameter names are those of every earlier layout, so older
  checkpoints' policies load into any critic structure.
  """
  config: hierarchy_config.HierarchyConfig
  action_size: int

  @nn.compact
  def __call__(self, carry, observation, reset,
               global_state: Optional[jax.Array] = None):
    """Unrolls T commands.

    Args:
      carry: [B, C] ML state before step 0 (before reset[0] applies); C = H,
        or 2H with a separate critic (the policy's, then the critic's).
      observation: [T, B, D] normalised observations.
      reset: [T, B] bool, true where observation[t] starts an episode.
      global_state: [T, B, S] normalised global state ('mappo' only).

    Returns:
      (carry [B, C] after step T - 1, dist_params [T, B, 2A], value [T, B]).
    """
    config = self.config
    head_outputs = (2 * self.action_size if config.state_dependent_std
                    else self.action_size)
    mlp_ = functools.partial(mlp.MLP, activation=config.activation)

    def trunk(prefix, carry):  # UL + ML -> (carry, features [T, B, H]).
      features = mlp_(config.upper_layer_sizes, activate_final=True,
                      name=f'{prefix}upper_layer')(observation)
      return MiddleLayer(
          config.middle_layer_size, recurrent=config.recurrent,
          activation=config.activation, name=f'{prefix}middle_layer')(
              carry, features, reset)

    if not config.uses_commands:
      policy_out = mlp_((*config.flat_sizes, head_outputs),
                        final_kernel_scale=_POLICY_HEAD_SCALE,
                        name='policy')(observation)
      value = mlp_((*config.flat_sizes, 1), name='value')(observation)
    else:
      size = config.middle_layer_size
      policy_carry, features = trunk('', carry[:, :size])
      policy_out = mlp_((*config.head_sizes, head_outputs),
                        final_kernel_scale=_POLICY_HEAD_SCALE,
                        name='command_head')(features)
      if config.critic == 'separate':
        critic_carry, critic_features = trunk('critic_', carry[:, size:])
        carry = jnp.concatenate([policy_carry, critic_carry], -1)
      else:
        carry = policy_carry
        critic_features = (jax.lax.stop_gradient(features)
                           if config.critic == 'stop_gradient' else features)
      if config.uses_global_state:
        if global_state is None:
          raise ValueError("agent='mappo' needs a global_state input.")
        critic_features = jnp.concatenate([critic_features, mlp_(
            config.critic_sizes, activate_final=True,
            name='global_state_encoder')(global_state)], -1)
      value = mlp_((*config.head_sizes, 1), name='value_head')(critic_features)
    if config.state_dependent_std:
      dist_params = policy_out
    else:
      # Pre-softplus scale, learned but shared by all states (see config).
      raw_scale = self.param('raw_scale', _raw_scale_init(config),
                             (self.action_size,))
      dist_params = jnp.concatenate(
          [policy_out, jnp.broadcast_to(raw_scale, policy_out.shape)], -1)
    return carry, dist_params, jnp.squeeze(value, -1)
