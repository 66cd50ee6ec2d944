"""Headless rendering: a still and a short mp4 through the CLI."""

import imageio
import numpy as np

from runners import video


def test_png_still_frames_agents(tmp_path):
  png = tmp_path / "still.png"
  video.main(["--task", "ravine", "--n-agents", "2", "--png", str(png),
              "--width", "160", "--height", "120"])
  image = imageio.imread(png)
  assert image.shape == (120, 160, 3)
  assert image.std() > 5  # Not a blank frame.


def test_mp4_has_one_frame_per_control_step(tmp_path):
  out = tmp_path / "clip.mp4"
  frames = video.record(video.VideoArgs(
      task="transport", n_agents=2, seconds=0.5, out=str(out), width=160,
      height=128, fps=20))
  assert frames == 10
  reader = imageio.get_reader(str(out))
  decoded = [frame for frame in reader]
  assert len(decoded) == 10
  assert decoded[0].shape == (128, 160, 3)
  # Agents move under random actions, so frames differ.
  assert np.abs(decoded[0].astype(int) - decoded[-1].astype(int)).mean() > 0.1


def test_unknown_policy_is_rejected():
  import pytest  # pylint: disable=g-import-not-at-top
  with pytest.raises(ValueError, match="random"):
    video.record(video.VideoArgs(policy="smart", png="x.png"))
  with pytest.raises(ValueError, match="Nothing to write"):
    video.record(video.VideoArgs())
