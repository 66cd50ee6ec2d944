"""coop_suite: cooperative MuJoCo Ant tasks as dm_control composer environments.

    import coop_suite
    env = coop_suite.load("transport", n_agents=4, seed=0)
    timestep = env.reset()          # observation: list of per-agent dicts
    timestep = env.step([a0, a1, a2, a3])   # one action [8] per agent

See `docs/observations.md` for every observation with its frame and units.
"""

import dataclasses
import numbers
import os
import sys

# Headless first: render through EGL unless the user chose a backend. Must be
# set before dm_control is imported (see `_headless_renderer` for when it was
# imported first).
_GL_CHOSEN_BY_USER = "MUJOCO_GL" in os.environ
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # pylint: disable=g-import-not-at-top

from coop_suite.environment import CoopEnvironment  # pylint: disable=g-import-not-at-top
from coop_suite.environment import is_truncation
from coop_suite.tasks import TASKS



def _headless_renderer():
  """Switches dm_control from GLFW to EGL where GLFW cannot render.

  A library that imports dm_control before coop_suite without MUJOCO_GL set
  (`ray.rllib` does) leaves dm_control on GLFW, its first choice, which
  needs a display: every `render()` then fails with `mujoco.FatalError`.
  dm_control looks its renderer up at each context creation, so replacing
  it is enough. A backend the user chose is kept.
  """
  render = sys.modules.get("dm_control._render")
  if (_GL_CHOSEN_BY_USER or render is None or render.BACKEND != "glfw"
      or os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
    return
  try:
    render.Renderer = render._import_egl()  # pylint: disable=protected-access
  except Exception as e:  # pylint: disable=broad-except
    error = (f"dm_control was imported before coop_suite without MUJOCO_GL "
             f"and chose GLFW, which cannot render without a display; EGL "
             f"is not available either ({e}). Set MUJOCO_GL=egl (or osmesa) "
             "in the environment before starting Python.")

    def no_renderer(*args, **kwargs):
      del args, kwargs
      raise RuntimeError(error)
    render.Renderer = no_renderer
    return
  render.BACKEND = "egl"
  render.USING_GPU = True


_headless_renderer()

__all__ = ["load", "check_options", "TASKS", "CoopEnvironment",
           "is_truncation", "pettingzoo_env", "rllib_env", "agent_range"]


def agent_range(task):
  """(min, max) number of agents `task` accepts."""
  _check_task(task)
  cls = TASKS[task][0]
  return cls.MIN_AGENTS, cls.MAX_AGENTS


def load(task, n_agents=None, *, seed=None, time_limit=None, fast_path=True,
         **kwargs):
  """Builds a multi-agent environment.

  Args:
    task: one of `TASKS`: 'transport', 'corridor', 'ravine' (cooperative),
      'walk_to_target', 'walk_velocity' (single-agent locomotion).
    n_agents: number of agents (for 'ravine': number of crossers; pushers are
      set by `n_pushers`). Defaults to 4 for the cooperative tasks, 2 crossers
      for the ravine and 1 for the locomotion tasks.
    seed: integer seed for the environment's random state; the same seed
      gives the same episodes.
    time_limit: episode length in seconds; defaults to the task's config.
    fast_path: False steps through plain composer (`coop_suite.fast`): the
      same numbers, several times slower; for checking the fast path.
    **kwargs: task options: any field of the task's config dataclass (e.g.
      `target_radius=1.5`), plus task arguments: `stage` (transport's and
      the ravine's training curricula) and the ravine's `n_pushers`.

  Returns:
    A `CoopEnvironment` (a `composer.Environment`). It pickles and copies
    as these arguments: the copy is a fresh build, not a snapshot of the
    current episode.

  Raises:
    ValueError: unknown task, agent count out of range, unknown option, an
      option out of its range (e.g. `time_limit` not a finite number > 0).
    TypeError: non-integer agent count or seed.
  """
  task_instance, config = _build_task(task, n_agents, seed, time_limit,
                                      kwargs)
  env = CoopEnvironment(task_instance, time_limit=config.time_limit,
                        random_state=np.random.RandomState(seed),
                        fast_path=fast_path)
  # What pickling and copying rebuild the environment from.
  env.load_arguments = ((task, n_agents),
                        dict(seed=seed, time_limit=time_limit,
                             fast_path=fast_path, **kwargs))
  return env


def check_options(task, n_agents=None, *, seed=None, time_limit=None,
                  **kwargs):
  """Raises what `load` with these arguments would raise, without building
  the environment (the task is built, the model is not compiled; ~0.1 s).

  For callers that must refuse bad options before acting on them, e.g.
  `coop-train` before it creates its run directory.
  """
  _build_task(task, n_agents, seed, time_limit, kwargs)


def _build_task(task, n_agents, seed, time_limit, kwargs):
  """(the task, its config) for `load`'s arguments; raises on bad ones."""
  cls, config_cls, default_agents = TASKS[_check_task(task)]
  if n_agents is None:
    n_agents = default_agents
  if isinstance(n_agents, bool) or not isinstance(n_agents, numbers.Integral):
    raise TypeError(f"n_agents must be an integer, got {n_agents!r}.")
  n_agents = int(n_agents)
  if not cls.MIN_AGENTS <= n_agents <= cls.MAX_AGENTS:
    raise ValueError(f"Task {task!r} accepts {cls.MIN_AGENTS} to "
                     f"{cls.MAX_AGENTS} agents, got {n_agents}.")
  if seed is not None and (isinstance(seed, bool)
                           or not isinstance(seed, numbers.Integral)):
    raise TypeError(f"seed must be an integer or None, got {seed!r}.")
  config_fields = {f.name for f in dataclasses.fields(config_cls)}
  config_kwargs = {k: v for k, v in kwargs.items() if k in config_fields}
  task_kwargs = {k: v for k, v in kwargs.items() if k not in config_fields}
  allowed_task_kwargs = getattr(cls, "TASK_OPTIONS", ())
  unknown = sorted(set(task_kwargs) - set(allowed_task_kwargs))
  if unknown:
    raise ValueError(
        f"Unknown option(s) {unknown} for task {task!r}; allowed: "
        f"{sorted(config_fields | set(allowed_task_kwargs))}.")
  if time_limit is not None:
    if isinstance(time_limit, bool) or not isinstance(time_limit,
                                                      numbers.Real):
      raise TypeError(f"time_limit must be a number of seconds or None, got "
                      f"{time_limit!r}.")
    # The task config checks the range (finite, > 0).
    config_kwargs["time_limit"] = float(time_limit)
  config = config_cls(**config_kwargs)
  return cls(n_agents, config=config, **task_kwargs), config


def pettingzoo_env(task, n_agents=None, *, flatten=False, render_mode=None,
                   render_size=(480, 640), **load_kwargs):
  """A PettingZoo `ParallelEnv` around `load(task, n_agents, **load_kwargs)`.

  `flatten`, `render_mode` and `render_size` go to
  `coop_suite.pettingzoo.ParallelEnv`; see docs/pettingzoo.md.
  """
  from coop_suite import pettingzoo  # pylint: disable=g-import-not-at-top
  return pettingzoo.ParallelEnv(load(task, n_agents, **load_kwargs),
                              flatten=flatten, render_mode=render_mode,
                              render_size=render_size)


def rllib_env(task, n_agents=None, **options):
  """An RLlib `MultiAgentEnv` around `load(task, n_agents, ...)`.

  `options`: `flatten` (default True), `render_mode`, `render_size` and any
  `load` option; see `coop_suite.rllib` (needs the `rllib` extra).
  """
  from coop_suite import rllib  # pylint: disable=g-import-not-at-top
  return rllib.MultiAgentEnv({"task": task, "n_agents": n_agents, **options})


def _check_task(task):
  if task not in TASKS:
    raise ValueError(f"Unknown task {task!r}; choose one of {sorted(TASKS)}.")
  return task

