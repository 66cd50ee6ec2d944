"""CommandWrapper: any coop_suite environment driven by per-agent commands.

The wrapped environment's action per agent is a 2-D command instead of 8
joint actions; the frozen lower layer turns it into joint actions for the
`command_period / control_timestep` low-level steps of one command period:

* position paradigm: the command is a target offset (m) in the agent's
  heading frame *at the time the command is issued*. It is turned into a
  world-frame target once per period; every low-level step the controller
  sees `command/target` = the offset from where the agent is now to that
  world target, in its current heading frame (exactly what `walk_to_target`
  trained it on).
* velocity paradigm: the command is a planar velocity (m/s) in the agent's
  heading frame at issue time. It is turned into a world-frame velocity once
  per period and held fixed in the world, so `command/velocity` turns with
  the agent in its heading frame, as in `walk_velocity` (where commands are
  fixed in the world between redraws). Holding the world direction makes a
  command mean "go that way", not "keep turning".

Commands are clipped to the action spec: each axis to +-`command_bound`
(default 3 m for position, 1 m/s for velocity), and velocity commands also to
a norm of at most `command_bound` (the controller never saw faster ones).

One wrapper step = one command period: rewards are summed per agent over the
low-level steps, discounts multiplied, and the period ends early when the
episode does. Observations are the wrapped environment's own (proprio/*,
extero/* and any command/* of the task), taken at the end of the period.
"""
from typing import Any, Optional

import dm_env
from dm_env import specs
import numpy as np

from coop_suite import kernels

DEFAULT_COMMAND_BOUND = {'position': 3.0, 'velocity': 1.0}
"""Per-axis bound of a command: metres (position) or m/s (velocity)."""


class CommandWrapper:
  """A multi-agent environment whose per-agent action is a command."""

  def __init__(self, env, controller, command_period: float = 0.5,
               command_bound: Optional[float] = None):
    """Args:
      env: a `coop_suite` environment (any task, any number of agents).
      controller: an `agents.lowlevel.Controller`.
      command_period: seconds between commands; a multiple of the env's
        control timestep.
      command_bound: per-axis bound of the commands; default by paradigm
        (see `DEFAULT_COMMAND_BOUND`).
    """
    self._env = env
    self._controller = controller
    self._paradigm = controller.paradigm
    dt = env.control_timestep()
    steps = int(round(command_period / dt))
    if steps < 1 or abs(steps * dt - command_period) > 1e-6:
      raise ValueError(f'command_period={command_period} s must be a positive '
                       f'multiple of the control timestep {dt} s.')
    self._low_level_steps = steps
    bound = float(command_bound if command_bound is not None
                  else DEFAULT_COMMAND_BOUND[self._paradigm])
    if bound <= 0:
      raise ValueError(f'command_bound must be > 0, got {bound}.')
    self._bound = bound
    self._action_spec = [
        specs.BoundedArray((2,), np.float64, -bound, bound, name=f'command_{i}')
        for i in range(env.n_agents)]
    self._input_proprio, self._proprio_columns, self._input_command = (
        _input_layout(controller))
    self._world_commands = np.zeros((env.n_agents, 2))
    self._reset_next_step = True

  # --- Properties and passthroughs ------------------------------------------

  @property
  def env(self):
    """The wrapped (low-level) environment."""
    return self._env

  @property
  def controller(self):
    return self._controller

  @property
  def n_agents(self) -> int:
    return self._env.n_agents

  @property
  def task(self):
    return self._env.task

  @property
  def physics(self):
    return self._env.physics

  @property
  def low_level_steps(self) -> int:
    """Low-level control steps per command."""
    return self._low_level_steps

  @property
  def world_commands(self) -> np.ndarray:
    """The current commands in the world frame [n_agents, 2]: targets (m)
    for position, velocities (m/s) for velocity."""
    return self._world_commands.copy()

  def control_timestep(self) -> float:
    """Seconds per wrapper step (the command period)."""
    return self._low_level_steps * self._env.control_timestep()

  def action_spec(self):
    """Per-agent command specs: list of BoundedArray [2]."""
    return list(self._action_spec)

  def observation_spec(self):
    return self._env.observation_spec()

  def reward_spec(self):
    return self._env.reward_spec()

  def discount_spec(self):
    return self._env.discount_spec()

  def episode_metrics(self):
    return self._env.episode_metrics()

  def close(self):
    self._env.close()

  # --- dm_env interface --------------------------------------------------------

  def reset(self) -> dm_env.TimeStep:
    timestep = self._env.reset()
    self._world_commands = self._frames().position[:, :2].copy() if (
        self._paradigm == 'position') else np.zeros((self.n_agents, 2))
    self._reset_next_step = False
    return timestep

  def step(self, commands) -> dm_env.TimeStep:
    """Runs one command period; `commands` [n_agents, 2] (see module doc)."""
    if self._reset_next_step:
      return self.reset()
    self.begin(commands)
    while not self.advance(self._controller.act(self.controller_input())):
      pass
    return self.end()

  # --- One period in phases (for copies stepped in lockstep) ---------------
  #
  # `step` is `begin`, then `advance(controller.act(controller_input()))`
  # until it returns True, then `end`. `runners.rollout.EnvBatch` runs the
  # same phases for all its copies at once, so that one controller call per
  # low-level step serves every copy (`controller_input(out=...)` writes
  # into the rows of one shared array), and `advance` in its two phases
  # (every copy's physics together, then every copy's outcome).

  def begin(self, commands) -> None:
    """Starts a command period with `commands` [n_agents, 2]."""
    if self._reset_next_step:
      raise RuntimeError('The episode has ended: call reset() first.')
    commands = self._validate(commands)
    frames = self._frames()
    world = np.stack(kernels.rotate.py_func(
        frames.cos, frames.sin, commands[:, 0], commands[:, 1]), -1)
    if self._paradigm == 'position':
      self._world_commands = frames.position[:, :2] + world
    else:
      self._world_commands = world
    self._period_steps = 0
    self._period_reward = np.zeros(self.n_agents)
    self._period_discount = 1.0
    self._period_last = None  # The period's latest low-level TimeStep.

  def controller_input(self, out: Optional[np.ndarray] = None) -> np.ndarray:
    """The controller's input [n_agents, observation_size] float32 for the
    current state: the task's packed proprioception, its columns taken in
    the controller's key order, and the command in the agent's current
    heading frame (no per-key dict).

    Args:
      out: an array of that shape to write into (e.g. rows of a larger
        batch); a new one if None.
    """
    if out is None:
      out = np.empty((self.n_agents, self._controller.observation_size),
                     np.float32)
    # One compiled call: in numpy it was five small-array operations, each
    # paying for the caches the physics has just flushed (docs/performance.md).
    kernels.command_input(
        self._frames().as_packed(),
        self._env.task.proprioception(self._env.physics),
        self._world_commands, self._paradigm == 'velocity',
        self._proprio_columns, self._input_proprio, self._input_command, out)
    return out

  def advance(self, actions) -> bool:
    """One low-level step with joint actions [n_agents, 8]; True when the
    period is over (its last step, or the episode ended)."""
    self.advance_physics(actions)
    return self.advance_outcome()

  def advance_physics(self, actions) -> None:
    """`advance`'s first phase: the environment's `step_physics` (nothing
    else, so `EnvBatch` runs its copies' first phases together through
    their environments, `coop_suite.environment.LockstepPhysics`)."""
    self._env.step_physics(actions)

  def advance_outcome(self) -> bool:
    """`advance`'s second phase (`step_outcome`): what `advance` returns."""
    self._period_steps += 1
    last_step = self._period_steps == self._low_level_steps
    # Only the period's last observation is returned: the steps before it
    # skip the exteroception (the environment still observes a LAST step).
    timestep = self._env.step_outcome(observe=last_step)
    self._period_reward += np.asarray(timestep.reward, np.float64)
    self._period_discount *= float(timestep.discount)
    self._period_last = timestep
    return last_step or timestep.last()

  def end(self) -> dm_env.TimeStep:
    """Ends the period: rewards summed over its steps, discounts multiplied,
    the last step's observation."""
    last = self._period_last.last()
    self._reset_next_step = last
    return dm_env.TimeStep(
        step_type=dm_env.StepType.LAST if last else dm_env.StepType.MID,
        reward=[np.float32(r) for r in self._period_reward],
        discount=np.float32(self._period_discount),
        observation=self._period_last.observation)

  # --- Internals -------------------------------------------------------------

  def _frames(self):
    return self._env.task.frames(self._env.physics)

  def _validate(self, commands) -> np.ndarray:
    n = self.n_agents
    try:
      commands = np.asarray(commands, np.float64)
    except (TypeError, ValueError) as e:
      raise TypeError(f'commands must be numeric, shape ({n}, 2): {e}') from None
    if commands.shape != (n, 2):
      raise ValueError(f'Expected commands of shape ({n}, 2) (one 2-D command '
                       f'per agent), got {commands.shape}.')
    if not np.isfinite(commands).all():
      raise ValueError(f'Commands contain NaN or inf: {commands}.')
    commands = np.clip(commands, -self._bound, self._bound)
    if self._paradigm == 'velocity':
      norm = np.linalg.norm(commands, axis=1, keepdims=True)
      commands = commands * np.minimum(1.0, self._bound / np.maximum(norm,
                                                                     1e-12))
    return commands


_PROPRIO_COLUMNS = dict(kernels.proprio_columns(0, 'proprio/'))
"""'proprio/<name>' -> its columns in `CoopTask.proprioception`'s array."""


def _input_layout(controller):
  """Where the controller's inputs come from, in its key order: (its
  proprioception columns, the packed proprioception's columns that fill
  them, its command columns)."""
  inputs, source, command, start = [], [], None, 0
  for key, size in zip(controller.observation_keys,
                       controller.config['observation_sizes']):
    columns = np.arange(start, start + size)
    start += size
    if key == controller.command_key:
      command = columns
    elif key in _PROPRIO_COLUMNS:
      where = _PROPRIO_COLUMNS[key]
      if where.stop - where.start != size:
        raise ValueError(f'The controller reads {size} values of {key!r}; '
                         f'the tasks give {where.stop - where.start}.')
      inputs.append(columns)
      source.append(np.arange(where.start, where.stop))
    else:
      raise ValueError(
          f'The controller reads {key!r}; a lower layer may read only '
          f'{sorted(_PROPRIO_COLUMNS)} and {controller.command_key!r}.')
  if command is None:
    raise ValueError(f'The controller does not read its command '
                     f'{controller.command_key!r}.')
  return np.concatenate(inputs), np.concatenate(source), command
