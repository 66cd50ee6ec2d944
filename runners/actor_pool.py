"""Where the rollout workers run: in this process, or as Ray actors.

Both pools answer `collect(variables, update) -> [Rollout]` (in worker
order) for one synchronous PPO update:

* `LocalPool` (`--actors 0`): one `RolloutWorker` in this process, no Ray.
* `RayPool`: one Ray actor process per worker. The variables are
  `ray.put` once per call and passed by reference; results are taken with
  `ray.wait` in completion order. A worker whose process dies (a crash,
  `kill -9`, a lost node) is restarted by Ray (`max_restarts`); its pending
  rollout is submitted again with the same variables reference, so the
  restarted worker is re-synced and the update still learns from one set
  of variables.

Ray notes (see docs/training.md): actors run with `JAX_PLATFORMS=cpu` and
single-threaded XLA/OpenMP, set through the actor's runtime environment
before JAX starts; they never fork. `init_ray` starts a local instance
quietly, listening on loopback only (its remaining Prometheus endpoints
too), with no dashboard and no core metrics; `--ray-address` joins a
cluster with the cluster's own settings (its token, see docs/training.md),
and actors are spread over its nodes.
"""
import logging
import os
import socket
import time
from typing import Any, Callable, Optional

import numpy as np

from runners import rollout

ACTOR_ENV_VARS = {
    'JAX_PLATFORMS': 'cpu',
    'XLA_FLAGS': ('--xla_cpu_multi_thread_eigen=false '
                  'intra_op_parallelism_threads=1'),
    'OMP_NUM_THREADS': '1',
    'MKL_NUM_THREADS': '1',
}
"""Environment of actor processes: CPU JAX, one thread each (an actor is one
CPU's worth of work; more threads only contend with the other actors)."""


def worker_seeds(seed: int, start_update: int, num_workers: int):
  """One seed per worker; a resumed run (start_update > 0) gets new ones
  so it does not replay the first updates' episodes."""
  sequence = np.random.SeedSequence([seed, start_update])
  return [int(s >> 1) for s in sequence.generate_state(num_workers)]


class LocalPool:
  """One worker in this process."""

  restarts = 0

  def __init__(self, spec, config, num_envs: int, seed: int):
    self._worker = rollout.RolloutWorker(spec, config, 0, seed, num_envs)

  def collect(self, variables, update, on_result=None):
    result = self._worker.collect(variables, update)
    if on_result is not None:
      on_result(result)
    return [result]

  def close(self):
    self._worker.close()


class ClusterUnreachable(ConnectionError):
  """`--ray-address` names no Ray cluster that lets this process join."""


class LocalRayTimeout(RuntimeError):
  """The local Ray instance did not start within Ray's own wait."""


RAY_START_TIMEOUT = 'timed out during startup'
"""What Ray's error says when its new node has not registered with its GCS
within the 30 s it waits (`ray._private.node.Node`, not configurable)."""


AUTH_HELP = (
    'A cluster with token authentication (`ray start --head` turns it on '
    'where ~/.ray/auth_token exists) needs RAY_AUTH_MODE=token here too, '
    'with its token in ~/.ray/auth_token, RAY_AUTH_TOKEN or '
    'RAY_AUTH_TOKEN_PATH (docs/training.md, "Running on a Ray cluster").')


def check_reachable(address: str, timeout: float = 5.0,
                    where: str = '--ray-address') -> None:
  """Raises `ClusterUnreachable` at once when nothing listens at a
  'host:port' or 'ray://host:port' address (Ray itself retries for
  minutes); 'auto' and other forms are left to Ray."""
  host_port = address.removeprefix('ray://')
  host, _, port = host_port.rpartition(':')
  if not host or not port.isdigit():
    return
  try:
    socket.create_connection((host.strip('[]'), int(port)), timeout).close()
  except OSError as e:
    raise ClusterUnreachable(
        f'{where} {address}: no Ray cluster answers there ({e}); '
        'start one with `ray start --head` or check the address.') from e


def _join(address: str, quiet: dict[str, Any], where: str) -> None:
  import ray  # pylint: disable=g-import-not-at-top
  check_reachable(address, where=where)
  try:
    ray.init(address=address, **quiet)
  except ConnectionError as e:
    # Ray reports a refused token as a failure to connect, after ~20 s.
    mode = os.environ.get('RAY_AUTH_MODE')
    hint = (f' (RAY_AUTH_MODE is {mode or "unset"} here). {AUTH_HELP}'
            if mode != 'token' else '; is the token the cluster\'s?')
    raise ClusterUnreachable(
        f'{where} {address}: could not join: {e}{hint}') from e


def init_ray(address: str = '', num_cpus: Optional[int] = None) -> bool:
  """Starts (or joins) Ray quietly; returns whether this call started it.

  Args:
    address: an existing cluster ('auto', 'host:port' of its head, ...);
      empty joins $RAY_ADDRESS when set (as `ray job submit` sets it), else
      starts a local instance with `num_cpus` CPUs, never joining a
      cluster that `ray start` left on this machine.
    num_cpus: CPUs of the local instance (None: all of this machine).

  Raises:
    ClusterUnreachable: nothing answers at `address`, or the cluster
      refused this process (e.g. without its token).
    LocalRayTimeout: the local instance did not start in Ray's 30 s (on
      2 cores beside two trainings, coop-train's did not).
  """
  import ray  # pylint: disable=g-import-not-at-top
  if ray.is_initialized():
    return False
  quiet = dict(logging_level=logging.WARNING, log_to_driver=False,
               configure_logging=True)
  if address:
    _join(address, quiet, '--ray-address')
    return True
  if os.environ.get('RAY_ADDRESS'):
    _join(os.environ['RAY_ADDRESS'], quiet, 'RAY_ADDRESS')
    return True
  # A local instance owned by this command: Ray's notice that it protects
  # the instance with a token (its default) is noise here.
  notice = logging.getLogger(
      'ray._private.authentication.authentication_token_setup')
  level = notice.level
  notice.setLevel(logging.ERROR)
  # Loopback only: Ray takes the machine's address as the node's and its
  # servers (GCS, raylet, workers, agents) listen on every interface; with
  # the loopback address as the node's they listen on 127.0.0.1. Ray turns
  # `_node_ip_address='127.0.0.1'` back into the external address; its
  # single-machine mode (the default on Windows and macOS) keeps loopback.
  from ray._private import ray_constants  # pylint: disable=g-import-not-at-top
  cluster_mode = ray_constants.ENABLE_RAY_CLUSTER
  ray_constants.ENABLE_RAY_CLUSTER = False
  try:
    # 'local': a new instance even where ray.init() would join the cluster
    # of the last `ray start` (/tmp/ray/ray_current_cluster).
    ray.init(address='local', num_cpus=num_cpus, include_dashboard=False,
             # No core metrics collection: nothing here reads it.
             _system_config={'enable_metrics_collection': False}, **quiet)
  except Exception as e:  # pylint: disable=broad-except
    if RAY_START_TIMEOUT not in str(e):  # Ray raises a bare Exception.
      raise
    raise LocalRayTimeout(
        f'Ray\'s local instance did not start: {e} Ray waits 30 s for its '
        'processes, which a machine busy with other work can exceed. Run '
        'the command again when the machine is less busy, or without Ray, '
        'in this one process: --actors 0.') from e
  finally:
    ray_constants.ENABLE_RAY_CLUSTER = cluster_mode
    notice.setLevel(level)
  return True


class RayPool:
  """`num_workers` rollout workers as Ray actors, restarted when they die."""

  def __init__(self, spec, config, num_envs: int, seeds, max_restarts: int = 3,
               restart_timeout: float = 300.0):
    """Args:
      spec: `EnvSpec` of the copies (controller bytes included).
      config: the `HierarchyConfig`.
      num_envs: copies per worker.
      seeds: one seed per worker (`worker_seeds`).
      max_restarts: restarts Ray grants each worker (-1: unlimited).
      restart_timeout: seconds to wait for a restarted worker to answer.
    """
    import ray  # pylint: disable=g-import-not-at-top
    if not ray.is_initialized():
      raise RuntimeError('RayPool needs Ray: call init_ray() first.')
    self._ray = ray
    remote = ray.remote(num_cpus=1, max_restarts=max_restarts,
                        max_task_retries=0)(rollout.RolloutWorker)
    # SPREAD: on a cluster, one actor per node in turn rather than filling
    # the learner's node first (one node: no difference).
    remote = remote.options(runtime_env={'env_vars': ACTOR_ENV_VARS},
                            scheduling_strategy='SPREAD')
    # The spec (with the controller's bytes) goes to the object store once
    # and reaches the workers with their first rollout, never as a
    # constructor argument: Ray cannot restart an actor whose large
    # constructor arguments it dropped (ray-project/ray#53727).
    self._spec_ref = ray.put(spec)
    cpus = ray.cluster_resources().get('CPU', 0)
    if cpus < len(seeds):
      print(f'Ray has {cpus:.0f} CPUs for {len(seeds)} actors of 1 CPU '
            'each: the rest wait until CPUs are added (an autoscaling '
            'cluster adds nodes).', flush=True)
    self._workers = [remote.remote(None, config, i, seed, num_envs)
                     for i, seed in enumerate(seeds)]
    self._max_restarts = max_restarts
    self._restart_timeout = restart_timeout
    self.restarts = 0
    self._restarts_per_worker = [0] * len(self._workers)

  def pids(self) -> list[int]:
    """Process ids of the workers (e.g. to kill one in a test)."""
    return self._ray.get([w.ping.remote() for w in self._workers])

  def collect(self, variables, update,
              on_result: Optional[Callable[[Any], None]] = None):
    """One rollout per worker, all with `variables` (see module doc).

    `on_result` sees each rollout as it arrives (completion order).
    """
    ray = self._ray
    variables_ref = ray.put(variables)  # Once; every worker reads the ref.
    submit = lambda i: self._workers[i].collect.remote(
        variables_ref, update, self._spec_ref)
    pending = {submit(i): i for i in range(len(self._workers))}
    results = {}
    while pending:
      ready, _ = ray.wait(list(pending), num_returns=1)
      for ref in ready:
        index = pending.pop(ref)
        try:
          result = ray.get(ref)
        except ray.exceptions.RayActorError as e:
          self._wait_for_restart(index, e)
          pending[submit(index)] = index
          continue
        results[index] = result
        if on_result is not None:
          on_result(result)
    return [results[i] for i in range(len(self._workers))]

  def _wait_for_restart(self, index: int, error: Exception) -> None:
    ray = self._ray
    self.restarts += 1
    self._restarts_per_worker[index] += 1
    if 0 <= self._max_restarts < self._restarts_per_worker[index]:
      raise RuntimeError(
          f'Actor {index} died more than --max-actor-restarts='
          f'{self._max_restarts} times; last error: {error}') from error
    deadline = time.monotonic() + self._restart_timeout
    while True:
      try:
        ray.get(self._workers[index].ping.remote(), timeout=30)
        return
      except (ray.exceptions.RayActorError,
              ray.exceptions.GetTimeoutError) as e:
        if time.monotonic() > deadline:
          raise RuntimeError(f'Actor {index} did not come back within '
                             f'{self._restart_timeout:.0f} s: {e}') from e
        time.sleep(0.5)

  def close(self):
    for worker in self._workers:
      self._ray.kill(worker)
    self._workers = []
