"""How close to raw `mj_step` the environment could get, part by part.

    python benchmarks/overhead_bounds.py [--task transport] [--n-agents 4]

Prints the env-step / raw-`mj_step` ratio of `env_throughput.py` four times
on one task: the full step; without building the observation
(`env.step(a, observe=False)`); with the task's status update and reward
replaced by no-ops (an upper bound for making them free, e.g. compiled);
and with both. The gaps between the rows are what each part costs in the
real loop, where the caches are cold after the physics; the third row bounds
what compiling the task logic could reach.
"""

import argparse

from env_throughput import measure  # pylint: disable=g-bad-import-order


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
  args = parser.parse_args()
  print(f"{args.task} with {args.n_agents} agents: env step / raw mj_step")
  for name, observe, prepare in (
      ("full step", True, None),
      ("observation skipped", False, None),
      ("status and reward as no-ops", True, _without_task_logic),
      ("both", False, _without_task_logic)):
    *_, ratio = measure(args.task, args.n_agents, args.steps, args.rounds,
                        observe=observe, prepare=prepare)
    print(f"  {name:30s} {ratio:5.2f}", flush=True)


if __name__ == "__main__":
  main()
