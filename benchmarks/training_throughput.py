"""Throughput of the distributed training pipeline (coop-train's loop).

    PYTHONPATH=. python benchmarks/training_throughput.py
    PYTHONPATH=. python benchmarks/training_throughput.py --task corridor \
        --envs-per-actor 8 --iterations 6

Prints, in agent-environment steps per second (low-level 0.05 s control
steps x agents):
  * bare: the same CommandWrapper copies stepped with random commands in
    one process through the same stepping layer (`rollout.EnvBatch`), no
    policy and no learning;
  * pipeline with 1 and with 2 Ray actors: whole synchronous iterations
    (collect + learn), the first iteration (start-up, compilation) left out;
    the 2 / 1 ratio and the fraction of bare throughput the 1-actor
    pipeline keeps;
  * the learner's seconds per 64k samples (commands) with the default
    network sizes and PPO settings.
Uses the shipped lower layer unless --controller is given.
"""
import argparse
import math
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))

import numpy as np  # pylint: disable=g-import-not-at-top

from runners import actor_pool  # pylint: disable=g-import-not-at-top
from runners import config as config_lib  # pylint: disable=g-import-not-at-top
from runners import learner_loop  # pylint: disable=g-import-not-at-top
from runners import rollout  # pylint: disable=g-import-not-at-top


def bare(args, train_args, seconds):
  """Agent steps / s of EnvBatch with random commands, one process."""
  config = config_lib.hierarchy_config(train_args)
  spec = learner_loop.environment_spec(train_args)
  batch = rollout.EnvBatch(spec, config, range(args.envs_per_actor))
  rng = np.random.default_rng(0)
  n_agents = batch.envs[0].n_agents

  def random_actions():
    return {s.name: rng.uniform(*s.action_bounds,
                                size=(len(batch.rows[s.name][1]), 2))
            for s in batch.species}
  batch.step(random_actions())  # Warm-up (controller compilation).
  steps, start = 0, time.perf_counter()
  while time.perf_counter() - start < seconds:
    steps += batch.step(random_actions())[2]
  elapsed = time.perf_counter() - start
  batch.close()
  return steps * n_agents / elapsed


def pipeline(args, actors, logdir):
  """Agent steps / s of whole training iterations with `actors` actors."""
  rows = []
  train_args = _train_args(args, actors, logdir)
  per_iteration = (actors * args.envs_per_actor * train_args.sequence_length
                   * round(train_args.command_period / 0.05))
  train_args = config_lib.TrainArgs(**{
      **vars(train_args), 'total_steps': per_iteration * args.iterations})
  learner_loop.train(train_args,
                     on_iteration=lambda i, row, pool: rows.append(row))
  steps = [r['agent_steps'] - p['agent_steps']
           for r, p in zip(rows[1:], rows)]  # Without the first iteration.
  seconds = sum(n / r['agent_sps'] for n, r in zip(steps, rows[1:]))
  return sum(steps) / seconds, np.mean([r['time/learn'] for r in rows[1:]])


def learner_seconds(args, samples=65536):
  """Seconds of one learner step on `samples` commands (default sizes)."""
  import jax  # pylint: disable=g-import-not-at-top
  from agents.hierarchy import builder as hierarchy_builder  # pylint: disable=g-import-not-at-top
  from agents.ppo import types  # pylint: disable=g-import-not-at-top
  config = config_lib.hierarchy_config(config_lib.TrainArgs(task=args.task))
  builder = hierarchy_builder.HierarchyBuilder(config)
  obs_dim = args.observation_size
  networks = builder.make_networks(obs_dim, 2)
  learner = builder.make_learner(networks)
  t, b = config.sequence_length, samples // config.sequence_length
  rng = np.random.default_rng(0)
  f32 = lambda *shape: rng.normal(size=shape).astype(np.float32)
  batch = types.SequenceBatch(
      observation=f32(t + 1, b, obs_dim), raw_action=f32(t, b, 2),
      log_prob=f32(t, b) - 2, reward=f32(t, b), discount=np.ones((t, b),
                                                               np.float32),
      reset=np.zeros((t + 1, b), bool), initial_carry=f32(b, networks.carry_size),
      truncation=np.zeros((t, b), np.float32))
  jax.block_until_ready(learner.step(batch))  # Compilation.
  start = time.perf_counter()
  jax.block_until_ready(learner.step(batch))
  return time.perf_counter() - start


def _train_args(args, actors, logdir):
  return config_lib.TrainArgs(
      task=args.task, n_agents=args.n_agents, actors=actors,
      envs_per_actor=args.envs_per_actor, logdir=logdir,
      controller=args.controller, progress=False, total_steps=1,
      num_minibatches=math.gcd(4, args.n_agents * args.envs_per_actor))


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--task', default='transport')
  parser.add_argument('--n-agents', type=int, default=4)
  parser.add_argument('--envs-per-actor', type=int, default=4)
  parser.add_argument('--iterations', type=int, default=4)
  parser.add_argument('--bare-seconds', type=float, default=10.0)
  parser.add_argument('--controller', default='')
  args = parser.parse_args(argv)
  actor_pool.init_ray(num_cpus=max(2, os.cpu_count()))
  with tempfile.TemporaryDirectory() as tmp:
    train_args = _train_args(args, 1, os.path.join(tmp, 'bare'))
    bare_sps = bare(args, train_args, args.bare_seconds)
    one, learn_one = pipeline(args, 1, os.path.join(tmp, 'one'))
    two, _ = pipeline(args, 2, os.path.join(tmp, 'two'))
    species = learner_loop.probe(learner_loop.environment_spec(train_args),
                                 config_lib.hierarchy_config(train_args))[0]
    args.observation_size = species[0].observation_size
  per_64k = learner_seconds(args)
  print(f'{args.task}, {args.n_agents} agents, {args.envs_per_actor} copies '
        f'per actor, {os.cpu_count()} CPUs')
  print(f'bare environments (random commands): {bare_sps:8.0f} agent steps/s')
  print(f'pipeline, 1 actor:                   {one:8.0f} agent steps/s '
        f'({100 * one / bare_sps:.0f}% of bare; learner {learn_one:.2f} s '
        'per iteration)')
  print(f'pipeline, 2 actors:                  {two:8.0f} agent steps/s '
        f'(x{two / one:.2f} of 1 actor)')
  print(f'learner: {per_64k:.2f} s per 64k samples (default networks)')


if __name__ == '__main__':
  main()
