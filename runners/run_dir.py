"""A training run's directory: one writer, crash-safe files, metrics.

Shared by the runners so that every run directory looks the same:

  writer.lock                          held by the run's one writer (`RunLock`)
  metrics.csv, events.out.tfevents.*   one row per update (`MetricsLog`)
  metrics.csv.gz                       instead of metrics.csv in a copy of a
                                       run whose file is large (`pack_metrics`)
  checkpoints/<update>/                orbax checkpoints (`runners.checkpoints`)

Every write survives a kill at any instant: files (`write_file`) and
directories (`write_directory`) are written under a temporary name ending in
`.tmp-<pid>` and renamed into place; a directory that replaces another
(`replace_directory`) moves the old one aside to `.old-<pid>` first, and
`recover_directory` puts it back if the writer died between the two renames.
Leftovers are removed only once their writer's process is gone
(`remove_stale`). These are the project's only writers of whole files and
directories; checkpoints go through orbax, which finalises its own.

`GracefulStop` turns the first Ctrl-C / SIGTERM (or a deadline passing) into a
request the training loop polls, so a run can stop with a checkpoint instead
of losing an update.
"""
import csv
import errno
import fcntl
import glob
import gzip
import io
import math
import os
import re
import shutil
import signal
import socket
import threading
import time
from typing import Optional

LOCK_FILE = 'writer.lock'
_LEFTOVER = re.compile(r'\.(tmp|old)-(\d+)$')


# --- One writer per run directory --------------------------------------------


class RunInUseError(RuntimeError):
  """Another live process is writing to the run directory (its pid and
  host in `holder`)."""

  holder = 'unknown'


class RunLock:
  """Context manager: exclusive writer of `logdir` for the whole run.

  An advisory `flock` on `<logdir>/writer.lock`, which holds the writer's
  pid and host. The kernel drops it when the process dies, however it dies,
  so a crashed run never blocks the next one. Creates `logdir`; if that
  directory was new and nothing but the lock was written into it (the run
  failed while setting up), it is removed again on exit.
  """

  def __init__(self, logdir: str):
    self._logdir = logdir
    self._path = os.path.join(logdir, LOCK_FILE)
    self._file = None
    self._created = False

  def __enter__(self):
    self._created = not os.path.isdir(self._logdir)
    while True:
      os.makedirs(self._logdir, exist_ok=True)
      try:
        handle = open(self._path, 'a+')  # pylint: disable=consider-using-with
      except FileNotFoundError:  # Its holder's `__exit__` removed it all.
        continue
      try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
      except OSError as e:
        handle.seek(0)
        holder = handle.read().strip() or 'unknown'
        handle.close()
        if e.errno not in (errno.EAGAIN, errno.EACCES):
          raise
        error = RunInUseError(
            f'{self._logdir} is being written by another run (pid, host: '
            f'{holder}); wait for it to finish, stop it, or choose another '
            '--logdir.')
        error.holder = holder
        raise error from None
      # The file may have been removed (by `__exit__` of a run that set up
      # nothing) between our open and our lock: then lock the new one.
      try:
        if os.stat(self._path).st_ino == os.fstat(handle.fileno()).st_ino:
          break
      except FileNotFoundError:
        pass
      handle.close()
    handle.seek(0)
    handle.truncate()
    handle.write(f'{os.getpid()} {socket.gethostname()}\n')
    handle.flush()
    self._file = handle
    return self

  def __exit__(self, *exc):
    if self._created and os.listdir(self._logdir) == [LOCK_FILE]:
      os.remove(self._path)  # Still locked: no one can hold a stale inode.
      try:
        os.rmdir(self._logdir)
      except OSError:  # Another process has locked a new file in it.
        pass
    self._file.close()  # Releases the lock.
    self._file = None


def lock_holder(logdir: str) -> str:
  """Who holds `logdir`'s `RunLock`: the '<pid> <host>' it wrote, or ''
  when no process does. Asks with a shared lock taken and dropped at once:
  a `RunLock` tried in that instant is refused as if held, so this is for
  locks whose refusal only defers work (coop-paper's claims), not for a
  run directory whose training would then fail."""
  try:
    handle = open(os.path.join(logdir, LOCK_FILE))  # pylint: disable=consider-using-with
  except FileNotFoundError:
    return ''
  with handle:
    try:
      fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError as e:
      if e.errno not in (errno.EAGAIN, errno.EACCES):
        raise
      return handle.read().strip() or 'unknown'
    fcntl.flock(handle, fcntl.LOCK_UN)
  return ''


# --- Crash-safe writes --------------------------------------------------------


def _alive(pid: int) -> bool:
  try:
    os.kill(pid, 0)
  except ProcessLookupError:
    return False
  except PermissionError:
    return True
  return True


def _leftovers(final: str):
  """[(path, kind 'tmp'/'old', pid)] left next to `final` by writers."""
  out = []
  for path in glob.glob(glob.escape(final) + '.*-*'):
    match = _LEFTOVER.search(path)
    if match and path[:match.start()] == final:
      out.append((path, match.group(1), int(match.group(2))))
  return out


def _remove(path: str) -> None:
  if os.path.isdir(path) and not os.path.islink(path):
    shutil.rmtree(path, ignore_errors=True)
  elif os.path.lexists(path):
    os.remove(path)


def recover_directory(final: str) -> None:
  """Puts back the directory `final` if a writer died while replacing it.

  `replace_directory` moves the old `final` to `final.old-<pid>` before it
  renames the new one in; a writer killed in between leaves no `final`.
  Only leftovers of dead writers are touched.
  """
  for path, kind, pid in _leftovers(final):
    if kind == 'old' and pid != os.getpid() and not _alive(pid):
      if os.path.exists(final):
        _remove(path)
      else:
        os.replace(path, final)


def replace_directory(tmp: str, final: str) -> None:
  """Renames the complete directory `tmp` to `final`, replacing any earlier
  `final` so that a kill at any instant leaves one of the two in place (or
  recoverable with `recover_directory`)."""
  recover_directory(final)
  old = f'{final}.old-{os.getpid()}'
  if os.path.exists(final):
    _remove(old)
    os.replace(final, old)
  os.replace(tmp, final)
  _remove(old)


def _write_synced(path: str, data) -> None:
  with open(path, 'w' if isinstance(data, str) else 'wb') as f:
    f.write(data)
    f.flush()
    os.fsync(f.fileno())


def write_file(path: str, data) -> None:
  """Writes `data` (bytes or str) to `path` whole (a temporary file, synced
  and renamed into place), replacing an earlier one; creates its folder."""
  os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
  tmp = f'{path}.tmp-{os.getpid()}'
  _write_synced(tmp, data)
  os.replace(tmp, path)


def write_directory(final: str, files) -> None:
  """Writes {name: bytes} as the directory `final`, atomically (all files
  or none), replacing an earlier one."""
  tmp = f'{final}.tmp-{os.getpid()}'
  _remove(tmp)
  os.makedirs(tmp)
  for name, data in files.items():
    _write_synced(os.path.join(tmp, name), data)
  replace_directory(tmp, final)


def remove_stale(directory: str, name: str = '') -> None:
  """Removes `.tmp-<pid>` / `.old-<pid>` leftovers in `directory` (only
  `name`'s, if given) whose writer is dead (never a live writer's work in
  progress); an `.old-` whose directory is missing is put back instead.
  Whether a writer lives is asked of this machine: where processes of
  other machines write into `directory` too, give the `name` that only
  this process writes."""
  pattern = (glob.escape(name) if name else '*') + '.*-*'
  for path in glob.glob(os.path.join(glob.escape(directory), pattern)):
    match = _LEFTOVER.search(path)
    if not match:
      continue
    pid = int(match.group(2))
    if pid == os.getpid() or _alive(pid):
      continue
    if match.group(1) == 'old':
      recover_directory(path[:match.start()])
    else:
      _remove(path)


# --- Logging -----------------------------------------------------------------


def _missing(value):
  return value is None or (isinstance(value, float) and math.isnan(value))


METRICS = 'metrics.csv'
"""A run's one row per update (`MetricsLog`)."""
PACKED_METRICS = METRICS + '.gz'
"""`METRICS` gzipped, in a copy of a run (`pack_metrics`)."""
PACK_ABOVE = 4 * 2 ** 20
"""Bytes of metrics.csv above which a copy keeps it gzipped: a `flat` run
logs a row every 1,024 env steps, ~6 MB over 12M steps, and no committed
file may pass 5 MB."""


def metrics_path(logdir):
  """`logdir`'s metrics.csv, or its `PACKED_METRICS` when that is what the
  folder holds."""
  path = os.path.join(logdir, METRICS)
  packed = os.path.join(logdir, PACKED_METRICS)
  return packed if not os.path.exists(path) and os.path.exists(packed) else path


def has_metrics(logdir):
  """Whether `logdir` holds a metrics.csv (plain or packed)."""
  return os.path.exists(metrics_path(logdir))


def pack_metrics(folder):
  """Gzips `folder`'s metrics.csv (a copy of a run's, `runners.paper`'s
  published and stashed runs) in place when it is over `PACK_ABOVE` bytes;
  the same rows give the same bytes."""
  path = os.path.join(folder, METRICS)
  if os.path.getsize(path) <= PACK_ABOVE:
    return
  packed = io.BytesIO()
  with open(path, 'rb') as f, gzip.GzipFile(
      fileobj=packed, mode='wb', mtime=0, filename='') as out:
    shutil.copyfileobj(f, out)
  write_file(os.path.join(folder, PACKED_METRICS), packed.getvalue())
  os.remove(path)


def unpack_metrics(logdir):
  """Makes a run directory copied from a packed copy (`pack_metrics`)
  writable again: its metrics.csv from `PACKED_METRICS`, which goes."""
  packed = os.path.join(logdir, PACKED_METRICS)
  if os.path.exists(packed):
    with gzip.open(packed, 'rb') as f:
      write_file(os.path.join(logdir, METRICS), f.read())
    os.remove(packed)


def read_metrics(logdir):
  """Rows of `logdir`'s metrics.csv (`MetricsLog`'s; plain or packed,
  `metrics_path`) as dicts of floats, empty and non-numeric cells
  dropped."""
  rows = []
  path = metrics_path(logdir)
  with (gzip.open(path, 'rt', newline='') if path.endswith('.gz')
        else open(path, newline='')) as f:
    for row in csv.DictReader(f):
      parsed = {}
      for key, value in row.items():
        try:
          parsed[key] = float(value)
        except (TypeError, ValueError):
          continue
      rows.append(parsed)
  return rows


def logged_row(logdir, update):
  """The metrics.csv row of `update` as {column: float} (`read_metrics`'s),
  or {} when there is none: what an export from a checkpoint reports."""
  if not has_metrics(logdir):
    return {}
  return next((row for row in read_metrics(logdir)
               if row.get('update') == update), {})


class MetricsLog:
  """metrics.csv (+ TensorBoard events) with a fixed column list.

  Rows are dicts keyed by column, with at least 'update' and 'env_steps'
  (the TensorBoard step); None / NaN are written as empty cells and skipped
  in TensorBoard. On resume (`resume_update`), rows after that update are
  dropped from the CSV and purged from the events: they are redone.
  """

  def __init__(self, logdir, columns, resume_update=None):
    self._path = os.path.join(logdir, METRICS)
    self.columns = list(columns)
    rows = []
    if resume_update is not None and os.path.exists(self._path):
      with open(self._path, newline='') as f:
        rows = [r for r in csv.DictReader(f)
                if int(r['update']) <= resume_update]
    # The kept rows go to a new file that replaces the old one: a kill
    # while writing leaves the old file whole.
    kept = io.StringIO(newline='')
    writer = csv.DictWriter(kept, self.columns, extrasaction='ignore')
    writer.writeheader()
    writer.writerows(rows)
    write_file(self._path, kept.getvalue())
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


DEADLINE = 'deadline'
"""`GracefulStop.reason` when its deadline, not a signal, stopped the run."""

clock = time.monotonic
"""The clock of `GracefulStop`'s deadlines (seconds): whoever sets one
reads this clock (`coop-paper --hours`)."""


class GracefulStop:
  """Context manager: the first SIGINT / SIGTERM, or `clock()` passing
  `deadline` (None for none), sets `requested`, which the training loop
  polls (to checkpoint and stop); a second signal interrupts at once. Only
  installs handlers in the main thread."""

  def __init__(self, deadline: Optional[float] = None):
    self._signalled = False
    self.reason = None
    """What requested the stop: the signal's name ('SIGTERM'...) or
    `DEADLINE`."""
    self.deadline = deadline
    self._previous = {}

  @property
  def requested(self) -> bool:
    if (self.reason is None and self.deadline is not None
        and clock() >= self.deadline):
      self.reason = DEADLINE
      print('Time limit reached: stopping with a checkpoint.', flush=True)
    return self.reason is not None

  def __enter__(self):
    if threading.current_thread() is threading.main_thread():
      for sig in (signal.SIGINT, signal.SIGTERM):
        self._previous[sig] = signal.signal(sig, self._handle)
    return self

  def _handle(self, signum, frame):
    if self._signalled:
      signal.signal(signum, self._previous.get(signum, signal.SIG_DFL))
      raise KeyboardInterrupt
    # After the deadline too, the first signal (e.g. a job's scheduler
    # ending it) lets the checkpoint finish.
    self._signalled = True
    self.reason = self.reason or signal.Signals(signum).name
    print(f'{signal.Signals(signum).name}: stopping after this update '
          '(again to interrupt now).', flush=True)

  def __exit__(self, *exc):
    for sig, handler in self._previous.items():
      signal.signal(sig, handler)
