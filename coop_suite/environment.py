"""`CoopEnvironment`: a composer.Environment that checks its multi-agent input.

These things differ from a plain `composer.Environment`, each for a reason:

* Actions are validated *before* anything is stepped, so a wrong count,
  shape, dtype or a NaN raises a clear error and the environment stays
  usable (composer would otherwise write garbage into `data.ctrl`).
* A physics divergence ends the episode (composer's
  `raise_exception_on_physics_error=False`) and the reward keeps its
  per-agent list form, which composer replaces by a scalar 0.0.
* The arena is static, so the MJCF is compiled once, not at every reset.
* The episode ends once the physics time is within half a physics step of
  the time limit: summing 0.01 s steps in floating point reaches 9.99999
  after 10 s, which would otherwise add one step to the episode.
* The step runs on the composer fast path (`coop_suite.fast`: a lean
  observation updater, substeps fused into one call, values computed once
  per physics state, compiled ray casts), the same numbers with less Python;
  any observable or hook it does not cover brings composer's own machinery
  back. `fast_path=False` runs plain composer throughout.
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
* `step` also comes in its two phases, `step_physics(action)` then
  `step_outcome(observe)`, for callers that step many copies in lockstep:
  every copy's physics, then every copy's outcome, which keeps each phase's
  code in the processor's caches (docs/performance.md). `LockstepPhysics`
  runs the physics phases of many copies with the Python of one.
"""

from dm_control import composer
from dm_control.composer.observation import updater as updater_lib
import dm_env
import numpy as np

from coop_suite import fast
from coop_suite import kernels


class CoopEnvironment(composer.Environment):
  """A multi-agent composer environment (see the module docstring)."""

  def __init__(self, task, time_limit, random_state, fast_path=True):
    """Args:
      task: a `CoopTask`.
      time_limit: episode length (s).
      random_state: a `np.random.RandomState`.
      fast_path: False runs plain composer (its own observation updater and
        step, nothing cached per state, MuJoCo's own ray casts): the same
        numbers, slower; for checking the fast path (`coop_suite.fast`).
    """
    self._fast_path = bool(fast_path)
    task.fast_path = self._fast_path
    super().__init__(
        task,
        # Half a physics step of slack (see the module docstring).
        time_limit=time_limit - 0.5 * task.physics_timestep,
        random_state=random_state,
        raise_exception_on_physics_error=False,
        strip_singleton_obs_buffer_dim=True,
        recompile_mjcf_every_episode=False)
    self._physics_diverged = False
    self._action_bounds = None  # (shape, minimum, maximum), on first use.
    self._stepper = None  # A `fast.FusedStep` or None, set at each reset.
    self._pending_action = None  # The action of a step in its two phases.
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
    updater = fast.LeanUpdater if self._fast_path else updater_lib.Updater
    return updater(self._task.observables,
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
    self._pending_action = None
    timestep = super().reset()
    # Hooks, observables and the physics are fixed once an episode starts.
    self._stepper = (fast.FusedStep.make(self, self.action_bounds()[1:])
                     if self._fast_path else None)
    return timestep

  def step(self, action, observe=True):
    """Steps every agent; `action` is [n_agents, 8] (or a list of [8]).

    Args:
      action: the agents' actions (see `validate_action`).
      observe: False may leave the observation of a MID step out (None;
        the fast path does); the LAST step of an episode always has it. Only
        for callers that read what they need from `task.features(physics,
        groups)`.
    """
    if self._reset_next_step:
      return self.reset()
    self.step_physics(action)
    return self.step_outcome(observe)

  # `step` in two phases, for callers that step many copies in lockstep
  # (`runners.rollout.EnvBatch`): every copy's physics, then every copy's
  # outcome, so that each phase's code stays in the caches across copies.
  # The same operations in the same order as `step`, so the same numbers.

  def step_physics(self, action):
    """The first phase of `step(action)`: checks `action`, writes the
    controls and runs the physics (on plain composer, where `step` cannot be
    split, it only checks and keeps `action`).

    Raises:
      RuntimeError: the episode has ended (call `reset()`).
    """
    if self._reset_next_step:
      raise RuntimeError("The episode has ended: call reset() first.")
    action = self._pending_action = self.validate_action(action)
    if self._stepper is not None:
      self._stepper.step_physics(action)

  def step_outcome(self, observe=True):
    """The second phase of `step`: its `dm_env.TimeStep` (see `step`).

    Raises:
      RuntimeError: no `step_physics` came before it.
    """
    action, self._pending_action = self._pending_action, None
    if action is None:
      raise RuntimeError("step_outcome() ends a step that step_physics() "
                         "began.")
    if self._stepper is not None:
      timestep = self._stepper.step_outcome(observe)
    else:
      timestep = super().step(action)
    if not isinstance(timestep.reward, list):
      # Composer's divergence path returns scalars: restore the contract.
      self._physics_diverged = True
      timestep = timestep._replace(
          reward=[np.zeros((), np.float32) for _ in range(self.n_agents)],
          discount=np.zeros((), np.float32))
    return timestep

  def action_bounds(self):
    """(shape [n_agents, 8], low [8], high [8]) of the actions: every agent
    has the first agent's (the Ant's) spec."""
    if self._action_bounds is None:
      specs = self.action_spec()
      shape = specs[0].shape
      self._action_bounds = (
          (len(specs),) + shape,
          np.broadcast_to(specs[0].minimum, shape).astype(np.float64),
          np.broadcast_to(specs[0].maximum, shape).astype(np.float64))
    return self._action_bounds

  def validate_action(self, action):
    """Returns `action` as a float array [n_agents, 8] or raises.

    Raises:
      TypeError: if `action` is not a sequence of numeric arrays.
      ValueError: wrong number of agents, wrong shape, or non-finite values.
    """
    shape, low, high = self.action_bounds()
    if type(action) in (list, tuple):  # pylint: disable=unidiomatic-typecheck
      # The documented convention, one array per agent: stacked in one call
      # when that gives a float array of the right shape; anything else goes
      # through the checks below, which name the agent at fault.
      try:
        stacked = np.asarray(action)
      except (TypeError, ValueError):
        stacked = None
      if stacked is not None and stacked.dtype.kind == "f":
        action = stacked
    if (type(action) is np.ndarray and action.shape == shape  # pylint: disable=unidiomatic-typecheck
        and action.dtype.kind == "f"):
      if action.dtype not in fast.ACTION_DTYPES:
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


class LockstepPhysics:
  """The physics phases of copies of one task, stepped together.

  `step_physics(actions, active)` is `envs[e].step_physics(actions[k])` for
  the k-th copy e of `active`, the same numbers, with the Python of one
  physics phase where every one of them is on the fast path with compiled
  controls (`fast.FusedStep.make`) and `actions` is one float array of the
  right shape: every copy's controls in one compiled call
  (`fast.write_controls`), each copy's substeps, every copy's warnings in
  one call (`fast.check_warnings`). Otherwise, or where an action is not
  finite, copy by copy, which raises the usual errors. An actor's copies
  stepped in lockstep (`runners.rollout.EnvBatch`) so skip composer's hooks
  and the action checks per copy (docs/performance.md).

  Should MuJoCo raise (`mujoco.FatalError`) in one copy's substeps, the
  copies before it have stepped, as copy by copy, and those after it have
  their controls written but not stepped: reset them.
  """

  def __init__(self, envs):
    """Args:
      envs: the copies, any objects with `step_physics`; only
        `CoopEnvironment`s are stepped together.
    """
    self._envs = list(envs)
    self._steppers = None  # Those the table below was made for.
    self._table = None  # (addresses [E, 3], low, high) or None.

  def step_physics(self, actions, active=None):
    """Steps the physics of copies `active` (indices; all if None) with
    `actions` [len(active), n_agents, 8], row k for copy active[k]."""
    envs = self._envs
    chosen = envs if active is None else [envs[e] for e in active]
    if len(actions) != len(chosen):
      raise ValueError(f"{len(chosen)} copies step, {len(actions)} actions.")
    steppers = [getattr(env, "_stepper", None) for env in chosen]
    if self._steppers is None or len(steppers) != len(self._steppers) or any(
        a is not b for a, b in zip(steppers, self._steppers)):
      self._steppers, self._table = steppers, self._make_table(chosen)
    written = None
    if self._table is not None and not any(
        env._reset_next_step for env in chosen):  # pylint: disable=protected-access
      addresses, low, high = self._table
      written = fast.write_controls(steppers, addresses, actions, low, high)
    if written is None:
      for env, action in zip(chosen, actions):
        env.step_physics(action)
      return
    clipped, before = written
    stepped = 0
    try:
      for env, stepper, action in zip(chosen, steppers, clipped):
        env._pending_action = action  # pylint: disable=protected-access
        stepper.compiled_substeps()
        stepped += 1
    finally:  # Those stepped are checked, even if one raised.
      fast.check_warnings(steppers[:stepped], addresses[:stepped],
                          before[:stepped])

  @staticmethod
  def _make_table(chosen):
    """What `fast.write_controls` needs for `chosen`, or None if one of
    them cannot be stepped by it (then all go copy by copy)."""
    # pylint: disable=protected-access
    if not all(isinstance(env, CoopEnvironment)
               and type(env).step_physics is CoopEnvironment.step_physics
               and type(env).validate_action is CoopEnvironment.validate_action
               and env._stepper is not None
               and env._stepper.addresses is not None for env in chosen):
      return None
    first = chosen[0]._stepper
    low, high = first.action_bounds
    for env in chosen:
      stepper = env._stepper
      if (stepper.action_shape != first.action_shape
          or not np.array_equal(stepper.action_bounds[0], low)
          or not np.array_equal(stepper.action_bounds[1], high)):
        return None
    return (np.array([env._stepper.addresses for env in chosen], np.intp),
            low, high)


def _rebuild(load_arguments):
  """`CoopEnvironment.__reduce__`'s inverse: calls `coop_suite.load` again."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  args, kwargs = load_arguments
  return coop_suite.load(*args, **kwargs)


def is_truncation(timestep: dm_env.TimeStep) -> bool:
  """True for a LAST step that ended by time limit rather than by the task."""
  return timestep.last() and float(timestep.discount) > 0.0
