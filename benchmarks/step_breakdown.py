"""Where one control step's time goes, as fractions of the whole step.

    python benchmarks/step_breakdown.py [--task transport] [--n-agents 4]

Times the pieces of `CoopEnvironment.step` separately on one environment
(physics substeps, observation features, reward, action validation) and
prints each as a fraction of a full `env.step`, so that the figures do not
depend on how busy the shared machine is.
"""

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # pylint: disable=g-import-not-at-top

import coop_suite


def _time(fn, repeats):
  start = time.perf_counter()
  for _ in range(repeats):
    fn()
  return (time.perf_counter() - start) / repeats


def main():
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--task", default="transport")
  parser.add_argument("--n-agents", type=int, default=4)
  parser.add_argument("--repeats", type=int, default=2000)
  args = parser.parse_args()
  env = coop_suite.load(args.task, args.n_agents, seed=0, time_limit=1e9)
  env.reset()
  task, physics = env.task, env.physics
  actions = np.zeros((env.n_agents, 8))
  substeps = task.physics_steps_per_control_step

  def fresh(fn):
    """`fn` on a state the task's per-state caches have not seen."""
    def run():
      task._state_version += 1  # pylint: disable=protected-access
      fn()
    return run

  pieces = {
      # The environment's own substep call (see `_SubstepRunner`).
      "physics substeps": lambda: env._substeps.step(substeps),  # pylint: disable=protected-access
      "observations": fresh(lambda: task.features(physics)),
      "reward": fresh(lambda: task.get_reward(physics)),
      "status (after_step)": fresh(lambda: task.after_step(physics, None)),
      "action validation": lambda: env.validate_action(actions),
  }
  total = _time(lambda: env.step(actions), args.repeats)
  print(f"{args.task} with {env.n_agents} agents: one env.step = 1.00")
  accounted = 0.0
  for name, fn in pieces.items():
    share = _time(fn, args.repeats) / total
    accounted += share
    print(f"  {name:22s} {share:5.2f}")
  print(f"  {'rest (composer, hooks)':22s} {max(0.0, 1 - accounted):5.2f}")


if __name__ == "__main__":
  main()
