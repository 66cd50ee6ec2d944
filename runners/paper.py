"""Runs the paper's experiment plan cell by cell: `coop-paper`.

    coop-paper --dry-run                      # the plan, each cell's status
    coop-paper                                # train + evaluate what is missing
    coop-paper --only transport/hrl --budget 200000   # a quick subset
    coop-paper --report --docs docs/results.md        # the tables, no training

The plan (`runners.paper_plan.PLAN`) is data: task x variant x population x
seed, with budgets and flags. A cell is done when `--results`/<cell>/ holds
its metrics.csv (metrics.csv.gz when over `run_dir.PACK_ABOVE` bytes, as
a `flat` cell's), its final checkpoint's policy (with the lower layer it was
trained with) and one `eval_n<N>.json` per evaluated population; done cells
are skipped, so the committed results are the plan's memory across sessions.
A cell whose run directory (`--runs`/<cell>/) has a checkpoint continues
from it (`coop-train --resume`), one whose training has finished is only
evaluated. Evaluation is the paper's protocol: the final checkpoint,
`--episodes` (100) episodes from seed `--eval-seed` (1000), which training
never uses. Training and evaluation run in this process
(`learner_loop.train`, `evaluate.evaluate`); with `--concurrent N`, N
cells at a time, each in a process of its own (`run_concurrently`).
Ctrl-C / SIGTERM stop the running cell after a checkpoint (exit status 128
+ the signal's number); run the same command again to continue.
`coop-paper --stash` copies unfinished runs into `--partial`
(results/paper_partial) to be committed at the end of a session; the
next session's `coop-paper` resumes from them. `--hours H` does both by
itself when H hours are up (a session's or a cluster job's time limit):
the cell stops with a checkpoint, is stashed, and coop-paper exits with
status 75 (`EXIT_OUT_OF_TIME`). coop-paper processes that share `--runs`
and `--results` (on one machine, or on several over a shared file system)
share the plan: each claims a cell before running it (`claim`) and passes
over the cells another one runs, exiting with status 3
(`EXIT_RUN_ELSEWHERE`) if one of those is still not done at its end. See
docs/paper.md.
"""
import contextlib
import csv
import dataclasses
import json
import math
import os
import shutil
import signal
import statistics
import sys
import time
from typing import Callable, Optional

from agents import fields
from runners import cli
from runners import paper_plan
from runners import run_dir

EVAL_FILE = 'eval_n{}.json'
EXIT_OUT_OF_TIME = 75
"""`coop-paper`'s exit status when `--hours` ran out (sysexits' EX_TEMPFAIL:
run it again)."""
EXIT_RUN_ELSEWHERE = 3
"""`coop-paper`'s exit status when it ran every selected cell it could but
passed over cells that other coop-paper processes run (`claim`): run it
again once they have ended."""
ELSEWHERE = 'elsewhere'
"""What `run_plan` returns when it passed over such cells."""
CLAIMS = '.claims'
"""`--runs`/.claims/<cell>/: the lock (`run_dir.RunLock`) that a coop-paper
process holds on a cell from before it trains it until it is published or
stashed (`claim`)."""


@dataclasses.dataclass(frozen=True)
class PaperArgs:
  """What to run of the paper's plan (every field is a `coop-paper` flag)."""

  only: tuple[str, ...] = ()
  """Cells to consider: task/variant[/stage]/n<N>/s<seed> paths or
  prefixes (transport/hrl, corridor/*/n6) or cell names; empty for all."""
  budget: int = fields.field(0, fields.NON_NEGATIVE)
  """Environment steps per cell instead of the plan's (quick runs); 0 keeps
  the plan's."""
  dry_run: bool = False
  """Print the plan with each cell's status and estimated wall time (and
  the pace of the cells running now); run nothing."""
  report: bool = False
  """Print the tables built from the committed results; run nothing."""
  docs: str = ''
  """With --report: write the tables into the block between
  '<!-- paper:begin -->' and '<!-- paper:end -->' of this markdown file
  (appended if absent) instead of printing them."""
  json: str = ''
  """With --report: also write every evaluation in marl-eval's JSON layout
  to this file."""
  figures: str = ''
  """With --report: also draw the learning curves of the committed cells
  (training success and return, mean +- s.e. over each configuration's
  models) as PNGs into this folder, linked from the tables' text."""
  results: str = 'results/paper'
  """Committed results: one folder per done cell."""
  runs: str = 'runs/paper'
  """Run directories of the cells being trained (checkpoints, events)."""
  partial: str = 'results/paper_partial'
  """Committed unfinished runs (`--stash`): one resumable folder per cell,
  so a session that ends mid-run hands its cell to the next one."""
  stash: bool = False
  """Copy every selected unfinished run's newest checkpoint, metrics.csv
  and lower layer into `--partial`/<cell>/ (commit them); train nothing.
  A later `coop-paper` resumes from there when `--runs` has no checkpoint
  of the cell."""
  baselines: str = 'results/baselines'
  """The difficulty references printed beside the learned figures."""
  actors: int = fields.field(2, fields.NON_NEGATIVE)
  """Actor processes per training run (0: one process, no Ray). They
  share a cell's environment copies per update (`Cell.copies`, 32), so
  the number must divide it: the update, and so the cell, is the same
  with 1, 2, 4, 8, 16 or 32 actors."""
  ray_address: str = ''
  """Join this Ray cluster (as coop-train --ray-address)."""
  episodes: int = fields.field(paper_plan.EPISODES, fields.COUNT)
  """Evaluation episodes per model and population."""
  eval_seed: int = paper_plan.EVAL_SEED
  """Evaluation seed (never used in training)."""
  eval_envs: int = fields.field(10, fields.COUNT)
  """Environment copies stepped together while evaluating."""
  progress: bool = True
  """Progress bar while training."""
  concurrent: int = fields.field(1, fields.COUNT)
  """Cells trained at the same time, each in a process of its own (a cell
  waits for the stage cells it starts from). A training leaves cores idle
  while its learner updates (on 2 cores a fifth of its wall time), which
  another cell's training fills: on the 2-core machine `--concurrent 2
  --actors 0` trains more of the plan per hour than one cell at a time
  with 2 actors (~25%: docs/performance.md, `benchmarks/concurrent_runs.py`),
  each cell taking ~1.6x as long. With --actors above 0 every
  process would start a Ray of its own, so that needs --ray-address (or
  RAY_ADDRESS: one cluster for all)."""
  hours: float = fields.field(0.0, fields.NON_NEGATIVE)
  """Wall-clock hours for this command, 0 for no limit (a session's or a
  cluster job's time, less a margin). When they are up, the cell being
  trained stops after its update with a checkpoint and is stashed (as
  --stash), and no other cell starts: commit --partial and run the same
  command again to continue. A cell whose training ends in time is still
  evaluated (minutes)."""
  finish_within: float = fields.field(0.0, fields.NON_NEGATIVE)
  """Minutes past --hours that a cell it stops may take to finish: one
  whose rest of training and evaluations fit in what is left of them at
  the pace it measures (`finishes_within`) trains on, its training
  stopped at the latest M minutes after --hours, and is evaluated and
  published instead of stashed (a signal meanwhile stops and stashes it).
  The evaluations have no deadline and may take longer than estimated:
  leave M minutes and a margin of the session after --hours. 0: none."""

  def __post_init__(self):
    fields.check(self)
    object.__setattr__(self, 'only', tuple(self.only))


def budget(cell: paper_plan.Cell, args: PaperArgs) -> int:
  return args.budget or cell.budget


def run_directory(cell: paper_plan.Cell, args: PaperArgs) -> str:
  return os.path.join(args.runs, cell.name)


def results_directory(cell: paper_plan.Cell, args: PaperArgs) -> str:
  return os.path.join(args.results, cell.name)


def stage_directories(cell: paper_plan.Cell, args: PaperArgs
                      ) -> list[tuple[str, str]]:
  """(species, results folder of the stage cell it starts from) of each
  species the cell's run starts from (`Cell.init_from`)."""
  return [(species, os.path.join(args.results, name))
          for species, name in cell.init_from]


def claim_directory(cell: paper_plan.Cell, args: PaperArgs) -> str:
  """Where the lock of the cell's claim (`claim`) goes."""
  return os.path.join(args.runs, CLAIMS, cell.name)


def partial_directory(cell: paper_plan.Cell, args: PaperArgs) -> str:
  return os.path.join(args.partial, cell.name)


def train_args(cell: paper_plan.Cell, args: PaperArgs, resume: bool = False):
  """The cell's `TrainArgs` (its `coop-train` command)."""
  from runners import config as config_lib  # pylint: disable=g-import-not-at-top
  values = {'task': cell.task, 'agent': cell.agent,
            'n_agents': cell.n_agents, 'seed': cell.seed,
            'total_steps': budget(cell, args),
            'logdir': run_directory(cell, args), 'actors': args.actors,
            'envs_per_actor': config_lib.envs_per_actor(
                cell.copies, args.actors,
                f'the {cell.copies} environment copies of an update of '
                f'{cell.path}'),
            'ray_address': args.ray_address, 'progress': args.progress,
            'resume': resume}
  if cell.stage:
    values['stage'] = cell.stage
  if cell.init_from:
    values['init_from'] = tuple(f'{species}={folder}' for species, folder
                                in stage_directories(cell, args))
  # A flag may not change what the cell's own fields (or this command's)
  # set: the cell would not be the run its name and path say.
  own = set(values) | {'stage', 'init_from'}
  clash = sorted(set(dict(cell.flags)) & own)
  if clash:
    raise ValueError(f'{cell.path}: its flags set {", ".join(clash)}, which '
                     'the cell\'s own fields and coop-paper\'s options set; '
                     'give them there, not in Cell.flags '
                     '(runners/paper_plan.py).')
  values.update(cell.flags)
  return config_lib.train_args(**values)


def command(cell: paper_plan.Cell, args: PaperArgs) -> str:
  """The `coop-train` command that trains the cell."""
  return cli.command_line(train_args(cell, args), 'coop-train',
                          skip=('progress', 'resume'))


def eval_flags(args: PaperArgs) -> str:
  """`coop-eval`'s flags of the paper's protocol (`--envs` too: the same
  seeds give the same episodes only with the same count)."""
  return (f'--episodes {args.episodes} --seeds {args.eval_seed} '
          f'--envs {args.eval_envs}')


def eval_command(cell: paper_plan.Cell, n_agents: int,
                 args: PaperArgs) -> str:
  """The `coop-eval` command of one evaluation of the cell's result."""
  words = [f'coop-eval --checkpoint {results_directory(cell, args)}',
           eval_flags(args)]
  if n_agents != cell.n_agents:
    words.append(f'--n-agents {n_agents}')
  return ' '.join(words)


@dataclasses.dataclass(frozen=True)
class Status:
  """Where a cell stands: 'done' (results committed), 'trained' (final
  checkpoint, not yet evaluated), 'partial' (a checkpoint short of the
  budget), 'todo', or 'foreign' (its run directory or stash holds a run of
  other settings, which `problem` names; nothing is run over it)."""
  state: str
  env_steps: int = 0
  problem: str = ''

  def describe(self, total: int) -> str:
    if self.state == 'partial':
      return f'partial {progress(self.env_steps, total)}'
    return self.state


def progress(env_steps: int, total: int) -> str:
  """A run's env steps against its budget: '8.04M/15M'."""
  return f'{env_steps / 1e6:.2f}M/{total / 1e6:g}M'


def is_done(cell: paper_plan.Cell, args: PaperArgs) -> bool:
  """Whether the cell's results are all in `--results`."""
  folder = results_directory(cell, args)
  return run_dir.has_metrics(folder) and all(
      os.path.exists(os.path.join(folder, EVAL_FILE.format(n)))
      for n in cell.populations)


def status(cell: paper_plan.Cell, args: PaperArgs) -> Status:
  """The cell's `Status`, from `--results` and its run directory."""
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  if is_done(cell, args):
    return Status('done')
  logdir = run_directory(cell, args)
  if not checkpoints.list_checkpoints(logdir):
    logdir = partial_directory(cell, args)  # A stashed run, if any.
    if not checkpoints.list_checkpoints(logdir):
      return Status('todo')
  saved = checkpoints.read_state(checkpoints.resolve(logdir))
  steps = saved['env_steps']
  differs = other_settings(cell, args, saved.get('args'))
  if differs:
    return Status('foreign', steps, f'{logdir} is not a run of cell '
                  f'{cell.path}: {differs} Move it away (or give coop-paper '
                  'other --runs).')
  return Status('trained' if steps >= budget(cell, args) else 'partial',
                steps)


def other_settings(cell: paper_plan.Cell, args: PaperArgs,
                   saved: Optional[dict]) -> str:
  """How a run (its saved `TrainArgs` dict) differs from the cell's, or ''
  when it is the cell's: the same settings as `coop-train --resume`
  requires, and started from the cell's own stage cells (a run trained
  before the plan changed is not taken for a cell of the new plan). None
  (a format-1 state saved no settings) compares as the cell's."""
  from runners import config as config_lib  # pylint: disable=g-import-not-at-top
  if saved is None:
    return ''
  current = train_args(cell, args)  # Its errors (--actors) are the command's.
  try:
    config_lib.check_resumable(saved, current)
  except ValueError as error:
    return str(error)
  started = config_lib.TrainArgs.from_dict(saved).init_sources()
  stages = dict(cell.init_from)
  if set(started) != set(stages) or any(  # Its stage cell's folder.
      stages[s] not in os.path.normpath(path).split(os.sep)
      for s, path in started.items()):
    return (f'the run started from {started or "scratch"}, the cell from '
            f'{stages or "scratch"}.')
  return ''


def selected(args: PaperArgs, plan=None) -> list[paper_plan.Cell]:
  cells = [c for c in (paper_plan.PLAN if plan is None else plan)
           if c.matches(args.only)]
  if not cells:
    raise ValueError(f'--only {" ".join(args.only)} selects no cell of the '
                     'plan; coop-paper --dry-run lists them.')
  return cells


PACE_WINDOW = 600.0
"""Seconds of a cell's latest updates that its pace is taken over
(metrics.csv's `wall_time`, `window_pace`); a metrics.csv not written for
this long is not taken as running (`measured_pace`)."""


def window_pace(rows: list[dict]) -> Optional[float]:
  """The env steps/s of metrics.csv `rows` over their last `PACE_WINDOW`
  seconds of updates (env steps over the updates' wall time, which leaves
  out the ~1-2% between updates), or None without 3 rows in that window."""
  rows = [r for r in rows if 'env_steps' in r and 'wall_time' in r]
  window = [r for r in rows
            if rows[-1]['wall_time'] - r['wall_time'] <= PACE_WINDOW]
  if len(window) < 3 or window[-1]['wall_time'] <= window[0]['wall_time']:
    return None
  rate = ((window[-1]['env_steps'] - window[0]['env_steps'])
          / (window[-1]['wall_time'] - window[0]['wall_time']))
  return rate if rate > 0 and math.isfinite(rate) else None


def measured_pace(cell: paper_plan.Cell, args: PaperArgs,
                  since_steps: int = -1) -> Optional[float]:
  """The `window_pace` of the running `cell` (its run directory's
  metrics.csv, None unless written in the last `PACE_WINDOW` seconds).
  With `since_steps` (where this process resumed it), only the rows past
  it: a resumed run's earlier rows ran elsewhere, maybe at another pace;
  another process (`dry_run`) cannot know that point and takes them all."""
  logdir = run_directory(cell, args)
  try:
    if time.time() - os.path.getmtime(os.path.join(logdir, run_dir.METRICS)
                                      ) > PACE_WINDOW:
      return None
    rows = run_dir.read_metrics(logdir)
  except (OSError, ValueError, csv.Error):
    return None
  return window_pace([r for r in rows if r.get('env_steps', -1) > since_steps])


def done_runs(args: PaperArgs, plan=None
              ) -> list[tuple[paper_plan.Cell, list[dict]]]:
  """Each done cell of `plan` (the plan's) with its committed metrics.csv
  rows; a cell whose file does not read is left out."""
  runs = []
  for cell in paper_plan.PLAN if plan is None else plan:
    if not is_done(cell, args):
      continue
    try:
      rows = run_dir.read_metrics(results_directory(cell, args))
    except (OSError, ValueError, csv.Error):
      continue
    if rows:
      runs.append((cell, rows))
  return runs


def done_pace(runs) -> dict[str, list[float]]:
  """{variant: the Ant steps/s of each of its `done_runs`' training}: env
  steps times the cell's Ants over the wall time of its updates (its
  metrics.csv's last row; resumed runs count on), whatever the machine
  and whatever ran beside it."""
  paces = {}
  for cell, rows in runs:
    last = rows[-1]
    if last.get('wall_time', 0) > 0 and last.get('env_steps', 0) > 0:
      paces.setdefault(cell.agent, []).append(
          last['env_steps'] * cell.ants / last['wall_time'])
  return paces


def measured_evaluations(cell: paper_plan.Cell, args: PaperArgs
                         ) -> list[tuple[float, float]]:
  """(`eval_seconds`, `eval_ant_steps`) of each of the published `cell`'s
  eval JSONs that measured itself (written since 29 November); empty for
  a cell not published."""
  measured = []
  for n in cell.populations:
    path = os.path.join(results_directory(cell, args), EVAL_FILE.format(n))
    try:
      with open(path) as f:
        figures = json.load(f)
    except (OSError, ValueError):
      continue
    seconds = figures.get('eval_seconds') or 0
    steps = figures.get('eval_ant_steps') or 0
    if seconds > 0 and steps > 0:
      measured.append((seconds, steps))
  return measured


def eval_shares(runs, args: PaperArgs) -> list[float]:
  """For each evaluation of the `done_runs` that measured itself
  (`measured_evaluations`): its Ant steps/s over the cell's training's in
  its last `PACE_WINDOW` seconds of updates (`window_pace`), which ran on
  the same machine just before it, so the share holds from machine to
  machine."""
  shares = []
  for cell, rows in runs:
    evaluations = measured_evaluations(cell, args)
    training = window_pace(rows) if evaluations else None
    if training:
      shares.extend(steps / seconds / (training * cell.ants)
                    for seconds, steps in evaluations)
  return shares


def eval_share(shares: list[float]) -> Optional[float]:
  """The median of `eval_shares`, or None without one: the estimates then
  evaluate at the training's rate."""
  return statistics.median(shares) if shares else None


def estimate_rates(paces: dict[str, list[float]], agents
                   ) -> dict[str, float]:
  """{variant: Ant steps/s the estimate takes}, for `paces`' variants and
  `agents`: the median of the variant's done cells (`done_pace`); a
  variant with none at `hrl`'s times its share (`paper_plan.variant_rate`;
  1 for `mappo`, which ran at or above `hrl`'s rate in short probes,
  docs/performance.md); empty without done `hrl` cells
  (`runners.paper_plan`'s constants)."""
  rates = {agent: statistics.median(values) for agent, values in paces.items()}
  if 'hrl' not in rates:
    return {}
  return {agent: rates.get(agent, paper_plan.variant_rate(agent,
                                                          rates['hrl']))
          for agent in dict.fromkeys(('hrl', *rates, *agents))}


def finishes_within(cell: paper_plan.Cell, args: PaperArgs, env_steps: int,
                    seconds: float, since_steps: int = -1) -> bool:
  """Whether `cell`, stopped at `env_steps`, would end its training and
  the evaluations of its final checkpoint within `seconds`: the training
  at the pace its run directory measures past `since_steps`
  (`measured_pace`), the evaluations at the done cells' share of it
  (`eval_share`, else at that pace too; `paper_plan.estimated_seconds`,
  episodes at their full length). False without a measured pace."""
  pace = measured_pace(cell, args, since_steps)
  if pace is None:
    return False
  left = max(budget(cell, args) - env_steps, 0)
  # Only the cells whose evaluations measured themselves have their
  # metrics read (done_runs reads every row, gzipped files whole).
  measured = [c for c in paper_plan.PLAN if measured_evaluations(c, args)]
  share = eval_share(eval_shares(done_runs(args, measured), args))
  return paper_plan.estimated_seconds(cell, left, args.episodes,
                                      pace * cell.ants, share) <= seconds


def dry_run(args: PaperArgs, plan=None) -> str:
  """The plan as text: per cell its status, budget, estimated remaining
  wall time (at the pace of the variant's done cells, `estimate_rates`;
  without done `hrl` cells at `runners.paper_plan`'s constants) and
  command (and, for a cell
  that a coop-paper process runs, i.e. holds its `claim`, which one and the
  pace it measures); then the total at the estimate's rate and, where
  cells run, at the pace they make together."""
  lines, total = [f'{"cell":32s} {"status":22s} {"budget":>7s}  '
                  f'{"to go":>9s}  command'], 0.0
  pace = []  # Each running cell's measured rate / its estimated rate.
  cells = selected(args, plan)
  runs = done_runs(args, plan)
  paces = done_pace(runs)
  rates = estimate_rates(paces, [cell.agent for cell in cells])
  shares = eval_shares(runs, args)
  evaluating = eval_share(shares)
  for cell in cells:
    state = status(cell, args)
    steps = budget(cell, args)
    remaining = {'done': None, 'trained': 0, 'foreign': steps}.get(
        state.state, steps - state.env_steps)
    seconds = 0.0 if remaining is None else paper_plan.estimated_seconds(
        cell, max(remaining, 0), args.episodes, rates.get(cell.agent),
        evaluating)
    total += seconds
    lines.append(f'{cell.path:32s} {state.describe(steps):22s} '
                 f'{steps / 1e6:6g}M  ~{seconds / 3600:6.1f} h  '
                 f'{command(cell, args)}')
    if state.problem:
      lines.append(f'  ! {state.problem}')
    holder = run_dir.lock_holder(claim_directory(cell, args))
    if holder:
      lines.append(f'  running: coop-paper pid, host {holder}')
      rate = measured_pace(cell, args)
      if rate is not None:
        pace.append(rate / paper_plan.estimated_rate(
            cell, rates.get(cell.agent)))
        lines.append(f'  pace: {rate:,.0f} env steps/s over its last '
                     f'{PACE_WINDOW / 60:g} min of updates, {pace[-1]:.2f}x '
                     'the estimate')
  if rates:
    lines.append(
        f'{len(cells)} cells, ~{total / 3600:.0f} h of cell time to go at '
        'the pace of the done cells (Ant steps/s, median of the '
        'variant\'s: ' + ', '.join(
            f'{agent} {rate:,.0f} of {len(paces[agent])}' if agent in paces
            else f'{agent} at hrl\'s' + (
                f' x {paper_plan.VARIANT_SPEED[agent]:g}'
                if agent in paper_plan.VARIANT_SPEED else '')
            for agent, rate in rates.items())
        + '; as they ran, beside what ran with them)')
  else:
    lines.append(f'{len(cells)} cells, ~{total / 3600:.0f} h to go at '
                 f'{paper_plan.AGENT_STEPS_PER_SECOND:,.0f} Ant steps/s, '
                 + ', '.join(f'{agent} at {share:g} of it'
                             for agent, share in
                             paper_plan.VARIANT_SPEED.items())
                 + ' (runners.paper_plan)')
  if evaluating:
    measured = (f'the median of {len(shares)} done ones that measured '
                'themselves, each' if len(shares) > 1 else
                'the one done evaluation that measured itself,')
    lines.append(f'  evaluations (every episode at its full length) at '
                 f'{evaluating:.2f}x the training\'s Ant steps/s: '
                 f'{measured} against its cell\'s last '
                 f'{PACE_WINDOW / 60:g} min of training')
  if pace:
    running = f'the {len(pace)} cells' if len(pace) > 1 else 'the cell'
    together = ' together' if len(pace) > 1 else ''
    lines.append(f'~{total / sum(pace) / 3600:.1f} h at the pace of {running} '
                 f'running now ({sum(pace):.2f}x the estimate{together}; '
                 'the rest run as many at a time on the same machines)')
  return '\n'.join(lines)


def evaluate_cell(cell: paper_plan.Cell, checkpoint: str, args: PaperArgs,
                  log: Callable[[str], None]) -> dict[int, dict]:
  """{population: eval JSON} of the final checkpoint (the paper's
  protocol)."""
  from runners import evaluate  # pylint: disable=g-import-not-at-top
  from runners import marl_eval  # pylint: disable=g-import-not-at-top
  out = {}
  for n in cell.populations:
    started = time.monotonic()
    result = evaluate.evaluate(evaluate.EvalArgs(
        checkpoint=(checkpoint,), episodes=args.episodes,
        seeds=(args.eval_seed,), envs=args.eval_envs,
        n_agents=0 if n == cell.n_agents else n),
        log=lambda line, n=n: log(f'{cell.path} with {n}: {line}'))
    model = result['models'][0]
    out[n] = {
        'cell': cell.name, 'experiment': cell.experiment, 'task': cell.task,
        'agent': cell.agent, 'stage': cell.stage, 'seed': cell.seed,
        'trained_n_agents': cell.n_agents, 'n_agents': n,
        'checkpoint': os.path.join('checkpoints',
                                   os.path.basename(checkpoint)),
        'update': model['update'], 'env_steps': model['env_steps'],
        'budget': budget(cell, args), 'episodes': result['episodes'],
        'eval_seed': args.eval_seed,
        'eval_seconds': round(time.monotonic() - started, 1),
        'eval_ant_steps': model['copy_steps'] * cell.ants_at(n),
        **{k: result[k] for k in ('success', 'success_se', 'return',
                                  'return_se')},
        'train_command': command(cell, args),
        'eval_command': eval_command(cell, n, args),
        'marl_eval': marl_eval.layout(result['models'])}
  return out


def publish(cell: paper_plan.Cell, checkpoint: str,
            evaluations: dict[int, dict], args: PaperArgs) -> str:
  """Copies the small artifacts into `--results`/<cell>/, whole or not at
  all: metrics.csv, the final checkpoint's policy (parameters and
  statistics, `checkpoints.write_policy`), the run's lower layer and the
  eval JSONs."""
  from runners import evaluate  # pylint: disable=g-import-not-at-top
  final = results_directory(cell, args)
  _copy_run(run_directory(cell, args), checkpoint, final, {
      EVAL_FILE.format(n): lambda path, figures=figures: evaluate.write_json(
          path, figures) for n, figures in evaluations.items()},
            policy_only=True)
  shutil.rmtree(partial_directory(cell, args), ignore_errors=True)
  return final


def _copy_run(logdir: str, checkpoint: str, final: str,
              extra: Optional[dict[str, Callable[[str], None]]] = None,
              policy_only: bool = False):
  """Writes `final` whole or not at all: `logdir`'s metrics.csv (gzipped
  when large, `run_dir.pack_metrics`) and lower layer and the one
  `checkpoint` (a run directory that coop-train can
  resume; with `policy_only`, its policy, `checkpoints.write_policy`, if
  its layout allows, else whole), plus {file name: writer(path)} of
  `extra`."""
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  parent = os.path.dirname(final)
  os.makedirs(parent, exist_ok=True)
  # Only `final`'s leftovers: its cell's claim (`claim`) makes this the
  # one process writing it, where other machines may write beside it.
  run_dir.remove_stale(parent, os.path.basename(final))
  tmp = f'{final}.tmp-{os.getpid()}'
  shutil.rmtree(tmp, ignore_errors=True)
  os.makedirs(os.path.join(tmp, 'checkpoints'))
  shutil.copy2(os.path.join(logdir, run_dir.METRICS), tmp)
  run_dir.pack_metrics(tmp)  # Committed files stay under 5 MB.
  if policy_only and checkpoints.policy_writable(checkpoint):
    checkpoints.write_policy(checkpoint, tmp)
  else:
    shutil.copytree(checkpoint, os.path.join(
        tmp, 'checkpoints', os.path.basename(checkpoint)))
  if os.path.isdir(os.path.join(logdir, 'controller')):
    shutil.copytree(os.path.join(logdir, 'controller'),
                    os.path.join(tmp, 'controller'))
  for name, write in (extra or {}).items():
    write(os.path.join(tmp, name))
  run_dir.replace_directory(tmp, final)


def stash(cell: paper_plan.Cell, args: PaperArgs) -> Optional[str]:
  """Copies the cell's unfinished run (its newest checkpoint, metrics.csv
  and lower layer) into `--partial`/<cell>/; returns that folder, or None
  when the cell is done or has no checkpoint in `--runs`."""
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  logdir = run_directory(cell, args)
  if is_done(cell, args) or not checkpoints.list_checkpoints(logdir):
    return None
  state = status(cell, args)
  if state.state == 'foreign':  # Not to be committed as the cell's.
    raise ValueError(state.problem)
  folder = partial_directory(cell, args)
  _copy_run(logdir, checkpoints.resolve(logdir), folder)
  return folder


def unstash(cell: paper_plan.Cell, args: PaperArgs) -> bool:
  """Puts a stashed run into `--runs`/<cell>/ when that has no checkpoint;
  returns whether it did."""
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  logdir, folder = run_directory(cell, args), partial_directory(cell, args)
  if (checkpoints.list_checkpoints(logdir)
      or not checkpoints.list_checkpoints(folder)):
    return False
  shutil.copytree(folder, logdir, dirs_exist_ok=True)
  run_dir.unpack_metrics(logdir)
  return True


class CellTaken(Exception):
  """Another coop-paper process holds the cell's claim."""


@contextlib.contextmanager
def claim(cell: paper_plan.Cell, args: PaperArgs):
  """Holds `cell`'s claim inside the block: an advisory lock on
  `--runs`/.claims/<cell>/ (`CLAIMS`), which the kernel drops when the
  process ends, however it ends. coop-paper processes sharing `--runs` and
  `--results` thus never run, stash or publish one cell twice, whichever
  machine they run on (given a file system whose `flock` works across
  machines: local, NFSv4, Lustre mounted with `flock`).

  Raises:
    CellTaken: another process holds it (its pid and host in the message).
  """
  lock = run_dir.RunLock(claim_directory(cell, args))
  try:
    lock.__enter__()
  except run_dir.RunInUseError as error:
    raise CellTaken(f'{cell.path}: run by another coop-paper (pid, host: '
                    f'{error.holder})') from None
  try:
    yield
  finally:
    lock.__exit__(None, None, None)


def _passed_over_for_stages(cell: paper_plan.Cell, elsewhere: dict,
                            args: PaperArgs,
                            log: Callable[[str], None]) -> bool:
  """Whether `cell` starts from stage cells that other coop-paper
  processes run (`elsewhere`: {`--results` folder: cell} of the cells
  passed over) and have not published; if so it is passed over too: said,
  and added to `elsewhere`."""
  waits = [os.path.basename(folder)
           for _, folder in stage_directories(cell, args)
           if folder in elsewhere
           and not run_dir.has_metrics(folder)]
  if waits:
    log(f'{cell.path}: starts from {", ".join(waits)}, which another '
        'coop-paper runs; passed over')
    elsewhere[results_directory(cell, args)] = cell
  return bool(waits)


def run_cell(cell: paper_plan.Cell, args: PaperArgs,
             log: Callable[[str], None] = print,
             deadline: Optional[float] = None) -> Optional[str]:
  """Trains (or resumes) and evaluates one cell, then publishes it;
  returns what stopped its training early (a signal's name, or
  `run_dir.DEADLINE` once `run_dir.clock()` passes `deadline`), else
  None."""
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  from runners import learner_loop  # pylint: disable=g-import-not-at-top
  # Loaded before it trains, as the modules above: a process that trains
  # for hours then evaluates with the code it trained with, whatever is
  # edited on disk meanwhile (else a newer evaluate.py meets the older
  # checkpoints module it holds).
  from runners import evaluate  # pylint: disable=g-import-not-at-top,unused-import
  from runners import marl_eval  # pylint: disable=g-import-not-at-top,unused-import
  state = status(cell, args)
  if state.state == 'done':
    return None
  if state.state == 'foreign':
    raise ValueError(state.problem)
  log(f'== {cell.path}: {state.describe(budget(cell, args))}')
  if unstash(cell, args):
    log(f'{cell.path}: continues from {partial_directory(cell, args)}')
  if state.state in ('todo', 'partial'):
    if state.state == 'todo':
      missing = [os.path.basename(folder)
                 for _, folder in stage_directories(cell, args)
                 if not run_dir.has_metrics(folder)]
      if missing:
        raise ValueError(f'{cell.name} starts from {missing}, which are not '
                         f'in {args.results} yet: run them first (--only).')
    summary = learner_loop.train(
        train_args(cell, args, resume=state.state == 'partial'),
        deadline=deadline)
    extra = args.finish_within * 60
    if summary.get('stopped_by') == run_dir.DEADLINE and extra:
      steps = status(cell, args).env_steps  # Its newest checkpoint's.
      if finishes_within(cell, args, steps,
                         deadline + extra - run_dir.clock(),
                         since_steps=state.env_steps):
        log(f'{cell.path}: out of time at {steps / 1e6:.2f}M of '
            f'{budget(cell, args) / 1e6:g}M; the rest fits in '
            f'--finish-within {args.finish_within:g}: trains on')
        summary = learner_loop.train(train_args(cell, args, resume=True),
                                     deadline=deadline + extra)
    if summary.get('stopped_by'):
      return summary['stopped_by']
  checkpoint = checkpoints.resolve(run_directory(cell, args))
  steps = checkpoints.read_state(checkpoint)['env_steps']
  if steps < budget(cell, args):
    raise ValueError(f'{checkpoint} has {steps} env steps, short of the '
                     f'budget {budget(cell, args)}: resume it first.')
  published = publish(cell, checkpoint,
                      evaluate_cell(cell, checkpoint, args, log), args)
  log(f'{cell.path}: done, results in {published}')
  return None


def run_plan(args: PaperArgs, plan=None,
             log: Callable[[str], None] = print) -> Optional[str]:
  """Runs every selected cell that is not done, in plan order (with
  `--concurrent` N, N at a time: `run_concurrently`); returns what stopped
  it early (`run_cell`), else `ELSEWHERE` if a cell it passed over because
  another coop-paper process runs it (`claim`) is still not done, else
  None. Out of `--hours`, the cell it stopped is stashed and no other
  starts."""
  deadline = run_dir.clock() + args.hours * 3600 if args.hours else None
  if args.finish_within and not args.hours:
    raise ValueError('--finish-within is time past --hours: give --hours.')
  default = PaperArgs()
  if args.budget and (args.results == default.results
                      or args.runs == default.runs
                      or args.partial == default.partial):
    raise ValueError('--budget runs are not the plan\'s: give them their '
                     'own --results, --runs and --partial (e.g. '
                     '/tmp/paper/results /tmp/paper/runs /tmp/paper/partial),'
                     f' not {default.results}, {default.runs} or '
                     f'{default.partial}.')
  # is_done reads no checkpoint, so the JAX-before-Ray rule below holds.
  cells = [cell for cell in selected(args, plan) if not is_done(cell, args)]
  if not cells:
    return None  # Nothing to train or evaluate: no Ray either.
  for cell in cells:  # Refuses --actors that split a cell's copies unevenly.
    train_args(cell, args)
  if args.concurrent > 1:
    if (args.actors and not args.ray_address
        and not os.environ.get('RAY_ADDRESS')):
      raise ValueError(
          f'--concurrent {args.concurrent} trains each cell in a process of '
          f'its own, and with --actors {args.actors} each would start a Ray '
          'of its own: give --actors 0 (each process steps its cell\'s '
          'copies itself) or --ray-address of one cluster.')
    return run_concurrently(args, cells, log, deadline)
  return _run_in_turn(args, cells, log, deadline)


def _run_in_turn(args: PaperArgs, cells: list[paper_plan.Cell],
                 log: Callable[[str], None],
                 deadline: Optional[float]) -> Optional[str]:
  """`run_plan`'s cells one after the other in this process."""
  # Ray before anything reads a checkpoint: orbax starts JAX, and Ray's
  # processes are not to be started from a process where JAX runs threads.
  from runners import actor_pool  # pylint: disable=g-import-not-at-top
  owns_ray = args.actors > 0 and actor_pool.init_ray(
      args.ray_address, num_cpus=max(os.cpu_count(), args.actors))
  elsewhere = {}  # --results folder -> cell, of the cells passed over.
  try:
    for cell in cells:
      if deadline and run_dir.clock() >= deadline:
        log(f'Out of time (--hours {args.hours:g}) before {cell.path}.')
        return run_dir.DEADLINE
      if _passed_over_for_stages(cell, elsewhere, args, log):
        continue
      try:
        with claim(cell, args):
          try:
            stopped = run_cell(cell, args, log, deadline)
          except KeyboardInterrupt:  # A signal outside training.
            if deadline and run_dir.clock() >= deadline:
              _stash_at_deadline(cell, args, log, 'interrupted')
            raise
          # Out of time, or stopped by a signal once --hours are up (in
          # --finish-within's minutes, or in the update that ran past
          # them; it keeps its exit status): stashed.
          if stopped == run_dir.DEADLINE or (
              stopped and deadline and run_dir.clock() >= deadline):
            _stash_at_deadline(cell, args, log, (
                f'out of time (--hours {args.hours:g})'
                if stopped == run_dir.DEADLINE
                else f'stopped by {stopped} with --hours up'))
      except CellTaken as taken:
        log(f'{taken}; passed over')
        elsewhere[results_directory(cell, args)] = cell
        continue
      if stopped:
        return stopped
    return _left_elsewhere(elsewhere, args)
  finally:
    if owns_ray:
      import ray  # pylint: disable=g-import-not-at-top
      ray.shutdown()


def _stash_at_deadline(cell: paper_plan.Cell, args: PaperArgs,
                       log: Callable[[str], None], why: str):
  """Stashes the cell that `why` stopped once `--hours` were up (a cell
  stopped before its first update starts afresh next time; a published
  one keeps its run directory)."""
  folder = stash(cell, args)  # None when published or without an update.
  if folder:
    log(f'{cell.path}: {why}; stashed in {folder}: commit it')
  elif is_done(cell, args):
    log(f'{cell.path}: {why}; published already, nothing to stash')
  else:
    shutil.rmtree(run_directory(cell, args), ignore_errors=True)
    log(f'{cell.path}: {why}; no update yet, nothing to stash')


class CellFailed(Exception):
  """A cell's process under `--concurrent` ended with an error (its own
  message, if it had one, is above it on the standard error)."""


POLL_SECONDS = 1.0
"""How often `run_concurrently` looks at its cells' processes."""
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def exit_status(stopped: Optional[str]) -> int:
  """coop-paper's exit status when `stopped` (what `run_plan` returns)
  stopped it: 0, `EXIT_OUT_OF_TIME`, `EXIT_RUN_ELSEWHERE`, or 128 + the
  signal's number."""
  if stopped is None:
    return 0
  if stopped == run_dir.DEADLINE:
    return EXIT_OUT_OF_TIME
  if stopped == ELSEWHERE:
    return EXIT_RUN_ELSEWHERE
  return 128 + signal.Signals[stopped].value


def _ended(status: int, signalled: Optional[str]) -> Optional[str]:
  """How a cell's process ended, from its exit status: None (done), what
  stopped it (`exit_status`'s inverse), or '' for an error. After a signal
  was passed on (`signalled`), dying by it or by its KeyboardInterrupt (a
  second one, or one before training started) is that signal's stop."""
  if status == 0:
    return None
  if status == EXIT_OUT_OF_TIME:
    return run_dir.DEADLINE
  if status == EXIT_RUN_ELSEWHERE:
    return ELSEWHERE
  stops = {128 + s: s.name for s in STOP_SIGNALS}
  if status in stops:
    return stops[status]
  if signalled and status in (1, *(-s for s in STOP_SIGNALS)):
    return signalled
  return ''


def _failure(cell: paper_plan.Cell, status: int) -> str:
  if status < 0:
    return f'{cell.path} (killed by {signal.Signals(-status).name})'
  return f'{cell.path} (exit status {status})'


def _cell_process(cell: paper_plan.Cell, args: PaperArgs,
                  deadline: Optional[float]):
  """A cell's own process under `--concurrent`: the cell as `coop-paper
  --only <cell>` trains it (stashed when out of time), ending with the
  same exit status; a signal outside its training (starting, evaluating)
  ends it at once with 128 + the signal's number."""
  os.setsid()  # Its signals come from coop-paper, once each.
  try:  # It stops (SIGTERM, with a checkpoint) if coop-paper dies.
    import ctypes  # pylint: disable=g-import-not-at-top
    ctypes.CDLL(None).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
  except (OSError, AttributeError):  # Not Linux: coop-paper's end only.
    pass
  # Several JAX processes share a GPU only if none takes most of it.
  os.environ.setdefault('XLA_PYTHON_CLIENT_PREALLOCATE', 'false')
  received = []

  def interrupt(signum, frame):
    received.append(signum)
    signal.default_int_handler(signum, frame)
  for signum in STOP_SIGNALS:  # Training's `GracefulStop` overrides these.
    signal.signal(signum, interrupt)
  try:
    stopped = _run_in_turn(args, [cell],
                           lambda line: print(line, flush=True), deadline)
  except cli.user_errors() as error:
    cli.fail('coop-paper', error)
  except KeyboardInterrupt:
    sys.exit(128 + (received[-1] if received else signal.SIGINT))
  sys.exit(exit_status(stopped))


def start_cell_process(cell: paper_plan.Cell, args: PaperArgs,
                       deadline: Optional[float]):
  """Starts `_cell_process` in a fresh interpreter (spawned: no JAX or Ray
  state of this one)."""
  import multiprocessing  # pylint: disable=g-import-not-at-top
  process = multiprocessing.get_context('spawn').Process(
      target=_cell_process, args=(cell, args, deadline), name=cell.name)
  process.start()
  return process


def _startable(waiting: list[paper_plan.Cell], running,
               args: PaperArgs) -> list[paper_plan.Cell]:
  """The waiting cells, in order, that start from no stage cell still
  waiting or running."""
  pending = {results_directory(c, args) for c in [*waiting, *running]}
  return [cell for cell in waiting if not any(
      folder in pending for _, folder in stage_directories(cell, args))]


def run_concurrently(args: PaperArgs, cells: list[paper_plan.Cell],
                     log: Callable[[str], None], deadline: Optional[float],
                     start=start_cell_process) -> Optional[str]:
  """Runs `cells` `--concurrent` at a time, each in a process of its own
  (`start(cell, args, deadline)`: a started process with `pid` and
  `exitcode`), taking them in order as processes end; a cell waits while a
  stage cell it starts from waits or runs. Each signal (SIGINT, SIGTERM) is
  passed on to the running cells: the first stops each after its update
  with a checkpoint (a cell starting or being evaluated stops at once), a
  second stops them at once. Out of --hours, the running cells stop and
  stash themselves and no other starts. Returns what stopped it early, as
  `run_plan`; once a cell's process ends with an error no other starts,
  and `CellFailed` is raised when the running ones have ended. A cell that
  another coop-paper runs (its process exits with `EXIT_RUN_ELSEWHERE`) is
  passed over, and so are the cells that start from it. The cells'
  processes get SIGTERM if this one ends otherwise (an error, or killed)."""
  own = dataclasses.replace(args, concurrent=1, progress=False)
  waiting, running, told, elsewhere = list(cells), {}, set(), {}
  stopped, signalled, failed = None, None, []

  def forward(name):
    for process in running.values():
      if process.exitcode is None:
        os.kill(process.pid, signal.Signals[name])

  with run_dir.GracefulStop() as stop:
    try:
      while waiting or running:
        if stop.requested and not signalled:
          stopped = signalled = stop.reason
          forward(signalled)
        if (waiting and not stopped and not failed and deadline
            and run_dir.clock() >= deadline):
          log(f'Out of time (--hours {args.hours:g}) before '
              f'{waiting[0].path}' + (f' and {len(waiting) - 1} other cells'
                                     if len(waiting) > 1 else '') + '.')
          stopped = run_dir.DEADLINE
        if stopped or failed:
          waiting = []
        waiting = [cell for cell in waiting if not _passed_over_for_stages(
            cell, elsewhere, args, log)]
        startable = _startable(waiting, running, args)
        free = args.concurrent - len(running)
        chosen = startable[:free]
        # Named once, when a free process passes it over.
        passed = (waiting[:waiting.index(chosen[-1])] if chosen
                  else waiting if free > 0 else [])
        for cell in passed:
          if cell not in startable and cell not in told:
            told.add(cell)
            log(f'{cell.path}: waits for its stage cells')
        for cell in chosen:
          waiting.remove(cell)
          log(f'{cell.path}: starts in a process of its own')
          running[cell] = start(cell, own, deadline)
        time.sleep(POLL_SECONDS)
        for cell, process in list(running.items()):
          if process.exitcode is None:
            continue
          del running[cell]
          ended = _ended(process.exitcode, signalled)
          if ended == '':
            failed.append(_failure(cell, process.exitcode))
            log(f'{failed[-1]}: failed; no other cell starts')
          elif ended == ELSEWHERE:  # Its process said so, and by whom.
            elsewhere[results_directory(cell, args)] = cell
          elif ended:
            stopped = stopped or ended
    except KeyboardInterrupt:  # A second signal: at once, everywhere.
      name = signalled or stop.reason or 'SIGINT'
      if not signalled:  # Both came before a look: pass on both.
        forward(name)
        time.sleep(0.1)
      forward(name)
      raise
    except BaseException:
      forward('SIGTERM')  # Each stops after its update.
      raise
  if failed:
    raise CellFailed(f'{", ".join(failed)} failed (its error, if any, is '
                     'above).')
  return stopped or _left_elsewhere(elsewhere, args)


def _left_elsewhere(elsewhere: dict, args: PaperArgs) -> Optional[str]:
  """`ELSEWHERE` if a cell passed over is not done yet, else None (the
  other processes finished them meanwhile)."""
  return (ELSEWHERE if any(not is_done(cell, args)
                           for cell in elsewhere.values()) else None)


def _command(args: PaperArgs) -> Optional[str]:
  """What `coop-paper` does with `args`; the signal that stopped training
  early, if any."""
  if args.report:
    from runners import paper_report  # pylint: disable=g-import-not-at-top
    text = paper_report.report(args)
    if args.json:
      from runners import evaluate  # pylint: disable=g-import-not-at-top
      evaluate.write_json(args.json, paper_report.marl_eval_data(args))
    if args.docs:
      paper_report.write_block(args.docs, text)
      print(f'Wrote the tables into {args.docs}.')
    else:
      print(text)
  elif args.dry_run:
    print(dry_run(args))
  elif args.stash:
    folders = []
    for cell in selected(args):
      try:
        with claim(cell, args):
          folders.append(stash(cell, args))
      except CellTaken as taken:
        print(f'{taken}: not stashed')
    folders = [f for f in folders if f]
    print('\n'.join(['Stashed (commit these; the next coop-paper resumes '
                     'from them):', *folders]) if folders
          else 'No unfinished run to stash.')
  else:
    return run_plan(args, log=lambda line: print(line, flush=True))
  return None


def main(argv=None):
  try:
    args, stopped = cli.run(PaperArgs, _command, argv, 'coop-paper',
                            __doc__.splitlines()[0])
  except CellFailed as error:
    print(f'coop-paper: error: {error}', file=sys.stderr, flush=True)
    sys.exit(1)
  if args.report or args.dry_run or args.stash:
    return
  if stopped == run_dir.DEADLINE:
    print('Out of time: run the same coop-paper command again to continue '
          '(after committing a stash, if one was made).', flush=True)
    sys.exit(EXIT_OUT_OF_TIME)
  if stopped == ELSEWHERE:
    print('Every other selected cell is done; the ones passed over above '
          'are run by other coop-paper processes: run the same command again '
          'once they have ended.', flush=True)
    sys.exit(EXIT_RUN_ELSEWHERE)
  if stopped:
    print(f'Stopped by {stopped}; run the same coop-paper command again to '
          'continue.', flush=True)
    sys.exit(exit_status(stopped))
  print('Every selected cell is done; coop-paper --report shows the tables.')


if __name__ == '__main__':
  main()
