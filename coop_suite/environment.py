"""`CoopEnvironment`: a composer.Environment that checks its multi-agent input.

These things differ from a plain `composer.Environment`, each for a reason:

* Actions are validated *before* anything is stepped, so a wrong count,
  shape, dtype or a NaN raises a clear error and the environment stays
  usable (composer would otherwise write garbage into `data.ctrl`).
* A physics divergence ends the episode (composer's
  `raise_exception_on_physics_error=False`) and the reward keeps its
  per-agent list form, which composer replaces by a scalar 0.0.
* The arena is static, so the MJCF is compiled once, not at every reset.
* When no entity or task hooks into substeps, the substeps of a control
  step run as one call (the same physics, fewer Python round trips), and
  `_SubstepRunner` makes that call without dm_control's per-call Python
  overhead (7% of a control step).
* Observations go through `_LeanUpdater`, which skips composer's buffering
  machinery when every observable has the default settings (no delay, no
  buffering, no noise): composer's per-observable bookkeeping otherwise costs
  more than the physics. Any non-default observable restores composer's own
  updater, so its semantics are always preserved.
* Pickling or copying (`pickle`, `copy.deepcopy`, cloudpickle in
  SuperSuit's and RLlib's vector environments) rebuilds the environment from
  its `coop_suite.load` arguments: composer's weak references cannot be
  pickled, and a fresh build is what a vectorising client wants anyway.
* `close()` may be called more than once (Gymnasium and SuperSuit call it
  again on cleanup).
* `step(action, observe=False)` skips building the observation of a step
  that does not end the episode, for callers that read only part of it from
  `task.features` (`CommandWrapper` runs the lower layer on proprioception
  for nine control steps out of ten and needs the exteroception only at the
  end of a command period).
"""

from absl import logging
from dm_control import composer
from dm_control.composer import environment as composer_env
from dm_control.composer.observation import updater as updater_lib
from dm_control.rl import control
import dm_env
import mujoco
import numpy as np

from coop_suite import kernels


def _is_plain(observable):
  """Whether composer would compute `observable` once, at the last substep."""
  return (observable.update_interval in (None, 1)
          and observable.delay in (None, 0)
          and observable.buffer_size in (None, 1)
          and observable.aggregator is None
          and observable.corruptor is None)


class _LeanUpdater(updater_lib.Updater):
  """composer's observation Updater with a fast path for plain observables.

  With plain observables composer evaluates each one once per control step,
  after the last substep. This updater does the same, but lazily in
  `get_observation`, with no buffers or schedules.
  """

  def reset(self, physics, random_state):
    super().reset(physics, random_state)
    structure = self._observables
    dicts = structure if isinstance(structure, (list, tuple)) else [structure]
    self._lean = all(_is_plain(o) for d in dicts for o in d.values()
                     if o.enabled)
    self._batch = None
    if self._lean:
      sources = [[getattr(o, "batch_source", None) for o in d.values()
                  if o.enabled] for d in dicts]
      owners = {src[0] for agent in sources for src in agent if src}
      if len(owners) == 1 and all(src for agent in sources for src in agent):
        # Every observable is one of the task's own features: read them all
        # at once instead of one callable per agent and feature, provided
        # every agent observes the same features (the tasks' default).
        names = [src[1] for src in sources[0]]
        if all([(src[1], src[2]) for src in agent] == [(n, i) for n in names]
               for i, agent in enumerate(sources)):
          self._batch = (owners.pop(), physics, tuple(names))
      self._callables = [
          [(name, enabled.observation_callable)
           for name, enabled in enabled_dict.items()]
          for enabled_dict in (self._enabled_structure if self._is_nested
                               else [self._enabled_structure])]

  def prepare_for_next_control_step(self):
    if not self._lean:
      super().prepare_for_next_control_step()

  def update(self):
    if not self._lean:
      super().update()

  def get_observation(self):
    if not self._lean:
      return super().get_observation()
    if self._batch is not None:
      task, physics, names = self._batch
      out = task.observation_batch(physics, names)
      return out if self._is_nested else out[0]
    out = [{name: np.array(fn()) for name, fn in callables}
           for callables in self._callables]
    return out if self._is_nested else out[0]


class _SubstepRunner:
  """`physics.step(n)` with dm_control's semantics and less overhead.

  dm_control's legacy stepping ends a control step with `mj_step1`, so that
  position- and velocity-dependent quantities (xpos, cvel...) match the new
  state; a new MuJoCo warning (e.g. divergence) raises `PhysicsError`. This
  does exactly that with the model and data pointers and the warning
  counters looked up once: `Physics.step` spends ~35 us of Python per call
  (wrappers, a context manager), 7% of a transport step with four Ants.
  Only for Euler-type integrators with legacy stepping (`make` checks).
  """

  def __init__(self, physics):
    self._model, self._data = physics.model.ptr, physics.data.ptr
    self._warnings = self._data.warning.number  # A live view.

  @classmethod
  def make(cls, physics):
    """A runner for `physics`, or None where `physics.step` must be used."""
    if (not physics.legacy_step or physics.model.opt.integrator
        == mujoco.mjtIntegrator.mjINT_RK4):
      return None
    return cls(physics)

  def step(self, n):
    model, data, warnings = self._model, self._data, self._warnings
    before = warnings.tobytes()  # Counts only grow: any change is new.
    mujoco.mj_step2(model, data)
    if n > 1:
      mujoco.mj_step(model, data, n - 1)
    mujoco.mj_step1(model, data)
    if warnings.tobytes() != before:
      new = warnings > np.frombuffer(before, dtype=warnings.dtype)
      names = np.compress(new, list(mujoco.mjtWarning.__members__))
      raise control.PhysicsError(
          f"Physics state is invalid. Warning(s) raised: {', '.join(names)}")


class CoopEnvironment(composer.Environment):
  """A multi-agent composer environment (see the module docstring)."""

  def __init__(self, task, time_limit, random_state):
    super().__init__(
        task,
        time_limit=time_limit,
        random_state=random_state,
        raise_exception_on_physics_error=False,
        strip_singleton_obs_buffer_dim=True,
        recompile_mjcf_every_episode=False)
    self._physics_diverged = False
    self._action_bounds = None  # (shape, minimum, maximum), on first use.
    self._substeps = None  # A _SubstepRunner, set at each reset.
    self._fuse = False  # Whether substeps run as one call; set at reset.
    self._time_up_at = None  # Physics time that ends the episode; at reset.
    self.load_arguments = None  # Set by `coop_suite.load`; see `__reduce__`.

  def __reduce__(self):
    """Pickles as the `coop_suite.load` call that built this environment.

    The copy is what `load` builds from the same arguments (task, agents,
    seed, options): the current episode and the position in the random
    stream are not carried over.
    """
    if self.load_arguments is None:
      raise TypeError(
          "Only environments built by coop_suite.load can be pickled or "
          "copied (they are rebuilt from its arguments); pass a factory such "
          "as `lambda: coop_suite.load(task, n_agents)` instead.")
    return _rebuild, (self.load_arguments,)

  def close(self):
    """Frees the physics; a second call does nothing."""
    if self._physics is not None:
      super().close()

  def _make_observation_updater(self):
    return _LeanUpdater(self._task.observables,
                        self._task.physics_steps_per_control_step,
                        self._strip_singleton_obs_buffer_dim, False)

  @property
  def n_agents(self):
    return self.task.n_agents

  @property
  def physics_diverged(self):
    """Whether the last episode ended because the physics diverged."""
    return self._physics_diverged

  def reset(self):
    self._physics_diverged = False
    timestep = super().reset()
    # Hooks, observables and the physics are fixed once an episode starts.
    self._fuse = self._can_fuse_substeps()
    self._substeps = _SubstepRunner.make(self._physics)
    # Half a physics step of slack: summing 0.01 s steps in floating point
    # reaches 9.99999 after 10 s, which would add one step to the episode.
    self._time_up_at = self._time_limit - 0.5 * self._physics.timestep()
    return timestep

  def step(self, action, observe=True):
    """Steps every agent; `action` is [n_agents, 8] (or a list of [8]).

    Args:
      action: the agents' actions (see `validate_action`).
      observe: False leaves the observation of a MID step out (None); the
        LAST step of an episode always has it. Only for callers that read
        what they need from `task.features(physics, groups)`.
    """
    if self._reset_next_step:
      return self.reset()
    action = self.validate_action(action)
    if self._fuse:
      timestep = self._fused_step(action, observe)
    else:
      timestep = super().step(action)
    if not isinstance(timestep.reward, list):
      # Composer's divergence path returns scalars: restore the contract.
      self._physics_diverged = True
      timestep = timestep._replace(
          reward=[np.zeros((), np.float32) for _ in range(self.n_agents)],
          discount=np.zeros((), np.float32))
    return timestep

  def _can_fuse_substeps(self):
    hooks = self._hooks
    # pylint: disable=protected-access
    return (self._observation_updater._lean
            and not hooks._before_substep.entity_hooks
            and not hooks._before_substep.extra_hooks
            and not hooks._after_substep.entity_hooks
            and not hooks._after_substep.extra_hooks
            and composer_env._callable_is_trivial(self._task.before_substep)
            and composer_env._callable_is_trivial(self._task.after_substep))

  def _fused_step(self, action, observe=True):
    """composer.Environment.step with the substeps in one physics call."""
    self._hooks.before_step(self._physics_proxy, action, self._random_state)
    try:
      if self._substeps is not None:
        self._substeps.step(self._n_sub_steps)
      else:
        self._physics.step(self._n_sub_steps)
      diverged = False
    except control.PhysicsError as e:
      if self._raise_exception_on_physics_error:
        raise
      logging.warning(e)
      diverged = True
    self._hooks.after_step(self._physics_proxy, self._random_state)
    if diverged:
      reward, discount, terminating = 0.0, 0.0, True
    else:
      reward = self._task.get_reward(self._physics_proxy)
      discount = self._task.get_discount(self._physics_proxy)
      time_up = self._physics.data.time >= self._time_up_at
      terminating = (self._task.should_terminate_episode(self._physics_proxy)
                     or time_up)
    observation = (self._observation_updater.get_observation()
                   if observe or terminating else None)
    if terminating:
      self._reset_next_step = True
      return dm_env.TimeStep(dm_env.StepType.LAST, reward, discount,
                             observation)
    return dm_env.TimeStep(dm_env.StepType.MID, reward, discount, observation)

  def validate_action(self, action):
    """Returns `action` as a float array [n_agents, 8] or raises.

    Raises:
      TypeError: if `action` is not a sequence of numeric arrays.
      ValueError: wrong number of agents, wrong shape, or non-finite values.
    """
    if self._action_bounds is None:
      specs = self.action_spec()
      shape = specs[0].shape
      self._action_bounds = (
          (len(specs),) + shape,
          np.broadcast_to(specs[0].minimum, shape).astype(np.float64),
          np.broadcast_to(specs[0].maximum, shape).astype(np.float64))
    shape, low, high = self._action_bounds
    if (type(action) is np.ndarray and action.shape == shape  # pylint: disable=unidiomatic-typecheck
        and action.dtype.kind == "f"):
      if action.dtype not in _KERNEL_DTYPES:
        # float16, long double, big-endian...: the compiled kernel takes
        # native float32/float64 only.
        action = action.astype(np.float64)
      # Fast path for the common case: one float array for all agents
      # (every agent has the Ant's action spec), checked and clipped in one
      # compiled call.
      clipped = kernels.clip_finite(action, low, high)
      if clipped is None:
        bad = np.flatnonzero(~np.isfinite(action).all(axis=1))
        raise ValueError(f"Actions of agents {bad.tolist()} contain NaN or "
                         "inf.")
      return clipped
    specs = self.action_spec()
    n = len(specs)
    if isinstance(action, (str, bytes, dict)) or not hasattr(action, "__len__"):
      raise TypeError(
          f"action must be a list of {n} arrays (one per agent) or an array "
          f"of shape ({n}, {specs[0].shape[0]}); got {type(action).__name__}.")
    if len(action) != n:
      raise ValueError(f"Expected actions for {n} agents, got {len(action)}.")
    out = np.empty((n,) + specs[0].shape)
    for i, (agent_action, spec) in enumerate(zip(action, specs)):
      if np.iscomplexobj(agent_action):
        raise TypeError(f"Action of agent {i} is complex; expected real "
                        "numbers.")
      try:
        values = np.asarray(agent_action, dtype=np.float64)
      except (TypeError, ValueError) as e:
        raise TypeError(f"Action of agent {i} is not numeric: {e}") from None
      if values.shape != spec.shape:
        raise ValueError(f"Action of agent {i} has shape {values.shape}; "
                         f"expected {spec.shape}.")
      if not np.all(np.isfinite(values)):
        raise ValueError(f"Action of agent {i} contains NaN or inf: {values}.")
      out[i] = np.clip(values, spec.minimum, spec.maximum)
    return out

  def episode_metrics(self):
    """The task's episode metrics plus `physics_diverged`."""
    metrics = self.task.episode_metrics(self.physics)
    metrics["physics_diverged"] = self._physics_diverged
    return metrics


_KERNEL_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


def _rebuild(load_arguments):
  """`CoopEnvironment.__reduce__`'s inverse: calls `coop_suite.load` again."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  args, kwargs = load_arguments
  return coop_suite.load(*args, **kwargs)


def is_truncation(timestep: dm_env.TimeStep) -> bool:
  """True for a LAST step that ended by time limit rather than by the task."""
  return timestep.last() and float(timestep.discount) > 0.0
