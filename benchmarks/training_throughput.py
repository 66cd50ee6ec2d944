"""Training throughput as ratios to raw MuJoCo, all measured in one run.

    python benchmarks/training_throughput.py
    python benchmarks/training_throughput.py --task corridor --updates 6

"raw" is the loop a bare simulator runs on the very same compiled model:
set `ctrl`, then one `mujoco.mj_step` per physics substep. It replays the
controls the measured loop applied, from the same start state (a copy of
the MjData), so both go through the same trajectory, contacts included.
Timed loops and their raw replays alternate in blocks; a ratio is the
median over the blocks of raw time / measured time. Prints:

  composer step, per-agent list of actions / raw   (target >= 0.85)
  composer step, one [n, 8] array / raw
  environment + lower layer, copies in lockstep / raw
                                   (`EnvBatch`; one core; target >= 0.70)
  environment + lower layer, copy by copy / raw
                                   (each copy's `CommandWrapper.step`)
  pipeline with N actors / (N x raw), N = 1, 2     (target >= 0.60 at 2)
    = an actor's rollout per CPU second / raw   (what its code makes of a
                                                 core)
      x its CPU share while it collects         (contention)
      x the share of the wall it collects       (the rest it waits: the
                                                 learner, the slowest
                                                 actor, transfers)
    (an actor's own rollout / raw: per second of its rollouts)
  the learner's share of the wall with the most actors

The pipeline's rate is over the wall time from the first update's end to
the last's, all of `coop-train`'s loop (metrics and checkpoints too), and
factors exactly into the three lines under it (the actors' own clocks,
`Rollout.seconds` and `Rollout.cpu_seconds`). Its raw is the one-core raw
rate; the pipeline's trajectories are its policy's, not the replayed ones.

`--actors 1 2 4 8 14` measures the pipeline for those actor counts instead
(the scaling curve, on a machine with that many cores; the one-core raw
rate stays the reference).

A raw rate belongs to its trajectory: MuJoCo's cost per step moves with it
(a trained transport policy's trajectories replay ~1.4x slower
than random commands'; `step_breakdown.py --rollout` measures a policy's,
docs/performance.md "Inside an actor's rollout").

The one-core loops run in a child process pinned to one CPU with the
actors' single-threaded settings (`actor_pool.ACTOR_ENV_VARS`); the
pipelines are `coop-train`'s own loop (`learner_loop.train`, Ray actors)
with the default training settings, the first update (start-up,
compilation) left out. Commands are random; the shipped lower layer
walks unless --controller is given.
"""
import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))

import mujoco  # pylint: disable=g-import-not-at-top
import numpy as np  # pylint: disable=g-import-not-at-top

from runners import actor_pool  # pylint: disable=g-import-not-at-top
from runners import config as config_lib  # pylint: disable=g-import-not-at-top
from runners import learner_loop  # pylint: disable=g-import-not-at-top
from runners import rollout  # pylint: disable=g-import-not-at-top

LONG_EPISODE = 10_000.0
"""Seconds: no episode ends inside a measurement."""


class _Controls:
  """Records the controls a coop_suite environment applies at each step,
  with the physics state each block, and each episode begun inside it,
  starts from, for a raw replay."""

  def __init__(self, env):
    self._env = env
    self.segments = []  # [(model, MjData at the segment's start, controls)]
    # `step_outcome` ends every step, whole or in phases; older commits (the
    # "before" figures of docs/performance.md) step only through `step`.
    name = 'step_outcome' if hasattr(env, 'step_outcome') else 'step'
    inner, reset = getattr(env, name), env.reset

    def recording(*args, **kwargs):
      timestep = inner(*args, **kwargs)
      self.segments[-1][2].append(self._data.ctrl.copy())
      return timestep

    def resetting():
      timestep = reset()
      self._segment()  # A new episode: the replay starts from its state.
      return timestep
    setattr(env, name, recording)
    env.reset = resetting
    self.begin()

  @property
  def steps(self) -> int:
    """Control steps recorded since `begin`."""
    return sum(len(controls) for _, _, controls in self.segments)

  def begin(self):
    """Marks the start of a block."""
    self.segments = []
    self._segment()

  def _segment(self):
    physics = self._env.physics  # A reset may have recompiled it.
    self._data = physics.data.ptr  # MuJoCo's own: dm_control's view costs.
    model = physics.model.ptr
    start = mujoco.MjData(model)
    mujoco.mj_copyData(start, model, self._data)
    self.segments.append((model, start, []))

  def replay_seconds(self, substeps):
    """Seconds of the raw loop through the block's controls."""
    seconds = 0.0
    for model, start, controls in self.segments:
      data = mujoco.MjData(model)
      mujoco.mj_copyData(data, model, start)
      begin = time.perf_counter()
      for control in controls:
        data.ctrl[:] = control
        for _ in range(substeps):
          mujoco.mj_step(model, data)
      seconds += time.perf_counter() - begin
    return seconds


def _ratio(run_block, recorders, substeps, blocks):
  """Median over blocks of (raw replay seconds / `run_block()` seconds),
  and the raw loop's median rate in control steps/s."""
  ratios, raw_rates = [], []
  for _ in range(blocks):
    for recorder in recorders:
      recorder.begin()
    begin = time.perf_counter()
    run_block()
    seconds = time.perf_counter() - begin
    raw = sum(r.replay_seconds(substeps) for r in recorders)
    ratios.append(raw / seconds)
    raw_rates.append(sum(r.steps for r in recorders) / raw)
  return float(np.median(ratios)), float(np.median(raw_rates))


def one_core(args):
  """The single-process ratios (run in the pinned child)."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  out = {}
  rng = np.random.default_rng(0)
  env = coop_suite.load(args.task, args.n_agents, seed=0,
                        time_limit=LONG_EPISODE)
  env.reset()
  substeps = env.task.physics_steps_per_control_step
  recorder = _Controls(env)
  arrays = rng.uniform(-1, 1, (args.block_steps, env.n_agents, 8))
  lists = [list(action) for action in arrays]  # The documented convention.
  for name, actions in (('composer_list', lists),
                        ('composer_array', arrays)):
    def block(actions=actions):
      for action in actions:
        env.step(action)
    block()  # Warm-up.
    out[name], out['raw_steps_per_s'] = _ratio(block, [recorder], substeps,
                                               args.blocks)
  env.close()

  train_args = _train_args(args, 1, '', time_limit=LONG_EPISODE)
  spec = learner_loop.environment_spec(train_args)
  batch = rollout.EnvBatch(spec, train_args.hierarchy,
                           range(args.envs_per_actor), global_state=False)
  recorders = [_Controls(copy.env) for copy in batch.envs]
  periods = max(1, args.block_steps // (batch.envs[0].low_level_steps
                                         * args.envs_per_actor))
  (species,) = batch.species  # Every agent commanded alike.
  commands = rng.uniform(-3, 3, (periods, args.envs_per_actor,
                                 len(species.agents), 2))

  def lockstep():
    for command in commands:
      batch.step({species.name: command.reshape(-1, 2)})

  def copy_by_copy():
    for command in commands:
      for copy, copy_command in zip(batch.envs, command):
        copy.step(copy_command)
  for name, block in (('lockstep', lockstep), ('copy_by_copy', copy_by_copy)):
    block()  # Warm-up (the controller's compilation).
    out[name], _ = _ratio(block, recorders, substeps, args.blocks)
  batch.close()
  return out


def pipeline(args, actors, logdir):
  """The pipeline's rate and its factors, `coop-train`'s loop with `actors`.

  Returns {'rate': env steps/s, 'learn': the learner's share of the wall,
  'own': an actor's env steps per second of its rollouts, 'own_cpu': per
  CPU second of them, 'cpu_share': CPU seconds / seconds of the rollouts,
  'collecting': the actors' rollout seconds / (actors x wall)}.

  The rate is over the wall time between the first update's end and the
  last's (everything the loop does: rollouts, learner steps, metrics,
  checkpoints). It factors exactly as
      rate / (actors x raw) = own_cpu / raw x cpu_share x collecting:
  what an actor's code makes of a core, how much of a core it gets while it
  collects, and how much of the time it collects at all (the rest it waits
  for the learner, the slowest actor, transfers). `Rollout.seconds` and
  `Rollout.cpu_seconds` are the actor's own clocks.
  """
  rows, rollouts, ends = [], [], []
  collect = actor_pool.RayPool.collect

  def recording(pool, *a, **kw):
    results = collect(pool, *a, **kw)
    rollouts.append([(r.env_steps, getattr(r, 'seconds', float('nan')),
                      getattr(r, 'cpu_seconds', float('nan')))
                     for r in results])  # Older commits lack the clocks.
    return results

  def on_update(update, row, pool):
    del update, pool
    ends.append(time.perf_counter())
    rows.append(row)
  train_args = _train_args(args, actors, logdir)
  per_update = (actors * args.envs_per_actor
                * train_args.hierarchy.sequence_length
                * round(train_args.command_period / 0.05))
  train_args = dataclasses.replace(
      train_args, total_steps=per_update * args.updates)
  # The callback by position: older commits (the "before" figures of
  # docs/performance.md) name the parameter on_iteration.
  actor_pool.RayPool.collect = recording
  try:
    learner_loop.train(train_args, on_update)
  finally:
    actor_pool.RayPool.collect = collect
  # Without the first update (start-up, compilation).
  wall = ends[-1] - ends[0]
  own = [r for update in rollouts[1:] for r in update]
  steps, seconds, cpu = (sum(column) for column in zip(*own))
  learn = sum(r['time/learn'] for r in rows[1:])
  return {'rate': steps / wall, 'learn': learn / wall,
          'own': steps / seconds, 'own_cpu': steps / cpu,
          'cpu_share': cpu / seconds,
          'collecting': seconds / (actors * wall)}


def _train_args(args, actors, logdir, **overrides):
  return config_lib.TrainArgs(**{
      'task': args.task, 'n_agents': args.n_agents, 'actors': actors,
      'envs_per_actor': args.envs_per_actor, 'logdir': logdir,
      'controller': args.controller, 'progress': False, 'total_steps': 1,
      **overrides})


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--task', default='transport')
  parser.add_argument('--n-agents', type=int, default=4)
  parser.add_argument('--envs-per-actor', type=int,
                      default=config_lib.TrainArgs.envs_per_actor)
  parser.add_argument('--updates', type=int, default=6,
                      help='pipeline updates, the first left out')
  parser.add_argument('--block-steps', type=int, default=400,
                      help='control steps per timed block (all copies)')
  parser.add_argument('--blocks', type=int, default=9)
  parser.add_argument('--controller', default='')
  parser.add_argument('--actors', type=int, nargs='+', default=[1, 2],
                      help='actor counts of the pipeline rows')
  parser.add_argument('--one-core', action='store_true',
                      help=argparse.SUPPRESS)  # The child's part.
  args = parser.parse_args(argv)
  if min(args.actors) < 1:
    parser.error(f'--actors must be >= 1, got {args.actors}')
  if args.updates < 2:
    parser.error(f'--updates must be >= 2 (the first is left out), got '
                 f'{args.updates}')
  if args.one_core:
    print(json.dumps(one_core(args)))
    return
  cpu = sorted(os.sched_getaffinity(0))[-1]
  child = subprocess.run(
      ['taskset', '-c', str(cpu), sys.executable, __file__, '--one-core',
       *(argv if argv is not None else sys.argv[1:])],
      env={**os.environ, **actor_pool.ACTOR_ENV_VARS}, check=True,
      capture_output=True, text=True)
  single = json.loads(child.stdout.strip().splitlines()[-1])
  raw = single['raw_steps_per_s']
  print(f'one core: raw {raw:.0f} control steps/s; ' + ', '.join(
      f'{k} / raw {v:.2f}' for k, v in single.items()
      if k != 'raw_steps_per_s'), flush=True)
  actor_pool.init_ray(num_cpus=max(2, os.cpu_count(), *args.actors))
  pipelines = {}
  with tempfile.TemporaryDirectory() as tmp:
    for n in args.actors:
      pipelines[n] = pipeline(args, n, os.path.join(tmp, str(n)))
      # As it goes: a long scaling curve cut short keeps what it measured.
      print(f'pipeline, {n} actor{"s" * (n > 1)}: '
            f'{pipelines[n]["rate"]:.0f} env steps/s (an actor\'s own '
            f'rollout: {pipelines[n]["own"]:.0f} env steps/s, '
            f'{pipelines[n]["own_cpu"]:.0f} per CPU second)', flush=True)
  print(f'{args.task}, {args.n_agents} agents, {args.envs_per_actor} copies '
        f'per actor, {os.cpu_count()} CPUs; raw {raw:.0f} control steps/s '
        'on one core')
  lines = [
      ('composer step, per-agent list / raw', single['composer_list'],
       '>= 0.85'),
      ('composer step, [n, 8] array / raw', single['composer_array'], ''),
      ('env + lower layer, lockstep / raw', single['lockstep'], '>= 0.70'),
      ('env + lower layer, copy by copy / raw', single['copy_by_copy'], ''),
  ]
  for n, p in pipelines.items():
    lines += [
        (f'pipeline, {n} actor{"s" * (n > 1)} / ({n} x raw)',
         p['rate'] / (n * raw), '>= 0.60' if n == 2 else ''),
        ("  = an actor's rollout per CPU second / raw", p['own_cpu'] / raw,
         ''),
        ('    x its CPU share while it collects', p['cpu_share'], ''),
        ('    x the share of the wall it collects', p['collecting'], ''),
        ("  (an actor's own rollout / raw)", p['own'] / raw, '')]
  most = max(pipelines)
  lines.append((f"learner's share of the wall, {most} actors",
                pipelines[most]['learn'], ''))
  for name, value, target in lines:
    print(f'{name:46s} {value:5.2f}  {target}')


if __name__ == '__main__':
  main()
