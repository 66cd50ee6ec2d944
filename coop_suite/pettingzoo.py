"""A PettingZoo `ParallelEnv` adapter for every coop_suite task.

    env = coop_suite.pettingzoo_env("ravine", 2, time_limit=20.0)
    observations, infos = env.reset(seed=0)
    while env.agents:
      actions = {a: env.action_space(a).sample() for a in env.agents}
      observations, rewards, terminations, truncations, infos = env.step(
          actions)

We do not use the generic dm_env bridge (Shimmy's
`DmControlMultiAgentCompatibilityV0`) because of three things it gets wrong
for a benchmark, each fixed here:

* Termination versus truncation. dm_env marks the task ending an episode
  (failure, physics divergence, success with `end_on_success`) with
  discount 0, and a time-limit end with discount 1
  (`coop_suite.is_truncation`). Gymnasium's `terminated` means "do not
  bootstrap", `truncated` means "bootstrap from the last observation".
  Shimmy maps discount 0 to truncation, which is backwards and makes value
  targets wrong at every terminal step.
* Seeding. `reset(seed=s)` reseeds `env.random_state`, which draws every
  episode's randomisation, so the same seed gives the same episode and the
  same rollout under the same actions. Shimmy documents that seeding does
  not work.
* Actions are matched to agents by id, not by dict order, and bad input
  gets the dm_env interface's clear errors instead of an assert.

Agent ids say species and index within the species, as the Ants' MJCF
names do: 'ant_0', 'ant_1' ... or 'crosser_0', 'crosser_1', 'pusher_0'.
All agents of a task start and end an episode together.
"""

from collections import abc
import numbers

from coop_suite import camera as camera_lib
from coop_suite.environment import is_truncation
import numpy as np

try:
  import gymnasium
  from gymnasium import spaces
  import pettingzoo
except ImportError as e:  # pragma: no cover - depends on the install.
  raise ImportError(
      "coop_suite.pettingzoo needs the optional PettingZoo extra: "
      "pip install -e .[pettingzoo]") from e

__all__ = ["ParallelEnv", "agent_ids"]

RENDER_MODES = ("rgb_array",)


def agent_ids(species):
  """Ids for `species`, e.g. ('crosser', 'crosser', 'pusher') ->
  ['crosser_0', 'crosser_1', 'pusher_0'], in the environment's agent order."""
  counts = {}
  ids = []
  for kind in species:
    ids.append(f"{kind}_{counts.get(kind, 0)}")
    counts[kind] = counts.get(kind, 0) + 1
  return ids


def _box(shape, low=-np.inf, high=np.inf):
  shape = tuple(shape)
  return spaces.Box(low=np.broadcast_to(np.float32(low), shape),
                    high=np.broadcast_to(np.float32(high), shape),
                    dtype=np.float32)


def _rebuild(env, options):
  """`ParallelEnv.__reduce__`'s inverse."""
  return ParallelEnv(env, **options)


class ParallelEnv(pettingzoo.ParallelEnv):
  """PettingZoo view of a `CoopEnvironment`; see the module docstring.

  Observations are float32: by default a dict 'proprio/...', 'extero/...',
  'command/...' -> [dim] per agent (see `docs/observations.md` for frames
  and units); with `flatten=True` one vector per agent, the keys
  concatenated in sorted order (`observation_keys(agent)` gives the slices).
  Actions are float32 [8] in [-1, 1]; values outside are clipped, as in
  the dm_env interface.
  """

  metadata = {"name": "coop_suite_v0", "render_modes": list(RENDER_MODES),
              "is_parallelizable": True}

  def __init__(self, env, *, flatten=False, render_mode=None,
               render_size=(480, 640)):
    """Args:
      env: a `coop_suite.CoopEnvironment`, e.g. from `coop_suite.load`.
      flatten: one flat float32 vector per agent instead of a dict.
      render_mode: None or 'rgb_array'.
      render_size: (height, width) of rendered frames, pixels.
    """
    if render_mode is not None and render_mode not in RENDER_MODES:
      raise ValueError(f"render_mode must be None or one of {RENDER_MODES}, "
                       f"got {render_mode!r}.")
    self.env = env
    self.flatten = bool(flatten)
    self.render_mode = render_mode
    self._render_size = tuple(render_size)
    self._camera = camera_lib.FramingCamera()
    # Per-instance copy: frames are one control step apart.
    self.metadata = dict(self.metadata,
                         render_fps=int(round(1.0 / env.control_timestep())))
    self.possible_agents = agent_ids(env.task.species)
    self.agents = []
    self._index = {agent: i for i, agent in enumerate(self.possible_agents)}
    self._layouts = {}
    self.observation_spaces = {}
    self.action_spaces = {}
    for agent, obs_spec, action_spec in zip(
        self.possible_agents, env.observation_spec(), env.action_spec()):
      layout, start = {}, 0
      for key in sorted(obs_spec):
        size = int(np.prod(obs_spec[key].shape))
        layout[key] = slice(start, start + size)
        start += size
      self._layouts[agent] = layout
      if self.flatten:
        self.observation_spaces[agent] = _box((start,))
      else:
        self.observation_spaces[agent] = spaces.Dict(
            {key: _box(obs_spec[key].shape) for key in layout})
      self.action_spaces[agent] = _box(
          action_spec.shape,
          np.broadcast_to(action_spec.minimum, action_spec.shape),
          np.broadcast_to(action_spec.maximum, action_spec.shape))
    self.state_space = _box(self.state().shape)

  # --- Spaces -------------------------------------------------------------------

  def observation_space(self, agent):
    """The same space object at every call (PettingZoo's space seeding)."""
    return self.observation_spaces[self._check_agent(agent)]

  def action_space(self, agent):
    """Box float32 [8] in [-1, 1]: the Ant's eight joint torques."""
    return self.action_spaces[self._check_agent(agent)]

  def observation_keys(self, agent):
    """Dict key -> slice: where each observation lies in the flat vector.

    Keys come in sorted order, the order of both the flat layout and the
    `Dict` space.
    """
    return dict(self._layouts[self._check_agent(agent)])

  # --- Episode ------------------------------------------------------------------

  def reset(self, seed=None, options=None):
    """Starts an episode; returns (observations, infos), keyed by agent id.

    Args:
      seed: None continues the environment's random stream; an integer in
        [0, 2**32) reseeds it first, so the same seed gives the same episode.
      options: accepted for the PettingZoo API; no option is defined.
    """
    if seed is not None:
      if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"seed must be an integer or None, got {seed!r}.")
      if not 0 <= seed < 2**32:
        raise ValueError(f"seed must be in [0, 2**32), got {seed}.")
      self.env.random_state.seed(int(seed))
    if options is not None and not isinstance(options, abc.Mapping):
      raise TypeError(f"options must be a dict or None, got {options!r}.")
    timestep = self.env.reset()
    self._camera.reset()
    self.agents = list(self.possible_agents)
    return (self._observations(timestep.observation),
            {agent: {} for agent in self.agents})

  def step(self, actions):
    """Steps every agent; returns (obs, rewards, terminations, truncations,
    infos), each a dict keyed by agent id.

    `terminations` are True when the task ended the episode (failure,
    physics divergence, success with `end_on_success`: dm_env discount 0),
    `truncations` only at the time limit. At the last step every agent's
    info holds 'episode_metrics' (`CoopEnvironment.episode_metrics()`), and
    `agents` becomes empty: call `reset()` before stepping again.

    Args:
      actions: dict agent id -> array-like [8], one entry per live agent.

    Raises:
      TypeError: `actions` is not a dict, or an action is not numeric.
      ValueError: missing or unknown agent ids, a wrong shape, NaN or inf.
      RuntimeError: no episode is running.
    """
    if not self.agents:
      raise RuntimeError("No episode is running (it ended, or reset() was "
                         "never called): call reset() before step().")
    timestep = self.env.step(self._action_batch(actions))
    agents = self.possible_agents
    rewards = {a: float(r) for a, r in zip(agents, timestep.reward)}
    truncated = timestep.last() and is_truncation(timestep)
    terminated = timestep.last() and not truncated
    if timestep.last():
      metrics = self.env.episode_metrics()
      infos = {agent: {"episode_metrics": dict(metrics)} for agent in agents}
      self.agents = []
    else:
      infos = {agent: {} for agent in agents}
    return (self._observations(timestep.observation), rewards,
            dict.fromkeys(agents, terminated), dict.fromkeys(agents, truncated),
            infos)

  def state(self):
    """The centralised critic's global state, float32 [state_space.shape]:
    per agent world x, y, z, cos/sin yaw, vx, vy, then the task's objects
    (`CoopTask.global_state`; metres, m/s)."""
    return self.env.task.global_state(self.env.physics)

  def episode_metrics(self):
    """Figures of the episode so far (also in the last step's infos)."""
    return self.env.episode_metrics()

  def render(self):
    """An RGB frame uint8 [height, width, 3] from the framing camera, which
    keeps every agent and the task object in view; None without
    render_mode."""
    if self.render_mode is None:
      gymnasium.logger.warn(
          "render() called without a render_mode; pass render_mode="
          "'rgb_array' to ParallelEnv.")
      return None
    height, width = self._render_size
    return camera_lib.render(self.env, self._camera, width=width,
                             height=height)

  def close(self):
    """Frees the physics; the environment cannot be used afterwards. A
    second call does nothing (Gymnasium and SuperSuit close again on
    cleanup)."""
    self.agents = []
    self.env.close()

  def __reduce__(self):
    """Pickles (and copies) as the `coop_suite.load` call of `env` plus this
    adapter's options; the copy is a fresh build (see
    `CoopEnvironment.__reduce__`)."""
    return _rebuild, (self.env, {"flatten": self.flatten,
                                 "render_mode": self.render_mode,
                                 "render_size": self._render_size})

  # --- Internals ----------------------------------------------------------------

  def _check_agent(self, agent):
    try:
      if agent in self._index:
        return agent
    except TypeError:  # Unhashable.
      pass
    raise ValueError(f"Unknown agent {agent!r}; this environment's agents "
                     f"are {self.possible_agents}.")

  def _observations(self, per_agent):
    """dm_env's list of per-agent dicts -> dict id -> float32 obs."""
    out = {}
    for agent, obs in zip(self.possible_agents, per_agent):
      layout = self._layouts[agent]
      if self.flatten:
        out[agent] = np.concatenate(
            [np.asarray(obs[key], np.float32).reshape(-1) for key in layout])
      else:
        # np.array copies, so a kept observation never changes under you.
        out[agent] = {key: np.array(obs[key], np.float32) for key in layout}
    return out

  def _action_batch(self, actions):
    """dict id -> [8] to the [n_agents, 8] array `CoopEnvironment` takes,
    with errors that name agent ids rather than indices."""
    if not isinstance(actions, abc.Mapping):
      raise TypeError(
          f"actions must be a dict agent id -> array of shape (8,), got "
          f"{type(actions).__name__}; agent ids: {self.agents}.")
    unknown = [a for a in actions if a not in self._index]
    if unknown:
      raise ValueError(f"Unknown agent id(s) {unknown}; this environment's "
                       f"agents are {self.possible_agents}.")
    missing = [a for a in self.agents if a not in actions]
    if missing:
      raise ValueError(f"Missing actions for agent(s) {missing}; every live "
                       f"agent must act: {self.agents}.")
    batch = np.empty((len(self.possible_agents),)
                     + self.action_spaces[self.possible_agents[0]].shape)
    for agent, i in self._index.items():
      try:
        value = np.asarray(actions[agent], dtype=np.float64)
      except (TypeError, ValueError) as e:
        raise TypeError(f"Action of {agent!r} is not numeric: {e}") from None
      expected = self.action_spaces[agent].shape
      if value.shape != expected:
        raise ValueError(f"Action of {agent!r} has shape {value.shape}; "
                         f"expected {expected}.")
      if not np.all(np.isfinite(value)):
        raise ValueError(f"Action of {agent!r} contains NaN or inf: {value}.")
      batch[i] = value
    return batch

