"""A hand-written transport policy: the reference a learned one is judged by.

    python -m runners.scripted --n-agents 4 --episodes 100

The policy issues position-paradigm commands through `CommandWrapper` and
the shipped lower layer, reading the world state a learned policy only sees
through its exteroception: every agent walks to a slot behind the cylinder
(on the side away from the target), then walks through the cylinder towards
the target; all stand still once the cylinder is near the target's centre.
It needs no training and no memory, so its success rate shows what the
command interface and the frozen lower layer allow within the time limit;
a learned policy far below it is limited by learning (samples, reward,
exploration), not by its legs.

Prints the success rate with its standard error over the episodes and the
mean episode length.
"""
import dataclasses
import os

import numpy as np

from runners import cli
from runners import evaluate

os.environ.setdefault('MUJOCO_GL', 'egl')

BEHIND = 1.6
"""How far behind the cylinder's centre the slots are (m): the cylinder's
0.6 m radius plus about an Ant's half length."""
SLOT_SPREAD = 0.75
"""Lateral half-width of the row of slots behind the cylinder (m)."""
PUSH_THROUGH = 2.5
"""Distance ahead (m) of a pushing agent's command, through the cylinder."""
STOP_RADIUS = 0.5
"""Once the cylinder's centre is this close to the target (m), every agent
is told to stand still (a zero offset) so that the cylinder comes to rest in
the 1 m zone."""


def push_from_behind(task, physics) -> np.ndarray:
  """Commands [n_agents, 2]: heading-frame target offsets (m).

  Args:
    task: a `coop_suite` transport task.
    physics: its physics.
  """
  from coop_suite.tasks import observables  # pylint: disable=g-import-not-at-top
  cylinder = task.cylinder.position(physics)[:2]
  target = task.arena.target_position
  n = len(task.walkers)
  distance = np.linalg.norm(target - cylinder)
  if distance < STOP_RADIUS:
    return np.zeros((n, 2))
  push = (target - cylinder) / distance
  side = np.array([-push[1], push[0]])
  frames = observables.AgentFrames.from_walkers(task.walkers, physics)
  slots = np.linspace(-SLOT_SPREAD, SLOT_SPREAD, n) if n > 1 else [0.0]
  goals = []
  for position, lateral_slot in zip(frames.position[:, :2], slots):
    along = np.dot(position - cylinder, push)
    lateral = abs(np.dot(position - cylinder, side))
    behind = cylinder - BEHIND * push + lateral_slot * side
    in_place = ((along < -0.9 and lateral < 1.2)
                or np.linalg.norm(position - behind) < 0.3)
    goals.append(position + PUSH_THROUGH * push if in_place else behind)
  return frames.to_heading_frame(np.array(goals))


@dataclasses.dataclass(frozen=True)
class ScriptedArgs:
  """What to play (every field is a flag)."""

  n_agents: int = 4
  """Ants pushing the cylinder."""
  episodes: int = 100
  """Episodes to play."""
  seed: int = 1000
  """Seed of the first episode; episode i uses seed + i."""
  time_limit: float = 0.0
  """Episode length (s); 0 keeps the task's default."""
  command_period: float = 0.5
  """Seconds between commands."""


def play(args: ScriptedArgs) -> dict:
  """Plays the episodes; returns success, its standard error and lengths."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  from agents import lowlevel  # pylint: disable=g-import-not-at-top
  controller = lowlevel.load('position')
  options = {'time_limit': args.time_limit} if args.time_limit > 0 else {}
  successes, lengths = [], []
  for episode in range(args.episodes):
    env = lowlevel.CommandWrapper(
        coop_suite.load('transport', args.n_agents, seed=args.seed + episode,
                        **options), controller, args.command_period)
    timestep, commands = env.reset(), 0
    while not timestep.last():
      timestep = env.step(push_from_behind(env.task, env.physics))
      commands += 1
    successes.append(float(env.episode_metrics()['success']))
    lengths.append(commands * args.command_period)
    env.close()
  success, error = evaluate.mean_and_error(successes)
  return {'success': success, 'success_se': error,
          'length': float(np.mean(lengths)), 'episodes': len(successes)}


def main(argv=None):
  args = cli.parse(ScriptedArgs, argv, description=__doc__.splitlines()[0])
  out = play(args)
  print(f'scripted push-from-behind, transport with {args.n_agents} agents, '
        f'seeds {args.seed}-{args.seed + args.episodes - 1}')
  print(f'success rate {100 * out["success"]:.1f}% +- '
        f'{100 * out["success_se"]:.1f}% (standard error over '
        f'{out["episodes"]} episodes); mean length {out["length"]:.1f} s')


if __name__ == '__main__':
  main()
