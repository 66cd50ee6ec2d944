"""`LeanUpdater`: composer's observation updater, fast for plain observables."""

from dm_control.composer.observation import updater as updater_lib
import numpy as np


def is_plain(observable):
  """Whether composer would compute `observable` once, at the last substep."""
  return (observable.update_interval in (None, 1)
          and observable.delay in (None, 0)
          and observable.buffer_size in (None, 1)
          and observable.aggregator is None
          and observable.corruptor is None)


class LeanUpdater(updater_lib.Updater):
  """composer's observation Updater with a fast path for plain observables.

  With plain observables (`is_plain`) composer evaluates each one once per
  control step, after the last substep. This updater does the same, but
  lazily in `get_observation`, with no buffers or schedules; where every
  observable is a feature of one task (`batch_source`, set by
  `CoopTask`), it reads all agents' observations in one call
  (`CoopTask.observation_batch`). Any non-plain observable restores
  composer's own behaviour (`lean` is then False).
  """

  @property
  def lean(self):
    """Whether the fast path is in use (set at `reset`)."""
    return self._lean

  def reset(self, physics, random_state):
    super().reset(physics, random_state)
    structure = self._observables
    dicts = structure if isinstance(structure, (list, tuple)) else [structure]
    self._lean = all(is_plain(o) for d in dicts for o in d.values()
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
