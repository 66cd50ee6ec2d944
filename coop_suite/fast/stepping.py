"""`FusedStep`: composer's control step with its substeps in one call.

Where the task writes its controls the way `CoopTask` does
(`CoopTask.compiled_controls`), its physics phase writes them from compiled
code (the actions clipped into the task's action buffer and the controls),
then runs the substeps, without composer's hooks. `write_controls` and
`check_warnings` do their parts for many such steps (an actor's environment
copies) in one call each.
"""

import math

from absl import logging
from dm_control.composer import environment as composer_env
from dm_control.rl import control
import dm_env
import mujoco
import numba
import numpy as np

from coop_suite.fast import libmujoco

# A compiled step's addresses (`FusedStep.addresses`), one row per step: its
# first control, the task's action buffer, its mjData's warnings.
_CONTROLS, _ACTIONS, _WARNINGS = range(3)

_WARNING_NAMES = list(mujoco.mjtWarning.__members__)
_N_WARNINGS = int(mujoco.mjtWarning.mjNWARNING)


def _warning_layout(warning):
  """Whether mjData's warnings are `_read_warnings`' pairs of ints
  (lastinfo, number), `_N_WARNINGS` of them."""
  start = warning.lastinfo.ctypes.data
  return (warning.number.shape == (_N_WARNINGS,)
          and warning.number.dtype == np.int32
          and warning.number.strides == (8,)
          and warning.number.ctypes.data == start + 4)


def _physics_error(new_warnings):
  """The `PhysicsError` for MuJoCo warnings counted anew ([bool] each)."""
  names = np.compress(new_warnings, _WARNING_NAMES)
  return control.PhysicsError(
      f"Physics state is invalid. Warning(s) raised: {', '.join(names)}")


class SubstepRunner:
  """`physics.step(n)` with dm_control's semantics and less overhead.

  dm_control's legacy stepping ends a control step with `mj_step1`, so that
  position- and velocity-dependent quantities (xpos, cvel...) match the new
  state; a new MuJoCo warning (e.g. divergence) raises `PhysicsError`. This
  does exactly that with the model and data pointers and the warning
  counters looked up once, without `Physics.step`'s wrappers. Only for
  Euler-type integrators with legacy stepping (`make` checks).
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
    warnings = self._warnings
    before = warnings.tobytes()  # Counts only grow: any change is new.
    self.run(n)
    if warnings.tobytes() != before:
      raise _physics_error(
          warnings > np.frombuffer(before, dtype=warnings.dtype))

  def run(self, n):
    """The n substeps alone, their warnings unchecked (`step` checks them;
    a compiled physics phase checks many steps' at once)."""
    model, data = self._model, self._data
    mujoco.mj_step2(model, data)
    if n > 1:
      mujoco.mj_step(model, data, n - 1)
    mujoco.mj_step1(model, data)


@numba.njit(cache=True)
def _write_controls(addresses, actions, low, high, n_warnings, clipped,
                    before):
  """For each row e of `addresses` (`_CONTROLS`...): its actions [n, d]
  clipped to [low[j], high[j]] into `clipped[e]`, the task's action buffer
  [n, d] and the n * d controls from the first; its warning counters into
  `before[e]`. Returns -1, or the first row whose actions hold a NaN or an
  inf (then nothing was written)."""
  steps, n, d = actions.shape
  for e in range(steps):
    for i in range(n):
      for j in range(d):
        if not math.isfinite(actions[e, i, j]):
          return e
  for e in range(steps):
    controls = numba.carray(libmujoco.pointer(addresses[e, _CONTROLS]),
                            n * d, np.float64)
    buffer = numba.carray(libmujoco.pointer(addresses[e, _ACTIONS]), n * d,
                          np.float64)
    for i in range(n):
      for j in range(d):
        value = min(max(actions[e, i, j], low[j]), high[j])
        clipped[e, i, j] = value
        buffer[i * d + j] = value
        controls[i * d + j] = value
    _read_warnings(addresses[e, _WARNINGS], n_warnings, before[e])
  return -1


@numba.njit(cache=True)
def _read_warnings(address, n_warnings, out):
  """mjData's warning counters into `out`: mjWarningStat is {int lastinfo;
  int number;}, so the counters are the odd ints from `address`."""
  warnings = numba.carray(libmujoco.pointer(address), 2 * n_warnings,
                          np.int32)
  for k in range(n_warnings):
    out[k] = warnings[2 * k + 1]


@numba.njit(cache=True)
def _new_warnings(addresses, before, new, diverged):
  """`new[e, k]`: whether row e's warning counter k grew since `before`;
  `diverged[e]`: whether any did."""
  now = np.empty(before.shape[1], np.int32)
  for e in range(addresses.shape[0]):
    _read_warnings(addresses[e, _WARNINGS], before.shape[1], now)
    diverged[e] = False
    for k in range(before.shape[1]):
      new[e, k] = now[k] > before[e, k]
      diverged[e] |= new[e, k]


def write_controls(steppers, addresses, actions, low, high):
  """The first part of the physics phases of `steppers` (`FusedStep`s with
  `addresses`, of copies of one task): every one's controls in one compiled
  call. Each step then runs its `compiled_substeps`, and `check_warnings`
  ends them.

  Args:
    steppers: the steps, E of them.
    addresses: their `addresses` rows stacked, [E, 3] intp (callers that step
      the same copies again keep it).
    actions: row e is steppers[e]'s action: written only as one
      `ACTION_DTYPES` array [E, n, d], [n, d] their `action_shape`.
    low, high: the action bounds [d] of every one of them.

  Returns:
    (the clipped actions [E, n, d] float64, the warning counters before the
    substeps [E, mjNWARNING]); None, with nothing written, if `actions` is
    anything else or a row holds a NaN or an inf (the steps' own checks then
    say what is wrong).
  """
  shape = (len(steppers),) + steppers[0].action_shape
  if (type(actions) is not np.ndarray or actions.dtype not in ACTION_DTYPES  # pylint: disable=unidiomatic-typecheck
      or actions.shape != shape or len(addresses) != len(steppers)
      or low.shape != shape[2:] or high.shape != shape[2:]):
    return None
  clipped = np.empty(actions.shape)
  before = np.empty((len(steppers), _N_WARNINGS), np.int32)
  if _write_controls(addresses, actions, low, high, _N_WARNINGS, clipped,
                     before) >= 0:
    return None
  return clipped, before


def check_warnings(steppers, addresses, before):
  """The last part of the physics phases of `steppers` (after each one's
  `compiled_substeps`): every one's warning counters against `before` in
  one compiled call; a step with new ones diverged (`FusedStep.diverged`)."""
  new = np.empty(before.shape, np.bool_)
  diverged = np.empty(len(steppers), np.bool_)
  _new_warnings(addresses, before, new, diverged)
  if diverged.any():
    for stepper, stepper_diverged, stepper_new in zip(steppers, diverged, new):
      if stepper_diverged:
        stepper.diverged(stepper_new)


ACTION_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))
"""The action dtypes the compiled kernels take (`write_controls`,
`kernels.clip_finite`)."""


class FusedStep:
  """`composer.Environment.step` with the substeps in one physics call.

  The same hooks in the same order, the same physics (`mj_step2`, n - 1
  `mj_step`, `mj_step1` is what n legacy `Physics.step` calls do), the
  observation read once at the end. `step(action, observe=False)` leaves
  out the observation of a MID step. Built by `make` after each reset, for
  one environment.
  """

  def __init__(self, env, substeps, compiled_controls=None):
    self._env = env
    self.substeps = substeps
    """The `SubstepRunner`, or None where `physics.step` runs them."""
    self._diverged = False  # Whether the last `step_physics` diverged.
    self.addresses = None
    """Where a compiled physics phase (`write_controls`, `check_warnings`)
    writes and reads (`_CONTROLS`...), or None where composer's hooks write
    the controls."""
    self.action_bounds = None
    """(low [d], high [d]) of a compiled step's actions."""
    self.action_shape = None
    """[n, d] of a compiled step's actions (its task's action buffer)."""
    if compiled_controls is not None:
      buffer, first, self.action_bounds = compiled_controls
      self.action_shape = buffer.shape
      data = env.physics.data.ptr  # Kept alive by `substeps`.
      self._buffer = buffer  # Its memory is written at `addresses`.
      self.addresses = (data.ctrl.ctypes.data + 8 * first,
                        buffer.ctypes.data,
                        data.warning.lastinfo.ctypes.data)
      self._address_table = np.array([self.addresses], np.intp)

  @classmethod
  def make(cls, env, action_bounds=None):
    """A `FusedStep` for `env` (a composer.Environment just reset), or None
    where composer's own step must run: an observable with non-default
    settings (composer's updater is in use) or a hook between substeps.

    Its physics phase is compiled (`addresses`) where the task offers it
    (`compiled_controls()`: its action buffer and first control), no other
    hook runs before the step, the substeps can be fused, physics errors end
    the episode rather than raise, and `action_bounds` (low [d], high [d],
    every agent's) are given.
    """
    # pylint: disable=protected-access
    hooks, task = env._hooks, env.task
    if (not getattr(env._observation_updater, "lean", False)
        or hooks._before_substep.entity_hooks
        or hooks._before_substep.extra_hooks
        or hooks._after_substep.entity_hooks
        or hooks._after_substep.extra_hooks
        or not composer_env._callable_is_trivial(task.before_substep)
        or not composer_env._callable_is_trivial(task.after_substep)):
      return None
    substeps = SubstepRunner.make(env.physics)
    controls = getattr(task, "compiled_controls", lambda: None)()
    compiled = None
    if (substeps is not None and controls is not None
        and action_bounds is not None
        and not hooks._before_step.entity_hooks
        and not hooks._before_step.extra_hooks
        and not env._raise_exception_on_physics_error):
      buffer, first = controls
      low, high = (np.ascontiguousarray(b, np.float64) for b in action_bounds)
      warning = env.physics.data.ptr.warning
      if (_warning_layout(warning) and buffer.dtype == np.float64
          and buffer.flags.c_contiguous
          and buffer.ndim == 2 and low.shape == high.shape == buffer.shape[1:]
          and 0 <= first and first + buffer.size <= env.physics.model.nu):
        compiled = (buffer, int(first), (low, high))
    return cls(env, substeps, compiled)

  def step(self, action, observe=True):
    """One control step of the validated `action`; a `dm_env.TimeStep`."""
    self.step_physics(action)
    return self.step_outcome(observe)

  # `step` in two phases, for copies stepped in lockstep: each copy's
  # physics, then each copy's outcome, so that each phase's code stays in
  # the caches across copies (`runners.rollout.EnvBatch`).

  def step_physics(self, action):
    """The first phase of `step`: the hooks before it, then the substeps."""
    if self.addresses is not None:
      written = write_controls((self,), self._address_table, action[None],
                               *self.action_bounds)
      if written is None:  # `validate_action` lets no such action through.
        raise ValueError(f"Cannot write actions {action!r}.")
      self.compiled_substeps()
      check_warnings((self,), self._address_table, written[1])
      return
    env = self._env
    # pylint: disable=protected-access
    env._hooks.before_step(env._physics_proxy, action, env._random_state)
    try:
      if self.substeps is not None:
        self.substeps.step(env._n_sub_steps)
      else:
        env._physics.step(env._n_sub_steps)
      self._diverged = False
    except control.PhysicsError as e:
      if env._raise_exception_on_physics_error:
        raise
      logging.warning(e)
      self._diverged = True

  def compiled_substeps(self):
    """A compiled physics phase's step after its controls (`write_controls`):
    what composer's hooks before a step do besides the controls (the
    episode's step count, with its log line; the task's `state_changed`),
    then the substeps (`SubstepRunner.run`; their warnings are checked for
    all steps at once: see `diverged`)."""
    env = self._env
    hooks = env._hooks  # pylint: disable=protected-access
    hooks._episode_step_count += 1  # pylint: disable=protected-access
    if (hooks._episode_step_count  # pylint: disable=protected-access
        % composer_env._STEPS_LOGGING_INTERVAL == 0):  # pylint: disable=protected-access
      logging.info("The current episode has been running for %d steps.",
                   hooks._episode_step_count)  # pylint: disable=protected-access
    env.task.state_changed()
    self._diverged = False
    self.substeps.run(env._n_sub_steps)  # pylint: disable=protected-access

  def diverged(self, new_warnings):
    """After `compiled_substeps`: MuJoCo counted the warnings
    `new_warnings` ([bool] each) anew; logged as `step_physics` does, and the
    step ends the episode."""
    self._diverged = True
    logging.warning(_physics_error(new_warnings))

  def step_outcome(self, observe=True):
    """The second phase of `step`: the hooks after it, reward, discount,
    termination and (where asked or at the end) the observation."""
    env = self._env
    # pylint: disable=protected-access
    env._hooks.after_step(env._physics_proxy, env._random_state)
    task = env._task
    if self._diverged:
      reward, discount, terminating = 0.0, 0.0, True
    else:
      reward = task.get_reward(env._physics_proxy)
      discount = task.get_discount(env._physics_proxy)
      time_up = env._physics.data.time >= env._time_limit
      terminating = task.should_terminate_episode(env._physics_proxy) or time_up
    observation = (env._observation_updater.get_observation()
                   if observe or terminating else None)
    if terminating:
      env._reset_next_step = True
      return dm_env.TimeStep(dm_env.StepType.LAST, reward, discount,
                             observation)
    return dm_env.TimeStep(dm_env.StepType.MID, reward, discount, observation)
