"""A learner's saved training state, and the learner files of older runs.

`Learner.save()` returns a saved state, `{'format', 'kind', 'state'}`, where
`state` is the training-state pytree as a flax state dict of host arrays;
`kind` names the learner (and the hierarchy's variant) so that a state never
loads into another learner, `format` its layout (the learners read the older
ones). Writing it to disk is the runner's business (`runners.checkpoints`,
through orbax), as in Acme, where a Checkpointer writes what `save()` returns.

Runs written before orbax kept one flax msgpack file of that dict per
learner; `read_file` reads one.
"""
from typing import Any

from flax import serialization
import jax
import jax.numpy as jnp
import numpy as np


def to_state_dict(state: Any) -> dict[str, Any]:
  """`state` (a pytree of arrays) as a flax state dict of host arrays."""
  return serialization.to_state_dict(jax.device_get(state))


def saved_state(state: Any, kind: str, format_version: int) -> dict[str, Any]:
  """What `Learner.save()` returns for the training state `state`."""
  return {'format': format_version, 'kind': kind,
          'state': to_state_dict(state)}


def read_file(path: str) -> dict[str, Any]:
  """The saved state in a learner file of the msgpack layout (a run from
  before orbax: `<logdir>/checkpoints/ckpt_<iteration>/<species>.msgpack`).
  """
  with open(path, 'rb') as f:
    return serialization.msgpack_restore(f.read())


def unpack(saved: dict[str, Any], kind: str, source: str
           ) -> tuple[int, Any]:
  """(format version, state dict) of a saved state.

  Raises ValueError (naming `source`) when it is of another kind. Learners
  that still read an older format convert its state dict themselves.
  """
  # States saved before `kind` existed (early PPO checkpoints) carry none.
  if saved.get('kind', kind) != kind:
    raise ValueError(f'{source} is not a {kind} checkpoint (it is a '
                     f'{saved.get("kind")} one).')
  return saved.get('format'), saved['state']


def _with_empty_arrays(template: Any, state_dict: Any) -> Any:
  """`state_dict` with None where `template` has a zero-size array put back
  as that array (checkpoints of format 2-3, and policies published from
  them, hold None there: orbax stores no arrays without elements)."""
  if isinstance(state_dict, dict) and isinstance(template, dict):
    return {k: _with_empty_arrays(template.get(k), v)
            for k, v in state_dict.items()}
  if state_dict is None and template is not None and np.size(template) == 0:
    return template
  return state_dict


def from_state_dict(source: str, template: Any, state_dict: Any) -> Any:
  """`state_dict` in the structure of `template`; ValueError (naming
  `source`) when the structure or an array's shape differs."""
  state_dict = _with_empty_arrays(to_state_dict(template), state_dict)
  try:
    state = serialization.from_state_dict(template, state_dict)
  except ValueError as e:
    raise ValueError(f'{source} holds another state structure; was it '
                     f'written with different networks or config? ({e})'
                     ) from None
  state = jax.tree.map(jnp.asarray, state)
  if jax.tree.map(jnp.shape, state) != jax.tree.map(jnp.shape, template):
    raise ValueError(f'{source} holds arrays of other shapes; was it written '
                     'with different networks or config?')
  return state
