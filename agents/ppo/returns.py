"""Value targets of a PPO iteration: truncation, GAE and value normalisation.

Shared by every PPO learner (`agents.ppo.learning`, `agents.hierarchy`), so a
rollout's rewards become advantages and value targets in one place.

Value normalisation is MAPPO's ValueNorm (Yu et al. 2022; rl_games'
`normalize_value`): the critic predicts returns standardised by running
statistics of all value targets seen so far. The paper's returns are
~100-200 even after reward scaling, so an unnormalised critic's squared error
is ~1e4 times the policy loss and its gradient dominates every clipped
update; standardised, both losses are O(1) whatever the task's reward scale.
GAE runs in return units: the critic's outputs are de-normalised with the
statistics *before* this iteration's targets are merged in (those the critic
was trained against), the targets are then merged, and the loss regresses
the critic onto the targets standardised with the new statistics.
"""
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from agents import normalization
from agents.ppo import losses


class Targets(NamedTuple):
  """What the loss needs from a rollout's values, rewards and discounts.

  Attributes:
    advantage: [T, B] GAE advantages, in (scaled) return units.
    target_value: [T, B] value targets in the critic's units (standardised
      when value normalisation is on).
    behaviour_value: [T, B] the rollout's values in the critic's units (for
      value clipping).
    value_normalizer: return statistics after this rollout (None when value
      normalisation is off).
    explained_variance: scalar, 1 - Var[target - value] / Var[target] in
      return units: 1 is a perfect critic, 0 one that predicts the mean, < 0
      one that is worse than the mean.
  """
  advantage: jax.Array
  target_value: jax.Array
  behaviour_value: jax.Array
  value_normalizer: Optional[normalization.NormalizerState]
  explained_variance: jax.Array


def compute_targets(
    values: jax.Array,
    rewards: jax.Array,
    discounts: jax.Array,
    truncation: Optional[jax.Array],
    value_normalizer: Optional[normalization.NormalizerState],
    gae_lambda: float,
) -> Targets:
  """Advantages and value targets of T steps of B rows.

  Args:
    values: [T + 1, B] critic outputs on observation[0..T] (the last is the
      bootstrap value); standardised if `value_normalizer` is given.
    rewards: [T, B] rewards, already scaled.
    discounts: [T, B] gamma x the environment's 0/1 discount.
    truncation: optional [T, B], 1 where the episode was cut by a time limit
      (see `types.SequenceBatch.truncation`).
    value_normalizer: [1]-dimensional return statistics, or None for a critic
      that predicts returns directly.
    gae_lambda: GAE lambda.
  """
  if value_normalizer is not None:
    values = normalization.denormalize(value_normalizer, values[..., None])
    values = values[..., 0]
  if truncation is not None:
    # The final observation of a truncated episode is gone (observation[t+1]
    # already starts the next one): bootstrap with V(observation[t]) instead
    # and cut the trace so nothing leaks across episodes. `discounts` is
    # already 0 where the episode also terminated: no bootstrap there.
    truncated = truncation.astype(rewards.dtype)
    rewards = rewards + truncated * discounts * values[:-1]
    discounts = discounts * (1.0 - truncated)
  advantages, returns = losses.compute_gae(
      rewards, values[:-1], discounts, values[-1], gae_lambda)
  explained_variance = 1.0 - jnp.var(returns - values[:-1]) / (
      jnp.var(returns) + 1e-8)
  behaviour_value = values[:-1]
  if value_normalizer is not None:
    value_normalizer = normalization.update(value_normalizer,
                                            returns[..., None])
    standardise = lambda x: normalization.normalize(
        value_normalizer, x[..., None], clip=np.inf)[..., 0]
    returns, behaviour_value = standardise(returns), standardise(
        behaviour_value)
  return Targets(advantage=advantages, target_value=returns,
                 behaviour_value=behaviour_value,
                 value_normalizer=value_normalizer,
                 explained_variance=explained_variance)
