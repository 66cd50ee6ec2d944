"""A training run's directory: metrics.csv + TensorBoard, checkpoints.

Shared by the runners so that every run directory looks the same:

  metrics.csv, events.out.tfevents.*   one row per update (`MetricsLog`)
  checkpoints/ckpt_<update>.msgpack    the learner's state (`learner.save`)
  checkpoints/ckpt_<update>.json       the runner's counters, written last

`GracefulStop` turns the first Ctrl-C / SIGTERM into a request the training
loop polls, so a run can stop with a checkpoint instead of losing an update.
"""
import csv
import glob
import json
import math
import os
import signal
import threading


# --- Checkpoints -------------------------------------------------------------


def checkpoint_paths(logdir):
  """[(update, msgpack path, json path)] of complete checkpoints, oldest first."""
  out = []
  for meta in sorted(glob.glob(os.path.join(logdir, 'checkpoints',
                                            'ckpt_*.json'))):
    state = meta[:-len('.json')] + '.msgpack'
    if os.path.exists(state):
      out.append((int(os.path.basename(meta)[5:-5]), state, meta))
  return sorted(out)


def save_checkpoint(learner, logdir, counters, keep):
  """learner state + counters, each file atomic; keeps the newest `keep`."""
  base = os.path.join(logdir, 'checkpoints', f'ckpt_{counters["update"]:08d}')
  learner.save(base + '.msgpack')
  tmp = f'{base}.json.tmp-{os.getpid()}'
  with open(tmp, 'w') as f:
    json.dump(counters, f)
  os.replace(tmp, base + '.json')  # Written last: marks the pair complete.
  for _, state, meta in checkpoint_paths(logdir)[:-keep]:
    os.remove(meta)
    os.remove(state)


def restore_checkpoint(learner, logdir):
  """Restores the newest checkpoint; returns its counters."""
  paths = checkpoint_paths(logdir)
  if not paths:
    raise FileNotFoundError(f'No checkpoint in {logdir}/checkpoints.')
  _, state, meta = paths[-1]
  learner.restore(state)
  with open(meta) as f:
    return json.load(f)


# --- Logging -----------------------------------------------------------------


def _missing(value):
  return value is None or (isinstance(value, float) and math.isnan(value))


def logged_row(logdir, update):
  """The metrics.csv row of `update` as {column: float} (empty cells left
  out), or {} when there is none: what an export from a checkpoint reports."""
  path = os.path.join(logdir, 'metrics.csv')
  if not os.path.exists(path):
    return {}
  with open(path, newline='') as f:
    for row in csv.DictReader(f):
      if int(row['update']) == update:
        return {k: float(v) for k, v in row.items() if v != ''}
  return {}


class MetricsLog:
  """metrics.csv (+ TensorBoard events) with a fixed column list.

  Rows are dicts keyed by column, with at least 'update' and 'env_steps'
  (the TensorBoard step); None / NaN are written as empty cells and skipped
  in TensorBoard. On resume (`resume_update`), rows after that update are
  dropped from the CSV and purged from the events: they are redone.
  """

  def __init__(self, logdir, columns, resume_update=None):
    self._path = os.path.join(logdir, 'metrics.csv')
    self.columns = list(columns)
    rows = []
    if resume_update is not None and os.path.exists(self._path):
      with open(self._path, newline='') as f:
        rows = [r for r in csv.DictReader(f)
                if int(r['update']) <= resume_update]
    with open(self._path, 'w', newline='') as f:
      writer = csv.DictWriter(f, self.columns, extrasaction='ignore')
      writer.writeheader()
      writer.writerows(rows)
    self._file = open(self._path, 'a', newline='')
    self._csv = csv.DictWriter(self._file, self.columns, extrasaction='ignore')
    self._tb = None
    try:
      import tensorboardX  # pylint: disable=g-import-not-at-top
    except ImportError:
      return
    purge_step = None
    if resume_update is not None:
      purge_step = int(rows[-1]['env_steps']) + 1 if rows else 0
    self._tb = tensorboardX.SummaryWriter(logdir, purge_step=purge_step)

  def write(self, row):
    self._csv.writerow({k: '' if _missing(v) else v for k, v in row.items()})
    self._file.flush()
    if self._tb is not None:
      step = int(row['env_steps'])
      for name, value in row.items():
        if name not in ('update', 'env_steps') and not _missing(value):
          self._tb.add_scalar(name, float(value), step)

  def close(self):
    self._file.close()
    if self._tb is not None:
      self._tb.close()


class GracefulStop:
  """Context manager: the first SIGINT / SIGTERM sets `requested`, which the
  training loop polls (to checkpoint and stop); a second one interrupts at
  once. Only installs handlers in the main thread."""

  def __init__(self):
    self.requested = False
    self._previous = {}

  def __enter__(self):
    if threading.current_thread() is threading.main_thread():
      for sig in (signal.SIGINT, signal.SIGTERM):
        self._previous[sig] = signal.signal(sig, self._handle)
    return self

  def _handle(self, signum, frame):
    if self.requested:
      signal.signal(signum, self._previous.get(signum, signal.SIG_DFL))
      raise KeyboardInterrupt
    self.requested = True
    print('Stopping after this update (again to interrupt now).', flush=True)

  def __exit__(self, *exc):
    for sig, handler in self._previous.items():
      signal.signal(sig, handler)
