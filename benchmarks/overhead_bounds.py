"""How close to raw `mj_step` the environment could get, part by part.

    python benchmarks/overhead_bounds.py [--task transport] [--n-agents 4]
    python benchmarks/overhead_bounds.py --lockstep [--copies 16]

Prints the env-step / raw-`mj_step` ratio of `env_throughput.py` four times
on one task: the full step; without building the observation
(`env.step(a, observe=False)`); with the task's status update and reward
replaced by no-ops (an upper bound for making them free, e.g. compiled);
and with both. The gaps between the rows are what each part costs in the
real loop, where the caches are cold after the physics; the third row bounds
what compiling the task logic could reach.

`--lockstep` bounds the same part in what an actor runs in training
(`EnvBatch`: `--copies` copies in lockstep with the shipped lower layer and
random commands): two batches, one with the task's status update and reward
as no-ops, stepped in short alternating blocks (the order swapped each
round, so that the shared machine's drift hits both alike); prints the
median and quartiles of the per-round time ratio (no-ops / full step). It
also compares, the same way, the copies' physics phases stepped together
(`LockstepPhysics`, what training runs) with each copy's own phase through
composer's hooks (the step before 2026-11-26). Run it pinned to one core
with the actors' settings, e.g. `JAX_PLATFORMS=cpu OMP_NUM_THREADS=1
XLA_FLAGS=--xla_cpu_multi_thread_eigen=false taskset -c 1 python ...`.
"""

import argparse
import time

from env_throughput import measure  # pylint: disable=g-bad-import-order
import numpy as np  # pylint: disable=g-bad-import-order
from step_breakdown import lockstep_batch  # pylint: disable=g-bad-import-order


def _without_task_logic(env):
  """Replaces the task's status update and reward by no-ops."""
  zeros = env.task.get_reward(env.physics)
  env.task.after_step = lambda physics, random_state: None
  env.task.get_reward = lambda physics: [0.0 * r for r in zeros]


def main():
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--task", default="transport")
  parser.add_argument("--n-agents", type=int, default=4)
  parser.add_argument("--steps", type=int, default=200)
  parser.add_argument("--rounds", type=int, default=20)
  parser.add_argument("--lockstep", action="store_true",
                      help="bound the task logic in EnvBatch's lockstep")
  parser.add_argument("--copies", type=int, default=16)
  args = parser.parse_args()
  if args.lockstep:
    lockstep(args)
    return
  print(f"{args.task} with {args.n_agents} agents: env step / raw mj_step")
  for name, observe, prepare in (
      ("full step", True, None),
      ("observation skipped", False, None),
      ("status and reward as no-ops", True, _without_task_logic),
      ("both", False, _without_task_logic)):
    *_, ratio = measure(args.task, args.n_agents, args.steps, args.rounds,
                        observe=observe, prepare=prepare)
    print(f"  {name:30s} {ratio:5.2f}", flush=True)


def _copy_by_copy_physics(batch):
  """Makes `batch` step each copy's physics phase on its own, through
  composer's hooks (the episodes are too long to end, so the copies keep
  these steppers)."""
  # pylint: disable=protected-access
  batch._physics._make_table = lambda chosen: None
  for copy in batch.envs:
    copy.env._stepper.addresses = None


def lockstep(args):
  """Shares of `EnvBatch`'s lockstep step (module doc)."""
  full = lockstep_batch(args.task, args.n_agents, args.copies)
  (species,) = full.species  # Every agent commanded alike.
  commands = np.random.RandomState(0).uniform(
      -3, 3, (4, args.copies * args.n_agents, 2))
  for name, change in (
      ("status and reward as no-ops", lambda copy: _without_task_logic(
          copy.env)),
      ("each copy's physics phase through composer's hooks", None)):
    other = lockstep_batch(args.task, args.n_agents, args.copies)
    if change is None:
      _copy_by_copy_physics(other)
    else:
      for copy in other.envs:
        change(copy)
    ratios, per_step = _alternate(full, other, species, commands, args.rounds)
    print(f"{args.task} with {args.n_agents} agents, {args.copies} copies in "
          f"lockstep ({per_step * 1e6:.0f} us per copy and control step): "
          f"{name} / training's step, per round: median "
          f"{np.median(ratios):.3f}, quartiles "
          f"{np.percentile(ratios, 25):.3f}-{np.percentile(ratios, 75):.3f} "
          f"({len(ratios)} rounds)", flush=True)
    other.close()
  full.close()


def _alternate(full, other, species, commands, rounds):
  """Per-round time ratios other / full over short alternating blocks, and
  full's median seconds per copy and control step."""
  def seconds(batch):
    start = time.perf_counter()
    for command in commands:
      batch.step({species.name: command})
    return time.perf_counter() - start
  seconds(full), seconds(other)  # Warm-up: compile, fill the caches.
  ratios, steps = [], []
  for round_ in range(rounds * 2):
    if round_ % 2 == 0:
      full_seconds = seconds(full)
      other_seconds = seconds(other)
    else:  # The other order, so that a drift hits both alike.
      other_seconds = seconds(other)
      full_seconds = seconds(full)
    ratios.append(other_seconds / full_seconds)
    steps.append(full_seconds)
  per_step = np.median(steps) / (len(commands) * full.envs[0].low_level_steps
                                 * len(full.envs))
  return ratios, per_step


if __name__ == "__main__":
  main()
