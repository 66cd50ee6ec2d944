"""One actor's rollout in this process against the same in a Ray actor.

    python benchmarks/actor_loop.py [--rounds 4]

Transport with 4 Ants and the training defaults (16 copies, 32 commands a
rollout, the shipped lower layer). A `RolloutWorker` here (this thread
pinned to one core once Ray has started, the actors' single-threaded
settings) and one as a Ray actor (not pinned)
(`actor_pool.RayPool`) collect in turn with the same variables, a fresh
learner's and then, each round, those after one learner step on the Ray
actor's rollout. Prints env steps/s per round and the medians:

  local_v0, ray_v0_own, ray_v0_driver    the fresh variables: here; in the
                                         Ray actor by its own clock
                                         (`Rollout.seconds`); the same seen
                                         from this process (transfers
                                         included)
  local_trained, ray_trained_own         the learner's variables

What separates an actor's loop from Ray's part of the pipeline; the
pipeline's own figures are `training_throughput.py`'s.
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))

from runners import actor_pool  # pylint: disable=g-import-not-at-top

os.environ.update(actor_pool.ACTOR_ENV_VARS)  # Before JAX is imported.

import jax  # pylint: disable=g-import-not-at-top
import numpy as np  # pylint: disable=g-import-not-at-top

from agents.ppo import types  # pylint: disable=g-import-not-at-top
from runners import config as config_lib  # pylint: disable=g-import-not-at-top
from runners import learner_loop  # pylint: disable=g-import-not-at-top
from runners import rollout  # pylint: disable=g-import-not-at-top


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--rounds', type=int, default=4)
  args = parser.parse_args(argv)
  train_args = config_lib.TrainArgs(task='transport', n_agents=4, actors=1,
                                    progress=False)
  spec, _, learners = learner_loop.fresh_learners(train_args)
  config = train_args.hierarchy

  fresh = learner_loop.actor_variables(learners)
  copies = train_args.envs_per_actor
  local = rollout.RolloutWorker(spec, config, 0, 0, copies)
  actor_pool.init_ray(num_cpus=max(2, os.cpu_count()))
  pool = actor_pool.RayPool(spec, config, copies, [0])
  try:
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})
    local.collect(fresh, 0)  # Start-up and compilation, both.
    pool.collect(fresh, 0)
    _rounds(args.rounds, local, pool, fresh, learners)
  finally:
    pool.close()


def _rounds(rounds, local, pool, fresh, learners):
  """Alternates the two workers; prints each round and the medians."""
  out = {k: [] for k in ('local_v0', 'ray_v0_own', 'ray_v0_driver',
                         'local_trained', 'ray_trained_own')}
  for r in range(rounds):
    begin = time.perf_counter()
    result = local.collect(fresh, 1)
    out['local_v0'].append(result.env_steps / (time.perf_counter() - begin))
    begin = time.perf_counter()
    (result,) = pool.collect(fresh, 1)
    seen = time.perf_counter() - begin
    out['ray_v0_own'].append(result.env_steps / result.seconds)
    out['ray_v0_driver'].append(result.env_steps / seen)
    for name, learner in learners.items():
      jax.device_get(learner.step(types.concatenate([result.batches[name]])))
    trained = learner_loop.actor_variables(learners)
    begin = time.perf_counter()
    result = local.collect(trained, 1)
    out['local_trained'].append(result.env_steps
                                / (time.perf_counter() - begin))
    (result,) = pool.collect(trained, 1)
    out['ray_trained_own'].append(result.env_steps / result.seconds)
    print(r, {k: round(v[-1]) for k, v in out.items()}, flush=True)
  print('median', {k: round(float(np.median(v))) for k, v in out.items()})


if __name__ == '__main__':
  main()
