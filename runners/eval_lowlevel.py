"""Evaluates a lower-layer controller on its locomotion task, deterministic.

    python -m runners.eval_lowlevel --paradigm position
    python -m runners.eval_lowlevel --paradigm velocity --controller runs/lowlevel_velocity/controller

Position: `walk_to_target` with a fixed target (not redrawn when reached):
success rate (reached within `reach_radius`), seconds to reach, final
distance, fall rate. Velocity: `walk_velocity`: velocity cosine, relative
speed error, speed while told to stand (transients after a redraw included),
fall rate; then as many 5 s episodes that command zero from the start, for
the drift of a standing ant. Means with standard errors over episodes
(`runners.evaluate.mean_and_error`, over the episodes where a figure is
defined); the episode seeds are `seed, seed + 1, ...`.
"""
import dataclasses
import json

import numpy as np

from agents import fields
from agents.lowlevel.paradigms import PARADIGMS
from runners import cli


@dataclasses.dataclass(frozen=True)
class LowLevelEvalArgs:
  """What to evaluate: a lower-layer controller (coop-eval's `EvalArgs` are
  for a trained run's checkpoint)."""

  paradigm: str = fields.field('position', fields.one_of(*PARADIGMS))
  """'position' or 'velocity'."""
  controller: str = ''
  """Controller directory; default: the weights shipped in agents/lowlevel."""
  episodes: int = fields.field(20, fields.COUNT)
  """Episodes to run."""
  seed: int = fields.field(1000, fields.SEED)
  """Seed of the first episode's environment."""
  time_limit: float = fields.field(10.0, fields.POSITIVE)
  """Episode length (s)."""

  def __post_init__(self):
    fields.check(self)


def _mean_and_error(rows):
  """{figure: (mean, standard error)} over the rows where it is finite
  (NaN for none)."""
  from runners import evaluate  # pylint: disable=g-import-not-at-top
  out = {}
  for name in rows[0]:
    values = np.array([r[name] for r in rows], np.float64)
    values = values[np.isfinite(values)]
    out[name] = (evaluate.mean_and_error(values) if len(values)
                 else (float('nan'), float('nan')))
  return out


def stand_still(controller, args: LowLevelEvalArgs,
                seconds: float = 5.0) -> dict:
  """Zero command from the first step: the ant's mean planar speed over the
  last half of the episode and how far its torso drifted (m)."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  rows = []
  for episode in range(args.episodes):
    env = coop_suite.load('walk_velocity', 1, seed=args.seed + episode,
                          time_limit=seconds, p_stand=1.0)  # Zero only.
    timestep = env.reset()
    start = env.task.walker.torso_position(env.physics)[:2].copy()
    speeds = []
    while not timestep.last():
      timestep = env.step(controller.batch(timestep.observation))
      speeds.append(np.linalg.norm(
          env.task.walker.world_velocity(env.physics)[:2]))
    drift = np.linalg.norm(
        env.task.walker.torso_position(env.physics)[:2] - start)
    rows.append({'stand_speed': float(np.mean(speeds[len(speeds) // 2:])),
                 'stand_drift': float(drift),
                 'stand_fall': float(env.episode_metrics()['failure'])})
    env.close()
  return _mean_and_error(rows)


def evaluate(args: LowLevelEvalArgs) -> dict:
  """Returns {metric: (mean, standard error)} over `args.episodes`."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  from agents import lowlevel  # pylint: disable=g-import-not-at-top
  controller = lowlevel.load(args.paradigm, args.controller or None)
  options = {'resample_on_reach': False} if args.paradigm == 'position' else {}
  rows = []
  for episode in range(args.episodes):
    env = coop_suite.load(PARADIGMS[args.paradigm].task, 1,
                          seed=args.seed + episode,
                          time_limit=args.time_limit, **options)
    timestep = env.reset()
    reached_at = None
    steps = 0
    while not timestep.last():
      timestep = env.step(controller.batch(timestep.observation))
      steps += 1
      metrics = env.episode_metrics()
      if (args.paradigm == 'position' and reached_at is None
          and metrics['success']):
        reached_at = steps * env.control_timestep()
    metrics = env.episode_metrics()
    row = {'return': metrics['return'], 'fall': float(metrics['failure'])}
    if args.paradigm == 'position':
      row.update(success=float(metrics['success']),
                 final_distance=metrics['target_distance'],
                 seconds_to_reach=reached_at if reached_at else np.nan)
    else:
      for name in ('velocity_cosine', 'speed_error', 'mean_speed_still'):
        row[name] = metrics.get(name, np.nan)
    rows.append(row)
    env.close()
  out = _mean_and_error(rows)
  if args.paradigm == 'velocity':
    out.update(stand_still(controller, args))
  return out


def main(argv=None):
  _, results = cli.run(LowLevelEvalArgs, evaluate, argv,
                       'python -m runners.eval_lowlevel',
                       __doc__.splitlines()[0])
  for name, (mean, se) in results.items():
    print(f'{name:>18}: {mean:8.3f} +- {se:.3f}')
  print(json.dumps({k: v[0] for k, v in results.items()}))


if __name__ == '__main__':
  main()
