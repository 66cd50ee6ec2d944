"""Environment throughput: composer step vs raw `mujoco.mj_step`, per task.

    python benchmarks/env_throughput.py [--steps 1000] [--rounds 5]

For each task and agent count, runs random actions through the composer
environment and, on the very same compiled model and data, the raw
`mj_step` loop a bare simulator would run (set `ctrl`, then one `mj_step` per
physics substep). The two alternate in short blocks and the ratio is the
median of the blocks' ratios, so that drift on a shared machine hits both
alike; the ratio is what matters, absolute rates vary with the machine's
load. Single process, one core.
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


def measure(task, n_agents, steps, rounds, seed=0, observe=True,
            prepare=None):
  """Returns (composer steps/s, raw steps/s, real-time factor, ratio).

  Rates are medians over the rounds; the ratio is the median of the rounds'
  own ratios, each from two back-to-back blocks, so that the drift of a
  shared machine cancels out. `prepare(env)`, if given, runs after the
  first reset (e.g. to switch parts of the step off).
  """
  env = coop_suite.load(task, n_agents, seed=seed, time_limit=1e9)
  env.reset()
  if prepare is not None:
    prepare(env)
  n = env.n_agents
  substeps = env.task.physics_steps_per_control_step
  control_dt = env.control_timestep()
  actions = np.random.RandomState(seed).uniform(-1, 1, (steps, n, 8))
  model, data = env.physics.model.ptr, env.physics.data.ptr
  composer_times, raw_times = [], []
  for _ in range(rounds):
    start = time.perf_counter()
    for action in actions:
      env.step(action, observe=observe)
    composer_times.append(time.perf_counter() - start)
    start = time.perf_counter()
    for action in actions:
      data.ctrl[:] = action.ravel()
      for _ in range(substeps):
        mujoco.mj_step(model, data)
    raw_times.append(time.perf_counter() - start)
  composer_rate = steps / np.median(composer_times)
  raw_rate = steps / np.median(raw_times)
  ratio = np.median(np.array(raw_times) / np.array(composer_times))
  return composer_rate, raw_rate, composer_rate * control_dt, ratio


def main():
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--steps", type=int, default=200,
                      help="control steps per block")
  parser.add_argument("--rounds", type=int, default=20,
                      help="pairs of blocks (composer, then raw)")
  parser.add_argument("--tasks", nargs="*", default=None,
                      help="restrict to these tasks")
  parser.add_argument("--skip-observation", action="store_true",
                      help="env.step(action, observe=False): what the step "
                      "costs without building the observation")
  args = parser.parse_args()
  print(f"{'task':16s} {'agents':>6s} {'steps/s':>9s} {'x real':>7s} "
        f"{'raw steps/s':>11s} {'ratio':>6s}")
  for task, n_agents in CASES:
    if args.tasks and task not in args.tasks:
      continue
    rate, raw, realtime, ratio = measure(
        task, n_agents, args.steps, args.rounds,
        observe=not args.skip_observation)
    print(f"{task:16s} {n_agents:6d} {rate:9.0f} {realtime:7.1f} {raw:11.0f} "
          f"{ratio:6.2f}", flush=True)


if __name__ == "__main__":
  main()
