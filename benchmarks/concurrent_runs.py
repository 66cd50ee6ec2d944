"""Two trainings at once against one on this machine: env steps/s in all.

    python benchmarks/concurrent_runs.py
    python benchmarks/concurrent_runs.py --task transport --seconds 120

A training alternates: every actor collects, then the learner updates while
the actors wait (synchronous on-policy PPO). On the 2-core machine a fifth of
the wall is the learner alone on about one core, and a few percent more the
faster actor waiting for the slower (docs/performance.md, "Where a
training's time goes"). Two trainings side by side, each in one process
(`--actors 0`: one process steps its 32 copies, then updates), fill each
other's gaps. Both configurations train the same update (32 copies), as
`coop-paper --actors N` splits a cell's copies over its actors.

Alternates, --rounds times:
  one: coop-train --actors 2 --envs-per-actor 16   (coop-paper's default)
  two: two coop-train --actors 0 --envs-per-actor 32, started together
       (seeds 0 and 1)
each for --seconds, then stopped with SIGINT. A training's rate is its
env steps over the wall time between the first and the last of its
updates that ended in the window from --warmup to --seconds after the
start (the benchmark polls each metrics.csv, whose rows are written as
updates end), so what happens between updates counts and nothing after
the window does; "two" sums its pair's over the same window. Prints each
round's rates and the median ratio two / one: above 1, training two cells
at once gets more of the paper's plan done per hour (each cell then takes
longer). With --single-threaded the pair runs with the Ray actors'
one-thread settings.
"""
import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
sys.path.insert(0, REPO)

from runners import actor_pool  # pylint: disable=g-import-not-at-top
from runners import run_dir  # pylint: disable=g-import-not-at-top


def _start(task, n_agents, actors, copies, seed, logdir, env=None):
  command = [sys.executable, '-m', 'runners.train', '--task', task,
             '--n-agents', str(n_agents), '--actors', str(actors),
             '--envs-per-actor', str(copies), '--seed', str(seed),
             '--total-steps', str(10**9), '--logdir', logdir,
             '--no-progress']
  with open(logdir + '.log', 'w') as log:
    return subprocess.Popen(command, cwd=REPO, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True,
                            env={**os.environ, **(env or {})})


def _env_steps(logdir):
  """The newest row's env steps in the run's metrics.csv (0 before one; a
  row caught half-written reads as fewer, which `measure` skips)."""
  if not run_dir.has_metrics(logdir):
    return 0
  rows = run_dir.read_metrics(logdir)
  return int(rows[-1].get('env_steps', 0)) if rows else 0


def _stop(process):
  """SIGINT to the training (its Ray goes with it), then anything left of
  its process group killed."""
  if process.poll() is None:
    os.kill(process.pid, signal.SIGINT)
  try:
    process.wait(timeout=120)
  except subprocess.TimeoutExpired:
    pass
  try:
    os.killpg(process.pid, signal.SIGKILL)
  except ProcessLookupError:
    pass
  process.wait()


def measure(args, runs, folder, env=None):
  """Starts `runs` [(actors, copies, seed)] together (with `env` added to
  their environment) and stops them after --seconds; each one's env
  steps/s between the first and the last of its updates that ended in the
  shared window from --warmup to --seconds (seen by polling metrics.csv;
  its rows are written as updates end), and that window's update count."""
  os.makedirs(folder)
  logdirs = [os.path.join(folder, f'run{i}') for i in range(len(runs))]
  processes, seen = [], [[] for _ in runs]
  try:
    for (actors, copies, seed), logdir in zip(runs, logdirs):
      processes.append(_start(args.task, args.n_agents, actors, copies, seed,
                              logdir, env))
    begin = time.monotonic()
    while (now := time.monotonic() - begin) < args.seconds:
      for logdir, points in zip(logdirs, seen):
        steps = _env_steps(logdir)
        if now >= args.warmup and (not points or steps > points[-1][1]):
          points.append((now, steps))
      if any(p.poll() is not None for p in processes):
        raise RuntimeError('a training ended early: see the logs in '
                           f'{folder}')
      time.sleep(0.25)
  finally:
    for process in processes:
      _stop(process)
  rates = []
  for logdir, points in zip(logdirs, seen):
    if len(points) < 3:
      raise RuntimeError(f'{logdir}: {max(len(points) - 2, 0)} updates '
                         f'between {args.warmup:g} and {args.seconds:g} s; '
                         'give more --seconds')
    # From the first update that ended in the window to the last.
    (t0, s0), (t1, s1) = points[1], points[-1]
    rates.append(((s1 - s0) / (t1 - t0), len(points) - 2))
  return rates


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--task', default='corridor')
  parser.add_argument('--n-agents', type=int, default=4)
  parser.add_argument('--seconds', type=float, default=150.0,
                      help='wall time of each configuration in a round')
  parser.add_argument('--warmup', type=float, default=45.0,
                      help='seconds of start-up and compilation left out')
  parser.add_argument('--rounds', type=int, default=2)
  parser.add_argument('--single-threaded', action='store_true',
                      help='run the pair with the Ray actors\' one-thread '
                      'settings (runners.actor_pool.ACTOR_ENV_VARS): XLA '
                      'on one thread for the learner too')
  args = parser.parse_args(argv)
  env = actor_pool.ACTOR_ENV_VARS if args.single_threaded else None
  print(f'{args.task} with {args.n_agents} agents, {os.cpu_count()} CPUs, '
        f'{args.seconds:g} s a configuration, rates after {args.warmup:g} s'
        + (', the pair single-threaded' if env else ''), flush=True)
  ratios = []
  for round_ in range(args.rounds):
    folder = tempfile.mkdtemp(prefix='concurrent_runs_')
    (one, n_one), = measure(args, [(2, 16, 0)], os.path.join(folder, 'one'))
    pair = measure(args, [(0, 32, 0), (0, 32, 1)],
                   os.path.join(folder, 'two'), env)
    shutil.rmtree(folder)  # Kept, with the logs, when a measure fails.
    two = sum(rate for rate, _ in pair)
    ratios.append(two / one)
    print(f'round {round_ + 1}: one training (2 actors) {one:,.0f} env '
          f'steps/s ({n_one} updates); two trainings (one process each) '
          + ' + '.join(f'{rate:,.0f}' for rate, _ in pair)
          + f' = {two:,.0f} ({"/".join(str(n) for _, n in pair)} updates); '
          f'two / one {two / one:.3f}', flush=True)
  print(f'two / one, median over {args.rounds} rounds: '
        f'{float(np.median(ratios)):.3f}')


if __name__ == '__main__':
  main()
