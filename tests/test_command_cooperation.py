"""The command interface can express cooperation.

Four Ants on `transport`, driven through `CommandWrapper` by the shipped
position controller and a hand-written command policy: line up behind the
cylinder (on the side away from the target), then walk through it towards
the target (`runners.scripted`). The cylinder must travel most of the way
to its target.
"""

import numpy as np

import coop_suite
from agents import lowlevel
from runners import scripted


def test_scripted_commands_push_the_cylinder_to_its_target():
  env = lowlevel.CommandWrapper(coop_suite.load("transport", 4, seed=0),
                                lowlevel.load("position"), command_period=0.5)
  timestep = env.reset()
  task, physics = env.task, env.physics
  start = np.linalg.norm(task.cylinder.position(physics)[:2]
                         - task.arena.target_position)
  for _ in range(60):  # 30 s of commands.
    timestep = env.step(scripted.push_from_behind(task, physics))
    if timestep.last() or env.episode_metrics()["success"]:
      break
  end = np.linalg.norm(task.cylinder.position(physics)[:2]
                       - task.arena.target_position)
  assert start > 4.0
  assert end < start - 2.5, (start, end)
  assert env.episode_metrics()["success"]


def test_scripted_runner_reports_a_success_rate(capsys):
  scripted.main(["--episodes", "2", "--time-limit", "2"])
  out = capsys.readouterr().out
  assert "success rate 0.0% +- 0.0% (standard error over 2 episodes)" in out
  assert "mean length 2.0 s" in out
