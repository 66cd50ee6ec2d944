"""Where a running training's CPU goes: processes, and inside an actor.

    python benchmarks/profile_training.py [--seconds 25] [--driver PID]

For a `coop-train` (or `coop-paper`) already running on this machine, over
one window of `--seconds`:

1. the machine's CPU time by process: the Ray actors (`ray::RolloutWorker`),
   the driver (`--driver`, else the process whose command line runs
   coop-train, coop-paper, runners.train or runners.paper), Ray's own
   processes, everything else (other work, kernel threads) and the idle
   time, in cores (CPU seconds per second of the window);
2. one actor sampled by py-spy (`pip install py-spy`; it reads the process
   without stopping it) over the same window: the share of its samples in
   each function on the stack (inclusive), i.e. of the time it was running
   Python or the native code under it. MuJoCo's calls sit under
   `SubstepRunner.run`, the lower layer's under `Controller.act`.

It measures the real training (its policy's trajectories, its contention)
instead of a replay, so it needs nothing but the running process; it takes
a little of one core for the sampling.
"""
import argparse
import collections
import os
import subprocess
import sys
import tempfile
import time

DRIVERS = ('coop-train', 'coop-paper', 'runners.train', 'runners.paper')
ACTOR = 'ray::RolloutWorker'


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


def _cpu_ticks(pids):
  """{pid: user + system clock ticks} of each pid still alive."""
  out = {}
  for pid in pids:
    try:
      with open(f'/proc/{pid}/stat') as f:
        fields = f.read().rsplit(')', 1)[1].split()
      out[pid] = int(fields[11]) + int(fields[12])
    except (OSError, IndexError):
      continue
  return out


def _idle_ticks():
  with open('/proc/stat') as f:
    fields = f.readline().split()[1:]
  return int(fields[3]) + int(fields[4])  # idle + iowait.


def _group(pid, name, command, driver):
  if name == 'py-spy':
    return 'this profile (py-spy)'
  if command.startswith(ACTOR) or name.startswith('ray::RolloutWor'):
    return 'actors'
  if pid == driver:
    return 'driver'
  if 'ray' in command.split(' ')[0] or '/ray/' in command or name.startswith(
      'ray::'):
    return "Ray's processes"
  return 'other (incl. kernel)'


def _find_driver(processes):
  own = os.getpid()
  found = [pid for pid, (_, command) in processes.items()
           if pid != own and 'profile_training' not in command
           and any(d in command for d in DRIVERS)]
  return min(found) if found else None


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
    processes = _processes()  # With py-spy.
    before, idle_before = _cpu_ticks(processes), _idle_ticks()
    begin = time.perf_counter()
    _, error = spy.communicate()
    window = time.perf_counter() - begin
    after, idle_after = _cpu_ticks(processes), _idle_ticks()
    if spy.returncode or not os.path.exists(raw_path):
      sys.exit(f'py-spy failed ({spy.returncode}): {error.strip()}')
    total, inclusive = _inclusive_shares(raw_path)
  cores = collections.Counter()
  for pid in after.keys() & before.keys():
    name, command = processes[pid]
    cores[_group(pid, name, command, driver)] += (
        (after[pid] - before[pid]) / hz / window)
  cores['idle'] = (idle_after - idle_before) / hz / window
  print(f'{os.cpu_count()} CPUs, {window:.1f} s window; {len(actors)} '
        f'actors, driver {driver}')
  print('cores used (CPU seconds per second):')
  for group in ('actors', 'driver', "Ray's processes",
                'other (incl. kernel)', 'this profile (py-spy)', 'idle'):
    per_actor = (f'  ({cores[group] / len(actors):.2f} per actor)'
                 if group == 'actors' else '')
    print(f'  {group:22s} {cores[group]:5.2f}{per_actor}')
  print(f'actor {actors[0]}: {total} samples in {window:.0f} s '
        f'({total / (args.rate * window):.2f} of the window running); '
        'share of them with the function on the stack:')
  for function, samples in inclusive.most_common(args.top):
    print(f'  {samples / total:5.3f}  {function}')


if __name__ == '__main__':
  main()
