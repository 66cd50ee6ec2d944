"""Does resuming a run from its stash change its learning curve?

    python benchmarks/resume_effect.py [--window 0.5] [--column success]

`coop-paper` stops a cell at a session's deadline and the next session
resumes it from its stash: parameters, optimiser, normalisers, counters and
the metrics window are restored, but every episode starts anew. This reads
where that happened from git: every commit of `results/paper_partial/` holds
a cell's stashed checkpoint (update N) and the stash's metrics.csv. A stash
counts as a resume of the published run when its row N is the published
metrics.csv's row N (same env steps and wall time); stashes of runs that
were later discarded and trained again under the cell's name do not. For
each resume it prints the change in `--column` (a mean over the metrics
window of the last episodes) from the `--window` million env steps up to
row N to the same after it, and a local placebo: the mean of the same
change at 2, 3 and 4 windows before and after in the same run, whole
windows only and away from any other resume (on one side the three
changes telescope, so the placebo is in effect the run's local slope).
Their difference is the resume's effect beyond the run's own trend; the
summary tests it across all resumes (t-test, Wilcoxon and sign test
against 0). Resumes where the column is 0 throughout the two windows (a
run that never succeeds yet) say nothing and are left out, as are the
resumes of cells not yet published. Reads committed files only; no
training.
"""
import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile

import numpy as np
from scipy import stats

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from runners import checkpoints, plot, run_dir  # noqa: E402


def _stash_rows(commit: str, folder: str):
  """`read_metrics` rows of the stash `folder` as `commit` holds it."""
  with tempfile.TemporaryDirectory() as tmp:
    for name in (run_dir.METRICS, run_dir.PACKED_METRICS):
      shown = subprocess.run(['git', 'show', f'{commit}:{folder}/{name}'],
                             capture_output=True)
      if shown.returncode == 0:
        with open(os.path.join(tmp, name), 'wb') as f:
          f.write(shown.stdout)
        return run_dir.read_metrics(tmp)
  return []


def resume_points(partial: str) -> dict:
  """{cell folder: {stashed update: [each stash's row of that update]}}
  over git history (a row is {} where its stash has no metrics row for it;
  two runs of one cell can have stashed the same update)."""
  commits = subprocess.run(
      ['git', 'log', '--format=%H', '--', partial], check=True,
      capture_output=True, text=True).stdout.split()
  points = collections.defaultdict(dict)
  partial = partial.rstrip('/')
  pattern = re.compile(rf'^{re.escape(partial)}/([^/]+)/checkpoints/[^/]+$')
  for commit in commits:
    listing = subprocess.run(
        ['git', 'ls-tree', '-r', '-d', '--name-only', commit, partial + '/'],
        check=True, capture_output=True, text=True).stdout.splitlines()
    for path in listing:
      match = pattern.match(path)
      try:
        update = match and checkpoints.checkpoint_update(path)
      except ValueError:  # Not a checkpoint (orbax's temporary folders).
        continue
      if match:
        cell = match.group(1)
        rows = _stash_rows(commit, f'{partial}/{cell}')
        points[cell].setdefault(update, []).append(next(
            (row for row in rows if row.get('update') == update), {}))
  return points


def _same_row(a, b) -> bool:
  return all(k in a and k in b and abs(a[k] - b[k]) < 1e-6
             for k in ('env_steps', 'wall_time'))


def change(rows, column, at, window):
  """(mean after - mean before, mean before) over `window` env steps on
  either side of `at` (windows (a, b]), or None where a side runs past the
  run's first or last row or has < 3 rows."""
  if at - window < rows[0]['env_steps'] or at + window > rows[-1]['env_steps']:
    return None
  before, after = plot.window_means(
      rows, column, [at - window, at, at + window])[:2]
  if min(before[3], after[3]) < 3:
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
  points = resume_points(args.partial)
  effects, raw, background = [], [], []
  for cell in sorted(os.listdir(args.results)):
    logdir = os.path.join(args.results, cell)
    if not run_dir.has_metrics(logdir):
      continue
    rows = run_dir.read_metrics(logdir)
    if not any(args.column in row for row in rows):
      continue
    published = {int(row['update']): row for row in rows}
    resumes = [published[u]['env_steps']
               for u, stashed in points.get(cell, {}).items()
               if u in published
               and any(_same_row(row, published[u]) for row in stashed)]

    def informative(at):  # The column is not 0 throughout the two windows.
      return any(row.get(args.column) for row in rows
                 if abs(row['env_steps'] - at) < window)

    for at in np.arange(rows[0]['env_steps'] + window,
                        rows[-1]['env_steps'], window):
      step = change(rows, args.column, at, window)
      if (step is not None and informative(at)
          and all(abs(at - other) > 1.5 * window for other in resumes)):
        background.append(step[0])
    for at in resumes:
      own = change(rows, args.column, at, window)
      if own is None or not informative(at):
        continue
      placebo = [change(rows, args.column, at + sign * k * window, window)
                 for k in (2, 3, 4) for sign in (-1, 1)
                 if all(abs(at + sign * k * window - other) > 1.5 * window
                        for other in resumes)]
      placebo = [p[0] for p in placebo if p is not None]
      if len(placebo) < 2:
        continue
      effects.append(own[0] - np.mean(placebo))
      raw.append(own[0])
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
  # The tails: how often the runs' own consecutive windows (every published
  # run, away from resumes) change as much as the largest changes at resumes.
  background = np.array(background)
  for name, extreme, share in (
      ('drops', sorted(raw)[:3], lambda v: (background <= v).mean()),
      ('rises', sorted(raw)[::-1][:3], lambda v: (background >= v).mean())):
    print(f'largest {name} at resumes (raw) ' + ', '.join(
        f'{v:+.3f} (the runs\' own windows: {100 * share(v):.1f}% of '
        f'{len(background)} as far, {share(v) * len(raw):.1f} of '
        f'{len(raw)} resumes expected)' for v in extreme))


if __name__ == '__main__':
  main()
