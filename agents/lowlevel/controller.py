"""The frozen lower layer: a pretrained walker policy, deterministic.

A controller is three small files in one directory, made by `files` (the
pretraining runner writes them whole with `runners.run_dir.write_directory`)
and read by `load_from`:

  params.msgpack   the policy network's parameters (flax msgpack; no critic)
  normalizer.npz   the observation statistics it was trained with
  config.json      paradigm, observation keys and sizes, the PPO config and
                   the environment config of the training run, its counters

It maps one agent's `proprio/*` plus its `command/target` (position paradigm,
heading-frame offset in metres) or `command/velocity` (velocity paradigm,
heading-frame m/s) to 8 joint actions in [-1, 1]: the mean of the trained
policy, squashed by tanh.
"""
import dataclasses
import io
import json
import os
from typing import Any, Mapping, Sequence, Union

from flax import serialization
import jax
import jax.numpy as jnp
import numpy as np

from agents import normalization
from agents import observations as obs_lib
from agents.lowlevel.paradigms import PARADIGMS
from agents.networks import policy_value
from agents.ppo import config as ppo_config

FORMAT = 1

FILES = ('params.msgpack', 'normalizer.npz', 'config.json')
"""A controller's files, as `files` writes them and `from_files` reads them."""


def files(policy_params: Any, normalizer: normalization.NormalizerState,
          config: Mapping[str, Any]) -> dict[str, bytes]:
  """A controller's three files, {file name: contents}.

  Args:
    policy_params: the policy's Flax variables (`params['policy']`).
    normalizer: observation statistics.
    config: JSON-able dict with at least 'paradigm', 'observation_keys',
      'observation_sizes', 'action_size' and 'ppo_config' (a PPOConfig as a
      dict); anything else (env config, training counters) is kept as is.
  """
  for key in ('paradigm', 'observation_keys', 'observation_sizes',
              'action_size', 'ppo_config'):
    if key not in config:
      raise ValueError(f'Controller config needs {key!r}.')
  params = jax.tree.map(lambda x: np.asarray(x, np.float32),
                        jax.device_get(policy_params))
  statistics = io.BytesIO()
  np.savez(statistics, **normalization.to_dict(jax.device_get(normalizer)))
  return {'params.msgpack': serialization.msgpack_serialize(params),
          'normalizer.npz': statistics.getvalue(),
          'config.json': json.dumps({'format': FORMAT, **config}, indent=2,
                                    default=_jsonable).encode()}


def _jsonable(value):
  if isinstance(value, (np.integer, np.floating, np.bool_)):
    return value.item()
  if isinstance(value, np.ndarray):
    return value.tolist()
  raise TypeError(f'Not JSON-serialisable: {type(value).__name__}')


@dataclasses.dataclass(frozen=True, eq=False)
class Controller:
  """A frozen walker policy; call it on observation dicts.

  Attributes:
    paradigm: 'position' or 'velocity'.
    command_key: 'command/target' or 'command/velocity'.
    observation_keys: the keys read, in flattening order.
    params: the policy's Flax variables.
    normalizer: the observation statistics it was trained with.
    config: the full config.json contents.
  """
  paradigm: str
  observation_keys: tuple[str, ...]
  params: Any = dataclasses.field(repr=False)
  normalizer: normalization.NormalizerState = dataclasses.field(repr=False)
  config: Mapping[str, Any] = dataclasses.field(repr=False)

  def __post_init__(self):
    ppo = ppo_config.PPOConfig(**self.config['ppo_config'])
    networks = policy_value.make_policy_value_networks(
        sum(self.config['observation_sizes']), self.config['action_size'],
        policy_hidden=ppo.policy_hidden, value_hidden=ppo.value_hidden,
        activation=ppo.activation)
    preprocess = normalization.make_preprocess_fn(
        ppo.normalize_observations, ppo.observation_clip)
    distribution = networks.distribution

    def act(params, normalizer, observation):
      dist_params = networks.apply_policy({'policy': params},
                                          preprocess(normalizer, observation))
      return distribution.squash(distribution.mode_raw(dist_params))

    object.__setattr__(self, '_act', jax.jit(act))
    object.__setattr__(self, 'observation_size',
                       sum(self.config['observation_sizes']))
    object.__setattr__(self, 'action_size', self.config['action_size'])

  @property
  def command_key(self) -> str:
    return PARADIGMS[self.paradigm].command_key

  def __call__(self, observation: Mapping[str, np.ndarray]) -> np.ndarray:
    """One agent's observation dict -> action [8] float32 in [-1, 1]."""
    flat = obs_lib.flatten(observation, self.observation_keys)
    return self.act(flat[None])[0]

  def batch(self, observations: Union[Sequence[Mapping[str, np.ndarray]],
                                      Mapping[str, np.ndarray]]
            ) -> np.ndarray:
    """Observations of B agents -> actions [B, 8] float32 in [-1, 1].

    Args:
      observations: a list of B per-agent dicts, or one dict of stacked
        arrays [B, k] per key.
    """
    if isinstance(observations, Mapping):
      flat = obs_lib.flatten(observations, self.observation_keys)
    else:
      flat = obs_lib.flatten_agents(observations, self.observation_keys)
    return self.act(flat)

  def act(self, flat: np.ndarray) -> np.ndarray:
    """Flat observations [B, observation_size] (the keys concatenated in
    `observation_keys` order) -> actions [B, 8] float32 in [-1, 1]."""
    if flat.shape[-1] != self.observation_size:
      raise ValueError(f'Expected {self.observation_size} features, got '
                       f'{flat.shape[-1]}.')
    return np.asarray(self._act(self.params, self.normalizer, flat))


def read_files(directory: str) -> dict[str, bytes]:
  """The contents of a controller's directory, {file name: bytes}.

  Raises:
    FileNotFoundError: a file of `FILES` is missing.
  """
  missing = [f for f in FILES
             if not os.path.exists(os.path.join(directory, f))]
  if missing:
    raise FileNotFoundError(f'No controller in {directory!r}: missing '
                            f'{missing}.')
  contents = {}
  for name in FILES:
    with open(os.path.join(directory, name), 'rb') as f:
      contents[name] = f.read()
  return contents


def load_from(directory: str) -> Controller:
  """Reads a controller's directory (`files`)."""
  return from_files(read_files(directory), where=directory)


def from_files(contents: Mapping[str, bytes], where: str = 'the files'
               ) -> Controller:
  """The controller in {file name: bytes} (the inverse of `files`);
  `where` names them in errors."""
  missing = [name for name in FILES if name not in contents]
  if missing:
    raise ValueError(f'{where} lack the controller files {missing}.')
  config = json.loads(contents['config.json'])
  if config.get('format') != FORMAT:
    raise ValueError(f'{where} holds controller format '
                     f'{config.get("format")}, expected {FORMAT}.')
  if config['paradigm'] not in PARADIGMS:
    raise ValueError(f'Unknown paradigm {config["paradigm"]!r} in '
                     f'{where}; expected one of {sorted(PARADIGMS)}.')
  params = jax.tree.map(jnp.asarray, serialization.msgpack_restore(
      contents['params.msgpack']))
  with np.load(io.BytesIO(contents['normalizer.npz'])) as arrays:
    normalizer = normalization.from_dict(arrays)
  return Controller(paradigm=config['paradigm'],
                    observation_keys=tuple(config['observation_keys']),
                    params=params, normalizer=normalizer, config=config)
