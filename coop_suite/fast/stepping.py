"""`FusedStep`: composer's control step with its substeps in one call."""

from absl import logging
from dm_control.composer import environment as composer_env
from dm_control.rl import control
import dm_env
import mujoco
import numpy as np


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


class FusedStep:
  """`composer.Environment.step` with the substeps in one physics call.

  The same hooks in the same order, the same physics (`mj_step2`, n - 1
  `mj_step`, `mj_step1` is what n legacy `Physics.step` calls do), the
  observation read once at the end. `step(action, observe=False)` leaves
  out the observation of a MID step. Built by `make` after each reset, for
  one environment.
  """

  def __init__(self, env, substeps):
    self._env = env
    self.substeps = substeps
    """The `SubstepRunner`, or None where `physics.step` runs them."""
    self._diverged = False  # Whether the last `step_physics` diverged.

  @classmethod
  def make(cls, env):
    """A `FusedStep` for `env` (a composer.Environment just reset), or None
    where composer's own step must run: an observable with non-default
    settings (composer's updater is in use) or a hook between substeps."""
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
    return cls(env, SubstepRunner.make(env.physics))

  def step(self, action, observe=True):
    """One control step of the validated `action`; a `dm_env.TimeStep`."""
    self.step_physics(action)
    return self.step_outcome(observe)

  # `step` in two phases, for copies stepped in lockstep: each copy's
  # physics, then each copy's outcome, so that each phase's code stays in
  # the caches across copies (`runners.rollout.EnvBatch`).

  def step_physics(self, action):
    """The first phase of `step`: the hooks before it, then the substeps."""
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
