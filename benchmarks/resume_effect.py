"""Does resuming a run from its stash change its learning curve?

    python benchmarks/resume_effect.py [--window 0.5] [--column success]

`coop-paper` stops a cell at a session's deadline and the next session
resumes it from its stash: parameters, optimiser, normalisers, counters and
the metrics window are restored, but every episode starts anew. This reads
where that happened from git: every commit of `results/paper_partial/` names
its stashed checkpoints (update N, so the resumed run's first row is update
N + 1), and each published cell's metrics.csv under `results/paper/` holds
its whole curve. For each resume it prints the change in `--column` (a mean
over the metrics window of the last episodes) from the `--window` million
env steps before the resume to the same after, and a local placebo: the
mean of the same change at 2, 3 and 4 windows before and after in the same
run, away from any other resume. Their difference is the resume's effect
beyond the run's own trend; the summary tests it across all resumes
(t-test, Wilcoxon and sign test against 0). Resumes where the column is 0
throughout the two windows (a run that never succeeds yet) say nothing and
are left out. Reads committed files only; no training.
"""
import argparse
import collections
import os
import re
import subprocess
import sys

import numpy as np
from scipy import stats

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from runners import plot, run_dir  # noqa: E402


def resume_points(partial: str) -> dict:
  """{cell folder: sorted stashed update numbers} over git history."""
  commits = subprocess.run(
      ['git', 'log', '--format=%H', '--', partial], check=True,
      capture_output=True, text=True).stdout.split()
  points = collections.defaultdict(set)
  pattern = re.compile(
      rf'^{re.escape(partial.rstrip("/"))}/([^/]+)/checkpoints/\D*0*(\d+)$')
  for commit in commits:
    listing = subprocess.run(
        ['git', 'ls-tree', '-r', '-d', '--name-only', commit, partial + '/'],
        check=True, capture_output=True, text=True).stdout.splitlines()
    for path in listing:
      match = pattern.match(path)
      if match:
        points[match.group(1)].add(int(match.group(2)))
  return {cell: sorted(updates) for cell, updates in points.items()}


def change(rows, column, at, window):
  """(mean after - mean before, mean before) over `window` env steps on
  either side of `at`, or None where a side is cut off or has < 3 rows."""
  before, after = plot.window_means(
      rows, column, [at - window, at, at + window])[:2]
  if min(before[3], after[3]) < 3 or at + window > rows[-1]['env_steps']:
    return None
  return after[2] - before[2], before[2]


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
  parser.add_argument('--results', default='results/paper')
  parser.add_argument('--partial', default='results/paper_partial')
  parser.add_argument('--window', type=float, default=0.5,
                      help='millions of env steps on each side')
  parser.add_argument('--column', default='success')
  args = parser.parse_args(argv)
  window = args.window * 1e6
  effects = []
  for cell, updates in sorted(resume_points(args.partial).items()):
    logdir = os.path.join(args.results, cell)
    if not run_dir.has_metrics(logdir):
      continue  # Still training.
    rows = run_dir.read_metrics(logdir)
    if not any(args.column in row for row in rows):
      continue
    first = {int(row['update']): row['env_steps'] for row in rows}
    resumes = [first[u + 1] for u in updates if u + 1 in first]
    for at in resumes:
      own = change(rows, args.column, at, window)
      near = [row[args.column] for row in rows
              if abs(row['env_steps'] - at) < window
              and args.column in row]
      if own is None or not any(near):
        continue
      placebo = [change(rows, args.column, at + sign * k * window, window)
                 for k in (2, 3, 4) for sign in (-1, 1)
                 if all(abs(at + sign * k * window - other) > 1.5 * window
                        for other in resumes)]
      placebo = [p[0] for p in placebo if p is not None]
      if len(placebo) < 2:
        continue
      effects.append(own[0] - np.mean(placebo))
      print(f'{cell:34s} at {at / 1e6:6.2f}M: {args.column} {own[1]:.3f} '
            f'before, change {own[0]:+.3f}, local placebo '
            f'{np.mean(placebo):+.3f} (sd {np.std(placebo, ddof=1):.3f} '
            f'over {len(placebo)})')
  effects = np.array(effects)
  if len(effects) < 2:
    sys.exit('Fewer than two resumes to compare.')
  below = int((effects < 0).sum())
  print(f'{len(effects)} resumes, window {args.window}M: change beyond the '
        f'local placebo {effects.mean():+.4f} +- '
        f'{effects.std(ddof=1) / np.sqrt(len(effects)):.4f} (mean +- se); '
        f't-test p = {stats.ttest_1samp(effects, 0).pvalue:.2f}, Wilcoxon '
        f'p = {stats.wilcoxon(effects).pvalue:.2f}; below it in {below} of '
        f'{len(effects)} (sign test p = '
        f'{stats.binomtest(below, len(effects)).pvalue:.2f})')


if __name__ == '__main__':
  main()
