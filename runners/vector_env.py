"""N copies of a coop_suite environment, stepped in parallel worker processes.

    envs = VectorEnv(make_env_fn('walk_to_target'), num_envs=64, seed=0,
                     num_workers=2)
    step = envs.reset()                     # step.observation [N, A, D]
    step = envs.step(actions)               # actions [N, A, 8]
    for episode in step.episodes: ...       # metrics of episodes that ended
    envs.close()

Copy i is built with seed `seed + i`, so a run is reproducible and the copies
differ. Copies are split into `num_workers` contiguous slices, one process
each (multiprocessing 'spawn': a fresh interpreter, never a fork of a process
that may have imported JAX); `num_workers=0` steps them in this process.

Auto-reset: when copy i's episode ends, the returned step has
`step_type[i] == LAST`, the terminal `reward[i]` and `discount[i]` (0 on a
fall, 1 on the time limit), `truncation[i]` set for a time-limit end,
`final_observation[i]` the episode's last observation and `observation[i]`
already the NEXT episode's first observation; the episode's metrics are in
`step.episodes`. This is what `agents.ppo.acting.PPOActor` expects.

Observations are flattened per agent with `agents.observations.flatten` over
`observation_keys` (by default sorted `proprio/*` then sorted `command/*`).
"""
import functools
import multiprocessing
import os
import signal
import traceback
from typing import Any, Callable, NamedTuple, Optional, Sequence

import numpy as np

from agents import observations as obs_lib

FIRST, MID, LAST = 0, 1, 2  # dm_env.StepType values.


class VectorStep(NamedTuple):
  """One step of all copies. N copies, A agents per copy, D features.

  Attributes:
    step_type: [N] int8, FIRST / MID / LAST (see the module docstring).
    reward: [N, A] float32 (0 after a reset).
    discount: [N] float32.
    truncation: [N] bool, the episode ended by its time limit (LAST and
      discount > 0).
    observation: [N, A, D] float32; the next episode's first one where LAST.
    final_observation: [N, A, D] float32; the ended episode's last observation
      where LAST, else the same as `observation`.
    episodes: one dict per episode that ended at this step: 'env' (copy
      index), 'length' (control steps), 'truncated', plus
      `env.episode_metrics()` ('return', 'success', ...).
  """
  step_type: np.ndarray
  reward: np.ndarray
  discount: np.ndarray
  truncation: np.ndarray
  observation: np.ndarray
  final_observation: np.ndarray
  episodes: list


def _load(task, n_agents, options, seed):
  import coop_suite  # pylint: disable=g-import-not-at-top
  return coop_suite.load(task, n_agents, seed=seed, **options)


def make_env_fn(task: str, n_agents: Optional[int] = None,
                **options) -> Callable[[int], Any]:
  """A picklable `seed -> coop_suite.load(task, n_agents, seed=seed, ...)`."""
  return functools.partial(_load, task, n_agents, dict(options))


class _EnvSlice:
  """Copies stepped one after another in one process (a worker's job)."""

  def __init__(self, env_fn, seeds, prefixes):
    self._envs = [env_fn(int(s)) for s in seeds]
    spec = self._envs[0].observation_spec()
    self.n_agents = len(spec)
    self.keys = obs_lib.observation_keys(spec[0], prefixes)
    self.sizes = obs_lib.observation_sizes(spec[0], self.keys)
    action_spec = self._envs[0].action_spec()[0]
    self.action_shape = tuple(action_spec.shape)
    self._lengths = np.zeros(len(self._envs), np.int64)

  def info(self):
    return dict(n_agents=self.n_agents, keys=self.keys, sizes=self.sizes,
                action_shape=self.action_shape)

  def _flat(self, observation):
    return obs_lib.flatten_agents(observation, self.keys)

  def reset(self):
    self._lengths[:] = 0
    obs = np.stack([self._flat(env.reset().observation) for env in self._envs])
    n, a = len(self._envs), self.n_agents
    return dict(step_type=np.full(n, FIRST, np.int8),
                reward=np.zeros((n, a), np.float32),
                discount=np.ones(n, np.float32),
                truncation=np.zeros(n, bool),
                observation=obs, final_observation=obs.copy(), episodes=[])

  def step(self, actions):
    n, a = len(self._envs), self.n_agents
    step_type = np.full(n, MID, np.int8)
    reward = np.empty((n, a), np.float32)
    discount = np.empty(n, np.float32)
    truncation = np.zeros(n, bool)
    obs = np.empty((n, a, sum(self.sizes)), np.float32)
    final = np.empty_like(obs)
    episodes = []
    for i, (env, action) in enumerate(zip(self._envs, actions)):
      ts = env.step(action)
      self._lengths[i] += 1
      reward[i] = ts.reward
      discount[i] = ts.discount
      final[i] = self._flat(ts.observation)
      if ts.last():
        step_type[i] = LAST
        truncation[i] = float(ts.discount) > 0.0
        metrics = dict(env.episode_metrics())
        metrics.update(env=i, length=int(self._lengths[i]),
                       truncated=bool(truncation[i]))
        episodes.append(metrics)
        self._lengths[i] = 0
        obs[i] = self._flat(env.reset().observation)
      else:
        obs[i] = final[i]
    return dict(step_type=step_type, reward=reward, discount=discount,
                truncation=truncation, observation=obs,
                final_observation=final, episodes=episodes)

  def close(self):
    for env in self._envs:
      env.close()


def _worker(conn, env_fn, seeds, prefixes):
  """A worker process's loop: commands in, results (or a traceback) out."""
  signal.signal(signal.SIGINT, signal.SIG_IGN)  # The parent handles Ctrl-C.
  envs = None
  try:
    envs = _EnvSlice(env_fn, seeds, prefixes)
    conn.send(('ok', envs.info()))
    while True:
      command, data = conn.recv()
      if command == 'close':
        break
      result = envs.reset() if command == 'reset' else envs.step(data)
      conn.send(('ok', result))
  except (EOFError, KeyboardInterrupt, BrokenPipeError):
    pass  # The parent went away.
  except Exception:  # pylint: disable=broad-except
    try:
      conn.send(('error', traceback.format_exc()))
    except (BrokenPipeError, OSError):
      pass
  finally:
    if envs is not None:
      envs.close()
    conn.close()


class VectorEnv:
  """`num_envs` copies of an environment with auto-reset; see module doc."""

  def __init__(self, env_fn: Callable[[int], Any], num_envs: int, *,
               seed: int = 0, num_workers: int = 0,
               prefixes: Sequence[str] = obs_lib.LOWER_LAYER_PREFIXES):
    """Args:
      env_fn: picklable `seed -> environment` (see `make_env_fn`).
      num_envs: N, number of copies.
      seed: copy i gets seed `seed + i`.
      num_workers: processes to spread the copies over (at most N); 0 steps
        them in this process.
      prefixes: observation groups to flatten, in order.
    """
    if num_envs < 1:
      raise ValueError(f'num_envs must be >= 1, got {num_envs}.')
    if num_workers < 0:
      raise ValueError(f'num_workers must be >= 0, got {num_workers}.')
    self.num_envs = num_envs
    self.num_workers = min(num_workers, num_envs)
    seeds = seed + np.arange(num_envs)
    self._local = None
    self._conns, self._processes = [], []
    self._closed = False
    if self.num_workers == 0:
      self._local = _EnvSlice(env_fn, seeds, prefixes)
      info = self._local.info()
    else:
      context = multiprocessing.get_context('spawn')
      self._slices = np.array_split(np.arange(num_envs), self.num_workers)
      # Workers run one env after another: extra BLAS threads only contend.
      env_backup = {k: os.environ.get(k) for k in ('OMP_NUM_THREADS',)}
      os.environ['OMP_NUM_THREADS'] = '1'
      try:
        for index in self._slices:
          parent, child = context.Pipe()
          process = context.Process(
              target=_worker, args=(child, env_fn, seeds[index], prefixes),
              daemon=True)
          process.start()
          child.close()
          self._conns.append(parent)
          self._processes.append(process)
      finally:
        for k, v in env_backup.items():
          if v is None:
            os.environ.pop(k, None)
          else:
            os.environ[k] = v
      infos = [self._receive(c) for c in self._conns]
      info = infos[0]
    self.n_agents = info['n_agents']
    self.observation_keys = tuple(info['keys'])
    self.observation_sizes = tuple(info['sizes'])
    self.observation_size = int(sum(self.observation_sizes))
    self.action_shape = tuple(info['action_shape'])

  def _receive(self, conn):
    try:
      status, payload = conn.recv()
    except EOFError:
      self.close()
      raise RuntimeError('A VectorEnv worker died without a word (out of '
                         'memory?).') from None
    if status == 'error':
      self.close()
      raise RuntimeError(f'A VectorEnv worker failed:\n{payload}')
    return payload

  def _gather(self, command, data_per_worker):
    if self._closed:
      raise RuntimeError('VectorEnv is closed.')
    if self._local is not None:
      parts = [self._local.reset() if command == 'reset'
               else self._local.step(data_per_worker[0])]
      offsets = [0]
    else:
      for conn, data in zip(self._conns, data_per_worker):
        conn.send((command, data))
      parts = [self._receive(c) for c in self._conns]
      offsets = [int(s[0]) for s in self._slices]
    episodes = []
    for part, offset in zip(parts, offsets):
      for episode in part['episodes']:
        episode['env'] += offset
        episodes.append(episode)
    fields = {name: np.concatenate([p[name] for p in parts])
              for name in VectorStep._fields if name != 'episodes'}
    return VectorStep(episodes=episodes, **fields)

  def reset(self) -> VectorStep:
    """Resets every copy; `step_type` FIRST, rewards 0."""
    return self._gather('reset', [None] * max(1, self.num_workers))

  def step(self, actions) -> VectorStep:
    """Steps every copy once.

    Args:
      actions: [N, A, action_dim] (or [N * A, action_dim]) in the env's
        action bounds.
    """
    actions = np.asarray(actions, np.float64).reshape(
        (self.num_envs, self.n_agents) + self.action_shape)
    if self._local is not None:
      return self._gather('step', [actions])
    return self._gather('step', [actions[s] for s in self._slices])

  def close(self) -> None:
    """Stops the workers (idempotent)."""
    if self._closed:
      return
    self._closed = True
    if self._local is not None:
      self._local.close()
    for conn in self._conns:
      try:
        conn.send(('close', None))
      except (BrokenPipeError, OSError):
        pass
    for process in self._processes:
      process.join(timeout=5)
      if process.is_alive():
        process.terminate()
        process.join(timeout=5)
    for conn in self._conns:
      conn.close()

  def __enter__(self):
    return self

  def __exit__(self, *exc):
    self.close()

  def __del__(self):
    try:
      self.close()
    except Exception:  # pylint: disable=broad-except
      pass
