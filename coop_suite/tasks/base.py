"""The multi-agent task base class, in dm_control soccer's convention.

A `CoopTask` owns the arena, one Ant per agent and the episode bookkeeping
(reward-term sums, success, termination). A concrete task is a small module
that only overrides the hooks below:

* `EXTERO_FEATURES`, `_exteroception(physics, frames)`: names and values
  ([n_agents, dim] arrays) of the task's own `extero/*` features.
* `COMMAND_FEATURES`, `_commands(physics, frames)`: the same for
  `command/*` (locomotion tasks only).
* `_initialize_layout(physics, random_state)`: starting poses.
* `_reward_terms(physics)`: dict of term -> per-agent array [n_agents].
* `_update_status(physics)`: after each control step; sets `self._success`
  and `self._failure`. Success is sticky (once reached, the episode counts
  as a success) and `self._success_event` is True on the step it is
  reached, when tasks pay their success bonus. Failure ends the episode with
  discount 0; success does too only with `end_on_success` (see
  `TaskConfig`).
* `_progress(physics)`: task-specific figures for `episode_metrics`.
* `_task_state(physics)`: task objects' part of the global state.

The three cooperative tasks compute what these hooks need from one state
(distances, heading-frame offsets, shaping terms) in one compiled `measure`
kernel each, computed once per state with `per_state`; the hooks only pick
from its named outputs. That is a speed choice (see `kernels.py`), not a
requirement: a new task can write its hooks in numpy first.

Everything computed from one physics state (frames, features, `measure`)
goes through `per_state`; `state_changed()` forgets it after a hand edit
of the physics. With `fast_path` off (`coop_suite.load(...,
fast_path=False)`) nothing is kept and the heights come from MuJoCo's own
ray casts (see `coop_suite.fast`).
"""

import dataclasses

from dm_control import composer
from dm_control.composer.observation import observable
from dm_env import specs
import numpy as np

from coop_suite.entities import Ant
from coop_suite.entities import ant as ant_lib
from coop_suite import fast
from coop_suite import kernels
from coop_suite.tasks import exteroception

SPECIES_COLOURS = {
    "ant": (0.8, 0.6, 0.4, 1.0),
    "pusher": (0.35, 0.55, 0.85, 1.0),
    "crosser": (0.85, 0.55, 0.25, 1.0),
}

FEATURE_GROUPS = ("proprio", "extero", "command")
"""Observation prefixes, each computed by `CoopTask.features` on demand."""


@dataclasses.dataclass(frozen=True)
class TaskConfig:
  """Settings shared by every task."""

  physics_timestep: float = 0.01
  """MuJoCo timestep (s). 10 ms keeps the Ant stable and fast."""
  control_timestep: float = 0.05
  """Time between actions (s); 5 physics steps per control step."""
  time_limit: float = 30.0
  """Episode length (s) after which the episode is truncated."""
  k_neighbours: int = 1
  """Number of nearest teammates (agents of its own species) in each
  agent's exteroception."""
  height_grid: int = 3
  """Height samples form a `height_grid` x `height_grid` square."""
  height_spacing: float = 0.6
  """Distance between height samples (m)."""
  memory_mb_per_agent: float = 1.0
  """MuJoCo constraint memory per agent (MiB), on top of 4 MiB."""
  end_on_success: bool = False
  """Whether success ends the episode (discount 0). Off by default: the
  paper's shaping terms pay every step (e.g. 10 / (1 + d) near the target),
  so an episode cut short at success forfeits more shaping reward than the
  one-off success bonus pays, and a learner is taught to linger near the
  goal without finishing. Running on to the time limit, the shaping terms
  keep paying most for staying at the goal. Success is counted, and its bonus
  paid, the first time it is reached either way."""

  def __post_init__(self):
    """Checks every field, the subclasses' included, before MuJoCo sees it.

    Numbers must be finite; a field named after a size, mass, friction or
    duration (`_POSITIVE`) must be > 0, one named after a speed, gap,
    tolerance, time or distance (`_NON_NEGATIVE`) >= 0, one named after a
    probability (`_UNIT`) in [0, 1], and a tuple named
    after a distance, range or offset is a (low, high) pair with
    low <= high.
    """
    name_of = type(self).__name__
    for field in dataclasses.fields(self):
      _check_config_value(name_of, field.name, getattr(self, field.name),
                          field.default)
    ratio = self.control_timestep / self.physics_timestep
    if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
      raise ValueError(
          f"{name_of}.control_timestep ({self.control_timestep} s) must be "
          f"a whole multiple of physics_timestep ({self.physics_timestep} "
          "s).")


# Field-name endings -> the range a value must lie in (see __post_init__).
_POSITIVE = ("timestep", "time_limit", "period", "spacing", "width",
             "thickness", "depth", "length", "mass", "radius", "friction",
             "memory_mb_per_agent", "k_neighbours", "height_grid")
_NON_NEGATIVE = ("speed", "gap", "tolerance", "time", "distance", "range")
_UNIT = ("probability",)  # In [0, 1].
_RANGES = ("distance", "range", "offset")  # Tuples named so: (low, high).


def _check_config_value(config_name, name, value, default):
  """Raises a ValueError/TypeError naming `config_name.name` if `value` is
  not of `default`'s kind or out of the range its name implies."""
  where = f"{config_name}.{name}"
  if isinstance(default, bool):
    if not isinstance(value, (bool, np.bool_)):
      raise TypeError(f"{where} must be True or False, got {value!r}.")
    return
  if isinstance(default, tuple):
    is_range = name.endswith(_RANGES)
    if (not isinstance(value, (tuple, list))
        or not all(_is_real(v) for v in value)
        or (is_range and len(value) != 2)):
      kind = "a (low, high) pair" if is_range else "a tuple"
      raise TypeError(f"{where} must be {kind} of numbers, got {value!r}.")
    for v in value:
      _check_number(where, name, v)
    if is_range and value[0] > value[1]:
      raise ValueError(f"{where} must have low <= high, got {value!r}.")
    return
  if not isinstance(default, (int, float)):
    return  # Not a number: the task checks it.
  integral = isinstance(default, int)
  if not _is_real(value) or (integral and not isinstance(
      value, (int, np.integer))):
    kind = "an integer" if integral else "a number"
    raise TypeError(f"{where} must be {kind}, got {value!r}.")
  _check_number(where, name, value)


def _is_real(value):
  return (isinstance(value, (int, float, np.integer, np.floating))
          and not isinstance(value, (bool, np.bool_)))


def _check_number(where, name, value):
  if not np.isfinite(value):
    raise ValueError(f"{where} must be finite, got {value!r}.")
  if name.endswith(_POSITIVE) and value <= 0:
    raise ValueError(f"{where} must be > 0, got {value!r}.")
  if name.endswith(_NON_NEGATIVE) and value < 0:
    raise ValueError(f"{where} must be >= 0, got {value!r}.")
  if name.endswith(_UNIT) and not 0 <= value <= 1:
    raise ValueError(f"{where} must be in [0, 1], got {value!r}.")


class CoopTask(composer.Task):
  """A cooperative task for `len(species)` Ants; see the module docstring."""

  EXTERO_FEATURES = ()
  COMMAND_FEATURES = ()
  SHARED_EXTERO = True
  """Whether agents see the shared exteroception (teammates, heights...)."""

  def __init__(self, arena, species, config):
    self._arena = arena
    self._config = config
    self._species = tuple(species)
    # Each agent's species as an int: teammates are of one's own species.
    names = list(dict.fromkeys(self._species))
    self._species_ids = np.array([names.index(s) for s in self._species],
                                 np.int64)
    self._walkers = []
    counts = {}
    for kind in self._species:
      index = counts.get(kind, 0)
      counts[kind] = index + 1
      walker = Ant(name=f"{kind}_{index}",
                   rgba=SPECIES_COLOURS.get(kind, SPECIES_COLOURS["ant"]))
      frame = arena.add_free_entity(walker)
      # Distinct default poses: MuJoCo runs forward kinematics at qpos0 when
      # the model is compiled, and 16 ants stacked at the origin would create
      # tens of thousands of contacts there (mjWARN_CNSTRFULL at time 0).
      slot = len(self._walkers)
      frame.pos = (3.0 * (slot % 4), 3.0 * (slot // 4), 2.0)
      self._walkers.append(walker)
    arena.mjcf_model.size.memory = (
        f"{int(4 + np.ceil(config.memory_mb_per_agent * len(species)))}M")
    self.set_timesteps(control_timestep=config.control_timestep,
                       physics_timestep=config.physics_timestep)
    self._last_actions = np.zeros((self.n_agents, ant_lib.NUM_ACTUATORS))
    for walker, row in zip(self._walkers, self._last_actions):
      walker.share_action_buffer(row)
    self._heights = exteroception.HeightSampler(config.height_grid,
                                         config.height_spacing)
    self._checked_groups = set()
    self._plans = {}  # Observation names -> what `observation_batch` builds.
    self._last_plan = (None, None)
    k, m = config.k_neighbours, self._heights.size
    self._shared_columns = (
        ("extero/self_pose", slice(0, 4)),
        ("extero/teammates", slice(4, 4 + 2 * k)),
        ("extero/teammates_mask", slice(4 + 2 * k, 4 + 3 * k)),
        ("extero/heights", slice(4 + 3 * k, 4 + 3 * k + m)))
    self._proprioception = None  # See `after_compile`.
    self._joint_ranges = None
    self._mjdata = None  # The compiled physics' mjData (`after_compile`).
    self._cache = fast.StateCache()
    self._zeros = np.zeros(self.n_agents)  # `each_agent(0.0)`.
    self._zeros.setflags(write=False)
    self._reset_bookkeeping()
    self._agent_observables = [
        self._build_agent_observables(i) for i in range(self.n_agents)]

  # --- Public API ------------------------------------------------------------

  @property
  def root_entity(self):
    return self._arena

  @property
  def arena(self):
    return self._arena

  @property
  def config(self):
    return self._config

  @property
  def walkers(self):
    return tuple(self._walkers)

  @property
  def species(self):
    """Species name of each agent, e.g. ('crosser', 'crosser', 'pusher')."""
    return self._species

  @property
  def n_agents(self):
    return len(self._species)

  @property
  def observables(self):
    return self._agent_observables

  @property
  def fast_path(self):
    """Whether per-state values are kept and heights ray-cast from compiled
    code (`coop_suite.fast`); set by `CoopEnvironment` before compilation."""
    return self._cache.enabled

  @fast_path.setter
  def fast_path(self, enabled):
    self._cache.enabled = bool(enabled)

  def episode_metrics(self, physics):
    """Figures of the episode so far.

    Returns a dict with `success` (bool), `return` (mean over agents of the
    summed reward), `reward/<term>` (mean over agents of each term's sum),
    `control_steps` and the task's progress figures.
    """
    metrics = {"success": bool(self._success),
               "failure": bool(self._failure),
               "return": float(np.mean(self._return)),
               "control_steps": self._steps}
    if self._term_sums is not None:
      for term, total in zip(self._term_names, self._term_sums):
        metrics[f"reward/{term}"] = float(np.mean(total))
    metrics.update(self._progress(physics))
    return metrics

  def global_state(self, physics):
    """The centralised critic's view, shape [7 * n_agents + task part].

    Per agent: world x, y, z, cos(yaw), sin(yaw), vx, vy; then the task's
    objects and goals (see `_task_state`). Metres, m/s.
    """
    parts = []
    for walker in self._walkers:
      yaw = walker.heading(physics)
      parts.append(np.concatenate([
          walker.torso_position(physics), [np.cos(yaw), np.sin(yaw)],
          walker.world_velocity(physics)[:2]]))
    parts.append(np.asarray(self._task_state(physics), dtype=np.float64))
    return np.concatenate(parts).astype(np.float32)

  @property
  def joint_ranges(self):
    """Every agent's joint limits as compiled, [n_agents, 8, 2] (rad)."""
    if self._joint_ranges is None:
      self._joint_ranges = np.stack([w._joint_limits for w in self._walkers])  # pylint: disable=protected-access
    return self._joint_ranges

  def tracked_positions(self, physics):
    """World positions [m, 3] a camera should keep in view."""
    return np.array([w.torso_position(physics) for w in self._walkers])

  # --- composer.Task hooks ---------------------------------------------------

  def action_spec(self, physics):
    return [walker.action_spec for walker in self._walkers]

  def get_reward_spec(self):
    return [specs.Array(shape=(), dtype=np.float32, name=f"reward_{i}")
            for i in range(self.n_agents)]

  def get_discount_spec(self):
    return specs.BoundedArray(shape=(), dtype=np.float32, minimum=0.0,
                              maximum=1.0, name="discount")

  def after_compile(self, physics, random_state):
    del random_state  # Unused.
    self._mjdata = physics.data.ptr
    self._cache.bind(self._mjdata)
    # Runs before the entities' own after_compile, so bind here.
    self._torso_ids = np.array(physics.bind(
        [w.root_body for w in self._walkers]).element_id)
    ids = np.array(physics.bind(
        [a for w in self._walkers for a in w.actuators]).element_id)
    # Usually consecutive (the Ants are the only actuated entities): a slice
    # writes the controls without fancy indexing.
    consecutive = np.array_equal(ids, np.arange(ids[0], ids[0] + len(ids)))
    first = int(ids[0])
    self._actuator_ids = (slice(first, first + len(ids)) if consecutive
                          else ids)
    # Built on first use, once the walkers' own after_compile has run.
    self._proprioception = None
    self._joint_ranges = None

  def initialize_episode(self, physics, random_state):
    self._reset_bookkeeping()
    self._last_actions[:] = 0.0
    self._initialize_layout(physics, random_state)

  def before_step(self, physics, action, random_state):
    """Writes every agent's action [n, 8] to the controls in one call (what
    `Ant.apply_action` does per walker; walkers' `prev_action` are rows of
    `_last_actions`), into the bound mjData (`physics`' own)."""
    del physics, random_state  # `self._mjdata` is physics' data.
    self.state_changed()
    self._last_actions[:] = action
    self._mjdata.ctrl[self._actuator_ids] = self._last_actions.ravel()

  def compiled_controls(self):
    """(the action buffer [n_agents, 8], the index of the first control)
    where compiled code may do what `before_step` does, i.e. where it is
    this class's own (not overridden, nor replaced on the instance) and the
    agents' controls are consecutive: a compiled physics phase
    (`coop_suite.fast.FusedStep`, chosen at each reset) clips the actions
    into the buffer and the controls, and calls `state_changed()`. None
    otherwise."""
    if getattr(self.before_step, "__func__", None) is not CoopTask.before_step:
      return None
    ids = self._actuator_ids
    if (not isinstance(ids, slice) or ids.step not in (None, 1)
        or ids.stop - ids.start != self._last_actions.size):
      return None
    return self._last_actions, ids.start

  def after_step(self, physics, random_state):
    self._steps += 1
    succeeded_before = self._success
    self._update_status(physics)
    self._success = bool(self._success or succeeded_before)
    self._success_event = self._success and not succeeded_before

  def get_reward(self, physics):
    terms = self._reward_terms(physics)
    values = np.array(tuple(terms.values()), dtype=np.float64)
    if self._term_sums is None:
      self._term_names = tuple(terms)
      self._term_sums = np.zeros((len(terms), self.n_agents))
    if values.shape != self._term_sums.shape:  # The kernel does not check.
      raise RuntimeError(
          f"{type(self).__name__} returned reward terms {tuple(terms)} of "
          f"shape {values.shape}; expected {self._term_names}, each "
          f"[{self.n_agents}].")
    # The sums and totals in one compiled call (~6 numpy calls otherwise).
    return list(kernels.add_rewards(values, self._term_sums, self._return))

  def get_discount(self, physics):
    return _ZERO if self._ended() else _ONE

  def should_terminate_episode(self, physics):
    return self._ended()

  def _ended(self):
    """Whether the task ends the episode now (a termination, discount 0)."""
    return bool(self._failure
                or (self._success and self._config.end_on_success))

  def observation_batch(self, physics, names):
    """Every agent's observation dict of the features `names`.

    The fast path of `CoopEnvironment`: every agent's arrays are views of
    the blocks its group computes once per state (`_blocks`), one view per
    agent and feature and nothing in between. Views are safe: the blocks are
    new arrays at every physics state.
    """
    if not isinstance(names, tuple):
      names = tuple(names)
    groups, wanted = self._observation_plan(names)
    blocks = []
    for group in groups:
      blocks.extend(self._blocks(group, physics))
    if wanted is not None:  # Some observables disabled: leave them out.
      blocks = [(values, tuple(c for c in columns if c[0] in wanted))
                for values, columns in blocks]
    observations = []
    for i in range(self.n_agents):
      agent = {}
      for values, columns in blocks:
        for name, where in columns:
          agent[name] = values[i, where]
      observations.append(agent)
    return observations

  def _observation_plan(self, names):
    """(groups to compute, names to keep or None for all) for `names`."""
    last_names, plan = self._last_plan
    if names is last_names:  # The environment asks with the same tuple.
      return plan
    plan = self._plans.get(names)
    if plan is None:
      groups = tuple(g for g in FEATURE_GROUPS
                     if any(n.startswith(g + "/") for n in names))
      every = {name for group in groups for name in self._declared(group)}
      plan = self._plans[names] = (
          groups, None if every == set(names) else frozenset(names))
    self._last_plan = (names, plan)
    return plan

  def frames(self, physics):
    """Every agent's torso position and heading (`AgentFrames`), computed
    once per physics state."""
    return self.per_state("frames", lambda: exteroception.AgentFrames
                          .from_packed(self._agent_state(physics)))

  def _agent_state(self, physics):
    """Every agent's frame and proprioception, packed [n, 5 +
    proprioception], from one compiled call (`ProprioceptionReader.state`):
    every step reads the frames (status, rewards) and, to act, the
    proprioception."""
    def compute():
      if self._proprioception is None:
        self._proprioception = ant_lib.ProprioceptionReader(self._walkers)
      return self._proprioception.state(physics, self._last_actions)
    return self.per_state("agent_state", compute)

  def proprioception(self, physics):
    """Every agent's proprioception packed [n_agents, kernels.PROPRIO_SIZE]
    in `kernels.PROPRIO_LAYOUT`'s column order: the array the `proprio/*`
    features are views of, for the lower layer to read without a dict."""
    return self._agent_state(physics)[:, _PROPRIO_START:]

  def features(self, physics, groups=FEATURE_GROUPS):
    """Observations of every agent: 'group/name' -> [n_agents, dim].

    Args:
      physics: the task's physics.
      groups: the prefixes to compute ('proprio', 'extero', 'command'). The
        lower layer reads only 'proprio' at each control step, while the
        exteroception (ray casts, nearest teammates) is needed only when the
        upper layer acts, so `CommandWrapper` asks for less.

    Each group is computed at most once per physics state and cached, since
    every agent's observables read from it; the returned arrays are views.
    """
    out = {}
    for group in groups:
      for values, columns in self._blocks(group, physics):
        for name, where in columns:
          out[name] = values[:, where]
    return out

  def _blocks(self, group, physics):
    """One group's features as blocks, computed once per physics state.

    A block is (values [n_agents, d], ((name, columns), ...)): each feature
    'group/name' is values[:, columns]. Packed kernel outputs are one block
    each (the proprioception, the shared exteroception), a task's feature
    dict one block per feature.
    """
    return self.per_state(group, lambda: self._compute_blocks(group, physics))

  def _compute_blocks(self, group, physics):
    if group == "proprio":
      blocks = ((self._agent_state(physics), _PROPRIO_COLUMNS),)
    elif group == "extero":
      frames = self.frames(physics)
      blocks = _as_blocks("extero/", self._exteroception(physics, frames))
      if self.SHARED_EXTERO:
        blocks += ((self._shared_exteroception(physics, frames),
                    self._shared_columns),)
    elif group == "command":
      blocks = _as_blocks("command/",
                          self._commands(physics, self.frames(physics)))
    else:
      raise ValueError(f"Unknown feature group {group!r}; expected one of "
                       f"{FEATURE_GROUPS}.")
    if group not in self._checked_groups:
      self._check_group(group, blocks)
    return blocks

  def _agent_feature(self, physics, name, index):
    """Agent `index`'s feature `name`, for observables read one by one
    (composer's own updater, when an observable has non-default settings):
    a view into its group's cached blocks, not a rebuilt feature dict."""
    for values, columns in self._blocks(name.split("/", 1)[0], physics):
      for feature, where in columns:
        if feature == name:
          return values[index, where]
    raise KeyError(f"{type(self).__name__} has no feature {name!r}.")

  def _declared(self, group):
    """The names a group must compute, 'group/name'."""
    names = {"proprio": ant_lib.PROPRIOCEPTION_KEYS,
             "extero": self.EXTERO_FEATURES + (
                 SHARED_EXTERO_FEATURES if self.SHARED_EXTERO else ()),
             "command": self.COMMAND_FEATURES}[group]
    return tuple(f"{group}/{name}" for name in names)

  def _check_group(self, group, blocks):
    """Checks a group's names and shapes once, on its first computation."""
    names = {name for _, columns in blocks for name, _ in columns}
    if names != set(self._declared(group)):
      raise RuntimeError(f"{type(self).__name__} computed {group} features "
                         f"{sorted(names)}, declared "
                         f"{sorted(self._declared(group))}.")
    for values, columns in blocks:
      if np.ndim(values) != 2 or len(values) != self.n_agents:
        raise RuntimeError(
            f"Features {[name for name, _ in columns]} come from an array of "
            f"shape {np.shape(values)}; expected [{self.n_agents}, dim].")
    self._checked_groups.add(group)

  # --- Hooks for subclasses ---------------------------------------------------

  def per_state(self, name, compute):
    """`compute()` once per physics state, under `name` (e.g. distances that
    both the status update and the reward need). The state is the
    environment's own physics; it changes at each step and reset, when the
    time moves on outside `step`, and at `state_changed()`."""
    return self._cache.get(name, compute)

  def each_agent(self, value):
    """[n_agents] float64 of `value`, e.g. a bonus term of the rewards. Zero
    (most steps) is one shared read-only array: a new one costs ~8 us of
    cold numpy per step (docs/performance.md)."""
    if value == 0.0:
      return self._zeros
    return np.full(self.n_agents, float(value))

  def state_changed(self):
    """Forgets the values computed for the current state (frames, features,
    `per_state`). Call it after editing the physics by hand outside `step`,
    e.g. placing a walker or a prop in a test: such an edit changes neither
    the step nor the simulation time the values are kept by."""
    self._cache.invalidate()

  def _exteroception(self, physics, frames):
    """The task's `extero/*` features named in `EXTERO_FEATURES`."""
    return {}

  def _commands(self, physics, frames):
    """The task's `command/*` features named in `COMMAND_FEATURES`."""
    return {}

  def _initialize_layout(self, physics, random_state):
    raise NotImplementedError

  def _reward_terms(self, physics):
    raise NotImplementedError

  def _update_status(self, physics):
    pass

  def _progress(self, physics):
    return {}

  def _task_state(self, physics):
    return np.zeros(0)

  # --- Internals ---------------------------------------------------------------

  def _reset_bookkeeping(self):
    self._success = False
    self._success_event = False
    self._failure = False
    self._steps = 0
    self._return = np.zeros(self.n_agents)
    self._term_names = ()
    self._term_sums = None  # [terms, n_agents], from the first reward on.
    self.state_changed()

  def _build_agent_observables(self, index):
    """One agent's observable dict, keys grouped by prefix."""
    names = [name for group in FEATURE_GROUPS
             for name in self._declared(group)]
    out = {}
    for name in names:
      out[name] = observable.Generic(
          lambda physics, name=name: self._agent_feature(physics, name, index))
      out[name].enabled = True
      # Lets `CoopEnvironment` read all agents' observations in one batch.
      out[name].batch_source = (self, name, index)
    return out

  def _shared_exteroception(self, physics, frames):
    """Features every cooperative task exposes (see `exteroception.py`), from
    one compiled call: [n, 4 + 3k + heights], `_shared_columns` name them.
    Without the fast path the call sees no terrain and MuJoCo's own ray
    casts fill the heights."""
    geom_args = self._heights.geom_args(physics)
    if not self.fast_path:
      geom_args = geom_args[:-1] + (_NO_GEOMS,)
    out = kernels.shared_exteroception(
        frames.as_packed(), self._config.k_neighbours, self._species_ids,
        *geom_args, *self._heights.ray_args)
    if not self.fast_path:
      out[:, self._shared_columns[-1][1]] = self._heights.multi_ray(
          physics, frames)
    return out


SHARED_EXTERO_FEATURES = ("self_pose", "teammates", "teammates_mask",
                          "heights")

# Discounts: immutable float32 scalars (shape (), as the spec says).
_ZERO, _ONE = np.float32(0.0), np.float32(1.0)

_NO_GEOMS = np.zeros(0, np.int64)

# The proprioception's columns in `CoopTask._agent_state`'s packed array
# (after the five frame columns).
_PROPRIO_START = 5
_PROPRIO_COLUMNS = kernels.proprio_columns(_PROPRIO_START, "proprio/")
_EVERYTHING = slice(None)


def _as_blocks(prefix, features):
  """A task hook's {name: [n, dim]} as blocks (see `CoopTask._blocks`)."""
  return tuple((values, ((prefix + name, _EVERYTHING),))
               for name, values in features.items())
