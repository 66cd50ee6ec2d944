"""Checkpoints of a run, through orbax: every species' learner plus counters.

One checkpoint is one orbax step, `<logdir>/checkpoints/<update>/`:

  learners/   {species name: {dtype name: one flat array}}: that species'
              saved learner state (params, optimiser, normalisers, update
              counter, PRNG key; `Learner.save()`) packed into one array
              per dtype (`runners.packing`), one of over 1 MiB padded with
              zeros to a multiple of 2^16 elements (`_write`)
  state/      a JSON item: counters (update, env_steps, episodes,
              wall_time, restarts), the run's `TrainArgs`, the agent's
              `HierarchyConfig`, the species layout, the episode window and
              each learner's kind, format and packing layout (each array's
              path in the state, dtype and shape, in packing order)
  metrics/    on the updates saved as a new best: the episode window's
              success and return

A published result (`coop-paper`) keeps a policy checkpoint instead
(`write_policy`): the same layout with each learner's parameters and
statistics only and `policy_only` in the state; it evaluates and starts
other runs (`--init-from`) but resumes nothing.

One `orbax.checkpoint.CheckpointManager` writes them: orbax writes a step
under a temporary name and renames it into place when complete, so a kill
at any instant leaves the whole checkpoint or none, and a temporary one is
never read (the next writer removes it). A run keeps one `Writer` (one
manager) from its first update to its end, and each of its saves finishes
in the background while the next update's rollouts are collected (orbax's
asynchronous checkpointing: ~0.2 s of each ~6 s update on the 2-core
machine, during which the driver only waits for its actors); the next save
and the writer's `close` wait for it, so a run that stops, fails or is
interrupted ends with its last checkpoint whole. Only a kill of the process
in that fraction of a second costs the update before the current one too.
`save` writes one checkpoint and returns when it is complete. The writer
keeps the newest `keep` and, with `--keep-best`, the best one by its
window's (success, return). `--resume` and `coop-eval` read the
newest checkpoint that reads completely (`resolve`): one damaged by
something else (a full disk, a copy cut short) is named and passed over for
the one before it. `coop-eval --checkpoint <logdir>/checkpoints/best` reads
the best one.

Packed because orbax's cost is per array written (`runners.packing`), at
one checkpoint an update of a few seconds. Checkpoints of format 2 and 3
(each learner's state as orbax's own PyTree, arrays of no elements left
out) and 4 (packed, not padded) read as before.

Runs from before orbax (`checkpoints/ckpt_<update>/` and `checkpoints/
best/`, each with a `<species>.msgpack` per learner and `state.json`) read as
before and resume; the resumed run writes orbax steps beside them, and the
old checkpoints go as the newest `keep` (and a new best) replace them.
States of format 1 and 2 name the update counter 'iteration'; they read
with it renamed (`_upgrade`).
"""
import contextlib
import glob
import logging
import os
import shutil
import sys
from typing import Any, Callable, Mapping, Optional, Sequence

from runners import packing
from runners import run_dir

FORMAT = 5
"""The checkpoint's layout (1: the `state.json` of runs before orbax; 2 and
3: the learners as orbax PyTrees, 2 with its counter named 'iteration'; 4:
the learners packed, `runners.packing`; 5: packed, each array of more than
`_CHUNK_BYTES` zero-padded to a multiple of 2^16 elements, see `_write`)."""
BEST = 'best'
STATE_FILE = 'state.json'  # Runs before orbax.
_LEGACY_PREFIX = 'ckpt_'
_ITEMS = ('learners', 'state')
_CHUNK_BYTES = 2 ** 20  # See `_write`.
_PADDING = (2 ** 16, _CHUNK_BYTES)  # `packing.pad`'s (multiple, above).


class CorruptCheckpoint(ValueError):
  """A checkpoint that cannot be read completely; names it."""


def _directory(logdir: str) -> str:
  return os.path.join(logdir, 'checkpoints')


def _step_path(logdir: str, update) -> str:
  """The directory of the orbax step (checkpoint) of `update`."""
  return os.path.join(_directory(logdir), str(int(update)))


def _score(metrics: Mapping[str, float]) -> tuple[float, float]:
  return metrics['success'], metrics['return']


def _manager(directory: str, keep: Optional[int] = None,
             background: bool = False):
  """The run's CheckpointManager over `directory`: a writer keeping the
  newest `keep` and the best one (saving in the `background` or not), or a
  reader when `keep` is None."""
  import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
  policies = ocp.checkpoint_managers
  with _orbax_quiet():
    return ocp.CheckpointManager(
        os.path.abspath(directory), options=ocp.CheckpointManagerOptions(
            read_only=keep is None, create=keep is not None,
            enable_async_checkpointing=background,
            cleanup_tmp_directories=keep is not None,
            best_fn=_score, best_mode='max',
            preservation_policy=None if keep is None else
            policies.AnyPreservationPolicy([
                policies.LatestN(keep),
                policies.BestN(get_metric_fn=_score, n=1,
                               keep_checkpoints_without_metrics=False)])))


@contextlib.contextmanager
def _orbax_quiet():
  """Orbax warns (absl) when a reader opens a directory read-only and when
  a step is saved without metrics (not a new best): both are what we ask
  for, not news for the user's terminal."""
  logger = logging.getLogger('absl')
  level = logger.level
  logger.setLevel(logging.ERROR)
  try:
    yield
  finally:
    logger.setLevel(level)


class _StepInFlightFilter(logging.Filter):
  """Drops orbax's two log lines about the metadata file of the step it is
  writing (`<update>.orbax-checkpoint-tmp/_CHECKPOINT_METADATA`): its
  background thread reads that file while its own queued write of it has
  not yet run ('does not exist') or is half done ('Failed to json parse',
  empty content). Orbax then takes the same answer from the save itself and
  commits the whole file before the step's rename, so these are no news;
  the same lines about a committed step still show."""

  _MISSING = 'Metadata file does not exist: %s'
  _UNPARSED = 'Failed to json parse Metadata file: %s, '

  def filter(self, record: logging.LogRecord) -> bool:
    args = record.args if isinstance(record.args, tuple) else ()
    if not args or not isinstance(args[0], (str, os.PathLike)):
      return True  # Not a path: any other line (a filter must not raise).
    if not _in_flight(args[0]):
      return True
    if record.msg == self._MISSING:
      return False
    return not (isinstance(record.msg, str)
                and record.msg.startswith(self._UNPARSED)
                and len(args) > 1 and not str(args[1]).strip())


def _in_flight(path) -> bool:
  """Whether `path` is a file of a step orbax has not committed yet."""
  return '.orbax-checkpoint-tmp' in os.path.basename(
      os.path.dirname(os.fspath(path)))


def _quiet_steps_in_flight() -> None:
  """Installs `_StepInFlightFilter` on absl's logger (once a process)."""
  logger = logging.getLogger('absl')
  if not any(isinstance(f, _StepInFlightFilter) for f in logger.filters):
    logger.addFilter(_StepInFlightFilter())


class Writer:
  """A run's checkpoint writer (its one writer process): one manager for
  the run, each checkpoint finishing in the background (module doc).
  Use it as a context manager, or `close()` it."""

  def __init__(self, logdir: str, keep: int, background: bool = True):
    """Args:
      logdir: the run directory.
      keep: newest checkpoints kept; older ones are deleted unless best.
      background: False: each `save` returns when its checkpoint is whole.
    """
    self._logdir, self._keep = logdir, keep
    _quiet_steps_in_flight()
    self._manager = _manager(_directory(logdir), keep, background)
    self._new_best = None  # Of the save in flight (see `_finish`).

  def save(self, learners: Mapping[str, Any], state: dict[str, Any],
           score: Optional[tuple[float, float]] = None) -> str:
    """Starts writing a checkpoint; returns the directory it will have.

    Args:
      learners: {species name: learner} (`save()` gives its state, host
        arrays of its own: later updates do not change what is written).
      state: JSON-able dict with at least 'update' (counters, config...).
      score: (success, return) of the episode window when this update is
        a new best (kept as the best until one scores higher), else None.
    """
    self._finish()
    saved = {name: learner.save() for name, learner in learners.items()}
    _write(self._manager, saved, state, score)
    self._new_best = score is not None
    return _step_path(self._logdir, state['update'])

  def _finish(self) -> None:
    """Waits for the save in flight, then removes what it replaces."""
    self._manager.wait_until_finished()
    if self._new_best is not None:
      _remove_legacy(self._logdir, self._keep, best=self._new_best)
      self._new_best = None

  def close(self) -> None:
    """Waits for the last checkpoint to be whole; the writer is done."""
    try:
      self._finish()
    finally:
      self._manager.close()

  def __enter__(self):
    return self

  def __exit__(self, *exc_info):
    self.close()


def save(logdir: str, learners: Mapping[str, Any], state: dict[str, Any],
         keep: int, score: Optional[tuple[float, float]] = None) -> str:
  """Writes one checkpoint (`Writer.save`) and returns its directory once
  it is whole."""
  with Writer(logdir, keep, background=False) as writer:
    return writer.save(learners, state, score)


def write_policy(checkpoint: str, logdir: str) -> str:
  """Writes the policy of `checkpoint` as `logdir`/checkpoints/<update>/, a
  checkpoint of its own (what a published result keeps): each species'
  `HANDED_ON` state (parameters and statistics, no optimiser: about a third
  of the size) and the state marked `policy_only`. `coop-eval` and
  `--init-from` read it; no run resumes from it (`restore` refuses).

  Raises:
    ValueError: `checkpoint` is not `policy_writable` (copy it whole).
  """
  from agents.ppo import learning  # pylint: disable=g-import-not-at-top
  read = _read(checkpoint) if _is_step(checkpoint) else None  # Read once.
  if read is None or not _in_todays_format(read['state']):
    raise ValueError(f'{checkpoint} is from before orbax or holds learner '
                     'states of an older format: copy it whole.')
  saved = {name: learning.handed_on(_saved_learner(read, name))
           for name in read['state']['learners']}
  with _manager(_directory(logdir), keep=1) as manager:
    _write(manager, saved, {**read['state'], 'policy_only': True})
  return _step_path(logdir, read['state']['update'])


def policy_writable(checkpoint: str) -> bool:
  """Whether `write_policy` can write `checkpoint`'s policy: an orbax step
  whose learners are all in today's format (older ones are read through
  their learner's upgrade, which only a built learner can do)."""
  return _is_step(checkpoint) and _in_todays_format(read_state(checkpoint))


def _in_todays_format(state: dict[str, Any]) -> bool:
  from agents.ppo import learning  # pylint: disable=g-import-not-at-top
  return all(entry.get('format') == learning.CHECKPOINT_FORMAT
             and entry.get('kind')
             for entry in state.get('learners', {}).values())


def _write(manager, saved: Mapping[str, dict[str, Any]],
           state: dict[str, Any],
           score: Optional[tuple[float, float]] = None) -> None:
  """Writes {species: saved learner state} and `state` as the orbax step
  `state['update']` of `manager` (a writer `_manager`)."""
  import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
  arrays, layouts = {}, {}
  for name, s in saved.items():
    packed, layouts[name] = packing.pack(s['state'])
    arrays[name] = packing.pad(packed, _PADDING)
  state = {**state, 'format': FORMAT, 'learners': {
      name: {'kind': s['kind'], 'format': s['format'],
             'layout': layouts[name]}
      for name, s in saved.items()}}
  metrics = None
  if score is not None:
    metrics = {'success': score[0], 'return': score[1]}
  update = int(state['update'])
  # Packed, a learner is one large array: chunked, and the chunks spread
  # over data files of ~2 MiB, no file of a checkpoint passes ~2.5 MB (a
  # published result or a stash is committed, and the repository takes no
  # file over 5 MB). Orbax's chunks divide the array: one whose length has
  # no divisor near 1 MiB's worth (a prime, as a policy's 271,553 floats)
  # would go in one-element chunks, ~5 s to write and ~85 s to read, hence
  # the padding to a multiple of 2^16 elements (float32 chunks of 256 KiB
  # to 1 MiB).
  save_args = {name: {dtype: ocp.SaveArgs(chunk_byte_size=_CHUNK_BYTES)
                      for dtype in padded}
               for name, padded in arrays.items()}
  with _orbax_quiet():
    manager.save(update, metrics=metrics, force=True,
                 args=ocp.args.Composite(
                     learners=ocp.args.PyTreeSave(
                         arrays, save_args=save_args,
                         ocdbt_target_data_file_size=2 * _CHUNK_BYTES),
                     state=ocp.args.JsonSave(state)))


def discard_after(logdir: str, update: int) -> None:
  """Deletes the checkpoints after `update` (a resumed run redoes them)."""
  for checkpoint in list_checkpoints(logdir):
    if checkpoint_update(checkpoint) > update:
      shutil.rmtree(checkpoint)


LIST_TRIES = 5
"""Times `list_checkpoints` lists a run before a step that vanishes while it
is listed (a running writer removing an old one) is taken as an error."""


def list_checkpoints(logdir: str) -> list[str]:
  """Checkpoint directories of a run (orbax steps and those from before
  orbax), oldest first; orbax's temporary ones are left out. A run that is
  being written can be listed (`coop-paper --dry-run` beside training):
  orbax reads each step it finds, and a step the writer removes between
  the two is listed again."""
  for tries_left in reversed(range(LIST_TRIES)):
    found = _legacy_checkpoints(logdir)
    try:
      if os.path.isdir(_directory(logdir)):
        with _manager(_directory(logdir)) as manager:
          found += [_step_path(logdir, step)
                    for step in manager.all_steps()]
    except FileNotFoundError:
      if not tries_left:
        raise
      continue
    return sorted(found, key=lambda path: (checkpoint_update(path), _is_step(path)))


def checkpoint_update(checkpoint: str) -> int:
  """The update a checkpoint directory holds, read from its name (an orbax
  step `<update>` or `ckpt_<update>` from before orbax); ValueError for a
  name of neither form."""
  return int(os.path.basename(checkpoint).removeprefix(_LEGACY_PREFIX))


def _is_step(path: str) -> bool:
  """Whether `path` is an orbax step (else a checkpoint from before)."""
  return os.path.isdir(os.path.join(path, 'state'))


def _report(message: str) -> None:
  print(message, file=sys.stderr, flush=True)


def _best(directory: str) -> Optional[str]:
  """The best orbax step in a run's checkpoint directory, if any."""
  if not os.path.isdir(directory):
    return None
  with _manager(directory) as manager:
    step = manager.best_step() if manager.all_steps() else None
    # Without metrics, orbax answers the latest step: no best.
    if step is None or manager.metrics(step) is None:
      return None
  return os.path.join(directory, str(step))


def resolve(path: str, report: Callable[[str], None] = _report) -> str:
  """The checkpoint directory to read: `path` itself if it is one (for
  `<logdir>/checkpoints/best`, the best one), else the newest checkpoint
  of the run directory `path` that reads completely.

  Checkpoints that do not read completely are passed over, and `report`
  is told which (with the error) and which one is used instead. A
  checkpoint given as `path` must read completely.

  Raises:
    FileNotFoundError: `path` holds no checkpoint.
    CorruptCheckpoint: `path` is a damaged checkpoint, or every checkpoint
      of the run is.
  """
  path = os.path.normpath(path)
  # A writer from before orbax killed while replacing `best/` left it aside.
  run_dir.recover_directory(path)
  run_dir.recover_directory(os.path.join(_directory(path), BEST))
  if os.path.basename(path) == BEST:
    path = _best(os.path.dirname(path)) or path
  if _is_step(path) or os.path.exists(os.path.join(path, STATE_FILE)):
    check_complete(path)
    return path
  found = list_checkpoints(path)
  if not found:
    raise FileNotFoundError(f'No checkpoint in {path!r}: expected a run '
                            'directory with checkpoints/<update>/ or a '
                            'checkpoint directory.')
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


def _read(checkpoint: str, items=_ITEMS) -> dict[str, Any]:
  """{item: contents} of an orbax step, read through.

  Raises:
    CorruptCheckpoint: it cannot be read, or holds no state.
    ValueError: another checkpoint format.
  """
  import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
  restore = {'learners': ocp.args.PyTreeRestore,
             'state': ocp.args.JsonRestore}
  try:
    if 'learners' in items:
      _check_arrays_stored(checkpoint)
    with ocp.Checkpointer(ocp.CompositeCheckpointHandler()) as checkpointer:
      read = checkpointer.restore(os.path.abspath(checkpoint),
                                  args=ocp.args.Composite(**{
                                      item: restore[item]() for item in items
                                  }))
  except Exception as e:  # pylint: disable=broad-except
    # Orbax and TensorStore raise ValueError, KeyError, OSError, JSON errors.
    raise CorruptCheckpoint(f'{checkpoint} cannot be read ({e}).') from None
  state = read['state']
  if not isinstance(state, dict):
    raise CorruptCheckpoint(f'{checkpoint} holds no checkpoint state.')
  if state.get('format') not in (2, 3, 4, FORMAT):
    raise ValueError(f'{checkpoint} has checkpoint format '
                     f'{state.get("format")}, expected 2 to {FORMAT}.')
  state = _upgrade(state)
  if 'learners' not in items:
    return {'state': state}
  learners = state.get('learners', {})
  missing = [n for n in learners if n not in read['learners']]
  if missing:
    raise CorruptCheckpoint(f'{checkpoint} holds no learner for {missing}.')
  saved = read['learners']
  if state['format'] >= 4:
    padding = _PADDING if state['format'] >= 5 else (1, 0)
    saved = {name: _unpacked(checkpoint, name, saved[name], entry, padding)
             for name, entry in learners.items()}
  return {'state': state, 'learners': saved}


def _check_arrays_stored(checkpoint: str) -> None:
  """Reads every value of the learners' OCDBT store (array metadata and
  chunks, as stored) through TensorStore, waiting on each: an array file
  cut short or lost (a full disk, a copy cut short) is named here, before
  orbax reads the step.

  Orbax reads the arrays concurrently (one `asyncio.gather` over every
  array's TensorStore open, then every read) in an event loop of its own
  that it closes as soon as the first error comes back, without cancelling
  or awaiting the other reads; those finish in TensorStore's threads and
  post their results to the closed loop ('Exception ignored in: None ...
  RuntimeError: Event loop is closed', at any later moment, and at times
  asyncio's 'Future exception was never retrieved'). Read here, nothing is
  left in flight when one fails (no read has an asyncio callback).

  Raises:
    ValueError, OSError: a value of the store cannot be read (TensorStore's
      OUT_OF_RANGE, DATA_LOSS...), named by `_read` as CorruptCheckpoint.
  """
  import tensorstore as ts  # pylint: disable=g-import-not-at-top
  learners = os.path.join(os.path.abspath(checkpoint), 'learners')
  if not os.path.exists(os.path.join(learners, 'manifest.ocdbt')):
    return  # Not OCDBT (or no learners at all): orbax names what fails.
  store = ts.KvStore.open({'driver': 'ocdbt', 'base': {
      'driver': 'file', 'path': learners + os.sep}}).result()
  keys = store.list().result()
  reads = [store.read(key) for key in keys]
  for key, read in zip(keys, reads):
    if read.result().state != 'value':
      raise ValueError(f'{key.decode()} is listed but missing')


def _unpacked(checkpoint: str, species: str, arrays: Any, entry: Any,
              padding: packing.Padding) -> dict[str, Any]:
  """A species' saved state dict from the packed arrays of a format-4 or
  -5 checkpoint and its state entry (`runners.packing`, with `padding`)."""
  try:
    return packing.unpack(arrays, entry['layout'], padding)
  except (KeyError, TypeError, ValueError) as e:
    raise CorruptCheckpoint(f'{checkpoint}: the {species} learner does not '
                            f'unpack with its layout ({e}).') from None


def read_state(checkpoint: str) -> dict[str, Any]:
  """The state (counters, config, species) of a checkpoint directory.

  Raises:
    CorruptCheckpoint: it cannot be read.
    ValueError: another checkpoint format.
  """
  if not _is_step(checkpoint):
    return _read_legacy_state(checkpoint)
  return _read(checkpoint, ('state',))['state']


def check_complete(checkpoint: str) -> dict[str, Any]:
  """Reads `checkpoint` through (the state and every species' learner)
  without building learners; returns the state.

  Raises:
    CorruptCheckpoint: naming what does not read completely.
  """
  if not _is_step(checkpoint):
    return _check_legacy(checkpoint)
  return _read(checkpoint)['state']


def saved_learner(checkpoint: str, species: str) -> dict[str, Any]:
  """One species' saved learner state (for `Learner.restore` or
  `initialize_from`)."""
  return saved_learners(checkpoint, (species,))[species]


def saved_learners(checkpoint: str,
                   species: Sequence[str]) -> dict[str, dict[str, Any]]:
  """{species: saved learner state} of `species`, the checkpoint read once.

  Raises:
    ValueError: `checkpoint` holds no learner for one of `species`.
  """
  if _is_step(checkpoint):
    read = _read(checkpoint)
    saved = {name: _saved_learner(read, name) for name in species
             if name in read['learners']}
  else:
    from agents import checkpointing  # pylint: disable=g-import-not-at-top
    paths = {name: os.path.join(checkpoint, f'{name}.msgpack')
             for name in species}
    saved = {name: checkpointing.read_file(path)
             for name, path in paths.items() if os.path.exists(path)}
  missing = [name for name in species if name not in saved]
  if missing:
    raise ValueError(f'{checkpoint} holds no learner for species '
                     f'{missing[0]!r}.')
  return saved


def _saved_learner(read: dict[str, Any], species: str) -> dict[str, Any]:
  """One species' saved learner state from a `_read` orbax step."""
  entry = read['state']['learners'][species]
  return {**{k: v for k, v in entry.items() if k != 'layout'},
          'state': read['learners'][species]}


def restore(checkpoint: str, learners: Mapping[str, Any]) -> dict[str, Any]:
  """Restores every species' learner; returns the state dict.

  Raises:
    ValueError: `checkpoint` holds a policy only (`write_policy`).
  """
  state = read_state(checkpoint)
  check_resumable(checkpoint, state)
  saved = saved_learners(checkpoint, tuple(learners))
  for name, learner in learners.items():
    learner.restore(saved[name], source=f'{checkpoint} ({name})')
  return state


def check_resumable(checkpoint: str, state: dict[str, Any]) -> None:
  """Raises ValueError if `checkpoint` (whose state is `state`) holds a
  policy only (`write_policy`), which no run resumes from."""
  if state.get('policy_only'):
    raise ValueError(
        f'{checkpoint} holds a policy only (a published result, without '
        'optimiser state), which no run resumes from: start a new run from '
        'it with --init-from SPECIES=PATH.')


def run_directory(checkpoint: str) -> str:
  """The run directory a checkpoint directory belongs to."""
  return os.path.dirname(os.path.dirname(os.path.abspath(checkpoint)))


# --- Checkpoints of runs from before orbax -----------------------------------


def _legacy_checkpoints(logdir: str) -> list[str]:
  paths = glob.glob(os.path.join(_directory(logdir), _LEGACY_PREFIX + '*'))
  return [p for p in paths
          if os.path.basename(p)[len(_LEGACY_PREFIX):].isdigit()
          and os.path.exists(os.path.join(p, STATE_FILE))]


def _remove_legacy(logdir: str, keep: int, best: bool) -> None:
  """Deletes the checkpoints from before orbax that are no longer among
  the newest `keep` (and the old `best/` once there is a new best), and
  what their writers left when killed (`.tmp-<pid>`, once it is dead)."""
  run_dir.remove_stale(_directory(logdir))
  old = set(_legacy_checkpoints(logdir))
  if old:  # Listing the orbax steps opens a manager: ms at every save.
    for path in list_checkpoints(logdir)[:-keep]:
      if path in old:
        shutil.rmtree(path)
  if best:
    shutil.rmtree(os.path.join(_directory(logdir), BEST), ignore_errors=True)


def _read_legacy_state(checkpoint: str) -> dict[str, Any]:
  """The state.json of a checkpoint from before orbax."""
  import json  # pylint: disable=g-import-not-at-top
  path = os.path.join(checkpoint, STATE_FILE)
  try:
    with open(path) as f:
      state = json.load(f)
  except (OSError, ValueError) as e:  # JSONDecodeError is a ValueError.
    raise CorruptCheckpoint(f'{path} cannot be read ({e}).') from None
  if not isinstance(state, dict):
    raise CorruptCheckpoint(f'{path} holds no checkpoint state.')
  if state.get('format') != 1:
    raise ValueError(f'{checkpoint} has checkpoint format '
                     f'{state.get("format")}, expected 1.')
  return _upgrade(state)


def _upgrade(state: dict[str, Any]) -> dict[str, Any]:
  """A state of format 1 or 2 in today's names: its counter 'iteration'
  is the update counter."""
  if 'update' not in state and 'iteration' in state:
    state = {('update' if k == 'iteration' else k): v
             for k, v in state.items()}
  return state


def _check_legacy(checkpoint: str) -> dict[str, Any]:
  from agents import checkpointing  # pylint: disable=g-import-not-at-top
  state = _read_legacy_state(checkpoint)
  for species in state.get('species', []):
    path = os.path.join(checkpoint, f'{species["name"]}.msgpack')
    try:
      contents = checkpointing.read_file(path)
    except Exception as e:  # pylint: disable=broad-except
      # msgpack raises ValueError ("incomplete input") or its own errors.
      raise CorruptCheckpoint(f'{path} cannot be read ({e}).') from None
    if not isinstance(contents, dict) or 'state' not in contents:
      raise CorruptCheckpoint(f'{path} holds no learner state.')
  return state
