"""Interfaces between actors, learners and the processes that run them.

These follow Acme's `acme/core.py` so that a runner can drive any agent the same
way: actors step environments and pull parameters from a `VariableSource`
(usually the learner, possibly behind a Ray handle); learners consume data in
`step()` and publish parameters through `get_variables()`.

As in Acme's `Saveable`, `save()` returns an in-memory state and a separate
checkpointer writes it (`runners.checkpoints`, through orbax, in place of
Acme's TensorFlow Checkpointer); `restore(state)` continues from it.
"""
import abc
from typing import Any, Sequence


class VariableSource(abc.ABC):
  """Something that publishes named variables (parameters, statistics)."""

  @abc.abstractmethod
  def get_variables(self, names: Sequence[str]) -> list[Any]:
    """Returns the current value of each named variable, in `names` order.

    Args:
      names: variable collection names, e.g. `["params", "normalizer"]`.

    Returns:
      One pytree per name.
    """


class Actor(abc.ABC):
  """Acts in (a batch of) environments and records what it saw.

  The calling sequence for one rollout segment is
  `observe_first(ts)`, then repeatedly `a = select_action(ts.observation)`,
  `ts = env.step(a)`, `observe(a, ts)`; `update()` between segments.
  """

  @abc.abstractmethod
  def select_action(self, observation: Any) -> Any:
    """Samples an action for `observation` with the actor's own parameters."""

  @abc.abstractmethod
  def observe_first(self, timestep: Any) -> None:
    """Records the first timestep of a segment (only its observation)."""

  @abc.abstractmethod
  def observe(self, action: Any, next_timestep: Any) -> None:
    """Records the transition that `action` caused."""

  @abc.abstractmethod
  def update(self, wait: bool = False) -> None:
    """Pulls fresh variables from the actor's `VariableSource`.

    Args:
      wait: block until the new variables have arrived (meaningful when the
        source is remote; in-process sources are always synchronous).
    """


class Learner(VariableSource):
  """Consumes data and improves parameters; the source actors pull from."""

  @abc.abstractmethod
  def step(self) -> Any:
    """Performs one learning update (for PPO: one batch, all epochs)."""

  def save(self) -> Any:
    """Everything needed to resume training, as host data (no files)."""
    raise NotImplementedError(f'{type(self).__name__} does not implement save.')

  def restore(self, saved: Any) -> None:
    """Resumes from what `save` returned."""
    raise NotImplementedError(
        f'{type(self).__name__} does not implement restore.')
