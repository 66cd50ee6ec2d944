"""Batched hierarchy actor: B agents of one species, one GRU state per row.

The runner calls, once per command (every k low-level steps):

    actions, extras = actor.select_action(observation [B, D], reset [B],
                                          global_state [B, S] or None)
    ...step the lower layer k times, sum the rewards...
    actor.observe(actions, next_timestep, next_global_state)

and every `HierarchyConfig.sequence_length` commands hands
`actor.take_rollout()` (a `SequenceBatch`) to the learner. `reset` is true
where `observation` is the first of an episode: the row's carry is replaced
by the initial one before acting. Timesteps are dm_env-style at the command
rate with a leading batch axis and auto-reset: where `step_type` is LAST,
`observation` already starts the next episode (`reset_from_step_type` turns
step types into resets).

The actor records what it acted on (observations, resets, global states,
the carry before the segment's first command), so the learner replays
exactly the actor's function. PPO is on-policy: parameters pulled by
`update()` mid-segment take effect from the next segment.
"""
from typing import Any, Optional

import jax
import jax.numpy as jnp
import numpy as np

from agents import core
from agents import normalization
from agents.hierarchy import config as hierarchy_config
from agents.hierarchy import networks as hierarchy_networks
from agents.ppo import types
from agents.networks import distributions

_MID, _LAST = 1, 2  # dm_env.StepType values; no dm_env import for two ints.
_ROW_FIELDS = ('observation', 'reset', 'global_state')
_STEP_FIELDS = ('raw_action', 'log_prob', 'reward', 'discount', 'truncation')


def reset_from_step_type(step_type) -> np.ndarray:
  """[B] bool, true where a (auto-reset) timestep's observation starts an
  episode: FIRST, or LAST (its observation is the next episode's first)."""
  return np.asarray(step_type) != _MID


class HierarchyActor(core.Actor):
  """Acts for B agents with the latest published parameters."""

  def __init__(self,
               networks: hierarchy_networks.HierarchyNetworks,
               config: hierarchy_config.HierarchyConfig,
               variable_source: core.VariableSource,
               key: jax.Array,
               action_bounds: Optional[tuple[Any, Any]] = None,
               deterministic: bool = False):
    """Args:
      networks: the networks (same as the learner's).
      config: used for its observation preprocessing settings.
      variable_source: publishes 'params', 'normalizer' and
        'global_state_normalizer' (the learner, or a Ray handle to it).
      key: PRNG key of the action noise.
      action_bounds: (low, high) of the command spec ([A] or scalars), onto
        which tanh's [-1, 1] is mapped; None keeps [-1, 1] ('flat' joints).
      deterministic: act with the policy's mean (evaluation).
    """
    preprocess = normalization.make_preprocess_fn(
        config.normalize_observations, config.observation_clip)
    distribution = networks.distribution

    def policy(params, normalizer, gs_normalizer, carry, observation, reset,
               global_state, key):
      key, sample_key = jax.random.split(key)
      if global_state is not None:
        global_state = preprocess(gs_normalizer, global_state)
      new_carry, dist_params, value = networks.step(
          params, carry, preprocess(normalizer, observation), reset,
          global_state)
      if deterministic:
        raw_action = distribution.mode_raw(dist_params)
      else:
        raw_action = distribution.sample_raw(dist_params, sample_key)
      action = distribution.squash(raw_action)
      if action_bounds is not None:
        action = distributions.rescale(action, *action_bounds)
      extras = {'raw_action': raw_action,
                'log_prob': distribution.log_prob(dist_params, raw_action),
                'value': value, 'carry_before': carry}
      return action, extras, new_carry, key

    self._policy = jax.jit(policy)
    self._networks = networks
    self._needs_global_state = networks.global_state_size is not None
    self._source = variable_source
    self._key = key
    self._carry = None  # [B, H], made at the first select_action.
    self._variables = None  # (params, normalizer, gs_normalizer) in use.
    self._pending_variables = None  # Pulled mid-segment, used from the next.
    self._segment = None  # Recorded lists, see observe_first.
    self._bootstrap = None  # Row after the last observed command.
    self.update(wait=True)

  @property
  def carry(self) -> Optional[np.ndarray]:
    """[B, H] middle-layer state before the next command (None before the
    first `select_action`)."""
    return None if self._carry is None else np.asarray(self._carry)

  @carry.setter
  def carry(self, value) -> None:
    self._carry = jnp.asarray(value, jnp.float32)

  @property
  def recorded_steps(self) -> int:
    """Commands observed since the segment started (0 when not recording)."""
    return 0 if self._segment is None else len(self._segment['reward'])

  def select_action(self, observation, reset, global_state=None):
    """Samples commands for B agents and advances their carries.

    Args:
      observation: [B, D] raw observations (normalised here).
      reset: [B] bool, true where `observation` starts an episode.
      global_state: [B, S] raw global state; required by 'mappo'.

    Returns:
      (actions [B, A] numpy, rescaled to `action_bounds`; extras of numpy
      arrays: 'raw_action' [B, A], 'log_prob' [B], 'value' [B],
      'carry_before' [B, H], the carry before `reset` was applied).
    """
    observation = np.asarray(observation, np.float32)
    reset = np.asarray(reset, bool)
    if self._needs_global_state and global_state is None:
      raise ValueError("agent='mappo' needs a global_state.")
    if self._needs_global_state:
      global_state = np.asarray(global_state, np.float32)
    else:
      global_state = None  # Other variants ignore it; don't record it.
    if self._carry is None:
      self._carry = self._networks.initial_carry(observation.shape[0])
    if self._carry.shape[0] != observation.shape[0]:
      raise ValueError(f'The actor carries {self._carry.shape[0]} rows, got '
                       f'{observation.shape[0]} observations.')
    segment = self._segment
    if segment is not None:
      if len(segment['observation']) > len(segment['reward']):
        raise RuntimeError('Call observe after each select_action.')
      if not segment['observation']:
        segment['initial_carry'] = np.asarray(self._carry)
    params, normalizer, gs_normalizer = self._variables
    action, extras, self._carry, self._key = self._policy(
        params, normalizer, gs_normalizer, self._carry, observation, reset,
        global_state, self._key)
    extras = {name: np.asarray(value) for name, value in extras.items()}
    if segment is not None:
      for name, value in (('observation', observation), ('reset', reset),
                          ('global_state', global_state),
                          ('raw_action', extras['raw_action']),
                          ('log_prob', extras['log_prob'])):
        segment[name].append(value)
    return np.asarray(action), extras

  def observe_first(self, timestep=None) -> None:
    """Starts recording a new segment (dropping an unfinished one).

    `timestep` is accepted for the Actor interface and unused: the segment's
    rows are what the next `select_action` receives.
    """
    del timestep
    self._start_segment()

  def observe(self, action, next_timestep, next_global_state=None) -> None:
    """Records the outcome of the last `select_action`'s commands.

    Args:
      action: unused (the raw actions were kept by `select_action`).
      next_timestep: dm_env-style, batched: reward [B] summed over the
        command, discount [B], step_type [B], observation [B, D] (auto-reset).
      next_global_state: [B, S] the global state after the command ('mappo').
    """
    del action
    segment = self._segment
    if segment is None or len(segment['observation']) != (
        len(segment['reward']) + 1):
      raise RuntimeError('Call observe_first and select_action before '
                         'observe.')
    discount = np.asarray(next_timestep.discount, np.float32)
    last = np.asarray(next_timestep.step_type) == _LAST
    segment['reward'].append(np.asarray(next_timestep.reward, np.float32))
    segment['discount'].append(discount)
    segment['truncation'].append((last & (discount > 0)).astype(np.float32))
    self._bootstrap = {
        'observation': np.asarray(next_timestep.observation, np.float32),
        'reset': reset_from_step_type(next_timestep.step_type),
        'global_state': (None if next_global_state is None else
                         np.asarray(next_global_state, np.float32))}

  def take_rollout(self) -> types.SequenceBatch:
    """The commands recorded since the segment started, as a SequenceBatch.

    Recording continues with a new segment that starts at the next
    `select_action` (from the carry the actor has then), with any variables
    pulled meanwhile.
    """
    if self.recorded_steps == 0:
      raise RuntimeError('No commands recorded since the last take_rollout.')
    segment, bootstrap = self._segment, self._bootstrap
    if self._needs_global_state and bootstrap['global_state'] is None:
      raise ValueError("agent='mappo' needs observe(..., next_global_state).")
    rows = {name: np.stack(segment[name] + [bootstrap[name]])
            for name in _ROW_FIELDS if name != 'global_state'
            or self._needs_global_state}
    steps = {name: np.stack(segment[name]) for name in _STEP_FIELDS}
    batch = types.SequenceBatch(initial_carry=segment['initial_carry'],
                                **rows, **steps)
    self._start_segment()
    return batch

  def update(self, wait: bool = False) -> None:
    """Pulls 'params' and the statistics from the variable source.

    `wait` is accepted for the Actor interface; the pull is synchronous.
    """
    del wait
    variables = tuple(self._source.get_variables(
        ['params', 'normalizer', 'global_state_normalizer']))
    if self._segment is not None and self._segment['observation']:
      self._pending_variables = variables
    else:
      self._variables = variables

  def _start_segment(self) -> None:
    if self._pending_variables is not None:
      self._variables = self._pending_variables
      self._pending_variables = None
    self._segment = {name: [] for name in (*_ROW_FIELDS, *_STEP_FIELDS)}
    self._bootstrap = None
