"""Learning-curve PNGs come from run directories' metrics.csv."""

import imageio
import numpy as np
import pytest

from runners import plot
from runners import run_dir


def _run(path, rows):
  path.mkdir()
  (path / "metrics.csv").write_text(
      "update,env_steps,wall_time,return,success\n" + "".join(
          f"{i + 1},{steps},{i + 1.0},{ret},{success}\n"
          for i, (steps, ret, success) in enumerate(rows)))
  return str(path)


def test_plot_writes_a_png_and_names_missing_columns(tmp_path):
  run = _run(tmp_path / "run", [(1000, 10.0, 0.0), (2000, "", 0.5),
                                (3000, 30.0, 1.0)])
  out = tmp_path / "curve.png"
  plot.main([run, "--columns", "return", "success", "--out", str(out)])
  assert imageio.v2.imread(out).ndim == 3
  with pytest.raises(ValueError, match="available"):
    plot.plot(run, ["nope"], str(out))


def test_several_runs_give_their_mean_and_band(tmp_path, capsys):
  a = _run(tmp_path / "s0", [(1000, 0.0, 0.0), (2000, 2.0, 0.5),
                             (3000, 4.0, 1.0)])
  b = _run(tmp_path / "s1", [(1500, 1.5, 0.0), (2500, 3.5, 1.0)])
  steps, mean, error = plot.mean_and_band([plot._curve(run_dir.read_metrics(r),  # pylint: disable=protected-access
                                                       "return")
                                           for r in (a, b)])
  # Where both runs have data, at both runs' steps, interpolated.
  np.testing.assert_allclose(steps, [1500, 2000, 2500])
  a_at = np.array([1.0, 2.0, 3.0])
  b_at = np.array([1.5, 2.5, 3.5])
  np.testing.assert_allclose(mean, (a_at + b_at) / 2)
  np.testing.assert_allclose(error, np.std([a_at, b_at], 0, ddof=1)
                             / np.sqrt(2))
  late = _run(tmp_path / "late", [(5000, 1.0, 0.0), (6000, 2.0, 0.0)])
  with pytest.raises(ValueError, match="no common"):
    plot.plot([a, late], ["return"], str(tmp_path / "none.png"))
  out = tmp_path / "seeds.png"
  plot.main([a, b, "--columns", "success", "--out", str(out)])
  assert imageio.v2.imread(out).ndim == 3 and "wrote" in capsys.readouterr().out
  with pytest.raises(SystemExit) as exit_info:
    plot.main([a, str(tmp_path / "missing"), "--out", str(out)])
  assert exit_info.value.code == 2
  assert "runners.plot: error" in capsys.readouterr().err


def test_the_stages_of_one_model_are_one_curve(tmp_path, capsys):
  push = _run(tmp_path / "push", [(1000, 1.0, 0.0), (2000, 2.0, 0.0)])
  joint = _run(tmp_path / "joint", [(500, 3.0, 0.5), (1500, 4.0, 1.0)])
  rows = plot.read_stages(f"{push}+{joint}")
  assert [r["env_steps"] for r in rows] == [1000, 2000, 2500, 3500]
  assert [r["wall_time"] for r in rows] == [1.0, 2.0, 3.0, 4.0]
  assert [r["return"] for r in rows] == [1.0, 2.0, 3.0, 4.0]
  out = tmp_path / "stages.png"
  plot.main([f"{push}+{joint}", "--out", str(out)])
  assert imageio.v2.imread(out).ndim == 3
  with pytest.raises(SystemExit):
    plot.main([f"{push}+{tmp_path / 'nope'}", "--out", str(out)])
  assert "nope" in capsys.readouterr().err


def test_success_by_start_gives_each_start_its_models_share(tmp_path):
  # Two models on the same three starts (episodes in model order): a start
  # is one point with its success share. A second panel draws one model's.
  x, y = [4.0, 5.0, 6.0] * 2, [3.0, 3.5, 4.0] * 2
  success = [1.0, 0.0, 1.0, 1.0, 0.0, 0.0]
  sx, sy, share = plot.starts_and_shares(x, y, success)
  assert sx.tolist() == [4.0, 5.0, 6.0] and sy.tolist() == [3.0, 3.5, 4.0]
  assert share.tolist() == [1.0, 0.0, 0.5]
  out = tmp_path / "starts.png"
  plot.success_by_start({"HRL": (x, y, success),
                         "one model": (x[:3], y[:3], success[:3])},
                        "x", "y", str(out), "by start")
  assert imageio.v2.imread(out).ndim == 3


def test_windows_print_the_mean_of_each_stretch_of_env_steps(tmp_path,
                                                              capsys):
  run = _run(tmp_path / "run", [(500_000, 1.0, 0.0), (1_000_000, 2.0, 0.2),
                                (1_500_000, 3.0, 0.6), (2_000_000, 4.0, 0.4),
                                (3_000_000, 5.0, 0.3)])
  rows = run_dir.read_metrics(run)
  assert plot.window_means(rows, "success", [0, 1e6, 2e6, 2.5e6]) == [
      (0, 1e6, pytest.approx(0.1), 2), (1e6, 2e6, pytest.approx(0.5), 2),
      (2e6, 2.5e6, pytest.approx(float("nan"), nan_ok=True), 0)]
  plot.main([run, "--columns", "success", "--windows", "0", "1", "3"])
  out = capsys.readouterr().out
  assert "success: 0-1M 0.10 (2), 1-3M 0.43 (3); max 0.60 at 1.50M, " \
         "last 0.30" in out
  assert "wrote" not in out  # no --out: no PNG
  for bad, message in ((["--windows", "1"], "two or more increasing edges"),
                       (["--windows", "0", "3", "2"], "increasing edges"),
                       ([], "--out: name the PNG")):
    with pytest.raises(SystemExit):
      plot.main([run, *bad])
    assert message in capsys.readouterr().err


def test_windows_leave_out_values_that_are_not_numbers(tmp_path, capsys):
  run = _run(tmp_path / "run", [(1_000_000, 1.0, 0.2), (2_000_000, 2.0, "nan"),
                                (3_000_000, 3.0, 0.4)])
  plot.main([run, "--columns", "success", "--windows", "0", "3"])
  assert "success: 0-3M 0.30 (2); max 0.40 at 3.00M, last 0.40" in (
      capsys.readouterr().out)
