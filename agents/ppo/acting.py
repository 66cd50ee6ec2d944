"""Batched feed-forward PPO actor that records on-policy rollouts.

The actor steps B environments (or B agents, IPPO-style) at once:
`select_action(obs [B, obs_dim]) -> action [B, A]`. With `observe_first` /
`observe` it also records the segment into a `types.SequenceBatch` (without
reset and carry: the networks have no memory) that `take_rollout()` hands
to the learner.

Timesteps are dm_env-style with a leading batch axis: `observation [B, D]`,
`reward [B]`, `discount [B]`, `step_type [B]`. The runner resets finished
environments itself (auto-reset): where `step_type` is LAST, `observation` is
already the next episode's first observation, `discount` is 0 on termination
and 1 on truncation (dm_control's time-limit convention).

PPO is on-policy, so parameters pulled by `update()` in the middle of a
segment only take effect when that segment is taken: a rollout is never
collected with two parameter versions.
"""
from typing import Any, Optional

import jax
import jax.numpy as jnp
import numpy as np

from agents import core
from agents import normalization
from agents.networks import policy_value
from agents.ppo import config as ppo_config
from agents.ppo import types

_LAST = 2  # dm_env.StepType.LAST; no dm_env import needed for one constant.
_FIELDS = ('observation', 'raw_action', 'log_prob', 'reward', 'discount',
           'truncation')  # The SequenceBatch fields a memoryless actor fills.


class PPOActor(core.Actor):
  """Acts with the latest published parameters and its own PRNG stream."""

  def __init__(self,
               networks: policy_value.PolicyValueNetworks,
               config: ppo_config.PPOConfig,
               variable_source: core.VariableSource,
               key: jax.Array,
               action_bounds: Optional[tuple[Any, Any]] = None,
               deterministic: bool = False):
    """Args:
      networks: the policy/value networks (same as the learner's).
      config: used for its observation preprocessing settings.
      variable_source: publishes 'params' and 'normalizer' (the learner).
      key: PRNG key of the action noise.
      action_bounds: optional Box (low, high) actions are rescaled onto.
      deterministic: act with the policy's mean (evaluation).
    """
    inference = policy_value.make_inference_fn(networks, action_bounds)
    preprocess = normalization.make_preprocess_fn(
        config.normalize_observations, config.observation_clip)

    def policy(params, normalizer, observation, key):
      key, sample_key = jax.random.split(key)
      action, extras = inference(
          params, preprocess(normalizer, observation), sample_key,
          deterministic)
      return action, extras, key

    self._policy = jax.jit(policy)
    self._source = variable_source
    self._key = key
    self._variables = None  # (params, normalizer) used for acting.
    self._pending_variables = None  # Pulled mid-segment, used from the next.
    self._extras = None  # From the last select_action.
    self._segment = None  # Lists of per-step arrays, see observe_first.
    self.update(wait=True)

  def select_action(self, observation) -> np.ndarray:
    """Samples actions [B, A] for observations [B, obs_dim]."""
    params, normalizer = self._variables
    action, self._extras, self._key = self._policy(
        params, normalizer, jnp.asarray(observation, jnp.float32), self._key)
    return np.asarray(action)

  def observe_first(self, timestep) -> None:
    """Starts a new segment at `timestep.observation` [B, obs_dim]."""
    self._start_segment(timestep.observation)

  def observe(self, action, next_timestep) -> None:
    """Records the step taken with the last `select_action`'s actions.

    `action` is what the environment received (squashed, maybe rescaled); the
    rollout stores the raw pre-tanh action kept from `select_action` instead.
    """
    del action
    if self._segment is None or self._extras is None:
      raise RuntimeError('Call observe_first and select_action before observe.')
    discount = np.asarray(next_timestep.discount, np.float32)
    last = np.asarray(next_timestep.step_type) == _LAST
    segment = self._segment
    segment['observation'].append(
        np.asarray(next_timestep.observation, np.float32))
    segment['raw_action'].append(np.asarray(self._extras['raw_action']))
    segment['log_prob'].append(np.asarray(self._extras['log_prob']))
    segment['reward'].append(np.asarray(next_timestep.reward, np.float32))
    segment['discount'].append(discount)
    segment['truncation'].append((last & (discount > 0)).astype(np.float32))
    self._extras = None  # One observe per select_action.

  def take_rollout(self) -> types.SequenceBatch:
    """Returns the steps recorded since the last call as a SequenceBatch
    [T, B].

    The next segment continues from the last observation, with any variables
    pulled meanwhile.
    """
    if self._segment is None or not self._segment['reward']:
      raise RuntimeError('No steps recorded since the last take_rollout.')
    rollout = types.SequenceBatch(
        **{name: np.stack(rows) for name, rows in self._segment.items()})
    self._start_segment(rollout.observation[-1])
    return rollout

  def update(self, wait: bool = False) -> None:
    """Pulls 'params' and 'normalizer' from the variable source.

    `wait` is accepted for the Actor interface; the pull is synchronous.
    """
    del wait
    variables = tuple(self._source.get_variables(['params', 'normalizer']))
    if self._segment is not None and self._segment['reward']:
      self._pending_variables = variables
    else:
      self._variables = variables

  def _start_segment(self, observation) -> None:
    if self._pending_variables is not None:
      self._variables = self._pending_variables
      self._pending_variables = None
    self._segment = {name: [] for name in _FIELDS}
    self._segment['observation'].append(np.asarray(observation, np.float32))
