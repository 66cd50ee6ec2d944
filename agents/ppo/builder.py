"""Wires a PPOConfig into networks, a learner and actors (Acme's builder).

    builder = PPOBuilder(PPOConfig())
    networks = builder.make_networks(obs_dim, action_dim)
    learner = builder.make_learner(networks)
    actor = builder.make_actor(networks, learner, actor_id=0)

Keys are derived from `config.seed` here, once: the learner and every actor
get independent streams, and the same seed reproduces a run.
"""
from typing import Any, Iterator, Optional

import jax

from agents import core
from agents.networks import policy_value
from agents.ppo import acting
from agents.ppo import config as ppo_config
from agents.ppo import learning
from agents.ppo import types


class PPOBuilder:
  """Makes PPO's components from one config."""

  def __init__(self, config: ppo_config.PPOConfig):
    self.config = config
    self._learner_key, self._actors_key = jax.random.split(
        jax.random.PRNGKey(config.seed))

  def make_networks(self, obs_dim: int,
                    action_dim: int) -> policy_value.PolicyValueNetworks:
    """Policy and value MLPs with the config's sizes and activation."""
    return policy_value.make_policy_value_networks(
        obs_dim, action_dim,
        policy_hidden=self.config.policy_hidden,
        value_hidden=self.config.value_hidden,
        activation=self.config.activation)

  def make_learner(
      self, networks: policy_value.PolicyValueNetworks,
      batches: Optional[Iterator[types.SequenceBatch]] = None,
  ) -> learning.PPOLearner:
    """A learner, optionally pulling batches from an iterator in `step()`."""
    return learning.PPOLearner(networks, self.config, batches,
                               key=self._learner_key)

  def make_actor(self, networks: policy_value.PolicyValueNetworks,
                 variable_source: core.VariableSource,
                 actor_id: int = 0,
                 action_bounds: Optional[tuple[Any, Any]] = None,
                 deterministic: bool = False) -> acting.PPOActor:
    """An actor with its own noise stream (one per `actor_id`)."""
    return acting.PPOActor(
        networks, self.config, variable_source,
        key=jax.random.fold_in(self._actors_key, actor_id),
        action_bounds=action_bounds, deterministic=deterministic)
