"""Records a task to mp4 (and/or one PNG still) headless, with no viewer.

    python -m runners.video --task transport --n-agents 4 --policy random \
        --seconds 10 --out transport.mp4 --png transport.png

Rendering uses MuJoCo's offscreen EGL context (`MUJOCO_GL=egl` is set by
`coop_suite` unless you chose another backend), so it works on a server.
"""

import collections
import dataclasses
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")
# imageio-ffmpeg starts ffmpeg with `preexec_fn=os.setpgrp` (to keep Ctrl-C
# from it), which makes Python run its fork handlers in a process where JAX
# (coop-eval) already runs threads: unsafe, and JAX warns "os.fork() ...
# deadlock" at every video. Without it ffmpeg shares our Ctrl-C, which is
# harmless: the writer is closed on the way out.
os.environ.setdefault("IMAGEIO_FFMPEG_NO_PREVENT_SIGINT", "1")

import imageio  # pylint: disable=g-import-not-at-top
import numpy as np
import tqdm

from agents import fields
import coop_suite
from coop_suite import camera as camera_lib
from runners import cli

POLICIES = ("random", "zero")


@dataclasses.dataclass(frozen=True)
class VideoArgs:
  """What to record."""

  task: str = "transport"
  """Task name: one of coop_suite.TASKS."""
  n_agents: int = 4
  """Number of agents (ravine: crossers)."""
  policy: str = fields.field("random", fields.one_of(*POLICIES))
  """'random' (uniform actions in [-1, 1]) or 'zero'."""
  seconds: float = fields.field(10.0, fields.POSITIVE)
  """Simulated seconds to record (the episode restarts if it ends)."""
  out: str = ""
  """mp4 file to write; empty for none."""
  png: str = ""
  """PNG still of the first frame to write; empty for none."""
  seed: int = fields.field(0, fields.SEED)
  """Environment and policy seed."""
  width: int = fields.field(640, fields.COUNT)
  """Frame width in pixels."""
  height: int = fields.field(480, fields.COUNT)
  """Frame height in pixels."""
  fps: int = fields.field(20, fields.COUNT)
  """Frames per second of the video (one frame per control step at 20)."""

  def __post_init__(self):
    fields.check(self)


def open_video(path, fps):
  """An mp4 writer (H.264) at `path` for uint8 frames [height, width, 3];
  `append_data(frame)`, then `close()`."""
  os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
  return imageio.get_writer(path, fps=fps, codec="libx264", quality=7,
                            macro_block_size=8)


def write_strip(video, png, count=5):
  """Writes to `png` `count` evenly spaced frames of the mp4 `video` (its
  first and last included) side by side at half size."""
  with imageio.get_reader(video) as reader:
    picked = np.linspace(0, reader.count_frames() - 1, count).round()
    frames = [reader.get_data(int(i))[::2, ::2] for i in picked]
  os.makedirs(os.path.dirname(os.path.abspath(png)), exist_ok=True)
  imageio.imwrite(png, np.concatenate(frames, axis=1))


def make_policy(name, env, seed):
  """A function timestep -> actions [n_agents, 8] for a non-learned policy."""
  if name not in POLICIES:
    raise ValueError(f"Unknown policy {name!r}; choose one of {POLICIES}.")
  n = env.n_agents
  rng = np.random.RandomState(seed)
  if name == "zero":
    return lambda timestep: np.zeros((n, 8))
  return lambda timestep: rng.uniform(-1.0, 1.0, (n, 8))


def record(args: VideoArgs, policy=None):
  """Runs the episode(s) and writes the requested files. Returns #frames."""
  if not args.out and not args.png:
    raise ValueError("Nothing to write: give --out FILE.mp4 and/or --png.")
  env = coop_suite.load(args.task, args.n_agents, seed=args.seed)
  policy = policy or make_policy(args.policy, env, args.seed)
  camera = camera_lib.FramingCamera()
  timestep = env.reset()
  control_dt = env.control_timestep()
  steps = max(1, int(round(args.seconds / control_dt)))
  frame_every = max(1, int(round(1.0 / (args.fps * control_dt))))
  writer = None
  if args.out:
    writer = open_video(args.out, args.fps)
  frames = 0
  try:
    for step in tqdm.trange(steps, desc=f"recording {args.task}",
                            disable=not sys.stderr.isatty()):
      if step % frame_every == 0:
        frame = camera_lib.render(env, camera, args.width, args.height)
        if args.png and frames == 0:
          imageio.imwrite(args.png, frame)
        if writer is not None:
          writer.append_data(frame)
        frames += 1
        if writer is None:
          break
      timestep = env.step(policy(timestep))
      if timestep.last():
        timestep = env.reset()
        camera.reset()
  finally:
    if writer is not None:
      writer.close()
    env.close()
  return frames


def population(species):
  """Who is in the picture, e.g. ('crosser', 'crosser', 'pusher') ->
  '2 crossers and 1 pusher'; one species of 'ant' -> '4 agents'."""
  counts = collections.Counter(species)
  if set(counts) == {"ant"}:
    return f"{counts['ant']} agent{'s' * (counts['ant'] != 1)}"
  return " and ".join(f"{n} {kind}{'s' * (n != 1)}"
                      for kind, n in counts.items())


def main(argv=None):
  args, frames = cli.run(VideoArgs, record, argv, "coop-video",
                         __doc__.splitlines()[0])
  for path in (args.out, args.png):
    if path:
      print(f"wrote {path} ({os.path.getsize(path) / 1e3:.0f} kB)")
  env = coop_suite.load(args.task, args.n_agents)  # For its species only.
  print(f"{frames} frames of {args.task} with {population(env.task.species)}")
  env.close()


if __name__ == "__main__":
  main()
