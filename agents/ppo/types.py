"""Data that flows between PPO's actors, learner and loss.

Time-major [T, B, ...]: T steps of B rows (IPPO: all agents of one species
in all environment copies are rows of B). Step t goes from observation[t]
with raw_action[t] to observation[t + 1], earning reward[t]. A step is a
control step for the lower layer's pretraining and a command for the upper
and middle layer (its reward summed over the command's control steps, the
runner's job).
"""
from typing import NamedTuple, Optional, Sequence

import jax
import numpy as np


class SequenceBatch(NamedTuple):
  """T steps of B rows, collected with one update's parameters.

  Attributes:
    observation: [T + 1, B, D] raw (unnormalised) observations. The last row
      is the bootstrap observation; where an episode ended at step t,
      observation[t + 1] is the next episode's first.
    raw_action: [T, B, A] pre-tanh actions u (the environment saw tanh(u),
      possibly rescaled); `log_prob` is the density at u, see
      `agents.networks.distributions`.
    log_prob: [T, B] behaviour policy's log-probability of the action.
    reward: [T, B] rewards (before the config's `reward_scaling`).
    discount: [T, B] environment discount: 0 where the episode terminated
      (a true end, the future is worth nothing), 1 otherwise (also where it
      was truncated, see `truncation`); the learner multiplies it by the
      config's `discount`.
    reset: [T + 1, B], 1 where observation[t] is the first of an episode: a
      recurrent network then starts from the initial carry instead of the
      carried one. None for networks without memory (`carry_size` 0).
    initial_carry: [B, C] the network's carry *before* step 0 (before
      reset[0] is applied), stored by the actor (Acme R2D2 style), so that
      the learner replays the sequence from the state the actor had. None
      for networks without memory.
    global_state: optional [T + 1, B, S] raw global state, required by a
      critic that reads it ('mappo'), ignored otherwise.
    truncation: optional [T, B], 1 where the episode was cut (time limit)
      without terminating. The learner then bootstraps with V(observation[t])
      in place of the unavailable final observation's value and cuts the GAE
      trace there (`agents.ppo.returns`).
  """
  observation: jax.Array
  raw_action: jax.Array
  log_prob: jax.Array
  reward: jax.Array
  discount: jax.Array
  reset: Optional[jax.Array] = None
  initial_carry: Optional[jax.Array] = None
  global_state: Optional[jax.Array] = None
  truncation: Optional[jax.Array] = None


def concatenate(batches: Sequence[SequenceBatch]) -> SequenceBatch:
  """Joins batches of equal T along the row axis B (e.g. from many actors).

  [T, B_i, ...] fields are joined on axis 1 and `initial_carry` [B_i, C] on
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


class TrainingBatch(NamedTuple):
  """Per-step inputs of the PPO loss; any leading shape, [T, B] here.

  Attributes:
    observation: [..., D] normalised observations.
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


class SequenceTrainingBatch(NamedTuple):
  """What the loss replays: sequences the network is unrolled on again.

  Attributes:
    steps: per-step PPO inputs [T, B, ...]; `steps.observation` is normalised.
    reset: [T, B] episode-start flags of steps.observation.
    initial_carry: [B, C] carry before step 0.
    global_state: [T, B, S] normalised global state, or None.
  """
  steps: TrainingBatch
  reset: jax.Array
  initial_carry: jax.Array
  global_state: Optional[jax.Array] = None
