"""Data that flows between the hierarchy's actor, learner and loss.

Time-major [T, B, ...] at the command rate: T commands of B agents (IPPO: all
agents of one species in all environment copies are rows of B). Step t goes
from observation[t] with raw_action[t] to observation[t + 1], earning
reward[t] (the sum over the command's k low-level steps, the runner's job).
"""
from typing import NamedTuple, Optional, Sequence

import jax
import numpy as np

from agents.ppo import types as ppo_types


class SequenceBatch(NamedTuple):
  """T commands of B agents, collected with one parameter version.

  Attributes:
    observation: [T + 1, B, D] raw (unnormalised) observations: the flattened
      `extero/*` features ('flat': `proprio/*` + `extero/*`). The last row is
      the bootstrap observation; where an episode ended at step t,
      observation[t + 1] is the next episode's first.
    raw_action: [T, B, A] pre-tanh actions u (the environment saw tanh(u)
      rescaled to the command bounds); log_prob is evaluated at u.
    log_prob: [T, B] behaviour policy's log-probability of the action.
    reward: [T, B] rewards (before `HierarchyConfig.reward_scaling`).
    discount: [T, B] environment discount: 0 where the episode terminated,
      1 otherwise (also where it was truncated, see `truncation`).
    reset: [T + 1, B], 1 where observation[t] is the first of an episode: the
      GRU then starts from the initial carry instead of the carried one.
    initial_carry: [B, H] the middle layer's carry *before* step 0 (before
      reset[0] is applied), stored by the actor (Acme R2D2 style), so that
      the learner replays the sequence from the state the actor had.
    global_state: optional [T + 1, B, S] raw global state, required by
      'mappo' (its critic's input), ignored by the other variants.
    truncation: optional [T, B], 1 where the episode was cut (time limit)
      without terminating; the learner bootstraps with V(observation[t]) as
      in `agents.ppo.types.Rollout`.
  """
  observation: jax.Array
  raw_action: jax.Array
  log_prob: jax.Array
  reward: jax.Array
  discount: jax.Array
  reset: jax.Array
  initial_carry: jax.Array
  global_state: Optional[jax.Array] = None
  truncation: Optional[jax.Array] = None


def concatenate(batches: Sequence[SequenceBatch]) -> SequenceBatch:
  """Joins batches of equal T along the agent axis B (e.g. from many actors).

  [T, B_i, ...] fields are joined on axis 1 and `initial_carry` [B_i, H] on
  axis 0. Optional fields must be present in all batches or in none.
  """
  def join(name, *values):
    if all(v is None for v in values):
      return None
    if any(v is None for v in values):
      raise ValueError(f'SequenceBatch.{name} is set in some batches only.')
    return np.concatenate(values, axis=0 if name == 'initial_carry' else 1)

  return SequenceBatch(*(join(name, *values) for name, values
                         in zip(SequenceBatch._fields, zip(*batches))))


class SequenceTrainingBatch(NamedTuple):
  """What the loss replays: sequences whose GRU is unrolled again.

  Attributes:
    steps: per-step PPO inputs [T, B, ...]; `steps.observation` is normalised.
    reset: [T, B] episode-start flags of steps.observation.
    initial_carry: [B, H] carry before step 0.
    global_state: [T, B, S] normalised global state, or None.
  """
  steps: ppo_types.TrainingBatch
  reset: jax.Array
  initial_carry: jax.Array
  global_state: Optional[jax.Array] = None
