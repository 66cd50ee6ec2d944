"""The command interface can express cooperation.

Four Ants on `transport`, driven through `CommandWrapper` by the shipped
position controller and a hand-written command policy: line up behind the
cylinder (on the side away from the target), then walk through it towards
the target. The cylinder must travel most of the way to its target.
"""

import numpy as np

import coop_suite
from agents import lowlevel
from coop_suite.tasks import observables


def _scripted_commands(task, physics):
  """Heading-frame target offsets [4, 2] for the push-behind policy."""
  cylinder = task.cylinder.position(physics)[:2]
  target = task.arena.target_position
  push = (target - cylinder) / np.linalg.norm(target - cylinder)
  side = np.array([-push[1], push[0]])
  frames = observables.AgentFrames.from_walkers(task.walkers, physics)
  goals = []
  for i, lateral_slot in enumerate((-0.75, -0.25, 0.25, 0.75)):
    position = frames.position[i, :2]
    along = np.dot(position - cylinder, push)
    lateral = abs(np.dot(position - cylinder, side))
    behind = cylinder - 1.6 * push + lateral_slot * side
    if (along < -0.9 and lateral < 1.2) or np.linalg.norm(
        position - behind) < 0.3:
      goals.append(position + 2.5 * push)  # In place: push through.
    else:
      goals.append(behind)  # Walk around to the back of the cylinder.
  return frames.to_heading_frame(np.array(goals))


def test_scripted_commands_push_the_cylinder_to_its_target():
  env = lowlevel.CommandWrapper(coop_suite.load("transport", 4, seed=0),
                                lowlevel.load("position"), command_period=0.5)
  timestep = env.reset()
  task, physics = env.task, env.physics
  start = np.linalg.norm(task.cylinder.position(physics)[:2]
                         - task.arena.target_position)
  for _ in range(60):  # 30 s of commands.
    timestep = env.step(_scripted_commands(task, physics))
    if timestep.last():
      break
  end = np.linalg.norm(task.cylinder.position(physics)[:2]
                       - task.arena.target_position)
  assert start > 4.0
  assert end < start - 2.5, (start, end)
  assert env.episode_metrics()["success"]
