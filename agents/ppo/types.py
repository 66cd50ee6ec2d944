"""Data that flows between PPO's actor, learner and loss.

Time-major layout [T, B, ...]: T steps of B independent environments (or
agents: IPPO flattens agents into B). Transition t goes from observation[t]
with raw_action[t] to observation[t + 1], earning reward[t].
"""
from typing import NamedTuple, Optional

import jax


class Rollout(NamedTuple):
  """One on-policy segment, collected with a single parameter version.

  Attributes:
    observation: [T + 1, B, obs_dim] raw (unnormalised) observations; the last
      row is the bootstrap observation after the final step. Where an episode
      ended at step t, observation[t + 1] is the next episode's first one.
    raw_action: [T, B, A] pre-tanh actions u (the environment saw tanh(u),
      possibly rescaled); `log_prob` is the density at u, see
      `agents.networks.distributions`.
    log_prob: [T, B] behaviour policy's log-probability of the action.
    reward: [T, B] rewards (before `PPOConfig.reward_scaling`).
    discount: [T, B] environment discount: 0 where the episode terminated
      (a true end, the future is worth nothing), 1 otherwise; the learner
      multiplies it by `PPOConfig.discount`.
    truncation: optional [T, B], 1 where the episode was cut (time limit)
      without terminating. The learner then bootstraps with V(observation[t])
      in place of the unavailable final observation's value and cuts the GAE
      trace there. A runner that has the true final observation can instead
      add gamma * V(final) to the reward, set discount 0 and leave this None.
  """
  observation: jax.Array
  raw_action: jax.Array
  log_prob: jax.Array
  reward: jax.Array
  discount: jax.Array
  truncation: Optional[jax.Array] = None


class TrainingBatch(NamedTuple):
  """Per-step inputs of the PPO loss; any leading shape, [T, B] here.

  Attributes:
    observation: [..., obs_dim] normalised observations.
    raw_action: [..., A] pre-tanh actions taken.
    behaviour_log_prob: [...] log-probabilities when acting.
    behaviour_value: [...] value estimates before this update (value clipping).
    advantage: [...] GAE advantages.
    target_value: [...] value targets (advantage + behaviour_value).
  """
  observation: jax.Array
  raw_action: jax.Array
  behaviour_log_prob: jax.Array
  behaviour_value: jax.Array
  advantage: jax.Array
  target_value: jax.Array
