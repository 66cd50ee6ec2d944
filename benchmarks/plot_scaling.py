"""The actor scaling curve from `training_throughput.py --actors ...` output.

    python benchmarks/plot_scaling.py \
        results/benchmarks/actor_scaling_2026-11-26/gpu_learner.txt \
        results/benchmarks/actor_scaling_2026-11-26/cpu_learner.txt \
        --out docs/images/actor_scaling.png

Each file is one run's printed output, saved as it was (`... | tee FILE`):
its "pipeline, N actors: R env steps/s" lines and the one-core raw rate.
Left: env steps/s against actors, with N x raw (the physics alone on N
cores) and 0.60 x N x raw (the issue's target) for the first file's raw
rate. Right: env steps/s per actor / raw, the ratio the benchmark prints.
"""
import argparse
import os
import re

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # pylint: disable=g-import-not-at-top

_PIPELINE = re.compile(r'^pipeline, (\d+) actors?: (\d+) env steps/s')
_RAW = re.compile(r'^one core: raw (\d+) control steps/s')


def read(path):
  """(raw control steps/s on one core, {actors: env steps/s}) of a run."""
  raw, rates = None, {}
  with open(path) as f:
    for line in f:
      if match := _RAW.match(line):
        raw = float(match.group(1))
      elif match := _PIPELINE.match(line.strip()):
        rates[int(match.group(1))] = float(match.group(2))
  if raw is None or not rates:
    raise ValueError(f'{path}: no "one core: raw" line or no pipeline rows; '
                     'is it training_throughput.py output?')
  return raw, rates


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('runs', nargs='+', help='saved benchmark outputs')
  parser.add_argument('--labels', nargs='*', default=None,
                      help='one per run (default: the file names)')
  parser.add_argument('--out', required=True, help='PNG to write')
  args = parser.parse_args(argv)
  labels = args.labels or [os.path.splitext(os.path.basename(p))[0]
                           for p in args.runs]
  if len(labels) != len(args.runs):
    parser.error(f'{len(labels)} labels for {len(args.runs)} runs')
  runs = [read(p) for p in args.runs]
  fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
  raw0 = runs[0][0]
  most = max(max(rates) for _, rates in runs)
  left.plot([1, most], [raw0, most * raw0], 'k:', label='N x raw')
  left.plot([1, most], [0.6 * raw0, 0.6 * most * raw0], 'k--', lw=0.8,
            label='0.60 x N x raw (target)')
  for label, (raw, rates) in zip(labels, runs):
    actors = sorted(rates)
    left.plot(actors, [rates[n] for n in actors], 'o-', label=label)
    right.plot(actors, [rates[n] / (n * raw) for n in actors], 'o-',
               label=label)
  left.set(xlabel='actors', ylabel='env steps/s', title='pipeline throughput')
  right.set(xlabel='actors', ylabel='env steps/s / (actors x raw)',
            ylim=(0, 1), title='per actor, against raw MuJoCo')
  right.axhline(0.6, color='k', ls='--', lw=0.8)
  for ax in (left, right):
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
  fig.tight_layout()
  fig.savefig(args.out, dpi=100)
  print(f'wrote {args.out}')


if __name__ == '__main__':
  main()
