"""Atomic checkpoint files of a learner's training state (flax msgpack).

A file is `{'format', 'kind', 'state'}` where `state` is the training-state
pytree as a flax state dict; `kind` names the learner (and the hierarchy's
variant) so that a file never loads into another learner, `format` its
layout (`agents.ppo.learning.PPOLearner` reads the older ones).
"""
import os
from typing import Any

from flax import serialization
import jax
import jax.numpy as jnp


def to_state_dict(state: Any) -> dict[str, Any]:
  """`state` (a pytree of arrays) as a flax state dict of host arrays."""
  return serialization.to_state_dict(jax.device_get(state))


def save_state(path: str, state: Any, kind: str, format_version: int) -> None:
  """Writes `state` (a pytree of arrays) to `path`, atomically.

  The file is written next to `path` and moved over it with `os.replace`, so
  a crash never leaves a truncated checkpoint behind.
  """
  state_dict = to_state_dict(state)
  data = serialization.msgpack_serialize(
      {'format': format_version, 'kind': kind, 'state': state_dict})
  directory = os.path.dirname(os.path.abspath(path))
  os.makedirs(directory, exist_ok=True)
  tmp_path = f'{path}.tmp-{os.getpid()}'
  with open(tmp_path, 'wb') as f:
    f.write(data)
    f.flush()
    os.fsync(f.fileno())
  os.replace(tmp_path, path)


def read(path: str, kind: str) -> tuple[int, Any]:
  """(format version, state dict) of a file written by `save_state`.

  Raises ValueError when the file is of another kind. Learners that still
  read an older format convert its state dict themselves.
  """
  with open(path, 'rb') as f:
    contents = serialization.msgpack_restore(f.read())
  # Files written before `kind` existed (early PPO checkpoints) carry none.
  if contents.get('kind', kind) != kind:
    raise ValueError(f'{path} is not a {kind} checkpoint (it is a '
                     f'{contents.get("kind")} one).')
  return contents.get('format'), contents['state']


def from_state_dict(path: str, template: Any, state_dict: Any) -> Any:
  """`state_dict` in the structure of `template`; ValueError (naming `path`)
  when the structure or an array's shape differs."""
  try:
    state = serialization.from_state_dict(template, state_dict)
  except ValueError as e:
    raise ValueError(f'{path} holds another state structure; was it written '
                     f'with different networks or config? ({e})') from None
  state = jax.tree.map(jnp.asarray, state)
  if jax.tree.map(jnp.shape, state) != jax.tree.map(jnp.shape, template):
    raise ValueError(f'{path} holds arrays of other shapes; was it written '
                     'with different networks or config?')
  return state

