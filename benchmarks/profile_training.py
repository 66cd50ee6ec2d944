"""Where a running training's CPU goes: processes, and inside an actor.

    python benchmarks/profile_training.py [--seconds 25] [--driver PID]

For a `coop-train` (or `coop-paper`) already running on this machine, over
one window of `--seconds`:

1. the machine's CPU time by process: the Ray actors (`ray::RolloutWorker`),
   the driver (`--driver`, else the process whose command line runs
   coop-train, coop-paper, runners.train or runners.paper), Ray's own
   processes, everything else (other work, kernel threads) and the idle
   time, in cores (CPU seconds per second of the window);
2. the time by phase, sampled every 0.1 s: every actor running (at least
   half of the interval), some of them (the others have finished their
   rollout and wait), the driver alone (the learner's update, between
   rollouts), none; with the machine's idle cores in each;
3. one actor sampled by py-spy (`pip install py-spy`; it reads the process
   without stopping it) over the same window: the share of its samples in
   each function on the stack (inclusive), i.e. of the time it was running
   Python or the native code under it. MuJoCo's calls sit under
   `SubstepRunner.run`, the lower layer's under `Controller.act`.

It measures the real training (its policy's trajectories, its contention)
instead of a replay, so it needs nothing but the running process; the
sampling takes a few percent of one core ("this profile"). Processes that
start during the window (an actor Ray restarts) are not counted.
"""
import argparse
import collections
import os
import resource
import subprocess
import sys
import tempfile
import time

DRIVERS = ('coop-train', 'coop-paper', 'runners.train', 'runners.paper')
ACTOR = 'ray::RolloutWorker'
RAY_SERVERS = ('gcs_server', 'raylet')
INTERVAL = 0.1
"""Seconds between the phase samples."""
PHASES = ('every actor collecting', 'some actors collecting',
          'driver only (the learner)', 'none of them')


def _processes():
  """{pid: (name, command line)} of every process."""
  out = {}
  for pid in os.listdir('/proc'):
    if not pid.isdigit():
      continue
    try:
      with open(f'/proc/{pid}/cmdline', 'rb') as f:
        command = f.read().replace(b'\0', b' ').decode(errors='replace')
      with open(f'/proc/{pid}/comm') as f:
        name = f.read().strip()
    except OSError:
      continue
    out[int(pid)] = (name, command.strip() or f'[{name}]')
  return out


def _stat(pid):
  """The fields of /proc/<pid>/stat after the command's name (state,
  parent, ...), or None when the process is gone."""
  try:
    with open(f'/proc/{pid}/stat') as f:
      return f.read().rsplit(')', 1)[1].split()
  except (OSError, IndexError):
    return None


def _cpu_ticks(pids):
  """{pid: user + system clock ticks} of each pid still alive."""
  stats = {pid: _stat(pid) for pid in pids}
  return {pid: int(fields[11]) + int(fields[12])
          for pid, fields in stats.items() if fields}


def _idle_ticks():
  with open('/proc/stat') as f:
    fields = f.readline().split()[1:]
  return int(fields[3]) + int(fields[4])  # idle + iowait.


def _group(pid, name, command, driver):
  if command.startswith(ACTOR) or name.startswith('ray::RolloutWor'):
    return 'actors'
  if pid == driver:
    return 'driver'
  if (name in RAY_SERVERS or name.startswith('ray::')
      or '/site-packages/ray/' in command):
    return "Ray's processes"
  return 'other (incl. kernel)'


def _parent(pid):
  fields = _stat(pid)
  return int(fields[1]) if fields else None


def _find_driver(processes):
  """The process that started the local Ray instance (the parent of its
  GCS server and raylet) when its command line is a training's; else the
  one Python process whose command line is (wrappers such as `timeout` or
  a shell also name the command); else None."""
  def is_training(pid):
    return pid in processes and any(d in processes[pid][1] for d in DRIVERS)
  parents = {_parent(pid) for pid, (name, _) in processes.items()
             if name in RAY_SERVERS}
  found = sorted(pid for pid in parents if is_training(pid))
  if not found:
    found = sorted(pid for pid, (name, command) in processes.items()
                   if pid != os.getpid() and is_training(pid)
                   and (name.startswith('python') or name.startswith('coop-'))
                   and 'profile_training' not in command)
  return found[0] if len(found) == 1 else None


def _inclusive_shares(raw_path):
  """(samples, {function: samples with it on the stack}) of a py-spy raw
  file (one 'frame;frame;... count' line per stack)."""
  total, inclusive = 0, collections.Counter()
  with open(raw_path) as f:
    for line in f:
      stack, _, count = line.rstrip('\n').rpartition(' ')
      if not stack:
        continue
      total += int(count)
      for function in {frame.split(' (')[0] for frame in stack.split(';')}:
        inclusive[function] += int(count)
  return total, inclusive


def _phases(spy, actors, driver, hz):
  """Until `spy` ends, every `INTERVAL`: which of the training's processes
  ran at least half of the interval, and the machine's idle CPU meanwhile.
  Returns {phase: [seconds, idle CPU seconds]}."""
  out = {phase: [0.0, 0.0] for phase in PHASES}
  pids = [*actors, driver]
  last, last_idle = _cpu_ticks(pids), _idle_ticks()
  last_time = time.perf_counter()
  while spy.poll() is None:
    time.sleep(INTERVAL)
    ticks, idle, now = _cpu_ticks(pids), _idle_ticks(), time.perf_counter()
    seconds = now - last_time
    busy = {pid: (ticks.get(pid, 0) - last.get(pid, 0)) / hz >= seconds / 2
            for pid in pids}
    running = sum(busy[pid] for pid in actors)
    if running == len(actors):
      phase = PHASES[0]
    elif running:
      phase = PHASES[1]
    else:
      phase = PHASES[2] if busy[driver] else PHASES[3]
    out[phase][0] += seconds
    out[phase][1] += (idle - last_idle) / hz
    last, last_idle, last_time = ticks, idle, now
  return out


def _own_cpu_seconds():
  """CPU seconds of this process and its reaped children (py-spy)."""
  return sum(r.ru_utime + r.ru_stime for r in (
      resource.getrusage(resource.RUSAGE_SELF),
      resource.getrusage(resource.RUSAGE_CHILDREN)))


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--seconds', type=float, default=25.0)
  parser.add_argument('--rate', type=int, default=50,
                      help="py-spy's samples per second")
  parser.add_argument('--driver', type=int, default=None,
                      help='the training process (default: found by name)')
  parser.add_argument('--top', type=int, default=20,
                      help='functions of the actor to print')
  args = parser.parse_args(argv)
  processes = _processes()
  actors = sorted(pid for pid, (name, command) in processes.items()
                  if _group(pid, name, command, None) == 'actors')
  if not actors:
    sys.exit(f'No {ACTOR} process is running: start a training first '
             '(coop-train with --actors >= 1).')
  driver = args.driver or _find_driver(processes)
  if driver is None:
    print('No single training process found (give --driver PID): the '
          "driver's share is counted under 'other'.", file=sys.stderr)
  hz = os.sysconf('SC_CLK_TCK')
  with tempfile.TemporaryDirectory() as tmp:
    raw_path = os.path.join(tmp, 'actor.raw')
    try:
      spy = subprocess.Popen(
          ['py-spy', 'record', '--pid', str(actors[0]), '--duration',
           str(max(1, round(args.seconds))), '--rate', str(args.rate),
           '--nonblocking', '--format', 'raw', '-o', raw_path],
          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    except FileNotFoundError:
      sys.exit('py-spy is not installed: pip install py-spy')
    processes = {pid: p for pid, p in _processes().items()
                 if pid not in (os.getpid(), spy.pid)}  # Counted apart.
    before, idle_before = _cpu_ticks(processes), _idle_ticks()
    own_before = _own_cpu_seconds()
    begin = time.perf_counter()
    phases = _phases(spy, actors, driver, hz)
    _, error = spy.communicate()
    window = time.perf_counter() - begin
    after, idle_after = _cpu_ticks(processes), _idle_ticks()
    own = _own_cpu_seconds() - own_before
    if spy.returncode or not os.path.exists(raw_path):
      sys.exit(f'py-spy failed ({spy.returncode}): {error.strip()}')
    total, inclusive = _inclusive_shares(raw_path)
  cores = collections.Counter()
  for pid in after.keys() & before.keys():
    name, command = processes[pid]
    cores[_group(pid, name, command, driver)] += (
        (after[pid] - before[pid]) / hz / window)
  cores['this profile (with py-spy)'] = own / window
  cores['idle'] = (idle_after - idle_before) / hz / window
  print(f'{os.cpu_count()} CPUs, {window:.1f} s window; {len(actors)} '
        f'actors, driver {driver}')
  print('cores used (CPU seconds per second):')
  for group in ('actors', 'driver', "Ray's processes",
                'other (incl. kernel)', 'this profile (with py-spy)', 'idle'):
    per_actor = (f'  ({cores[group] / len(actors):.2f} per actor)'
                 if group == 'actors' else '')
    print(f'  {group:26s} {cores[group]:5.2f}{per_actor}')
  sampled = sum(seconds for seconds, _ in phases.values()) or 1.0
  print(f'time by phase (sampled every {INTERVAL} s), idle cores in it:')
  for phase, (seconds, idle) in phases.items():
    print(f'  {phase:27s} {seconds / sampled:5.2f} of the time, '
          f'{idle / seconds if seconds else 0.0:4.2f} idle cores')
  print(f'actor {actors[0]}: {total} samples in {window:.0f} s '
        f'({total / (args.rate * window):.2f} of the window running); '
        'share of them with the function on the stack:')
  for function, samples in inclusive.most_common(args.top):
    print(f'  {samples / total:5.3f}  {function}')


if __name__ == '__main__':
  main()
