"""What a run's checkpoint costs: its learners packed or as orbax's PyTree.

    python benchmarks/checkpoint_cost.py [--task ravine] [--agent hrl]
        [--saves 15]

A run writes one checkpoint an update (`--checkpoint-every 1`), finishing
in the background while the next rollouts are collected, so its CPU time
is taken from the actors. This builds a task's fresh learners (the ravine's
joint task: two species), then writes checkpoints of their whole state
(`Learner.save()`) two ways that alternate, `--saves` each after two
rounds of warm-up, with a pause between saves where a run would collect:
`runners.checkpoints.Writer` (the learners packed, `runners.packing`: what
runs write) and, as a stand-in for the format-3 writer, orbax's own
PyTree of the same state dicts (arrays without elements as None, as that
writer wrote them) through a bare asynchronous `CheckpointManager` (no
best-checkpoint policy, and not the old writer's listing of the run's
steps at each save, so it is if anything cheaper than that writer was).
Prints the number of arrays in the learners' states, the process's CPU
time per save (the writing threads included, each save waited for before
the clock is read) and the driver's wall time per save beyond the pause
(medians), each way's newest checkpoint's size on disk, and the median
ratio of the CPU times. The packed checkpoint is read back and compared
with the learners' state. CPU times are the machine's: run it idle for
absolute figures; the ratio is measured in one run.
"""
import argparse
import os
import resource
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..'))

import jax  # pylint: disable=g-import-not-at-top
import numpy as np  # pylint: disable=g-import-not-at-top

from runners import checkpoints  # pylint: disable=g-import-not-at-top
from runners import config as config_lib  # pylint: disable=g-import-not-at-top
from runners import learner_loop  # pylint: disable=g-import-not-at-top


def _cpu_seconds() -> float:
  usage = resource.getrusage(resource.RUSAGE_SELF)
  return usage.ru_utime + usage.ru_stime


def _megabytes(directory: str) -> float:
  return sum(os.path.getsize(os.path.join(d, f))
             for d, _, files in os.walk(directory) for f in files) / 1e6


class _PyTreeWriter:
  """The same checkpoints with each learner's state dict as orbax's own
  PyTree (arrays without elements left out, as format 3 did)."""

  def __init__(self, directory: str):
    import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
    self._ocp = ocp
    self._manager = ocp.CheckpointManager(
        directory, options=ocp.CheckpointManagerOptions(
            max_to_keep=3, create=True, enable_async_checkpointing=True))

  def save(self, learners, state):
    self._manager.wait_until_finished()
    arrays = {name: jax.tree.map(lambda a: None if np.size(a) == 0 else a,
                                 learner.save()['state'])
              for name, learner in learners.items()}
    self._manager.save(state['update'], args=self._ocp.args.Composite(
        learners=self._ocp.args.PyTreeSave(arrays),
        state=self._ocp.args.JsonSave(state)))

  def wait(self):
    self._manager.wait_until_finished()

  def close(self):
    self.wait()
    self._manager.close()


class _PackedWriter(checkpoints.Writer):
  """What runs write, waited for like `_PyTreeWriter`."""

  def wait(self):
    self._finish()


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--task', default='ravine')
  parser.add_argument('--n-agents', type=int, default=2)
  parser.add_argument('--agent', default='hrl',
                      help='variant: hrl, no_memory, flat or mappo')
  parser.add_argument('--saves', type=int, default=15)
  parser.add_argument('--pause', type=float, default=0.5,
                      help='seconds between saves (the next rollouts)')
  args = parser.parse_args(argv)
  train_args = config_lib.train_args(task=args.task, n_agents=args.n_agents,
                                     agent=args.agent, progress=False)
  _, _, learners = learner_loop.fresh_learners(train_args)
  arrays = sum(len(jax.tree.leaves(l.save()['state']))
               for l in learners.values())
  with tempfile.TemporaryDirectory() as root:
    writers = {'packed': _PackedWriter(os.path.join(root, 'packed'), keep=3),
               'pytree': _PyTreeWriter(os.path.join(root, 'pytree'))}
    cpu = {name: [] for name in writers}
    wall = {name: [] for name in writers}
    update, last = 0, {}
    try:
      for r in range(args.saves + 2):  # The first two warm up.
        for name in sorted(writers, reverse=bool(r % 2)):
          update += 1
          last[name] = update
          state = {'update': update, 'species': sorted(learners)}
          c, t = _cpu_seconds(), time.perf_counter()
          writers[name].save(learners, state)
          time.sleep(args.pause)
          writers[name].wait()
          if r >= 2:
            cpu[name].append(_cpu_seconds() - c)
            wall[name].append(time.perf_counter() - t - args.pause)
    finally:
      for writer in writers.values():
        writer.close()
    newest = checkpoints.resolve(os.path.join(root, 'packed'))
    size = {'packed': _megabytes(newest),
            'pytree': _megabytes(os.path.join(root, 'pytree',
                                              str(last['pytree'])))}
    for name, learner in learners.items():
      back = checkpoints.saved_learner(newest, name)['state']
      ours = learner.save()['state']
      same = jax.tree.map(np.array_equal, back, ours)
      assert all(jax.tree.leaves(same)), f'{name} did not read back'
  print(f'{args.task} with {args.n_agents} agents, {args.agent}: '
        f'{len(learners)} '
        f'learners, {arrays} arrays; {args.saves} saves each, '
        f'{args.pause} s apart')
  for name in writers:
    print(f'  {name:7s} CPU per save {np.median(cpu[name]) * 1e3:6.1f} ms, '
          f'driver beyond the pause {np.median(wall[name]) * 1e3:6.1f} ms, '
          f'{size[name]:.2f} MB on disk')
  ratio = np.median(np.divide(cpu['pytree'], cpu['packed']))
  print(f'CPU per save, orbax PyTree / packed: {ratio:.2f}')


if __name__ == '__main__':
  main()
