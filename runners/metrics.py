"""What a cooperative run reports: episode figures, losses, throughput.

One row per update goes to `metrics.csv` and TensorBoard (through
`runners.run_dir.MetricsLog`, step = env_steps) and to the progress bar:

  update, env_steps, agent_steps, wall_time   counters
  sps, agent_sps                             low-level (agent) steps / s
  episodes, return, success, reward/<term>,  means over the last `window`
  <task progress figures>                     ended episodes (`episode_metrics`)
  learner/<species>/<loss>                   the update's PPO figures
                                             (`LOSS_METRICS`; value_loss in
                                             normalised units)
  time/collect, time/learn, restarts         where the time went, actor deaths
"""
import collections
import sys
import time
from typing import Any, Iterable

import numpy as np

LOSS_METRICS = ('total_loss', 'policy_loss', 'value_loss', 'entropy',
                'approx_kl', 'clip_fraction', 'grad_norm', 'learning_rate',
                'action_std', 'explained_variance')
COUNTERS = ('update', 'env_steps', 'agent_steps', 'wall_time', 'sps',
            'agent_sps', 'episodes')
_SKIP = ('env', 'control_steps')  # Per-episode bookkeeping, not figures.


def episode_figures(metrics: dict[str, Any]) -> dict[str, float]:
  """The numeric figures of one ended episode (an `episode_metrics()` dict,
  with or without the rollout's bookkeeping) as floats: success is 0 / 1."""
  return {k: float(v) for k, v in metrics.items() if k not in _SKIP
          and isinstance(v, (bool, int, float, np.number, np.bool_))}


def episode_keys(metrics: dict[str, Any]) -> list[str]:
  """Numeric episode figures of one `episode_metrics()` dict, in log order:
  return, success, reward terms, then the task's progress figures."""
  keys = list(episode_figures(metrics))
  head = [k for k in ('return', 'success') if k in keys]
  terms = sorted(k for k in keys if k.startswith('reward/'))
  rest = sorted(k for k in keys if k not in head and k not in terms)
  return head + ['length'] + terms + rest


def columns(keys: Iterable[str], species: Iterable[str]) -> list[str]:
  """The CSV columns of a run with these episode keys and species."""
  losses = [f'learner/{s}/{m}' for s in species for m in LOSS_METRICS]
  return [*COUNTERS, *keys, *losses, 'time/collect', 'time/learn',
          'restarts']


class EpisodeWindow:
  """The last `size` ended episodes and their mean figures."""

  def __init__(self, keys: Iterable[str], size: int, control_timestep: float):
    self._keys = list(keys)
    self._episodes = collections.deque(maxlen=size)
    self._dt = control_timestep
    self.total = 0

  def extend(self, episodes: Iterable[dict[str, Any]]) -> None:
    for episode in episodes:
      episode = dict(episode)
      episode['length'] = episode.get('control_steps', 0) * self._dt
      self._episodes.append(episode)
      self.total += 1

  def state(self) -> list[dict[str, Any]]:
    """The window's episodes, JSON-able (checkpoints keep them)."""
    return [{k: (v.item() if isinstance(v, np.generic) else v)
             for k, v in e.items()} for e in self._episodes]

  def restore(self, episodes: Iterable[dict[str, Any]]) -> None:
    self._episodes.extend(episodes)

  @property
  def full(self) -> bool:
    """Whether the window holds `size` episodes (its means are comparable)."""
    return len(self._episodes) == self._episodes.maxlen

  def summary(self) -> dict[str, float]:
    """{key: mean over the window} (NaN before any episode ended)."""
    out = {}
    for key in self._keys:
      values = [float(e[key]) for e in self._episodes if key in e]
      out[key] = float(np.mean(values)) if values else float('nan')
    return out


class Progress:
  """A tqdm bar on a terminal, else one line every `every` seconds."""

  def __init__(self, total: int, initial: int, enabled: bool = True,
               every: float = 30.0):
    import tqdm  # pylint: disable=g-import-not-at-top
    self._interactive = sys.stderr.isatty()
    self._enabled = enabled
    self._every = every
    self._last = time.monotonic()
    self._bar = tqdm.tqdm(total=total, initial=initial, unit='step',
                          unit_scale=True, dynamic_ncols=True,
                          disable=not (enabled and self._interactive))

  def update(self, row: dict[str, Any], steps: int) -> None:
    postfix = {'sps': f'{row["sps"]:.0f}',
               'return': f'{row.get("return", float("nan")):.1f}',
               'success': f'{row.get("success", float("nan")):.2f}'}
    self._bar.update(steps)
    self._bar.set_postfix(postfix, refresh=False)
    now = time.monotonic()
    if self._enabled and not self._interactive and (
        now - self._last > self._every):
      self._last = now
      print(f'update {row["update"]} env_steps {row["env_steps"]} '
            + ' '.join(f'{k} {v}' for k, v in postfix.items()), flush=True)

  def extend(self, steps: int) -> None:
    """Raises the bar's total by `steps` (a run that goes on)."""
    self._bar.total += steps
    self._bar.refresh()

  def close(self) -> None:
    self._bar.close()


def learner_row(species: str, metrics: dict[str, Any]) -> dict[str, float]:
  """`learner/<species>/<loss>` entries; raises on a non-finite loss."""
  out = {}
  for name in LOSS_METRICS:
    if name in metrics:
      value = float(metrics[name])
      if not np.isfinite(value):
        raise FloatingPointError(
            f'The {species} learner produced {name} = {value}; stopping '
            'before the parameters are written (lower --learning-rate?).')
      out[f'learner/{species}/{name}'] = value
  return out

