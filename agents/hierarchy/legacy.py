"""Reads hierarchy checkpoints of the first layout (format 1) into today's.

Format 1 (the first transport run, `results/transport_hrl_n4_s0`) had the
value head on the policy's middle layer, no value statistics and a constant
learning rate. Its policy's parameters keep their names in every critic
layout (`modules.HierarchyPolicyValue`), so they load exactly and the
evaluation of an old checkpoint is unchanged. The critic is rebuilt so that
it computes the old values: a separate critic's upper and middle layers are
copies of the old shared ones, the value statistics are the identity (the
old head predicted returns directly). What cannot be carried over starts
fresh: the optimiser (its moments belong to the old layout), and the old
'mappo' critic (an MLP over the global state alone).
"""
from typing import Any

from flax import serialization
import jax
import numpy as np
import optax

from agents import checkpointing
from agents import normalization

FORMAT = 1
_CRITIC_PREFIX = 'critic_'


def _same_shapes(a, b) -> bool:
  shapes = lambda tree: jax.tree.map(np.shape, tree)
  return jax.tree.structure(a) == jax.tree.structure(b) and (
      shapes(a) == shapes(b))


def convert(old: dict[str, Any], template: Any,
            optimizer: optax.GradientTransformation) -> dict[str, Any]:
  """A format-1 state dict as a state dict of today's `TrainingState` (the
  update counter keeps its old name, `step`).

  Args:
    old: the state dict read from a format-1 file.
    template: the learner's current `TrainingState`; modules the old file
      lacks keep the template's parameters.
    optimizer: the learner's optimiser, initialised afresh on the result.
  """
  new = checkpointing.to_state_dict(template)
  old_modules = old['params']['params']
  modules = {}
  for name, current in new['params']['params'].items():
    source = old_modules.get(name)
    if source is None and name.startswith(_CRITIC_PREFIX):
      source = old_modules.get(name[len(_CRITIC_PREFIX):])
    modules[name] = (source if source is not None
                     and _same_shapes(source, current) else current)
  params = serialization.from_state_dict(template.params,
                                         {'params': modules})
  return {
      **new,
      'params': {'params': modules},
      'opt_state': serialization.to_state_dict(optimizer.init(params)),
      'normalizer': old['normalizer'],
      'global_state_normalizer': old['global_state_normalizer'],
      'value_normalizer': checkpointing.to_state_dict(normalization.init(1)),
      'step': old['step'],
      'key': old['key'],
  }
