"""Learning curves from a run's metrics.csv, as a PNG.

    python -m runners.plot runs/lowlevel_position --columns return success \
        --out docs/images/lowlevel_position.png

One panel per column against environment steps (and wall time on a second
x axis label), so a figure in docs/ always comes from a run directory.
"""

import argparse
import csv
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # pylint: disable=g-import-not-at-top


def read_metrics(run_dir):
  """Rows of `run_dir/metrics.csv` as dicts of floats (empty cells dropped)."""
  path = os.path.join(run_dir, "metrics.csv")
  rows = []
  with open(path, newline="") as f:
    for row in csv.DictReader(f):
      parsed = {}
      for key, value in row.items():
        try:
          parsed[key] = float(value)
        except (TypeError, ValueError):
          continue
      rows.append(parsed)
  return rows


def plot(run_dir, columns, out, title=None):
  """Writes one panel per column of `columns` against env steps to `out`."""
  rows = read_metrics(run_dir)
  if not rows:
    raise ValueError(f"{run_dir}/metrics.csv has no rows.")
  missing = [c for c in columns if not any(c in r for r in rows)]
  if missing:
    raise ValueError(f"Columns {missing} are not in {run_dir}/metrics.csv; "
                     f"available: {sorted(rows[-1])}.")
  fig, axes = plt.subplots(1, len(columns), figsize=(4.2 * len(columns), 3.2),
                           squeeze=False)
  for ax, column in zip(axes[0], columns):
    points = [(r["env_steps"], r[column]) for r in rows
              if column in r and "env_steps" in r]
    ax.plot([p[0] / 1e6 for p in points], [p[1] for p in points], lw=1.2)
    ax.set_xlabel("environment steps (millions)")
    ax.set_title(column)
    ax.grid(alpha=0.3)
  wall = rows[-1].get("wall_time", 0.0) / 60
  fig.suptitle(title or f"{os.path.basename(os.path.normpath(run_dir))} "
               f"({wall:.0f} min wall time)")
  fig.tight_layout()
  os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
  fig.savefig(out, dpi=100)
  plt.close(fig)


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("run_dir")
  parser.add_argument("--columns", nargs="+", default=["return", "success"])
  parser.add_argument("--out", required=True)
  parser.add_argument("--title", default=None)
  args = parser.parse_args(argv)
  plot(args.run_dir, args.columns, args.out, args.title)
  print(f"wrote {args.out}")


if __name__ == "__main__":
  main()
