"""The learner's loop: synchronous on-policy PPO over a pool of actors.

    summary = learner_loop.train(TrainArgs(task='transport', n_agents=4))

The one training loop: every variant, and the lower layer's pretraining
(`agent='lowlevel'`, which `runners.pretrain_lowlevel` sets up).

One update (number u):
  1. every species' variables (params, observation statistics) are fetched
     from its `HierarchyLearner` once and handed to the pool (Ray: one
     `ray.put`, every actor reads the reference);
  2. every actor collects `sequence_length` commands of its copies with
     the variables of update u (`RolloutWorker.collect`); a dead actor is
     restarted and its rollout redone with the same ones
     (`actor_pool.RayPool`);
  3. each species' learner trains once on the union of its rows from all
     actors (`types.concatenate`, in actor order, so a run is reproducible
     whatever order the rollouts arrived in), the species at the same time
     (`step_learners`);
  4. a row goes to metrics.csv / TensorBoard / the progress bar, and every
     `checkpoint_every` updates a checkpoint (`runners.checkpoints`).

The run lasts ceil(total_steps / nominal steps per update) updates,
nominal = actors x envs_per_actor x sequence_length x low-level steps per
command, and more while it has taken fewer than total_steps (an episode
that ends inside a command period takes fewer steps than nominal); a
resumed run collects what is left of total_steps at its own batch
size. Ctrl-C / SIGTERM stop after the current update with a
checkpoint; `--resume` continues from the newest one.
"""
import concurrent.futures
import dataclasses
import math
import os
import time
from typing import Any, Callable, Optional

import jax
import numpy as np

from agents.hierarchy import builder as hierarchy_builder
from agents.ppo import types
from runners import actor_pool
from runners import checkpoints
from runners import config as config_lib
from runners import envs as envs_lib
from runners import metrics as metrics_lib
from runners import rollout
from runners import run_dir


def check_run_directory(args: config_lib.TrainArgs) -> Optional[str]:
  """The checkpoint to resume from (None for a new run); raises when the
  directory holds another run or the settings differ from the saved ones."""
  if args.resume_from:
    checkpoint = checkpoints.resolve(args.resume_from)
    if checkpoints.run_directory(checkpoint) != os.path.abspath(args.logdir):
      raise ValueError(f'--resume-from {args.resume_from} is not a checkpoint '
                       f'of --logdir {args.logdir}.')
  elif args.resume:
    checkpoint = checkpoints.resolve(args.logdir)
  if args.resume:
    saved = checkpoints.read_state(checkpoint)
    checkpoints.check_resumable(checkpoint, saved)
    config_lib.check_resumable(saved['args'], args)
    return checkpoint
  if (checkpoints.list_checkpoints(args.logdir)
      or run_dir.has_metrics(args.logdir)):
    raise FileExistsError(f'{args.logdir} already holds a run: pass --resume '
                          'or choose another --logdir.')
  return None


def _controller_copy(args: config_lib.TrainArgs) -> str:
  """Where the run keeps its lower layer: a resumed run and its evaluation
  use the controller the policy was trained with, whatever --controller
  says then."""
  return os.path.join(args.logdir, 'controller')


def _has_controller_copy(args: config_lib.TrainArgs) -> bool:
  return args.resume and os.path.exists(
      os.path.join(_controller_copy(args), 'config.json'))


def environment_spec(args: config_lib.TrainArgs) -> envs_lib.EnvSpec:
  """The run's environments, with its lower layer (the run's copy when
  resuming); writes nothing."""
  files = None
  uses_commands = args.hierarchy.uses_commands
  if uses_commands:
    files = envs_lib.read_controller(
        args.paradigm, _controller_copy(args) if _has_controller_copy(args)
        else args.controller)
  return envs_lib.EnvSpec(args.task, args.n_agents, args.env_options(),
                          uses_commands, args.command_period, files,
                          args.hierarchy.adds_locomotion_terms)


def probe(spec: envs_lib.EnvSpec, config):
  """(species layout, episode metric keys, low-level steps per action,
  control timestep) from one throw-away copy."""
  env = spec.make(0)
  try:
    layout = envs_lib.species_layout(env, config)
    env.reset()
    n_actions = layout[0].action_size
    env.step(np.zeros((env.n_agents, n_actions)))
    keys = metrics_lib.episode_keys(env.episode_metrics())
    dt = envs_lib.control_timestep(env)
    per_action = int(round(env.control_timestep() / dt))
  finally:
    env.close()
  return layout, keys, per_action, dt


def train(args: config_lib.TrainArgs,
          on_update: Optional[Callable[..., None]] = None,
          deadline: Optional[float] = None) -> dict[str, Any]:
  """Runs (or resumes) a run; returns its last row plus 'checkpoint' and
  'stopped_by' (None, a signal's name, or `run_dir.DEADLINE`).

  `on_update(update, row, pool)` is called after every update. Past
  `deadline` (`run_dir.clock()` seconds) the run stops after its update
  with a checkpoint, as on SIGTERM.
  """
  # Options the task refuses (a stage it lacks, an agent count out of its
  # range) fail here, before the run directory exists.
  import coop_suite  # pylint: disable=g-import-not-at-top
  coop_suite.check_options(args.task, args.n_agents, **args.env_options())
  # One writer per run directory, from the check that it is free to the end.
  with run_dir.RunLock(args.logdir):
    # Ray first, before the checkpoints are read (orbax starts JAX): its
    # processes are then not started from a process where JAX runs threads.
    owns_ray = args.actors > 0 and actor_pool.init_ray(
        args.ray_address, num_cpus=max(os.cpu_count(), args.actors))
    try:
      checkpoint = check_run_directory(args)
      print(f'Writing to {os.path.abspath(args.logdir)}'
            + (f', resuming from {checkpoint}' if checkpoint else ''),
            flush=True)
      return _train(args, checkpoint, on_update, deadline)
    finally:
      if owns_ray:
        import ray  # pylint: disable=g-import-not-at-top
        ray.shutdown()


def actor_variables(learners) -> dict[str, dict[str, Any]]:
  """What the actors act with: {species: {variable name: numpy pytree}}
  of each learner's `rollout.VARIABLE_NAMES`."""
  return {name: dict(zip(rollout.VARIABLE_NAMES, jax.device_get(
      learner.get_variables(rollout.VARIABLE_NAMES))))
          for name, learner in learners.items()}


def step_learners(learners, results, threads=None) -> dict[str, float]:
  """One update of every species' learner on its rows of `results` (in
  actor order); returns their metrics as one row (`learner/<species>/...`).

  With `threads` (an executor), the species' updates run at the same time:
  each is one compiled XLA call that releases the GIL, and one alone
  leaves much of a second core idle (`benchmarks/learner_threads.py`,
  docs/performance.md). The learners share nothing, so the numbers are
  those of one after the other.
  """
  def step(name):
    batch = types.concatenate([r.batches[name] for r in results])
    return jax.device_get(learners[name].step(batch))

  if threads is None:
    metrics = {name: step(name) for name in learners}
  else:
    futures = {name: threads.submit(step, name) for name in learners}
    metrics = {name: future.result() for name, future in futures.items()}
  row = {}
  for name in learners:  # The species' order, whatever finished first.
    row.update(metrics_lib.learner_row(name, metrics[name]))
  return row


def fresh_learners(args: config_lib.TrainArgs):
  """(spec, species layout, {species: fresh learner}) of a run of `args`,
  before any checkpoint or --init-from (benchmarks and tests)."""
  spec = environment_spec(args)
  layout = probe(spec, args.hierarchy)[0]
  return spec, layout, make_learners(args.hierarchy, layout)


def make_learners(config, layout) -> dict[str, Any]:
  """A fresh learner per species: {species name: HierarchyLearner}."""
  learners = {}
  for s in layout:
    builder = hierarchy_builder.HierarchyBuilder(config, s.species_id)
    learners[s.name] = builder.make_learner(builder.make_networks(
        s.observation_size, s.action_size, s.global_state_size))
  return learners


def initialize_from_runs(args: config_lib.TrainArgs,
                         learners: dict[str, Any]) -> None:
  """`--init-from`: each named species starts from its learner in another
  run of the same task (parameters and normalisers, fresh optimiser).

  Raises:
    ValueError: a species this run lacks or the other run lacks, a run of
      another task, or other networks (naming the file).
    FileNotFoundError: a path that holds no checkpoint.
  """
  for species, path in args.init_sources().items():
    where = f'--init-from {species}={path}'
    if species not in learners:
      raise ValueError(f'{where}: this run has no species {species!r}; it '
                       f'has {sorted(learners)}.')
    source = checkpoints.resolve(path)
    saved = checkpoints.read_state(source)
    task = saved.get('args', {}).get('task')
    if task != args.task:
      raise ValueError(f'{where}: {source} is a {task!r} run, this one is '
                       f'{args.task!r}.')
    names = [s['name'] for s in saved.get('species', [])]
    if species not in names:
      raise ValueError(f'{where}: {source} has species {names}, not '
                       f'{species!r}.')
    learners[species].initialize_from(
        checkpoints.saved_learner(source, species),
        source=f'{source} ({species})')
    print(f'{species}: parameters and normalisers from {source}', flush=True)


def _train(args, checkpoint, on_update, deadline):
  config = args.hierarchy
  spec = environment_spec(args)
  layout, keys, per_action, dt = probe(spec, config)
  for s in layout:
    rows = args.num_actors * args.envs_per_actor * len(s.agents)
    if rows % config.num_minibatches:
      raise ValueError(
          f'Species {s.name!r} has {rows} agents per update (actors x '
          f'envs-per-actor x {len(s.agents)}), not divisible by '
          f'--num-minibatches {config.num_minibatches}.')
  if spec.controller_files and not _has_controller_copy(args):
    # Once the settings are known to work; whole or not at all.
    run_dir.write_directory(_controller_copy(args), spec.controller_files)
  learners = make_learners(config, layout)
  if checkpoint is None:
    initialize_from_runs(args, learners)
  counters = {'update': 0, 'env_steps': 0, 'episodes': 0,
              'wall_time': 0.0, 'restarts': 0}
  window = metrics_lib.EpisodeWindow(keys, args.window, dt)
  best_score = None  # (success, return) of the best full window so far.
  if checkpoint is not None:
    saved = checkpoints.restore(checkpoint, learners)
    counters.update({k: saved[k] for k in counters})
    window.restore(saved.get('window', []))
    if saved.get('best_score') is not None:  # JSON gives a list.
      best_score = tuple(saved['best_score'])
    # Later updates are redone, as the metrics rows after this one.
    checkpoints.discard_after(args.logdir, counters['update'])
  state = {'args': args.to_dict(), 'agent_config': config_lib.json_safe(
      dataclasses.asdict(config)), 'species': [s.to_dict() for s in layout]}
  per_update = (args.num_actors * args.envs_per_actor
                   * config.sequence_length * per_action)

  def updates_to_go():
    """Updates for what is left of the budget, at today's batch size (a
    resumed run may collect more or less per update than before)."""
    return math.ceil(max(0, args.total_steps - counters['env_steps'])
                     / per_update)
  updates = counters['update'] + updates_to_go()
  n_agents = sum(len(s.agents) for s in layout)

  log = run_dir.MetricsLog(
      args.logdir, metrics_lib.columns(keys, learners),
      resume_update=counters['update'] if checkpoint else None)
  progress = metrics_lib.Progress(updates * per_update,
                                  counters['env_steps'], args.progress)
  saved_at = counters['update']  # The update whose state is on disk.
  restarts_at_start = counters['restarts']
  learning = False
  row = {}

  def save(score=None):
    return writer.save(learners, {**counters, **state,
                                  'window': window.state(),
                                  'best_score': best_score}, score)

  pool = threads = None
  # Each checkpoint is written while the next update is collected; `close`
  # waits for the last (checkpoints.Writer).
  writer = checkpoints.Writer(args.logdir, args.keep_checkpoints)
  try:
    pool = _make_pool(args, spec, config, counters['update'])
    if len(learners) > 1:  # The species' updates at the same time.
      threads = concurrent.futures.ThreadPoolExecutor(len(learners))
    with run_dir.GracefulStop(deadline) as stop:
      while counters['update'] < updates and not stop.requested:
        tick = time.perf_counter()
        variables = actor_variables(learners)
        results = pool.collect(variables, counters['update'])
        collected = time.perf_counter()
        assert all(r.update == counters['update'] for r in results)
        learning = True  # Learners change now: no checkpoint on error.
        losses = step_learners(learners, results, threads)
        seconds = time.perf_counter() - tick
        steps = sum(r.env_steps for r in results)
        episodes = [e for r in results for e in r.episodes]
        counters['update'] += 1
        counters['env_steps'] += steps
        counters['episodes'] += len(episodes)
        counters['wall_time'] += seconds
        counters['restarts'] = restarts_at_start + pool.restarts
        learning = False
        more = updates_to_go() if counters['update'] == updates else 0
        if more:
          # Episodes that ended inside a command period (a crosser falling
          # into the ravine) took fewer steps than nominal: go on until the
          # budget is spent, as a resumed run would.
          updates += more
          progress.extend(more * per_update)
        window.extend(episodes)
        row = {'update': counters['update'],
               'env_steps': counters['env_steps'],
               'agent_steps': counters['env_steps'] * n_agents,
               'wall_time': round(counters['wall_time'], 2),
               'sps': steps / seconds, 'agent_sps': steps * n_agents / seconds,
               'episodes': counters['episodes'], **window.summary(), **losses,
               'time/collect': collected - tick,
               'time/learn': seconds - (collected - tick),
               'restarts': counters['restarts']}
        log.write(row)
        progress.update(row, steps)
        score = _window_score(row) if window.full else None
        best = args.keep_best and score and (best_score is None
                                             or score > best_score)
        if best:
          best_score = score
        if (best or counters['update'] % args.checkpoint_every == 0
            or counters['update'] == updates or stop.requested):
          save(score if best else None)
          saved_at = counters['update']
        if on_update is not None:
          on_update(counters['update'], row, pool)
      if saved_at < counters['update']:  # A stop after the update's save test.
        save()
        saved_at = counters['update']
  except BaseException:
    if not learning and saved_at < counters['update']:
      save()  # The last complete update is not lost.
    raise
  finally:
    progress.close()
    log.close()
    if threads is not None:  # Its last update has returned or raised.
      threads.shutdown(wait=False, cancel_futures=True)
    try:
      if pool is not None:
        pool.close()
    finally:
      writer.close()
  return {**row, 'updates': updates, 'stopped_by': stop.reason,
          'checkpoint': (checkpoints.list_checkpoints(args.logdir) or [''])[-1]}


def _window_score(row):
  """(success, return) means of the episode window, or None if undefined."""
  score = (row.get('success'), row.get('return'))
  if any(v is None or not np.isfinite(v) for v in score):
    return None
  return tuple(float(v) for v in score)


def _make_pool(args, spec, config, update):
  seeds = actor_pool.worker_seeds(args.seed, update, args.num_actors)
  if args.actors == 0:
    return actor_pool.LocalPool(spec, config, args.envs_per_actor, seeds[0])
  return actor_pool.RayPool(spec, config, args.envs_per_actor, seeds,
                            max_restarts=args.max_actor_restarts)
