"""Prototype, not the library: the learner's minibatch over 2 host devices.

    python results/benchmarks/learner_devices_2026-11-26/learner_devices.py \
        --way spmd|shard_map [--rounds 6]

Transport with 4 Ants, the training defaults' batch for 2 actors (one
actor's 16-copy rollout taken twice), one species. Builds a second set of
learners whose every SGD step splits its minibatch over two host devices
(`--xla_force_host_platform_device_count=2`) and times an update of each
set in alternating rounds; prints the largest parameter difference after
one update from the same start and the median ratio one / two devices.
`spmd`: sharding constraints on the minibatch, the partitioner inserts the
collectives (the same algorithm). `shard_map`: each device computes its
half's gradient and metrics, then pmean (advantages are normalised per
half: not the same algorithm). Measure it with both cores free.
"""
import argparse
import os
import sys
import time

os.environ['XLA_FLAGS'] = (os.environ.get('XLA_FLAGS', '') +
                           ' --xla_force_host_platform_device_count=2')
sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..', '..', '..'))

# pylint: disable=g-import-not-at-top,wrong-import-position
import jax
from jax.experimental.shard_map import shard_map
import jax.numpy as jnp
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
import numpy as np
import optax

from agents.ppo import learning
from agents.ppo import step_size
from runners import config as config_lib
from runners import learner_loop
from runners import rollout

MESH = Mesh(np.array(jax.devices()[:2]), ('b',))


def _specs(minibatch):
  """The row axis ('b') of every array of a minibatch: 1, initial carry 0."""
  def rows(x):
    return P(*([None, 'b'] + [None] * (x.ndim - 2)))
  return minibatch._replace(
      steps=jax.tree.map(rows, minibatch.steps), reset=P(None, 'b'),
      initial_carry=P('b', None),
      global_state=jax.tree.map(rows, minibatch.global_state))


def spmd_step(loss_fn, optimizer, target_kl=0.0):
  def constrained(params, minibatch, key):
    minibatch = jax.tree.map(
        lambda x, spec: jax.lax.with_sharding_constraint(
            x, NamedSharding(MESH, spec)), minibatch, _specs(minibatch))
    return loss_fn(params, minibatch, key)
  return REAL_STEP(constrained, optimizer, target_kl)


def shard_map_step(loss_fn, optimizer, target_kl=0.0):
  def sgd_step(carry, minibatch_and_key):  # learning.make_sgd_step's.
    params, opt_state = carry
    minibatch, key = minibatch_and_key

    def half(params, minibatch, key):
      grads, metrics = jax.grad(loss_fn, has_aux=True)(params, minibatch, key)
      return jax.lax.pmean((grads, metrics), 'b')
    grads, metrics = shard_map(
        half, mesh=MESH, in_specs=(P(), _specs(minibatch), P()),
        out_specs=P(), check_rep=False)(params, minibatch, key)
    metrics['grad_norm'] = optax.tree.norm(grads)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    if target_kl > 0:
      metrics['learning_rate'] = step_size.learning_rate(opt_state)
      opt_state = step_size.adapt(opt_state, metrics['approx_kl'], target_kl)
    return (optax.apply_updates(params, updates), opt_state), metrics
  return sgd_step


REAL_STEP = learning.make_sgd_step
WAYS = {'spmd': spmd_step, 'shard_map': shard_map_step}


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--way', choices=sorted(WAYS), required=True)
  parser.add_argument('--rounds', type=int, default=6)
  args = parser.parse_args(argv)
  train_args = config_lib.train_args(task='transport', actors=2,
                                     progress=False)
  spec, layout, one = learner_loop.fresh_learners(train_args)
  worker = rollout.RolloutWorker(spec, train_args.hierarchy, 0, 0,
                                 train_args.envs_per_actor)
  results = [worker.collect(learner_loop.actor_variables(one), 0)] * 2
  worker.close()
  learning.make_sgd_step = WAYS[args.way]
  two = learner_loop.make_learners(train_args.hierarchy, layout)
  learning.make_sgd_step = REAL_STEP
  sets = {'one device': one, 'two devices': two}
  for learners in sets.values():  # One update each from the same start.
    learner_loop.step_learners(learners, results)
  leaves = [jax.tree.leaves(next(iter(s.values())).state.params)
            for s in sets.values()]
  print('max param diff', max(float(jnp.max(jnp.abs(a - b)))
                              for a, b in zip(*leaves)))
  seconds = {name: [] for name in sets}
  for r in range(args.rounds):  # Each first in every other round.
    for name, learners in sorted(sets.items(), reverse=bool(r % 2)):
      begin = time.perf_counter()
      learner_loop.step_learners(learners, results)
      seconds[name].append(time.perf_counter() - begin)
    print(r, {k: round(v[-1], 3) for k, v in seconds.items()}, flush=True)
  ratio = np.median(np.divide(seconds['one device'], seconds['two devices']))
  print(f'{args.way}: median seconds', {k: round(float(np.median(v)), 3)
                                        for k, v in seconds.items()},
        f'ratio one / two devices {ratio:.2f}')


if __name__ == '__main__':
  main()
