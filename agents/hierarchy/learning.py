"""The hierarchy's learner: the PPO learner whose files name the variant.

Training is `agents.ppo.learning.PPOLearner`'s (recurrent PPO over stored
sequences, value normalisation, KL-adaptive learning rate). This front-end
only names the checkpoint kind after the variant, so that an 'hrl' file
never loads into a 'mappo' learner even where the shapes would allow it,
and reads the hierarchy's older file formats: 2 (its own learner's, the
counter named `step`) and 1 (the first layout, `agents.hierarchy.legacy`).
"""
from typing import Any

from agents.hierarchy import legacy
from agents.ppo import learning as ppo_learning


class HierarchyLearner(ppo_learning.PPOLearner):
  """Trains one species' upper and middle layer (see `PPOLearner`)."""

  older_formats = (legacy.FORMAT, 2)

  def __init__(self, networks, config, batches=None, key=None):
    """Args: see `PPOLearner`; `networks` are `HierarchyNetworks`."""
    super().__init__(networks, config, batches, key)
    self.checkpoint_kind = f'hierarchy/{networks.agent}'

  def _upgrade(self, file_format: int,
               state_dict: dict[str, Any]) -> dict[str, Any]:
    """Format 1: converted (the policy exactly, a separate critic as a copy
    of the shared trunk, a fresh optimiser); format 2: today's layout."""
    if file_format == legacy.FORMAT:
      return legacy.convert(state_dict, self._state, self._optimizer)
    return state_dict
