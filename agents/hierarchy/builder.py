"""Wires a HierarchyConfig into networks, a learner and actors.

One builder per species (IPPO: parameters are shared within a species and
separate between species):

    builder = HierarchyBuilder(HierarchyConfig(), species_id=0)
    networks = builder.make_networks(obs_dim, action_dim=2)
    learner = builder.make_learner(networks)
    actor = builder.make_actor(networks, learner, actor_id=0,
                               action_bounds=(command_low, command_high))

Keys are derived from `(config.seed, species_id)` here, once: every species'
learner and every actor get independent streams, and the same seed
reproduces a run.
"""
from typing import Any, Iterator, Optional

import jax

from agents import core
from agents.hierarchy import acting
from agents.hierarchy import config as hierarchy_config
from agents.hierarchy import learning
from agents.hierarchy import networks as hierarchy_networks
from agents.ppo import types


class HierarchyBuilder:
  """Makes one species' hierarchy components from one config."""

  def __init__(self, config: hierarchy_config.HierarchyConfig,
               species_id: int = 0):
    self.config = config
    self.species_id = species_id
    species_key = jax.random.fold_in(jax.random.PRNGKey(config.seed),
                                     species_id)
    self._learner_key, self._actors_key = jax.random.split(species_key)

  def make_networks(
      self, obs_dim: int, action_dim: int,
      global_state_dim: Optional[int] = None,
  ) -> hierarchy_networks.HierarchyNetworks:
    """The variant `config.agent`; see `make_hierarchy_networks`.

    Args:
      obs_dim: D, flattened `extero/*` width ('flat': proprio + extero).
      action_dim: 2 for the command; the joint count (8) for 'flat'.
      global_state_dim: S, required by 'mappo', ignored otherwise.
    """
    return hierarchy_networks.make_hierarchy_networks(
        self.config, obs_dim, action_dim, global_state_dim)

  def make_learner(
      self, networks: hierarchy_networks.HierarchyNetworks,
      batches: Optional[Iterator[types.SequenceBatch]] = None,
  ) -> learning.HierarchyLearner:
    """A learner, optionally pulling batches from an iterator in `step()`."""
    return learning.HierarchyLearner(networks, self.config, batches,
                                     key=self._learner_key)

  def make_actor(self, networks: hierarchy_networks.HierarchyNetworks,
                 variable_source: core.VariableSource,
                 actor_id: int = 0,
                 action_bounds: Optional[tuple[Any, Any]] = None,
                 deterministic: bool = False) -> acting.HierarchyActor:
    """An actor with its own noise stream (one per `actor_id`).

    `action_bounds` is the command spec's (low, high); None keeps [-1, 1].
    """
    return acting.HierarchyActor(
        networks, self.config, variable_source,
        key=jax.random.fold_in(self._actors_key, actor_id),
        action_bounds=action_bounds, deterministic=deterministic)
