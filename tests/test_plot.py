"""Learning-curve PNGs come from a run directory's metrics.csv."""

import imageio
import pytest

from runners import plot


def test_plot_writes_a_png_and_names_missing_columns(tmp_path):
  run = tmp_path / "run"
  run.mkdir()
  (run / "metrics.csv").write_text(
      "update,env_steps,wall_time,return,success\n"
      "1,1000,1.0,10.0,0.0\n2,2000,2.0,,0.5\n3,3000,3.0,30.0,1.0\n")
  out = tmp_path / "curve.png"
  plot.main([str(run), "--columns", "return", "success", "--out", str(out)])
  assert imageio.v2.imread(out).ndim == 3
  with pytest.raises(ValueError, match="available"):
    plot.plot(str(run), ["nope"], str(out))
