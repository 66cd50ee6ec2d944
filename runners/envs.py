"""The environments a cooperative run steps, and who acts in them.

`EnvSpec` is a picklable recipe that an actor process (possibly on another
machine) turns into environment copies:

* 'hrl', 'no_memory', 'mappo': `CommandWrapper(coop_suite.load(...))`: the
  policy sends one 2-D command per agent every `command_period`; the frozen
  lower layer walks. The controller travels *inside* the spec as the bytes of
  its three files, so remote actors need no shared file system.
* 'flat': the bare environment (8 joint actions per agent every control
  step) as a `FlatEnv`, whose rewards add the lower layer's locomotion terms
  (alive, up, action / energy / joint-limit costs), as the paper's
  no-hierarchy baseline is trained.
* 'lowlevel': the bare locomotion task (walk_to_target, walk_velocity),
  whose rewards are the lower layer's already.

`species_layout` lists the species of a task (in order of first appearance)
with the agents, observation keys and sizes that one policy per species
needs.
"""
import dataclasses
import hashlib
import os
from typing import Any, Callable, Mapping, Optional

import numpy as np

from agents import observations as obs_lib

_CONTROLLERS = {}  # Per process: files digest -> Controller (one jit each).


def read_controller(paradigm: str, directory: str = '') -> dict[str, bytes]:
  """Checks and reads a lower-layer controller's files.

  Args:
    paradigm: 'position' or 'velocity'.
    directory: a controller folder (`agents.lowlevel.files`); empty for the
      weights shipped with the package.

  Returns:
    {file name: contents}, what `EnvSpec.controller_files` holds.

  Raises:
    FileNotFoundError: no controller there, with how to make one.
  """
  from agents import lowlevel  # pylint: disable=g-import-not-at-top
  from agents.lowlevel import controller as controller_lib  # pylint: disable=g-import-not-at-top
  directory = directory or os.path.join(lowlevel.WEIGHTS_DIR, paradigm)
  try:
    lowlevel.load(paradigm, directory)  # Checks it whole.
  except FileNotFoundError as e:
    raise FileNotFoundError(
        f'No trained {paradigm}-paradigm lower layer in {directory} ({e}). '
        f'Train one with `coop-pretrain-lowlevel --paradigm {paradigm}` and '
        f'export it there, or pass --controller DIR.') from None
  return controller_lib.read_files(directory)


def controller_from_files(files: Mapping[str, bytes]):
  """The `agents.lowlevel.Controller` in `files`, loaded once per process."""
  from agents.lowlevel import controller as controller_lib  # pylint: disable=g-import-not-at-top
  digest = hashlib.sha1(b''.join(files[n] for n in controller_lib.FILES)
                        ).digest()
  if digest not in _CONTROLLERS:
    _CONTROLLERS[digest] = controller_lib.from_files(files)
  return _CONTROLLERS[digest]


@dataclasses.dataclass(frozen=True, eq=False)
class EnvSpec:
  """How to build one environment copy of a run."""

  task: str
  n_agents: int
  options: Mapping[str, Any]
  """Extra `coop_suite.load` options (time_limit, stage, n_pushers...)."""
  uses_commands: bool
  """`HierarchyConfig.uses_commands`: the policy commands the lower layer
  (False: 'flat' and 'lowlevel', which step joints)."""
  command_period: float
  controller_files: Optional[Mapping[str, bytes]] = dataclasses.field(
      default=None, repr=False)
  """From `read_controller`; unused (may be None) without commands."""
  locomotion_terms: bool = True
  """Without commands: add the locomotion terms (`FlatEnv`,
  `HierarchyConfig.adds_locomotion_terms`); False steps the bare task."""

  def make(self, seed: int, wrap_raw: Optional[Callable[[Any], Any]] = None):
    """One copy with environment seed `seed`.

    `wrap_raw`, if given, wraps the bare environment before the command or
    flat layer goes on top (e.g. to render every control step).
    """
    import coop_suite  # pylint: disable=g-import-not-at-top
    env = coop_suite.load(self.task, self.n_agents, seed=int(seed),
                          **dict(self.options))
    if wrap_raw is not None:
      env = wrap_raw(env)
    if not self.uses_commands:
      return FlatEnv(env) if self.locomotion_terms else env
    if self.controller_files is None:
      raise ValueError('Commands need a lower-layer controller.')
    from agents.lowlevel import wrapper  # pylint: disable=g-import-not-at-top
    return wrapper.CommandWrapper(
        env, controller_from_files(self.controller_files),
        command_period=self.command_period)


def control_timestep(env) -> float:
  """Seconds per low-level step of a copy made by `EnvSpec.make`."""
  return getattr(env, 'env', env).control_timestep()


class FlatEnv:
  """A bare environment whose per-agent rewards add the locomotion terms.

  The terms are `coop_suite.tasks.rewards.locomotion_terms` with the
  coefficients of `LocomotionConfig` (what the lower layer learns to walk
  with); their sums appear in `episode_metrics()` as `reward/<term>` and in
  its `return`.
  """

  def __init__(self, env):
    from coop_suite.tasks import locomotion  # pylint: disable=g-import-not-at-top
    from coop_suite.tasks import rewards  # pylint: disable=g-import-not-at-top
    self.env = env
    self._config = locomotion.LocomotionConfig()
    self._rewards = rewards
    self._sums = None  # [terms, n_agents] from the first reward on.
    self._actions = None  # Those of a step in its two phases.

  def __getattr__(self, name):  # task, physics, specs, control_timestep...
    return getattr(self.env, name)

  def reset(self):
    self._sums = None
    return self.env.reset()

  def step(self, actions):
    return self._with_terms(self.env.step(actions), actions)

  def step_physics(self, actions):
    """`CoopEnvironment.step_physics` (for copies stepped in lockstep)."""
    self.env.step_physics(actions)
    self._actions = actions

  def step_outcome(self, observe=True):
    """`CoopEnvironment.step_outcome`, its rewards with the terms."""
    actions, self._actions = self._actions, None
    return self._with_terms(self.env.step_outcome(observe), actions)

  def _with_terms(self, timestep, actions):
    if timestep.first() or self.env.physics_diverged:
      return timestep
    task = self.env.task
    terms = self._rewards.locomotion_term_array(  # [terms, n_agents]
        task.features(self.env.physics, ('proprio',)),
        np.clip(np.asarray(actions, np.float64), -1.0, 1.0),
        task.joint_ranges, self._config)
    if self._sums is None:
      self._sums = np.zeros_like(terms)
    self._sums += terms
    total = np.zeros(terms.shape[1])
    for term in terms:  # In order, one after the other.
      total += term
    reward = (np.asarray(timestep.reward, np.float64)
              + total).astype(np.float32)
    return timestep._replace(reward=list(reward))

  def episode_metrics(self):
    metrics = self.env.episode_metrics()
    if self._sums is not None:
      for name, total in zip(self._rewards.LOCOMOTION_TERMS, self._sums):
        metrics[f'reward/{name}'] = float(np.mean(total))
        metrics['return'] += float(np.mean(total))
    return metrics


@dataclasses.dataclass(frozen=True)
class Species:
  """One species of a task: its agents and what its policy reads and emits.

  Attributes:
    name: e.g. 'ant', 'pusher', 'crosser'.
    species_id: index in the layout (folded into the agent's keys).
    agents: indices of its agents in one environment copy.
    observation_keys: flattened keys, `HierarchyConfig.observation_prefixes`.
    observation_size: D.
    action_size: 2 (command) or 8 (joints, 'flat', 'lowlevel').
    action_bounds: (low, high) of the command, or None (joints: [-1, 1]).
    global_state_size: S for 'mappo' (the task's global state followed by
      the agent's own observation, MAPPO's agent-specific state), else None.
  """
  name: str
  species_id: int
  agents: tuple[int, ...]
  observation_keys: tuple[str, ...]
  observation_size: int
  action_size: int
  action_bounds: Optional[tuple[float, float]]
  global_state_size: Optional[int] = None

  def to_dict(self) -> dict[str, Any]:
    return dataclasses.asdict(self)


def species_layout(env, config) -> list[Species]:
  """The species of `env` (a copy made by `EnvSpec.make`), first seen first.

  Args:
    env: an environment copy (its physics is read for the global state).
    config: the `HierarchyConfig` (observation prefixes, variant).
  """
  names = list(dict.fromkeys(env.task.species))
  observation_spec = env.observation_spec()
  action_spec = env.action_spec()
  out = []
  for species_id, name in enumerate(names):
    agents = tuple(i for i, s in enumerate(env.task.species) if s == name)
    try:
      keys = obs_lib.observation_keys(observation_spec[agents[0]],
                                      config.observation_prefixes)
    except ValueError as e:
      raise ValueError(f'Agent {config.agent!r} cannot read this task: {e}'
                       + (' It trains on walk_to_target or walk_velocity.'
                          if config.agent == 'lowlevel' else '')) from None
    size = int(sum(obs_lib.observation_sizes(observation_spec[agents[0]],
                                             keys)))
    spec = action_spec[agents[0]]
    bounds = ((float(np.min(spec.minimum)), float(np.max(spec.maximum)))
              if config.uses_commands else None)
    global_size = None
    if config.uses_global_state:
      global_size = len(env.task.global_state(env.physics)) + size
    out.append(Species(name, species_id, agents, keys, size,
                       int(np.prod(spec.shape)), bounds, global_size))
  return out
