"""Trains the cooperative agents with actors on Ray: `coop-train`.

    coop-train --task transport --n-agents 4                   # local Ray
    coop-train --task corridor --agent no_memory --actors 8 --envs-per-actor 16
    coop-train --task ravine --stage pushers --n-agents 2 --n-pushers 2
    coop-train --task transport --ray-address auto             # a cluster
    coop-train --task transport --actors 0 --total-steps 20000 # no Ray
    coop-train --task transport --resume                       # continue

Writes to --logdir (default runs/<task>_<agent>_n<N>_s<seed>): metrics.csv
and TensorBoard events (every reward term, success, losses, steps/s),
checkpoints/<update>/ (orbax, atomic; the newest --keep-checkpoints and the best kept),
controller/ (the lower layer the run uses). See docs/training.md.
Evaluate with `coop-eval --checkpoint <logdir>`.
"""
import json
import os
import signal
import sys

from runners import cli
from runners import config as config_lib


def main(argv=None):
  """Exit status 0 when the run finished, 128 + the signal's number when
  SIGINT / SIGTERM stopped it early (with a checkpoint), 2 for a user
  error (one line)."""
  def work(args):
    from runners import learner_loop  # pylint: disable=g-import-not-at-top
    return learner_loop.train(args)
  args, summary = cli.run(config_lib.TrainArgs, work, argv, 'coop-train',
                          __doc__.splitlines()[0])
  keys = ('update', 'env_steps', 'return', 'success', 'wall_time')
  print(json.dumps({k: summary.get(k) for k in keys}))
  print(f'checkpoint: {summary["checkpoint"]}')
  print(f'evaluate:   coop-eval --checkpoint {os.path.abspath(args.logdir)}')
  if summary.get('stopped_by'):
    print(f'Stopped by {summary["stopped_by"]} after update '
          f'{summary.get("update")} of {summary["updates"]}; continue '
          f'with: coop-train --logdir {args.logdir} --resume', flush=True)
    sys.exit(128 + signal.Signals[summary['stopped_by']].value)


if __name__ == '__main__':
  main()
