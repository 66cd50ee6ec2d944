"""Checkpoints of a cooperative run: every species' learner plus counters.

One checkpoint is one directory, `<logdir>/checkpoints/ckpt_<iteration>/`:

  <species>.msgpack   that species' full learner state (`learner.save`:
                      params, optimiser, normalisers, update step, PRNG key)
  state.json          counters (iteration, env_steps, episodes, wall_time,
                      restarts), the run's `TrainArgs`, the agent's
                      `HierarchyConfig` and the species layout

It is written into a temporary sibling directory and renamed into place, so
a crash leaves either the whole checkpoint or none; the newest `keep` are
kept. `--resume` and `coop-eval` read the newest complete one.

`<logdir>/checkpoints/best/` (with `--keep-best`) is a checkpoint of the same
form holding the iteration whose episode window scored best (`save_best`);
`coop-eval --checkpoint <logdir>/checkpoints/best` evaluates it.
"""
import glob
import json
import os
import shutil
from typing import Any, Mapping

FORMAT = 1
STATE_FILE = 'state.json'
BEST = 'best'
_PREFIX = 'ckpt_'


def _directory(logdir: str) -> str:
  return os.path.join(logdir, 'checkpoints')


def list_checkpoints(logdir: str) -> list[str]:
  """Complete checkpoint directories of a run, oldest first."""
  paths = glob.glob(os.path.join(_directory(logdir), _PREFIX + '*'))
  return sorted(p for p in paths if os.path.basename(p)[len(_PREFIX):]
                .isdigit() and os.path.exists(os.path.join(p, STATE_FILE)))


def _write(final: str, learners: Mapping[str, Any], state: dict[str, Any]):
  """Writes a checkpoint directory `final` atomically (temporary sibling,
  then rename), replacing any earlier one of that name."""
  tmp = f'{final}.tmp-{os.getpid()}'
  shutil.rmtree(tmp, ignore_errors=True)
  os.makedirs(tmp)
  for name, learner in learners.items():
    learner.save(os.path.join(tmp, f'{name}.msgpack'))
  with open(os.path.join(tmp, STATE_FILE), 'w') as f:
    json.dump({'format': FORMAT, **state}, f, indent=1)
    f.flush()
    os.fsync(f.fileno())
  if os.path.exists(final):  # The same iteration again after a resume.
    shutil.rmtree(final)
  os.replace(tmp, final)


def save(logdir: str, learners: Mapping[str, Any], state: dict[str, Any],
         keep: int) -> str:
  """Writes a checkpoint atomically; returns its directory.

  Args:
    logdir: the run directory.
    learners: {species name: HierarchyLearner}.
    state: JSON-able dict with at least 'iteration' (counters, config...).
    keep: newest checkpoints kept; older ones are deleted.
  """
  final = os.path.join(_directory(logdir),
                       f'{_PREFIX}{int(state["iteration"]):08d}')
  _write(final, learners, state)
  for old in list_checkpoints(logdir)[:-keep]:
    shutil.rmtree(old, ignore_errors=True)
  for stale in glob.glob(os.path.join(_directory(logdir), '*.tmp-*')):
    shutil.rmtree(stale, ignore_errors=True)  # Left by a crashed writer.
  return final


def save_best(logdir: str, learners: Mapping[str, Any],
              state: dict[str, Any]) -> str:
  """Writes `state` and the learners as `checkpoints/best/`, atomically,
  replacing the previous best; returns its directory."""
  final = os.path.join(_directory(logdir), BEST)
  _write(final, learners, state)
  return final


def resolve(path: str) -> str:
  """A checkpoint directory from a run directory (newest checkpoint) or a
  checkpoint directory itself."""
  if os.path.exists(os.path.join(path, STATE_FILE)):
    return path
  found = list_checkpoints(path)
  if not found:
    raise FileNotFoundError(f'No checkpoint in {path!r}: expected a run '
                            f'directory with checkpoints/{_PREFIX}*/ or a '
                            f'checkpoint directory holding {STATE_FILE}.')
  return found[-1]


def read_state(checkpoint: str) -> dict[str, Any]:
  """The state.json of a checkpoint directory."""
  with open(os.path.join(checkpoint, STATE_FILE)) as f:
    state = json.load(f)
  if state.get('format') != FORMAT:
    raise ValueError(f'{checkpoint} has checkpoint format '
                     f'{state.get("format")}, expected {FORMAT}.')
  return state


def restore(checkpoint: str, learners: Mapping[str, Any]) -> dict[str, Any]:
  """Restores every species' learner; returns the state dict."""
  state = read_state(checkpoint)
  missing = [n for n in learners
             if not os.path.exists(os.path.join(checkpoint, f'{n}.msgpack'))]
  if missing:
    raise ValueError(f'{checkpoint} holds no learner for species {missing}.')
  for name, learner in learners.items():
    learner.restore(os.path.join(checkpoint, f'{name}.msgpack'))
  return state


def run_directory(checkpoint: str) -> str:
  """The run directory a checkpoint directory belongs to."""
  return os.path.dirname(os.path.dirname(os.path.abspath(checkpoint)))
