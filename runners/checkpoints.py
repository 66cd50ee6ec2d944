"""Checkpoints of a cooperative run: every species' learner plus counters.

One checkpoint is one directory, `<logdir>/checkpoints/ckpt_<iteration>/`:

  <species>.msgpack   that species' full learner state (`learner.save`:
                      params, optimiser, normalisers, update step, PRNG key)
  state.json          counters (iteration, env_steps, episodes, wall_time,
                      restarts), the run's `TrainArgs`, the agent's
                      `HierarchyConfig` and the species layout

It is written into a temporary sibling directory and renamed into place
(`run_dir.replace_directory`), so a kill at any instant leaves either the
whole checkpoint or none, and a checkpoint written again (`best/`, or the
same iteration after a resume) is never lost in between; the newest `keep`
are kept. `--resume` and `coop-eval` read the newest checkpoint that reads
completely (`resolve`): one damaged by something else (a full disk, a
copy cut short) is named and passed over for the one before it.

`<logdir>/checkpoints/best/` (with `--keep-best`) is a checkpoint of the same
form holding the iteration whose episode window scored best (`save_best`);
`coop-eval --checkpoint <logdir>/checkpoints/best` evaluates it.
"""
import glob
import json
import os
import shutil
import sys
from typing import Any, Callable, Mapping

from runners import run_dir

FORMAT = 1
STATE_FILE = 'state.json'
BEST = 'best'
_PREFIX = 'ckpt_'


class CorruptCheckpoint(ValueError):
  """A checkpoint file that cannot be read completely; names the file."""


def _directory(logdir: str) -> str:
  return os.path.join(logdir, 'checkpoints')


def list_checkpoints(logdir: str) -> list[str]:
  """Checkpoint directories of a run (complete when written), oldest first."""
  paths = glob.glob(os.path.join(_directory(logdir), _PREFIX + '*'))
  return sorted(p for p in paths if os.path.basename(p)[len(_PREFIX):]
                .isdigit() and os.path.exists(os.path.join(p, STATE_FILE)))


def _write(final: str, learners: Mapping[str, Any], state: dict[str, Any]):
  """Writes a checkpoint directory `final` atomically (temporary sibling,
  then rename), replacing any earlier one of that name."""
  tmp = f'{final}.tmp-{os.getpid()}'
  run_dir.remove_stale(os.path.dirname(final))
  shutil.rmtree(tmp, ignore_errors=True)  # Ours, from a failed write.
  os.makedirs(tmp)
  for name, learner in learners.items():
    learner.save(os.path.join(tmp, f'{name}.msgpack'))
  with open(os.path.join(tmp, STATE_FILE), 'w') as f:
    json.dump({'format': FORMAT, **state}, f, indent=1)
    f.flush()
    os.fsync(f.fileno())
  run_dir.replace_directory(tmp, final)


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
  return final


def save_best(logdir: str, learners: Mapping[str, Any],
              state: dict[str, Any]) -> str:
  """Writes `state` and the learners as `checkpoints/best/`, atomically,
  replacing the previous best; returns its directory."""
  final = os.path.join(_directory(logdir), BEST)
  _write(final, learners, state)
  return final


def _report(message: str) -> None:
  print(message, file=sys.stderr, flush=True)


def resolve(path: str, report: Callable[[str], None] = _report) -> str:
  """The checkpoint directory to read: `path` itself if it is one, else the
  newest checkpoint of the run directory `path` that reads completely.

  Checkpoints that do not read completely are passed over, and `report`
  is told which (with the file and the error) and which one is used
  instead. A checkpoint directory given as `path` must read completely.

  Raises:
    FileNotFoundError: `path` holds no checkpoint.
    CorruptCheckpoint: `path` is a damaged checkpoint, or every checkpoint
      of the run is.
  """
  # A writer killed while replacing `best/` leaves it aside: put it back.
  run_dir.recover_directory(os.path.normpath(path))
  run_dir.recover_directory(os.path.join(_directory(path), BEST))
  if os.path.exists(os.path.join(path, STATE_FILE)):
    check_complete(path)
    return path
  found = list_checkpoints(path)
  if not found:
    raise FileNotFoundError(f'No checkpoint in {path!r}: expected a run '
                            f'directory with checkpoints/{_PREFIX}*/ or a '
                            f'checkpoint directory holding {STATE_FILE}.')
  damaged = []
  for checkpoint in reversed(found):
    try:
      check_complete(checkpoint)
    except CorruptCheckpoint as e:
      damaged.append(str(e))
      continue
    if damaged:
      report('Skipped damaged checkpoint(s): ' + ' '.join(damaged)
             + f' Using the newest complete one, {checkpoint}.')
    return checkpoint
  raise CorruptCheckpoint(f'No checkpoint of {path} reads completely: '
                          + ' '.join(damaged))


def read_state(checkpoint: str) -> dict[str, Any]:
  """The state.json of a checkpoint directory.

  Raises:
    CorruptCheckpoint: the file is missing, empty or not JSON.
    ValueError: another checkpoint format.
  """
  path = os.path.join(checkpoint, STATE_FILE)
  try:
    with open(path) as f:
      state = json.load(f)
  except (OSError, ValueError) as e:  # JSONDecodeError is a ValueError.
    raise CorruptCheckpoint(f'{path} cannot be read ({e}).') from None
  if not isinstance(state, dict):
    raise CorruptCheckpoint(f'{path} holds no checkpoint state.')
  if state.get('format') != FORMAT:
    raise ValueError(f'{checkpoint} has checkpoint format '
                     f'{state.get("format")}, expected {FORMAT}.')
  return state


def check_complete(checkpoint: str) -> dict[str, Any]:
  """Reads `checkpoint` through (state.json and every species' learner
  file) without building learners; returns the state.

  Raises:
    CorruptCheckpoint: naming the first file that does not read completely.
  """
  from flax import serialization  # pylint: disable=g-import-not-at-top
  state = read_state(checkpoint)
  for species in state.get('species', []):
    path = os.path.join(checkpoint, f'{species["name"]}.msgpack')
    try:
      with open(path, 'rb') as f:
        contents = serialization.msgpack_restore(f.read())
    except Exception as e:  # pylint: disable=broad-except
      # msgpack raises ValueError ("incomplete input") or its own errors.
      raise CorruptCheckpoint(f'{path} cannot be read ({e}).') from None
    if not isinstance(contents, dict) or 'state' not in contents:
      raise CorruptCheckpoint(f'{path} holds no learner state.')
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
