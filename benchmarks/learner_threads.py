"""The species' learner updates one after the other against at the same time.

    python benchmarks/learner_threads.py [--rounds 6]

The ravine's joint task (2 pushers, 2 crossers: two species) with the
training defaults' batch for 2 actors: one actor's rollout of 16 copies,
its rows taken twice. The two ways of `learner_loop.step_learners`, each
update ending with the metrics on the host, alternate for `--rounds`;
prints each round's seconds and the median ratio in turn / at the same
time (each way goes first in every other round). Run it on an otherwise
idle machine: it measures how much of the learner's phase a second core
takes off.
"""
import argparse
import concurrent.futures
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))

import numpy as np  # pylint: disable=g-import-not-at-top

from runners import config as config_lib  # pylint: disable=g-import-not-at-top
from runners import learner_loop  # pylint: disable=g-import-not-at-top
from runners import rollout  # pylint: disable=g-import-not-at-top


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--rounds', type=int, default=6)
  args = parser.parse_args(argv)
  train_args = config_lib.train_args(task='ravine', n_agents=2, actors=2,
                                     progress=False)
  spec, _, learners = learner_loop.fresh_learners(train_args)
  worker = rollout.RolloutWorker(spec, train_args.hierarchy, 0, 0,
                                 train_args.envs_per_actor)
  result = worker.collect(learner_loop.actor_variables(learners), 0)
  worker.close()
  results = [result, result]  # Two actors' rows.
  with concurrent.futures.ThreadPoolExecutor(len(learners)) as threads:
    ways = {'in turn': None, 'at the same time': threads}
    for way in ways.values():  # Compilation.
      learner_loop.step_learners(learners, results, way)
    seconds = {name: [] for name in ways}
    for r in range(args.rounds):
      # Each first in every other round.
      for name, way in sorted(ways.items(), reverse=bool(r % 2)):
        begin = time.perf_counter()
        learner_loop.step_learners(learners, results, way)
        seconds[name].append(time.perf_counter() - begin)
      print(r, {k: round(v[-1], 3) for k, v in seconds.items()}, flush=True)
  ratios = np.divide(seconds['in turn'], seconds['at the same time'])
  print(f'{os.cpu_count()} CPUs; species {sorted(learners)}; median '
        f'seconds: in turn {np.median(seconds["in turn"]):.3f}, at the same '
        f'time {np.median(seconds["at the same time"]):.3f}; in turn / at '
        f'the same time {np.median(ratios):.2f} (per round '
        f'{min(ratios):.2f}-{max(ratios):.2f})')


if __name__ == '__main__':
  main()
