"""A run directory under every mistake: a second writer, kills in the middle
of a write, damaged checkpoints, bad flags, SIGTERM."""
import csv
import json
import logging
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time

from flax import serialization
import jax
import numpy as np
import pytest

from runners import checkpoints
from runners import cli
from runners import config as config_lib
from runners import evaluate
from runners import learner_loop
from runners import run_dir
from runners import train
from tests.test_train import STEPS
from tests.test_train import _args
from tests.test_train import _argv
from tests.test_train import _rows
from tests.test_train import controller  # pylint: disable=unused-import

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
pytestmark = pytest.mark.filterwarnings('ignore:os.fork:RuntimeWarning')


FAKE_LEARNER = """
import numpy as np
class FakeLearner:
  # A saved learner state without networks.
  def __init__(self, value):
    self.value = value
  def save(self):
    return {'format': 1, 'kind': 'fake',
            'state': {'w': np.full(3, self.value, np.float32)}}
"""
exec(FAKE_LEARNER)  # pylint: disable=exec-used


def _state(update):
  return {'update': update, 'species': [{'name': 'ant'}]}


def _save(logdir, update, keep=5, score=None):
  return checkpoints.save(logdir, {'ant': FakeLearner(update)},
                          _state(update), keep, score)


def _truncate_arrays(checkpoint):
  """Cuts every array file of an orbax step in half (a copy cut short)."""
  for directory, _, names in os.walk(os.path.join(checkpoint, 'learners')):
    if os.path.basename(directory) == 'd':
      for name in names:
        path = os.path.join(directory, name)
        with open(path, 'r+b') as f:
          f.truncate(os.path.getsize(path) // 2)


def _holder(script):
  """A python process running `script` that prints 'ready' then sleeps."""
  process = subprocess.Popen(
      [sys.executable, '-c', textwrap.dedent(script) +
       '\nprint("ready", flush=True)\nimport time\ntime.sleep(120)\n'],
      cwd=REPO, stdout=subprocess.PIPE, text=True)
  assert process.stdout.readline().strip() == 'ready'
  return process


def _dead_pid():
  process = subprocess.Popen([sys.executable, '-c', 'pass'])
  process.wait()
  return process.pid


# --- 1. One writer -------------------------------------------------------------


def test_second_writer_is_refused_until_the_first_dies(tmp_path):
  logdir = str(tmp_path / 'run')
  holder = _holder(f'''
      from runners import run_dir
      lock = run_dir.RunLock({logdir!r}).__enter__()''')
  try:
    with pytest.raises(run_dir.RunInUseError,
                       match=f'another run .*{holder.pid}'):
      with run_dir.RunLock(logdir):
        pass
  finally:
    holder.kill()
    holder.wait()
  with run_dir.RunLock(logdir):  # The kernel dropped the dead writer's lock.
    assert open(os.path.join(logdir, run_dir.LOCK_FILE)).read().split()[0] \
        == str(os.getpid())


def test_a_lock_whose_holder_just_left_is_taken(tmp_path, monkeypatch):
  """The holder of a new directory's lock removes it as it leaves; one
  coming in between making the directory and opening its lock file makes
  it again and takes the lock."""
  logdir = str(tmp_path / 'claim')
  opened = []

  def open_after_holder_left(path, *args):
    if not opened:  # The holder's `__exit__` runs just now.
      shutil.rmtree(logdir)
    opened.append(path)
    return open(path, *args)
  monkeypatch.setattr(run_dir, 'open', open_after_holder_left, raising=False)
  with run_dir.RunLock(logdir) as lock:
    assert len(opened) == 2 and os.path.isfile(opened[-1])
  assert lock._file is None  # pylint: disable=protected-access


def test_training_takes_the_lock_before_checking_the_directory(controller,
                                                               tmp_path):
  logdir = str(tmp_path / 'run')
  with run_dir.RunLock(logdir):
    for resume in (False, True):
      with pytest.raises(run_dir.RunInUseError, match='--logdir'):
        learner_loop.train(_args(logdir, controller, resume=resume))
    assert os.listdir(logdir) == [run_dir.LOCK_FILE]  # Nothing written.
  assert not os.path.exists(logdir)  # The lock's own directory, removed.


def test_a_stop_between_checkpoints_still_saves_its_update(controller,
                                                         tmp_path):
  # Checkpoints every 2 updates; SIGTERM after update 1's save was decided.
  logdir = str(tmp_path / 'run')
  summary = learner_loop.train(
      _args(logdir, controller, total_steps=4 * STEPS, checkpoint_every=2),
      on_update=lambda *_: os.kill(os.getpid(), signal.SIGTERM))
  assert (summary['stopped_by'], summary['update']) == ('SIGTERM', 1)
  assert checkpoints.read_state(checkpoints.resolve(logdir))['update'] == 1


def test_only_dead_writers_temporaries_are_removed(tmp_path):
  directory = str(tmp_path / 'controller')
  holder = _holder('pass')
  try:
    live = f'{directory}.tmp-{holder.pid}'
    dead = f'{directory}.tmp-{_dead_pid()}'
    for path in (live, dead):
      os.makedirs(path)
    # Named: only that name's (a writer on another machine looks dead here).
    other = f'{tmp_path}/other.tmp-{_dead_pid()}'
    os.makedirs(other)
    run_dir.remove_stale(str(tmp_path), 'controller')
    assert os.path.isdir(live)  # Another writer's work in progress.
    assert not os.path.exists(dead)
    assert os.path.isdir(other)
    run_dir.remove_stale(str(tmp_path))
    assert not os.path.exists(other) and os.path.isdir(live)
  finally:
    holder.kill()
    holder.wait()


# --- 2. Damaged checkpoints ----------------------------------------------------


def test_damaged_newest_checkpoint_is_named_and_passed_over(tmp_path):
  logdir = str(tmp_path)
  paths = [_save(logdir, i) for i in (1, 2, 3)]
  _truncate_arrays(paths[2])
  reports = []
  assert checkpoints.resolve(logdir, reports.append) == paths[1]
  assert paths[2] in reports[0] and paths[1] in reports[0]
  # Named when asked for by name.
  with pytest.raises(checkpoints.CorruptCheckpoint, match=paths[2]):
    checkpoints.resolve(paths[2])
  # An empty state item too.
  open(os.path.join(paths[1], 'state', 'metadata'), 'w').close()
  reports.clear()
  assert checkpoints.resolve(logdir, reports.append) == paths[0]
  assert paths[1] in reports[0]
  shutil.rmtree(paths[0])
  with pytest.raises(checkpoints.CorruptCheckpoint, match='reads completely'):
    checkpoints.resolve(logdir)


@pytest.fixture(scope='module')
def run3(tmp_path_factory, controller):  # pylint: disable=redefined-outer-name
  """Three updates in one process."""
  logdir = str(tmp_path_factory.mktemp('runs') / 'three')
  learner_loop.train(_args(logdir, controller, total_steps=3 * STEPS))
  return logdir


# Orbax left reads in flight on a damaged step (see
# `test_a_damaged_checkpoint_is_named_before_orbax_reads_it`).
@pytest.mark.filterwarnings('error::pytest.PytestUnraisableExceptionWarning')
def test_resume_and_eval_fall_back_from_a_damaged_checkpoint(
    run3, controller, tmp_path, capsys, monkeypatch):
  real_train = learner_loop.train
  logdir = str(tmp_path / 'damaged')
  shutil.copytree(run3, logdir)
  newest = checkpoints.list_checkpoints(logdir)[-1]
  assert newest.endswith(os.path.join('checkpoints', '3'))
  learner_file = newest
  _truncate_arrays(newest)
  controller_file = os.path.join(logdir, 'controller', 'config.json')
  before = os.stat(controller_file)

  video = str(tmp_path / 'episode.mp4')
  evaluate.main(['--checkpoint', logdir, '--episodes', '1', '--envs', '1',
                 '--video', video, '--width', '64', '--height', '48'])
  captured = capsys.readouterr()
  assert learner_file in captured.err and os.path.join(
      'checkpoints', '2.') in captured.err
  assert 'model 1/1, seed 1000: 1 episodes, success 0.0%' in captured.err
  assert 'success rate' in captured.out
  # The tiny policy does not move a cylinder in 0.8 s.
  assert f'video: {video} (the filmed episode failed)' in captured.out

  summary = learner_loop.train(_args(logdir, controller, resume=True,
                                     total_steps=3 * STEPS))
  out = capsys.readouterr()
  assert learner_file in out.err
  assert 'resuming from' in out.out and out.out.split('resuming from ')[1] \
      .startswith(os.path.join(logdir, 'checkpoints', '2'))
  assert summary['update'] == 3
  assert [int(r['update']) for r in _rows(logdir)] == [1, 2, 3]
  checkpoints.check_complete(newest)  # Iteration 3 was written again.
  # The controller copy is read, never rewritten, on resume.
  after = os.stat(controller_file)
  assert (after.st_ino, after.st_mtime_ns) == (before.st_ino,
                                               before.st_mtime_ns)

  # --resume-from picks one (implies --resume; later rows go), and SIGTERM
  # stops with a checkpoint and the status of a signal, not success's 0.
  chosen = os.path.join(logdir, 'checkpoints', '2')
  with pytest.raises(ValueError, match='not a checkpoint of --logdir'):
    learner_loop.train(_args(str(tmp_path / 'other'), controller,
                             resume_from=chosen))
  monkeypatch.setattr(learner_loop, 'train', lambda args: real_train(
      args, on_update=lambda *_: os.kill(os.getpid(), signal.SIGTERM)))
  with pytest.raises(SystemExit) as exit_info:
    train.main(['--resume-from', chosen, *_argv(controller, 5 * STEPS)])
  assert exit_info.value.code == 128 + signal.SIGTERM
  out = capsys.readouterr().out
  assert 'resuming from ' + chosen in out
  assert 'Stopped by SIGTERM after update 3 of 5' in out
  assert [int(r['update']) for r in _rows(logdir)] == [1, 2, 3]
  last = checkpoints.resolve(logdir)  # Written by the stopped run.
  assert checkpoints.read_state(last)['args']['resume_from'] == chosen


# --- 3. Crash-safe writes ------------------------------------------------------


def test_a_checkpoint_killed_while_written_is_never_read(tmp_path):
  logdir = str(tmp_path)
  first = _save(logdir, 1)
  script = FAKE_LEARNER + textwrap.dedent(f'''
      import os
      from runners import checkpoints
      rename = os.rename
      def rename_or_die(source, target):
        if 'orbax-checkpoint-tmp' in str(source):
          os._exit(9)  # Killed with the checkpoint written, not finalised.
        rename(source, target)
      os.rename = rename_or_die
      checkpoints.save({logdir!r}, {{'ant': FakeLearner(2.0)}}, {_state(2)!r},
                       5)
      ''')
  result = subprocess.run([sys.executable, '-c', script],
                          cwd=REPO, check=False)
  assert result.returncode == 9
  directory = os.path.join(logdir, 'checkpoints')
  assert len(os.listdir(directory)) == 2  # The whole of 1, a temporary 2.
  assert checkpoints.list_checkpoints(logdir) == [first]
  assert checkpoints.resolve(logdir) == first
  second = _save(logdir, 2)  # The next writer removes the temporary.
  assert sorted(os.listdir(directory)) == ['1', '2']
  assert checkpoints.saved_learner(second, 'ant')['state']['w'][0] == 2.0


def test_a_run_writer_saves_in_the_background_what_one_shot_saves_keep(
    tmp_path):
  # A run's writer: each save finishes while the run goes on; the same
  # checkpoints kept as one-shot saves keep, each whole once the writer is
  # closed, with the values of its update (not what the learner holds
  # later).
  scores = {2: (0.5, 1.0), 3: (0.5, 2.0), 4: (0.4, 9.0)}  # 3 is the best.
  one_shot = str(tmp_path / 'one_shot')
  expected = [_save(one_shot, i, keep=2, score=scores.get(i))
              for i in range(1, 7)]
  logdir = str(tmp_path / 'run')
  learner = FakeLearner(0.0)
  paths = []
  with checkpoints.Writer(logdir, keep=2) as writer:
    for i in range(1, 7):
      learner.value = float(i)
      paths.append(writer.save({'ant': learner}, _state(i), scores.get(i)))
      learner.value = -1.0  # The next update changes the learner.
  assert paths == [p.replace(one_shot, logdir) for p in expected]
  kept = checkpoints.list_checkpoints(logdir)
  assert kept == [p.replace(one_shot, logdir)
                  for p in checkpoints.list_checkpoints(one_shot)]
  assert kept == [paths[2], paths[4], paths[5]]
  for path in kept:
    update = checkpoints.check_complete(path)['update']
    assert checkpoints.saved_learner(path, 'ant')['state']['w'][0] == update
  assert checkpoints.resolve(os.path.join(logdir, 'checkpoints',
                                          checkpoints.BEST)) == paths[2]


def test_a_run_is_listed_while_its_writer_removes_a_step(tmp_path,
                                                        monkeypatch):
  # The writer of a running run removes its oldest step after orbax found
  # it and before orbax reads it: the listing is taken again.
  from orbax.checkpoint._src.path import step as step_lib  # pylint: disable=g-import-not-at-top
  logdir = str(tmp_path)
  paths = [_save(logdir, i, keep=3) for i in range(1, 4)]
  find_all, to_remove = step_lib._StandardNameFormat.find_all, [paths[0]]

  def find_all_then_remove(self, base_path):
    found = list(find_all(self, base_path))
    if to_remove:
      shutil.rmtree(to_remove.pop())
    return found
  monkeypatch.setattr(step_lib._StandardNameFormat, 'find_all',
                      find_all_then_remove)
  assert checkpoints.list_checkpoints(logdir) == paths[1:]
  assert not to_remove
  monkeypatch.setattr(checkpoints, 'LIST_TRIES', 1)  # Once: the error.
  to_remove.append(paths[1])
  with pytest.raises(FileNotFoundError, match=re.escape(paths[1])):
    checkpoints.list_checkpoints(logdir)


def test_orbax_reading_its_step_in_flight_is_not_logged(tmp_path, caplog):
  # Orbax's background thread reads the metadata file of the step it is
  # writing before its own queued write has run (missing) or finished
  # (empty); a writer hides those two lines, not the same about a
  # committed step.
  from orbax.checkpoint._src.metadata import checkpoint as metadata_lib  # pylint: disable=g-import-not-at-top
  logdir = str(tmp_path)
  _save(logdir, 1)  # A writer has run in this process.
  store = metadata_lib.metadata_store(enable_write=False)
  folder = os.path.join(logdir, 'checkpoints')
  in_flight = os.path.join(folder, '2.orbax-checkpoint-tmp')
  os.makedirs(in_flight)
  missing = os.path.join(in_flight, '_CHECKPOINT_METADATA')
  committed = os.path.join(folder, '3', '_CHECKPOINT_METADATA')
  with caplog.at_level(logging.WARNING):
    assert store.read(missing) is None
    open(missing, 'w').close()  # Created, not yet written.
    assert store.read(missing) is None
    assert caplog.records == []
    logging.getLogger('absl').warning('step %d of %s', 5, 'x')  # Any other.
    assert [r.getMessage() for r in caplog.records] == ['step 5 of x']
    caplog.clear()
    assert store.read(committed) is None
    os.makedirs(os.path.dirname(committed))
    open(committed, 'w').close()
    assert store.read(committed) is None
  assert [r.getMessage().split(':')[0] for r in caplog.records] == [
      'Metadata file does not exist', 'Failed to json parse Metadata file']
  assert all(committed in r.getMessage() for r in caplog.records)


def test_the_newest_and_the_best_are_kept(tmp_path):
  logdir = str(tmp_path)
  assert checkpoints.list_checkpoints(logdir) == []
  scores = {2: (0.5, 1.0), 3: (0.5, 2.0), 4: (0.4, 9.0)}  # 3 is the best.
  paths = [_save(logdir, i, keep=2, score=scores.get(i)) for i in range(1, 7)]
  assert checkpoints.list_checkpoints(logdir) == [paths[2], paths[4],
                                                  paths[5]]
  best = os.path.join(logdir, 'checkpoints', checkpoints.BEST)
  assert checkpoints.resolve(best) == paths[2]
  assert checkpoints.resolve(logdir) == paths[5]
  state = checkpoints.read_state(paths[2])
  assert state['update'] == 3 and state['format'] == checkpoints.FORMAT
  checkpoints.discard_after(logdir, 4)  # A run resumed from 4 redoes 5, 6.
  assert checkpoints.list_checkpoints(logdir) == [paths[2]]
  other = str(tmp_path / 'other')
  _save(other, 1)
  with pytest.raises(FileNotFoundError, match='No checkpoint'):
    checkpoints.resolve(os.path.join(other, 'checkpoints', checkpoints.BEST))


def test_a_format_2_checkpoint_reads_with_its_counter_named_update():
  """Orbax checkpoints written before the counter's rename (format 2, the
  published seed-0 cell) read, and resume, as `update`."""
  published = os.path.join(REPO, 'results', 'transport_no_curriculum',
                           'transport_hrl_n4_s0',
                           'checkpoints', '1465')
  with open(os.path.join(published, 'state', 'metadata')) as f:
    on_disk = json.load(f)
  assert on_disk['format'] == 2 and on_disk['iteration'] == 1465
  state = checkpoints.read_state(published)
  assert state['update'] == 1465 and 'iteration' not in state
  assert state['env_steps'] == on_disk['env_steps']


class _NestedLearner:
  """A saved state with what a real learner's holds: nested dicts, three
  dtypes, a scalar, an array without elements and an empty dict (optax's
  empty states), in today's learner format."""

  def __init__(self, value):
    self.state = {
        'params': {'dense': {'kernel': np.arange(6, dtype=np.float32)
                             .reshape(2, 3) * value,
                             'bias': np.full(3, value, np.float32)}},
        'normalizer': {'mean': np.full(2, value, np.float32),
                       'empty': np.zeros((0, 4), np.float32)},
        'value_normalizer': {'count': np.array(7, np.int32)},
        'opt_state': {'0': {'count': np.array(-3, np.int32)}, '1': {}},
        'key': np.array([1, 2 ** 32 - 1], np.uint32)}

  def save(self):
    from agents.ppo import learning  # pylint: disable=g-import-not-at-top
    return {'format': learning.CHECKPOINT_FORMAT, 'kind': 'fake',
            'state': self.state}


def _orbax_items(checkpoint):
  import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
  with ocp.Checkpointer(ocp.CompositeCheckpointHandler()) as checkpointer:
    return checkpointer.restore(checkpoint, args=ocp.args.Composite(
        learners=ocp.args.PyTreeRestore(), state=ocp.args.JsonRestore()))


def _assert_same_state(back, ours):
  flat_back = jax.tree_util.tree_flatten_with_path(back)[0]
  flat_ours = jax.tree_util.tree_flatten_with_path(ours)[0]
  assert [k for k, _ in flat_back] == [k for k, _ in flat_ours]
  for (_, a), (_, b) in zip(flat_back, flat_ours):
    assert a.dtype == b.dtype and a.shape == b.shape
    np.testing.assert_array_equal(a, b)


def test_learners_are_packed_one_array_per_dtype_and_read_back_whole(
    tmp_path):
  """Orbax costs Python per array written, so each species' state is one
  array per dtype on disk (`runners.packing`); it reads back as it was
  saved: structure, dtypes, shapes and values, empty dicts included."""
  learner = _NestedLearner(1.5)
  path = checkpoints.save(str(tmp_path), {'ant': learner}, _state(4), 3)
  on_disk = _orbax_items(path)
  assert sorted(on_disk['learners']['ant']) == ['float32', 'int32',
                                                'uint32']
  assert on_disk['learners']['ant']['float32'].shape == (11,)
  assert on_disk['state']['format'] == checkpoints.FORMAT == 5
  saved = checkpoints.saved_learner(path, 'ant')
  assert sorted(saved) == ['format', 'kind', 'state']
  _assert_same_state(saved['state'], learner.state)
  assert saved['state']['opt_state']['1'] == {}
  # A layout that does not match the arrays is a damaged checkpoint.
  metadata = os.path.join(path, 'state', 'metadata')
  with open(metadata) as f:
    state = json.load(f)
  for layout in ([[['a'], 'float32', [3, 3]]], 'not a layout', None):
    state['learners']['ant']['layout'] = layout
    with open(metadata, 'w') as f:
      json.dump(state, f)
    with pytest.raises(checkpoints.CorruptCheckpoint, match='layout'):
      checkpoints.check_complete(path)
  with pytest.raises(ValueError, match='not an array of numbers'):
    checkpoints.save(str(tmp_path / 'none'),
                     {'ant': FakeLearner(1.0)} | {'bee': _TextLearner()},
                     _state(1), 3)


class _BigLearner:

  def save(self):
    rng = np.random.default_rng(0)  # Random: orbax compresses.
    return {'format': 1, 'kind': 'fake',
            'state': {'w': rng.random(2 ** 21, np.float32),
                      'v': rng.random(2 ** 19, np.float32)}}


def test_no_file_of_a_checkpoint_passes_three_megabytes(tmp_path):
  """Published results and stashes are committed (no file over 5 MB): a
  learner of 10 MB of float32, packed into one array, spreads over files
  of ~2.5 MB at most."""
  path = checkpoints.save(str(tmp_path), {'ant': _BigLearner()},
                          _state(1), 3)
  sizes = [os.path.getsize(os.path.join(d, f))
           for d, _, files in os.walk(path) for f in files]
  assert sum(sizes) > 8e6 and max(sizes) < 3e6, sorted(sizes)[-4:]
  np.testing.assert_array_equal(
      checkpoints.saved_learner(path, 'ant')['state']['w'],
      _BigLearner().save()['state']['w'])


def _write_by_hand(directory, step, arrays, state):
  """An orbax step as a run of an older format wrote it: `arrays` as the
  learners' tree, `state` as the JSON item; returns its directory."""
  import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
  with ocp.CheckpointManager(directory, options=ocp.CheckpointManagerOptions(
      create=True)) as manager:
    manager.save(step, args=ocp.args.Composite(
        learners=ocp.args.PyTreeSave(arrays), state=ocp.args.JsonSave(state)))
  return os.path.join(directory, str(step))


class _PrimeLearner:
  """A policy's size: 271,553 float32 (a prime number of them, > 1 MiB)."""

  def save(self):
    rng = np.random.default_rng(1)
    return {'format': 1, 'kind': 'fake',
            'state': {'w': rng.random(271_553, np.float32),
                      'count': np.array(3, np.int32)}}


def _chunk_shape(checkpoint, species, dtype):
  import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
  with ocp.Checkpointer(ocp.PyTreeCheckpointHandler()) as checkpointer:
    tree = checkpointer.metadata(os.path.join(checkpoint, 'learners')
                                 ).item_metadata.tree
  return tuple(tree[species][dtype].storage.chunk_shape)


def test_a_packed_array_of_prime_length_is_padded_into_large_chunks(
    tmp_path):
  """Orbax's chunks divide the array: a packed learner of a prime length
  would be written as one-element chunks (a ravine policy's 271,553: ~5 s to
  write, ~85 s to read). Arrays over 1 MiB are padded with zeros to a
  multiple of 2^16 elements, and read back without them."""
  path = checkpoints.save(str(tmp_path), {'ant': _PrimeLearner()},
                          _state(1), 3)
  on_disk = _orbax_items(path)['learners']['ant']
  assert on_disk['float32'].shape == (5 * 2 ** 16,)  # 327,680.
  assert not on_disk['float32'][271_553:].any()
  assert on_disk['int32'].shape == (1,)  # Small arrays as they are.
  assert _chunk_shape(path, 'ant', 'float32')[0] >= 2 ** 16
  back = checkpoints.saved_learner(path, 'ant')['state']
  _assert_same_state(back, _PrimeLearner().save()['state'])
  # Anything but exactly the padding's zeros after the layout's values is
  # damage: other values, more zeros, zeros after a small array (never
  # padded), an array of a dtype the layout does not place.
  state = checkpoints.read_state(path)
  values = on_disk['float32'][:271_553]
  for i, damaged in enumerate([
      {'float32': np.concatenate([values, np.ones(3, np.float32)])},
      {'float32': np.concatenate([values, np.zeros(2 ** 16, np.float32)])},
      {'float32': on_disk['float32'][:-1]},
      {'int32': np.zeros(4, np.int32)},
      {'int64': np.zeros(4, np.int64)}]):
    checkpoint = _write_by_hand(str(tmp_path / f'damaged{i}'), 1,
                                {'ant': {**on_disk, **damaged}}, state)
    with pytest.raises(checkpoints.CorruptCheckpoint, match='layout'):
      checkpoints.check_complete(checkpoint)


def test_a_format_4_checkpoint_reads_unpadded(tmp_path):
  """Checkpoints packed before the padding (format 4: the stashes and
  results of 27 November) read as they were written, and nothing may follow
  their layout's values."""
  from runners import packing  # pylint: disable=g-import-not-at-top
  learner = _NestedLearner(3.0)
  packed, layout = packing.pack(learner.save()['state'])
  state = {**_state(2), 'format': 4, 'learners': {'ant': {
      'kind': 'fake', 'format': learner.save()['format'], 'layout': layout}}}
  exact, padded = (
      _write_by_hand(str(tmp_path / name), 2, {'ant': {
          **packed, 'float32': np.concatenate(
              [packed['float32'], np.zeros(extra, np.float32)])}}, state)
      for name, extra in (('exact', 0), ('padded', 1)))
  _assert_same_state(checkpoints.saved_learner(exact, 'ant')['state'],
                     learner.state)
  with pytest.raises(checkpoints.CorruptCheckpoint, match='layout'):
    checkpoints.check_complete(padded)


class _TextLearner:

  def save(self):
    return {'format': 1, 'kind': 'fake', 'state': {'w': 'text'}}


def test_a_format_3_checkpoint_reads_and_publishes_packed(tmp_path):
  """A run checkpoint written before the packing (format 3: orbax's own
  tree, arrays without elements as None; the stashes of 27 November and
  before) reads as it did, and its policy is published packed."""
  learner = _NestedLearner(2.0)
  arrays = {'ant': jax.tree.map(lambda a: None if np.size(a) == 0 else a,
                                learner.save()['state'])}
  state = {**_state(5), 'format': 3, 'learners': {'ant': {
      'kind': 'fake', 'format': learner.save()['format']}}}
  logdir = str(tmp_path / 'run')
  _write_by_hand(os.path.join(logdir, 'checkpoints'), 5, arrays, state)
  old = checkpoints.resolve(logdir)
  assert checkpoints.read_state(old)['format'] == 3
  back = checkpoints.saved_learner(old, 'ant')['state']
  assert back['normalizer']['empty'] is None  # As format 3 stored it.
  _assert_same_state({**back, 'normalizer': {'mean': back['normalizer']
                                             ['mean']}},
                     {**learner.state, 'normalizer': {
                         'mean': learner.state['normalizer']['mean']}})
  published = checkpoints.write_policy(old, str(tmp_path / 'published'))
  assert checkpoints.check_complete(published)['format'] == checkpoints.FORMAT
  policy = checkpoints.saved_learner(published, 'ant')['state']
  assert sorted(policy) == ['normalizer', 'params', 'value_normalizer']
  assert policy['normalizer']['empty'] is None  # Carried as read.
  _assert_same_state(policy['params'], learner.state['params'])
  # The committed results of format 3 read completely.
  assert checkpoints.check_complete(os.path.join(
      REPO, 'results', 'paper', 'transport_hrl_n4_s0', 'checkpoints',
      '1172'))['format'] == 3


def _to_old_layout(checkpoint, learners):
  """`checkpoint` as a run from before orbax wrote it:
  `ckpt_<iteration>/` with `<species>.msgpack` (what `learner.save(path)`
  wrote) and `state.json`, its counter named 'iteration'; returns that
  directory."""
  state = checkpoints.restore(checkpoint, learners)
  del state['learners']
  state['iteration'] = state.pop('update')
  old = os.path.join(os.path.dirname(checkpoint),
                     f'ckpt_{state["iteration"]:08d}')
  os.makedirs(old)
  for name, learner in learners.items():
    with open(os.path.join(old, f'{name}.msgpack'), 'wb') as f:
      f.write(serialization.msgpack_serialize(learner.save()))
  with open(os.path.join(old, checkpoints.STATE_FILE), 'w') as f:
    json.dump({**state, 'format': 1}, f)
  shutil.rmtree(checkpoint)
  return old


def test_a_run_from_before_orbax_evaluates_and_resumes(run3, controller,
                                                       tmp_path, capsys):
  logdir = str(tmp_path / 'old')
  shutil.copytree(run3, logdir)
  new = checkpoints.list_checkpoints(logdir)
  spec, config, models, _ = evaluate.load_model(
      new[1], evaluate.EvalArgs(checkpoint=(logdir,)))
  learners = {name: model[3] for name, model in models.items()}
  want = {n: jax.device_get(l.state) for n, l in learners.items()}
  old = [_to_old_layout(c, learners) for c in new]
  assert checkpoints.list_checkpoints(logdir) == old
  assert checkpoints.resolve(logdir) == old[-1]
  del spec, config
  # The old files restore the same state, bit for bit.
  _, _, models, state = evaluate.load_model(old[1], evaluate.EvalArgs(
      checkpoint=(logdir,)))
  assert state['update'] == 2 and 'iteration' not in state
  for name, model in models.items():
    for a, b in zip(jax.tree.leaves(want[name]),
                    jax.tree.leaves(jax.device_get(model[3].state))):
      np.testing.assert_array_equal(a, b)
  evaluate.main(['--checkpoint', logdir, '--episodes', '1', '--envs', '1'])
  assert 'update 3' in capsys.readouterr().out

  # Resumed, it continues from the old update 3 in orbax steps; the old
  # checkpoints go as the newest --keep-checkpoints (3) replace them.
  summary = learner_loop.train(_args(logdir, controller, resume=True,
                                     total_steps=5 * STEPS))
  assert summary['update'] == 5
  assert 'resuming from ' + old[-1] in capsys.readouterr().out
  assert [os.path.basename(p) for p in checkpoints.list_checkpoints(
      logdir)] == ['ckpt_00000003', '4', '5']
  assert checkpoints.read_state(checkpoints.resolve(logdir))['episodes'] > (
      checkpoints.read_state(old[-1])['episodes'])


def test_metrics_csv_survives_a_kill_while_resuming(tmp_path, monkeypatch):
  logdir = str(tmp_path)
  log = run_dir.MetricsLog(logdir, ['update', 'env_steps'])
  for update in (1, 2, 3):
    log.write({'update': update, 'env_steps': 10 * update})
  log.close()

  class Killed(BaseException):
    pass

  class DyingWriter(csv.DictWriter):
    def writerows(self, rows):
      raise Killed

  monkeypatch.setattr(run_dir.csv, 'DictWriter', DyingWriter)
  with pytest.raises(Killed):
    run_dir.MetricsLog(logdir, ['update', 'env_steps'], resume_update=2)
  monkeypatch.undo()
  assert [int(r['update']) for r in _rows(logdir)] == [1, 2, 3]
  run_dir.MetricsLog(logdir, ['update', 'env_steps'], resume_update=2).close()
  assert [int(r['update']) for r in _rows(logdir)] == [1, 2]


def test_directory_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
  final = str(tmp_path / 'controller')
  run_dir.write_directory(final, {'a': b'old', 'b': b'old'})

  class Killed(BaseException):
    pass

  fsync = os.fsync
  calls = []

  def fsync_then_die(fd):
    calls.append(fd)
    if len(calls) == 2:
      raise Killed
    fsync(fd)

  monkeypatch.setattr(run_dir.os, 'fsync', fsync_then_die)
  with pytest.raises(Killed):
    run_dir.write_directory(final, {'a': b'new', 'b': b'new'})
  monkeypatch.undo()
  assert sorted(os.listdir(final)) == ['a', 'b']
  assert open(os.path.join(final, 'b'), 'rb').read() == b'old'


# --- 8. Settings and signals ---------------------------------------------------


def test_invalid_settings_leave_no_directory(controller, tmp_path):
  logdir = str(tmp_path / 'bad')
  with pytest.raises(ValueError, match='--num-minibatches'):
    learner_loop.train(_args(logdir, controller, num_minibatches=3))
  assert not os.path.exists(logdir)


@pytest.mark.parametrize('argv,flag', [
    (['--time-limit', 'nan'], '--time-limit'),
    (['--time-limit', '-5'], '--time-limit'),
    (['--command-period', 'nan'], '--command-period'),
    (['--seed', '-1'], '--seed'),
    (['--max-actor-restarts', '-5'], '--max-actor-restarts'),
])
def test_bad_flags_give_one_line_naming_the_flag(argv, flag, capsys):
  with pytest.raises(SystemExit) as exit_info:
    cli.parse(config_lib.TrainArgs, argv)
  assert exit_info.value.code == 2
  lines = capsys.readouterr().err.strip().splitlines()
  assert len(lines) == 1 and ': error: ' in lines[0], lines
  assert flag in lines[0]


@pytest.mark.parametrize('argv,flag', [
    (['--time-limit', '-1'], '--time-limit'),
    (['--time-limit', 'inf'], '--time-limit'),
    (['--seeds', '0', '-3'], '--seeds'),
])
def test_bad_eval_flags_name_the_flag(argv, flag, capsys):
  with pytest.raises(SystemExit):
    evaluate.main(['--checkpoint', 'runs/x', *argv])
  assert flag in capsys.readouterr().err


def test_user_errors_are_one_line(tmp_path, capsys):
  with pytest.raises(SystemExit) as exit_info:
    evaluate.main(['--checkpoint', str(tmp_path)])
  assert exit_info.value.code == 2
  lines = capsys.readouterr().err.strip().splitlines()
  assert len(lines) == 1, lines
  assert lines[0].startswith('coop-eval: error: No checkpoint')


def test_a_damaged_checkpoint_is_named_before_orbax_reads_it(
    tmp_path, monkeypatch):
  # Orbax reads every array at once in an event loop of its own and closes
  # it at the first error with the other reads in flight; when they finish,
  # they post to the closed loop ('Exception ignored in: None ...
  # RuntimeError: Event loop is closed', at any later moment).
  import orbax.checkpoint as ocp  # pylint: disable=g-import-not-at-top
  logdir = str(tmp_path)
  rng = np.random.default_rng(0)  # Random: orbax compresses.
  learners = {name: FakeLearner(0) for name in ('ant', 'bee')}
  for learner in learners.values():
    learner.save = lambda: {'format': 1, 'kind': 'fake', 'state': {
        'w': rng.standard_normal(2 ** 20).astype(np.float32),
        'n': np.arange(3, dtype=np.int32), 'k': np.arange(2, dtype=np.uint32)}}
  state = {'update': 1, 'species': [{'name': n} for n in learners]}
  path = checkpoints.save(logdir, learners, state, keep=1)
  checkpoints.check_complete(path)  # Whole, it reads.
  _truncate_arrays(path)
  restores = []
  real_restore = ocp.Checkpointer.restore

  def restore(self, *args, **kwargs):
    restores.append(args)
    return real_restore(self, *args, **kwargs)

  monkeypatch.setattr(ocp.Checkpointer, 'restore', restore)
  unraisable = []
  monkeypatch.setattr(sys, 'unraisablehook', unraisable.append)
  for _ in range(10):
    with pytest.raises(checkpoints.CorruptCheckpoint,
                       match=re.escape(path) + '.*OUT_OF_RANGE'):
      checkpoints.check_complete(path)
  assert not restores  # Named before orbax reads it...
  time.sleep(0.5)  # ...so no read is left in flight to report later.
  assert not unraisable


class _Restored:
  """A learner that records what `restore` gives it."""

  def __init__(self):
    self.saved = None

  def restore(self, saved, source):
    self.saved = (saved['state']['w'][0], source)


def test_a_run_resumes_every_species_from_one_read_of_its_step(
    tmp_path, monkeypatch):
  """Each read of a step is every array of it: a ravine run restores its
  pushers and crossers from one, and names a species the step lacks."""
  path = checkpoints.save(
      str(tmp_path), {'pusher': FakeLearner(1.0), 'crosser': FakeLearner(2.0)},
      {'update': 3, 'species': [{'name': 'pusher'}, {'name': 'crosser'}]}, 3)
  reads = []
  read = checkpoints._read  # pylint: disable=protected-access

  def counted(checkpoint, items=checkpoints._ITEMS):  # pylint: disable=protected-access
    reads.append(tuple(items))
    return read(checkpoint, items)

  monkeypatch.setattr(checkpoints, '_read', counted)
  learners = {'pusher': _Restored(), 'crosser': _Restored()}
  assert checkpoints.restore(path, learners)['update'] == 3
  assert learners['pusher'].saved == (1.0, f'{path} (pusher)')
  assert learners['crosser'].saved == (2.0, f'{path} (crosser)')
  assert [items for items in reads if 'learners' in items] == [
      ('learners', 'state')]
  with pytest.raises(ValueError, match="no learner for species 'bee'"):
    checkpoints.restore(path, {**learners, 'bee': _Restored()})
