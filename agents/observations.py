"""Observation dicts -> flat float32 vectors, in one documented key order.

coop_suite gives each agent a dict of named arrays (`proprio/joints_pos`,
`command/target`, `extero/cylinder`, ...). Networks read one flat vector, so
the trainer that fits the lower layer and the controller that runs it later
must concatenate the same keys in the same order. Both call these functions,
and an exported controller stores its key list next to its weights.

Order: the groups in the order of `prefixes` (by default `proprio/*` then
`command/*`), keys sorted alphabetically within a group. With the locomotion
tasks that is

    proprio/angular_velocity[3], proprio/gravity[3], proprio/joints_pos[8],
    proprio/joints_vel[8], proprio/prev_action[8], proprio/torso_height[1],
    proprio/velocity[3], command/target[2] (or command/velocity[2])

36 floats in all. Pure numpy; no JAX, no coop_suite import.
"""
from typing import Mapping, Sequence

import numpy as np

LOWER_LAYER_PREFIXES = ('proprio', 'command')
"""What the lower layer (walker controller) reads."""


def observation_keys(observation: Mapping[str, object],
                     prefixes: Sequence[str] = LOWER_LAYER_PREFIXES
                     ) -> tuple[str, ...]:
  """The keys of `observation` under `prefixes`, in flattening order.

  Args:
    observation: one agent's observation dict, or its spec dict (any mapping
      whose keys are 'group/name').
    prefixes: groups to keep, in output order.

  Returns:
    Keys grouped by prefix (in `prefixes` order), sorted within a group.

  Raises:
    ValueError: if a prefix matches no key (e.g. a task without commands).
  """
  keys = []
  for prefix in prefixes:
    group = sorted(k for k in observation if k.split('/', 1)[0] == prefix)
    if not group:
      raise ValueError(f'No observation key under {prefix!r}/; keys are '
                       f'{sorted(observation)}.')
    keys.extend(group)
  return tuple(keys)


def observation_sizes(observation: Mapping[str, object],
                      keys: Sequence[str]) -> tuple[int, ...]:
  """Flat size of each key's value (works for arrays and dm_env specs)."""
  return tuple(int(np.prod(observation[k].shape)) for k in keys)


def flatten(observation: Mapping[str, np.ndarray],
            keys: Sequence[str]) -> np.ndarray:
  """Concatenates `observation[k]` for `k` in `keys` along the last axis.

  Args:
    observation: one agent's dict of arrays [k_i] (-> [D]), or a dict of
      stacked arrays [..., k_i] with the same leading shape (-> [..., D]).
    keys: from `observation_keys`; other keys of `observation` are ignored.

  Returns:
    float32 array [..., D], D = sum of the k_i.

  Raises:
    KeyError: naming the missing key.
  """
  try:
    parts = [observation[key] for key in keys]
  except KeyError as missing:
    raise KeyError(f'Observation has no {missing.args[0]!r}; it has '
                   f'{sorted(observation)}.') from None
  # One cast after joining (the same float32 values as casting each part:
  # float32 and smaller types join into float64 exactly): a third of the
  # time of casting the parts, paid per agent and decision.
  return np.concatenate(parts, axis=-1).astype(np.float32, copy=False)


def flatten_agents(observations: Sequence[Mapping[str, np.ndarray]],
                   keys: Sequence[str]) -> np.ndarray:
  """A list of per-agent dicts (a coop_suite observation) -> [n_agents, D]."""
  return np.stack([flatten(o, keys) for o in observations])
