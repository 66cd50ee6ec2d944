"""Where one control step's time goes, as fractions of the whole step.

    python benchmarks/step_breakdown.py [--task transport] [--n-agents 4]

Runs the real `env.step` with a timer around each piece it calls (action
validation, the task's `before_step`, the physics substeps, the status
update, the reward, the observation) and prints each piece's share of the
step, so that the figures do not depend on how busy the shared machine is.
The pieces are timed where they run, with the caches as the physics leaves
them; timed alone and warm they would look two to three times cheaper.
"""

import argparse
import collections
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # pylint: disable=g-import-not-at-top

import coop_suite


def _timed(fn, totals, name):
  """`fn` that adds its own duration to totals[name]."""
  def run(*args, **kwargs):
    start = time.perf_counter()
    try:
      return fn(*args, **kwargs)
    finally:
      totals[name] += time.perf_counter() - start
  return run


def main():
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--task", default="transport")
  parser.add_argument("--n-agents", type=int, default=4)
  parser.add_argument("--steps", type=int, default=3000)
  args = parser.parse_args()
  env = coop_suite.load(args.task, args.n_agents, seed=0, time_limit=1e9)
  env.reset()
  task = env.task
  totals = collections.defaultdict(float)
  # pylint: disable=protected-access
  env.validate_action = _timed(env.validate_action, totals,
                               "action validation")
  task.before_step = _timed(task.before_step, totals, "before_step (controls)")
  task.after_step = _timed(task.after_step, totals, "status (after_step)")
  task.get_reward = _timed(task.get_reward, totals, "reward")
  updater = env._observation_updater
  updater.get_observation = _timed(updater.get_observation, totals,
                                   "observation")
  runner = env._stepper.substeps if env._stepper is not None else None
  if runner is not None:
    runner.step = _timed(runner.step, totals, "physics substeps")
  # pylint: enable=protected-access
  actions = np.random.RandomState(0).uniform(-1, 1,
                                             (args.steps, env.n_agents, 8))
  for action in actions[:200]:  # Warm-up: compile, fill the caches.
    env.step(action)
  totals.clear()
  start = time.perf_counter()
  for action in actions:
    env.step(action)
  total = time.perf_counter() - start
  print(f"{args.task} with {env.n_agents} agents: one env.step = 1.00 "
        f"({total / args.steps * 1e6:.0f} us)")
  for name, seconds in totals.items():
    print(f"  {name:24s} {seconds / total:5.2f}")
  rest = 1 - sum(totals.values()) / total
  print(f"  {'rest (composer, timers)':24s} {rest:5.2f}")


if __name__ == "__main__":
  main()
