"""The actor side: environment copies stepped with batched policies.

`EnvBatch` steps E copies of a task together and lays their agents out as
one batch per species: species s has B_s = E * (its agents per copy) rows,
row e * n_s + j being its j-th agent in copy e. Copies auto-reset: where a
copy's episode ended, its rows' next observation is already the next
episode's first (step_type LAST), as `HierarchyActor` expects.

`RolloutWorker` is what one actor process runs (a Ray actor, or the driver
itself with `--actors 0`): one `HierarchyActor` per species over all rows of
that species, so each command is one jitted policy call per species for
all copies. `collect(variables, update)` acts with exactly those
variables for `sequence_length` commands and returns one `SequenceBatch`
per species plus the episodes that ended.

Commanded copies step their command periods in lockstep (the phases of
`CommandWrapper.step`): one lower-layer call per low-level step serves all
copies and agents, fed by one array the copies' packed proprioception and
commands are written into. Measured on one core (shipped controller), a
call takes ~130 us for 4 rows and ~350 us for 64, so an actor with 16
copies of 4 Ants pays for about three calls' worth where it paid for 16
(docs/performance.md).
"""
import os
import sys
import time
from typing import Any, NamedTuple, Optional

import numpy as np

from agents import core
from agents import observations as obs_lib
from agents.hierarchy import builder as hierarchy_builder
from agents.ppo import types
from runners import envs as envs_lib

_MID, _LAST = 1, 2  # dm_env.StepType values.
VARIABLE_NAMES = ('params', 'normalizer', 'global_state_normalizer')


class SpeciesStep(NamedTuple):
  """One command's outcome for the B_s rows of a species (dm_env style)."""
  step_type: np.ndarray  # [B_s] MID or LAST.
  reward: np.ndarray  # [B_s] summed over the command's low-level steps.
  discount: np.ndarray  # [B_s] 0 where the episode terminated.
  observation: np.ndarray  # [B_s, D] the next observation (auto-reset).


class EnvBatch:
  """E environment copies with their agents grouped per species."""

  def __init__(self, spec: envs_lib.EnvSpec, config, seeds,
               global_state: bool = True, wrap_raw=None):
    """Args:
      spec: how to build a copy.
      config: the `HierarchyConfig` (observation prefixes, variant).
      seeds: one environment seed per copy.
      global_state: compute 'mappo' global-state rows (evaluation, which
        does not need the critic, turns this off).
      wrap_raw: passed to `EnvSpec.make` (e.g. to film every control step).
    """
    self.envs = [spec.make(seed, wrap_raw) for seed in seeds]
    self.species = envs_lib.species_layout(self.envs[0], config)
    self._global_state = global_state and config.uses_global_state
    self._dt = envs_lib.control_timestep(self.envs[0])
    self._controller = self.envs[0].controller if spec.uses_commands else None
    from coop_suite import environment  # pylint: disable=g-import-not-at-top
    # Every copy's physics phase in one call (a `CommandWrapper`'s
    # `advance_physics` is its environment's `step_physics`).
    self._physics = environment.LockstepPhysics(
        env.env if spec.uses_commands else env for env in self.envs)
    if self._controller is not None:
      if any(env.controller is not self._controller for env in self.envs):
        raise ValueError('Copies stepped together share one controller.')
      self._inputs = np.zeros((self.num_envs * self.envs[0].n_agents,
                               self._controller.observation_size),
                              np.float32)
    self._observations = [env.reset().observation for env in self.envs]
    self._reset = np.ones(len(self.envs), bool)
    self._rows = self._compute_rows()

  @property
  def num_envs(self) -> int:
    return len(self.envs)

  @property
  def rows(self) -> dict[str, tuple[np.ndarray, np.ndarray, Any]]:
    """{species: (observation [B_s, D], reset [B_s], global_state [B_s, S]
    or None)}: the copies' current state, what the actors act on next."""
    return self._rows

  def _compute_rows(self):
    out = {}
    for s in self.species:
      observation = np.stack([
          obs_lib.flatten(obs[a], s.observation_keys)
          for obs in self._observations for a in s.agents])
      reset = np.repeat(self._reset, len(s.agents))
      out[s.name] = (observation, reset,
                     self._global_rows(s, observation))
    return out

  def _global_rows(self, species, observation):
    if not self._global_state:
      return None
    state = np.stack([env.task.global_state(env.physics)
                      for env in self.envs])  # [E, S0]
    return np.concatenate(
        [np.repeat(state, len(species.agents), axis=0), observation], -1)

  def step(self, actions: dict[str, np.ndarray]):
    """Steps every copy by one command (or control step, joint actions).

    Args:
      actions: {species: [B_s, A]}.

    Returns:
      ({species: SpeciesStep}, episodes: metric dicts of the episodes that
      ended, each with 'env' (copy index), env_steps: low-level steps taken
      by all copies together).
    """
    n_agents = self.envs[0].n_agents
    rewards = np.zeros((self.num_envs, n_agents), np.float32)
    discounts = np.ones(self.num_envs, np.float32)
    last = np.zeros(self.num_envs, bool)
    episodes, env_steps = [], 0
    start = [env.physics.data.time for env in self.envs]
    for e, (env, timestep) in enumerate(zip(self.envs, self._step_copies(
        self._copy_actions(actions)))):
      env_steps += max(1, int(round((env.physics.data.time - start[e])
                                    / self._dt)))
      rewards[e] = timestep.reward
      discounts[e] = timestep.discount
      if timestep.last():
        last[e] = True
        episodes.append({**env.episode_metrics(), 'env': e})
        timestep = env.reset()
      self._observations[e] = timestep.observation
    self._reset = last
    self._rows = self._compute_rows()
    steps = {}
    for s in self.species:
      n = len(s.agents)
      steps[s.name] = SpeciesStep(
          step_type=np.repeat(np.where(last, _LAST, _MID), n),
          reward=rewards[:, list(s.agents)].reshape(-1),
          discount=np.repeat(discounts, n),
          observation=self._rows[s.name][0])
    return steps, episodes, env_steps

  def _copy_actions(self, actions):
    """{species: [B_s, A]} -> one [n_agents, A] array per copy."""
    n_agents = self.envs[0].n_agents
    out = np.zeros((self.num_envs, n_agents, self.species[0].action_size))
    for s in self.species:
      out[:, list(s.agents)] = actions[s.name].reshape(
          self.num_envs, len(s.agents), -1)
    return out

  def _step_copies(self, actions):
    """Every copy's TimeStep after one step with its actions. Commanded
    copies (`CommandWrapper`) run their command periods in lockstep: one
    lower-layer call per low-level step for all copies and agents, fed by
    one array whose rows the copies fill (a copy whose period ended early
    keeps its last rows, so the call's shape, and its compilation, stay
    the same). Every low-level step goes in its two phases: all copies'
    physics, then all copies' outcomes (`CoopEnvironment.step_physics`)."""
    if self._controller is None:
      self._physics.step_physics(actions)
      return [env.step_outcome() for env in self.envs]
    for env, a in zip(self.envs, actions):
      env.begin(a)
    n = self.envs[0].n_agents
    active = list(range(self.num_envs))
    while active:
      for e in active:
        self.envs[e].controller_input(out=self._inputs[e * n:(e + 1) * n])
      joints = self._controller.act(self._inputs).reshape(self.num_envs, n,
                                                          -1)
      # `advance` in its two phases: every copy's physics with the Python of
      # one, then each copy's outcome, whose code stays in the caches from
      # one copy to the next (docs/performance.md).
      self._physics.step_physics(
          joints if len(active) == self.num_envs else joints[active], active)
      active = [e for e in active if not self.envs[e].advance_outcome()]
    return [env.end() for env in self.envs]

  def close(self):
    for env in self.envs:
      env.close()


class _Variables(core.VariableSource):
  """Hands the actors the variables of the rollout being collected."""

  def __init__(self, variables):
    self.variables = variables

  def get_variables(self, names):
    return [self.variables[name] for name in names]


class Rollout(NamedTuple):
  """What one actor returns for one update's variables.

  Attributes:
    worker: the actor's index.
    update: the update whose variables chose every command (the
      learner's update counter when they were taken).
    batches: {species: SequenceBatch [T, B_s]}.
    episodes: metric dicts of the episodes that ended during the rollout.
    env_steps: low-level steps taken by all copies together.
    seconds: wall time of the collection.
    cpu_seconds: CPU time of this process meanwhile, all its threads (in
      a Ray actor also Ray's own, which are nearly idle; in the driver,
      `--actors 0`, also its background checkpoint writer): about the
      share of a core the collection got, times `seconds`.
  """
  worker: int
  update: int
  batches: dict[str, types.SequenceBatch]
  episodes: list[dict[str, Any]]
  env_steps: int
  seconds: float
  cpu_seconds: float


class RolloutWorker:
  """Steps `num_envs` copies with one batched actor per species."""

  def __init__(self, spec: Optional[envs_lib.EnvSpec], config, index: int,
               seed: int, num_envs: int):
    """Args:
      spec: the environments; None to receive them with the first
        `collect` (Ray actors: a restart then needs no large constructor
        argument, see `actor_pool`).
      config: the `HierarchyConfig` (same as the learner's).
      index: this actor's index (results carry it).
      seed: seeds the copies and the action noise of this worker.
      num_envs: copies stepped together.
    """
    if _restarted_by_ray():
      # A restarted process must not replay its predecessor's episodes.
      seed = int(np.random.SeedSequence([seed, os.getpid()])
                 .generate_state(1)[0] >> 1)
    seeds = np.random.SeedSequence(seed).generate_state(num_envs + 1) >> 1
    self._config = config
    self._index = index
    self._actor_id = int(seeds[-1])
    self._seeds = seeds[:-1]
    self._batch = None if spec is None else EnvBatch(spec, config,
                                                     self._seeds)
    self._source = None
    self._actors = None

  def ping(self) -> int:
    """This process's id (also a liveness check)."""
    return os.getpid()

  def collect(self, variables: dict[str, dict[str, Any]], update: int,
              spec: Optional[envs_lib.EnvSpec] = None) -> Rollout:
    """`sequence_length` commands of every copy with `variables`.

    Args:
      variables: {species: {'params', 'normalizer',
        'global_state_normalizer'}}, numpy pytrees from the learner.
      update: returned as is; the caller's name for `variables`.
      spec: the environments, if the constructor had none (used once).
    """
    start, cpu_start = time.perf_counter(), time.process_time()
    if self._batch is None:
      if spec is None:
        raise ValueError('This RolloutWorker was made without an EnvSpec: '
                         'pass one to collect().')
      self._batch = EnvBatch(spec, self._config, self._seeds)
    if self._actors is None:
      self._source = {s.name: _Variables(variables[s.name])
                      for s in self._batch.species}
      self._actors = {}
      for s in self._batch.species:
        builder = hierarchy_builder.HierarchyBuilder(self._config,
                                                     s.species_id)
        networks = builder.make_networks(s.observation_size, s.action_size,
                                         s.global_state_size)
        actor = builder.make_actor(networks, self._source[s.name],
                                   actor_id=self._actor_id,
                                   action_bounds=s.action_bounds)
        actor.observe_first()
        self._actors[s.name] = actor
    else:
      for name, actor in self._actors.items():
        # Between segments, so the whole rollout uses these variables.
        self._source[name].variables = variables[name]
        actor.update()
    episodes, env_steps = [], 0
    for _ in range(self._config.sequence_length):
      rows = self._batch.rows
      actions = {name: actor.select_action(*rows[name])[0]
                 for name, actor in self._actors.items()}
      steps, ended, n = self._batch.step(actions)
      episodes += ended
      env_steps += n
      for name, actor in self._actors.items():
        actor.observe(actions[name], steps[name],
                      self._batch.rows[name][2])
    batches = {name: actor.take_rollout()
               for name, actor in self._actors.items()}
    return Rollout(self._index, update, batches, episodes, env_steps,
                   time.perf_counter() - start,
                   time.process_time() - cpu_start)

  def close(self) -> None:
    if self._batch is not None:
      self._batch.close()


def _restarted_by_ray() -> bool:
  ray = sys.modules.get('ray')
  try:
    return bool(ray is not None and ray.is_initialized()
                and ray.get_runtime_context().was_current_actor_reconstructed)
  except Exception:  # pylint: disable=broad-except
    return False
