"""Learning curves from runs' metrics.csv, as a PNG.

    python -m runners.plot runs/lowlevel_position --columns return success \
        --out docs/images/lowlevel_position.png
    python -m runners.plot results/paper/transport_hrl_n4_s0 \
        results/paper/transport_hrl_n4_s1 results/paper/transport_hrl_n4_s2 \
        --columns success learner/ant/value_loss learner/ant/approx_kl \
        learner/ant/action_std --out docs/images/transport_hrl_n4.png

One panel per column against environment steps, so a figure in docs/ always
comes from run directories. One run: its curve. Several runs (the seeds of
one cell): each run thin, their mean bold in a band of +- one standard error
between the runs, over the steps that every run covers (each curve
interpolated linearly at the union of the runs' logged steps).

The stages of one model are one curve: `A+B` is run B continuing run A
(B's environment steps and wall time counted after A's), e.g. transport's
push stage and the joint run started from it:

    python -m runners.plot results/paper/transport_hrl_push_n4_s0+results/paper/transport_hrl_n4_s0 \
        --columns success --out docs/images/transport_curriculum_s0.png

`--windows` prints the numbers that docs/results.md quotes as "training
windows": per run and column, the mean of the logged values over each
stretch of environment steps, the largest value (its "best") and the last:

    python -m runners.plot results/paper/transport_no_memory_n4_s1 \
        --columns success --windows 0 1 3 6 12
"""

import dataclasses
import os
from typing import Annotated, Mapping, Sequence, Union

import matplotlib
import numpy as np
import tyro

from runners import cli
from runners import run_dir

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # pylint: disable=g-import-not-at-top


@dataclasses.dataclass(frozen=True)
class PlotArgs:
  """What to plot (every field is a CLI flag; the runs are positional)."""

  runs: Annotated[tuple[str, ...], tyro.conf.Positional]
  """Run directories (or published results), each with a metrics.csv;
  `A+B`: run B continuing run A, one curve."""
  out: str = ""
  """The PNG to write (needed unless --windows is given)."""
  columns: tuple[str, ...] = ("return", "success")
  """metrics.csv columns, one panel each."""
  title: str = ""
  """Figure title; default: the runs' names and wall time."""
  windows: tuple[float, ...] = ()
  """Edges in millions of env steps, e.g. `0 1 3 6 12`: also print, per
  run and column, the mean of the logged values in each window (a, b]
  (for `success`, each value is itself a window of the last episodes),
  the largest value and the last."""

  def __post_init__(self):
    if not self.runs:
      raise ValueError("Give at least one run directory.")
    if not self.columns:
      raise ValueError("--columns must name at least one column.")
    if not self.out and not self.windows:
      raise ValueError("--out: name the PNG to write (or give --windows).")
    if len(self.windows) == 1 or any(
        b <= a for a, b in zip(self.windows, self.windows[1:])):
      raise ValueError(f"--windows: two or more increasing edges, got "
                       f"{list(self.windows)}.")


STAGES = "+"
"""Joins the stages of one model in a run argument (`read_stages`)."""


def stages(run):
  """The run directories of a run argument: `A+B` -> [A, B]; a directory
  whose own name holds a '+' is one run."""
  return [run] if os.path.exists(run) else run.split(STAGES)


def read_stages(run):
  """`run_dir.read_metrics` of a run, or of the stages of one model written
  `A+B` (B's env steps and wall time after A's last ones)."""
  rows = []
  for stage in stages(run):
    stage_rows = run_dir.read_metrics(stage)
    if rows:
      offset = {key: rows[-1][key] for key in ("env_steps", "wall_time")
                if key in rows[-1]}
      stage_rows = [{**r, **{key: r[key] + start
                             for key, start in offset.items() if key in r}}
                    for r in stage_rows]
    rows += stage_rows
  return rows



def _curve(rows, column):
  """(env steps, values) of the rows that have `column`."""
  points = np.array([(r["env_steps"], r[column]) for r in rows
                     if column in r and "env_steps" in r], np.float64)
  return points.reshape(-1, 2).T


def mean_and_band(curves):
  """(steps, mean, standard error) of several (steps, values) curves over
  the steps that all of them cover; the standard error is 0 for one
  curve."""
  if any(len(steps) == 0 for steps, _ in curves):
    raise ValueError("A run has no logged value of this column.")
  start = max(steps[0] for steps, _ in curves)
  end = min(steps[-1] for steps, _ in curves)
  if start > end:
    raise ValueError(f"The runs cover no common environment steps (from "
                     f"{start:g} to {end:g}): give runs of one cell.")
  grid = np.unique(np.concatenate([steps[(steps >= start) & (steps <= end)]
                                   for steps, _ in curves]))
  values = np.stack([np.interp(grid, steps, v) for steps, v in curves])
  error = (values.std(0, ddof=1) / np.sqrt(len(curves)) if len(curves) > 1
           else np.zeros_like(grid))
  return grid, values.mean(0), error


def _read_runs(runs, columns):
  """Every run's rows; raises ValueError for a run without rows or one of
  `columns`."""
  all_rows = []
  for run in runs:
    rows = read_stages(run)
    if not rows:
      raise ValueError(f"{run}/metrics.csv has no rows.")
    missing = [c for c in columns if not any(c in r for r in rows)]
    if missing:
      raise ValueError(f"Columns {missing} are not in {run}/metrics.csv; "
                       f"available: {sorted(rows[-1])}.")
    all_rows.append(rows)
  return all_rows


def _panels(columns):
  fig, axes = plt.subplots(1, len(columns), figsize=(4.2 * len(columns), 3.2),
                           squeeze=False)
  for ax, column in zip(axes[0], columns):
    ax.set_xlabel("environment steps (millions)")
    ax.set_title(column)
    ax.grid(alpha=0.3)
  return fig, axes[0]


def _save(fig, out):
  if fig.get_layout_engine() is None:  # Not made with layout='constrained'.
    fig.tight_layout()
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  fig.savefig(out, dpi=100)
  plt.close(fig)


def plot(runs: Union[str, Sequence[str]], columns, out, title=None):
  """Writes one panel per column of `columns` against env steps to `out`,
  for one run directory or several (mean and band, see the module doc)."""
  runs = [runs] if isinstance(runs, str) else list(runs)
  all_rows = _read_runs(runs, columns)
  fig, axes = _panels(columns)
  names = [STAGES.join(os.path.basename(os.path.normpath(stage))
                    for stage in stages(run)) for run in runs]
  for ax, column in zip(axes, columns):
    curves = [_curve(rows, column) for rows in all_rows]
    if len(curves) == 1:
      ax.plot(curves[0][0] / 1e6, curves[0][1], lw=1.2)
    else:
      for (steps, values), name in zip(curves, names):
        ax.plot(steps / 1e6, values, lw=0.7, alpha=0.45, label=name)
      steps, mean, error = mean_and_band(curves)
      ax.plot(steps / 1e6, mean, lw=1.8, color="black", label="mean")
      ax.fill_between(steps / 1e6, mean - error, mean + error, color="black",
                      alpha=0.15, lw=0, label="+- s.e.")
  if len(runs) > 1:
    axes[0].legend(fontsize=7)
  wall = np.mean([rows[-1].get("wall_time", 0.0) for rows in all_rows]) / 60
  fig.suptitle(title or (
      f"{names[0]} ({wall:.0f} min wall time)" if len(runs) == 1 else
      f"mean +- s.e. of {len(runs)} runs (legend; {wall:.0f} min wall "
      "time per run on average)"))
  _save(fig, out)


def _finite_curve(rows, column):
  """`_curve` without its values that are not finite numbers (NaN)."""
  steps, values = _curve(rows, column)
  finite = np.isfinite(values)
  return steps[finite], values[finite]


def window_means(rows, column, edges):
  """[(a, b, mean, count)] of `column`'s finite values over the rows whose
  env steps lie in each window (a, b] of `edges` (env steps); mean is nan
  for an empty window."""
  steps, values = _finite_curve(rows, column)
  out = []
  for a, b in zip(edges, edges[1:]):
    inside = values[(steps > a) & (steps <= b)]
    out.append((a, b, float(inside.mean()) if len(inside) else float("nan"),
                len(inside)))
  return out


def _number(x: float) -> str:
  """Two decimals as docs/results.md quotes success; 3 digits for small or
  large figures (a KL of 0.011, a return of 5,835)."""
  if abs(x) >= 100:
    return f"{x:,.0f}"
  return f"{x:.2f}" if abs(x) >= 0.1 else f"{x:.3g}"


def windows_text(runs, columns, edges_millions) -> str:
  """`window_means` of every run and column as text, one line each, with
  the column's largest value (and its env steps) and its last."""
  edges = [round(e * 1e6) for e in edges_millions]
  lines = []
  for run, rows in zip(runs, _read_runs(runs, columns)):
    lines.append(f"{run} ({rows[-1].get('env_steps', 0) / 1e6:.2f}M env "
                 f"steps, {rows[-1].get('wall_time', 0.0):,.0f} s)")
    for column in columns:
      steps, values = _finite_curve(rows, column)
      if not len(values):
        lines.append(f"  {column}: no finite value")
        continue
      cells = [f"{a / 1e6:g}-{b / 1e6:g}M {_number(m)} ({n})"
               for a, b, m, n in window_means(rows, column, edges)]
      top = int(np.argmax(values))
      lines.append(f"  {column}: {', '.join(cells)}; max "
                   f"{_number(values[top])} at {steps[top] / 1e6:.2f}M, "
                   f"last {_number(values[-1])}")
  return "\n".join(lines)


def succeeded(success):
  """Each episode's success (a 0/1 or boolean value per episode) as bools."""
  return np.asarray(success, np.float64) > 0.5


def starts_and_shares(x, y, success):
  """(x, y, share) per distinct start of the episodes (x, y, success): the
  models of one variant are evaluated on the same starts, so each start is
  one point, with the share of its episodes that succeeded."""
  points = np.stack([np.asarray(x, np.float64), np.asarray(y, np.float64)],
                    axis=1)
  starts, index = np.unique(np.round(points, 6), axis=0, return_inverse=True)
  index = index.reshape(-1)
  won = succeeded(success)
  share = np.bincount(index, weights=won) / np.bincount(index)
  return starts[:, 0], starts[:, 1], share


def success_by_start(panels: Mapping[str, tuple], xlabel, ylabel, out,
                     title):
  """Writes one scatter panel per label of `panels` (label -> (x, y,
  success) arrays over episodes) to `out`: one point per start, coloured by
  the share of its episodes (one per model) that succeeded
  (`starts_and_shares`), the panel's success rate in its title."""
  fig, axes = plt.subplots(1, len(panels),
                           figsize=(max(6.5, 4.2 * len(panels)) + 0.8, 3.8),
                           squeeze=False, sharex=True, sharey=True,
                           layout="constrained")  # Room for the colour bar.
  for ax, (label, (x, y, success)) in zip(axes[0], panels.items()):
    won = succeeded(success)
    sx, sy, share = starts_and_shares(x, y, success)
    points = ax.scatter(sx, sy, c=share, s=16, cmap="RdYlGn", vmin=0.0,
                        vmax=1.0, edgecolors="black", linewidths=0.3)
    ax.set_title(f"{label.replace('`', '')}:\n{100 * won.mean():.0f}% of "
                 f"{len(won)} episodes, {len(sx)} starts", fontsize=9)
    ax.set_xlabel(xlabel)
    ax.grid(alpha=0.3)
  axes[0][0].set_ylabel(ylabel)
  fig.colorbar(points, ax=list(axes[0]), fraction=0.03,
               label="share of the start's episodes that succeeded")
  fig.suptitle(title, fontsize=10)
  _save(fig, out)


def plot_groups(groups: Mapping[str, Sequence[str]], columns, out, title):
  """Writes one panel per column to `out` with, for every group (label ->
  run directories, e.g. a variant's seeds), the mean of its runs in a band
  of +- one standard error (`mean_and_band`; one run: its curve)."""
  fig, axes = _panels(columns)
  for label, runs in groups.items():
    all_rows = _read_runs(runs, columns)
    for ax, column in zip(axes, columns):
      steps, mean, error = mean_and_band(
          [_curve(rows, column) for rows in all_rows])
      line, = ax.plot(steps / 1e6, mean, lw=1.5,
                      label=f"{label} ({len(runs)})")
      ax.fill_between(steps / 1e6, mean - error, mean + error,
                      color=line.get_color(), alpha=0.2, lw=0)
  axes[0].legend(fontsize=7, title="runs per line", title_fontsize=7)
  fig.suptitle(title)
  _save(fig, out)


def _work(args):
  text = (windows_text(args.runs, args.columns, args.windows)
          if args.windows else "")
  if args.out:
    plot(args.runs, args.columns, args.out, args.title or None)
  return text


def main(argv=None):
  args, text = cli.run(PlotArgs, _work, argv, "python -m runners.plot",
                       __doc__.splitlines()[0])
  if text:
    print(text)
  if args.out:
    print(f"wrote {args.out}")


if __name__ == "__main__":
  main()
