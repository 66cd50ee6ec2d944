"""Environment throughput: composer step vs raw `mujoco.mj_step`, per task.

    python benchmarks/env_throughput.py [--steps 1000] [--rounds 5]

For each task and agent count, runs random actions through the composer
environment and, on the very same compiled model and data, the raw
`mj_step` loop a bare simulator would run (set `ctrl`, then one `mj_step` per
physics substep). The two are interleaved in rounds so that drift on a shared
machine hits both alike; the printed ratio is what matters, absolute rates
vary with the machine's load. Single process, one core.
"""

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # pylint: disable=g-import-not-at-top
import numpy as np

import coop_suite

CASES = [(task, n) for task in ("transport", "corridor", "ravine")
         for n in (1, 2, 4, 8)] + [("walk_to_target", 1), ("walk_velocity", 1)]


def measure(task, n_agents, steps, rounds, seed=0):
  """Returns (composer steps/s, raw steps/s, real-time factor)."""
  env = coop_suite.load(task, n_agents, seed=seed, time_limit=1e9)
  env.reset()
  n = env.n_agents
  substeps = env.task.physics_steps_per_control_step
  control_dt = env.control_timestep()
  actions = np.random.RandomState(seed).uniform(-1, 1, (steps, n, 8))
  model, data = env.physics.model.ptr, env.physics.data.ptr
  composer_time = raw_time = 0.0
  for _ in range(rounds):
    start = time.perf_counter()
    for action in actions:
      env.step(action)
    composer_time += time.perf_counter() - start
    start = time.perf_counter()
    for action in actions:
      data.ctrl[:] = action.ravel()
      for _ in range(substeps):
        mujoco.mj_step(model, data)
    raw_time += time.perf_counter() - start
  total = steps * rounds
  composer_rate, raw_rate = total / composer_time, total / raw_time
  return composer_rate, raw_rate, composer_rate * control_dt


def main():
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--steps", type=int, default=1000,
                      help="control steps per round")
  parser.add_argument("--rounds", type=int, default=5)
  parser.add_argument("--tasks", nargs="*", default=None,
                      help="restrict to these tasks")
  args = parser.parse_args()
  print(f"{'task':16s} {'agents':>6s} {'steps/s':>9s} {'x real':>7s} "
        f"{'raw steps/s':>11s} {'ratio':>6s}")
  for task, n_agents in CASES:
    if args.tasks and task not in args.tasks:
      continue
    rate, raw, realtime = measure(task, n_agents, args.steps, args.rounds)
    print(f"{task:16s} {n_agents:6d} {rate:9.0f} {realtime:7.1f} {raw:11.0f} "
          f"{rate / raw:6.2f}", flush=True)


if __name__ == "__main__":
  main()
