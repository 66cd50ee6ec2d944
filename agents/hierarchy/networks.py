"""The hierarchy's networks as a dataclass of pure functions (Acme / Brax).

The object holds no parameters: `init(key)` makes them and `unroll` / `step`
are pure functions of `(params, carry, inputs)`, so the learner can jit and
differentiate through them and an actor can run any update's parameters.
`step` *is* `unroll` on a length-1 sequence: the actor and the learner's
replay of a stored sequence compute the same function.

Inputs arrive normalised (see `agents.normalization`); the command comes out
as `dist_params` for `NormalTanhDistribution` ([-1, 1] after tanh; the actor
rescales it to the command bounds).
"""
import dataclasses
from typing import Any, Callable, Optional

import jax
import jax.numpy as jnp

from agents.hierarchy import config as hierarchy_config
from agents.hierarchy import modules
from agents.networks import distributions

Params = Any  # Flax variables {'params': ...} of `HierarchyPolicyValue`.
UnrollFn = Callable[..., tuple[jax.Array, jax.Array, jax.Array]]


@dataclasses.dataclass(frozen=True)
class HierarchyNetworks:
  """Recurrent actor-critic of one species.

  Attributes:
    init: key -> params.
    unroll: (params, carry [B, C], observation [T, B, D], reset [T, B],
      global_state [T, B, S] or None) -> (carry [B, C] after the last step,
      dist_params [T, B, 2A], value [T, B]). The carry is replaced by the
      initial one at every step whose reset is true, before that step.
    step: the same for one command: (params, carry [B, C], observation
      [B, D], reset [B], global_state [B, S] or None) -> (carry [B, C],
      dist_params [B, 2A], value [B]).
    initial_carry: batch size B -> [B, C] zeros, the carry of a fresh episode.
    distribution: reads `dist_params` (sample, log_prob, entropy).
    agent: the `HierarchyConfig.agent` variant.
    observation_size: D.
    action_size: A (2 for a command, 8 joint actions for 'flat' and
      'lowlevel').
    carry_size: C = H, or 2H with a separate critic (the policy's middle
      layer state, then the critic's); carried but unused by 'no_memory',
      'flat' and 'lowlevel'.
    global_state_size: S for 'mappo', else None (global state is ignored).
  """
  init: Callable[[jax.Array], Params]
  unroll: UnrollFn
  step: UnrollFn
  initial_carry: Callable[[int], jax.Array]
  distribution: distributions.NormalTanhDistribution
  agent: str
  observation_size: int
  action_size: int
  carry_size: int
  global_state_size: Optional[int] = None


def make_hierarchy_networks(
    config: hierarchy_config.HierarchyConfig,
    obs_dim: int,
    action_dim: int,
    global_state_dim: Optional[int] = None,
) -> HierarchyNetworks:
  """Builds the variant `config.agent` with the config's layer sizes.

  Args:
    config: agent variant and network sizes.
    obs_dim: D, width of the flattened observation ('flat': proprio +
      extero; 'lowlevel': proprio + command; otherwise extero only).
    action_dim: A, 2 for the command, the joint count for 'flat' and
      'lowlevel'.
    global_state_dim: S, required by 'mappo', ignored by the others.
  """
  if config.uses_global_state:
    if global_state_dim is None:
      raise ValueError("agent='mappo' needs global_state_dim.")
  else:
    global_state_dim = None
  module = modules.HierarchyPolicyValue(config=config, action_size=action_dim)
  carry_size = config.carry_size

  def initial_carry(batch_size: int) -> jax.Array:
    return jnp.zeros((batch_size, carry_size), jnp.float32)

  def unroll(params, carry, observation, reset, global_state=None):
    if global_state_dim is None:
      global_state = None  # Never reaches a critic that does not read it.
    return module.apply(params, carry, observation, reset.astype(bool),
                        global_state)

  def step(params, carry, observation, reset, global_state=None):
    add_time = lambda x: None if x is None else x[None]
    carry, dist_params, value = unroll(
        params, carry, observation[None], add_time(reset),
        add_time(global_state))
    return carry, dist_params[0], value[0]

  def init(key: jax.Array) -> Params:
    global_state = (None if global_state_dim is None
                    else jnp.zeros((1, 1, global_state_dim)))
    return module.init(key, initial_carry(1), jnp.zeros((1, 1, obs_dim)),
                       jnp.zeros((1, 1), bool), global_state)

  return HierarchyNetworks(
      init=init, unroll=unroll, step=step, initial_carry=initial_carry,
      distribution=distributions.NormalTanhDistribution(
          action_dim, min_std=config.min_action_std),
      agent=config.agent, observation_size=obs_dim, action_size=action_dim,
      carry_size=carry_size, global_state_size=global_state_dim)
