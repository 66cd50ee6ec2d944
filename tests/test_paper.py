"""coop-paper on tiny budgets and fixture results, and coop-eval --json."""
import csv
import dataclasses
import functools
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time

import imageio
import pytest

from agents.hierarchy import config as hierarchy_config
from runners import actor_pool
from runners import baselines
from runners import checkpoints
from runners import cli
from runners import compare
from runners import config as config_lib
from runners import evaluate
from runners import learner_loop
from runners import marl_eval
from runners import paper
from runners import paper_plan
from runners import paper_report
from runners import plot
from runners import run_dir
from tests.test_run_safety import REPO
from tests.test_train import controller  # pylint: disable=unused-import
from tests.test_train import STEPS
from tests.test_train import TINY

pytestmark = pytest.mark.filterwarnings('ignore:os.fork:RuntimeWarning')
BASELINES = os.path.join(os.path.dirname(__file__), '..', 'results',
                         'baselines')


@pytest.fixture(scope='module')
def tiny_run(tmp_path_factory, controller):  # pylint: disable=redefined-outer-name
  """One update of 2 (the cells' budget) of TINY's hrl on transport."""
  logdir = str(tmp_path_factory.mktemp('paper') / 'hrl')
  learner_loop.train(config_lib.train_args(
      **{**TINY, 'task': 'transport', 'logdir': logdir,
         'controller': controller, 'total_steps': STEPS}))
  return logdir


def _tiny_plan(controller_dir):  # pylint: disable=redefined-outer-name
  """Two cells with TINY's agent and task flags (the machine's flags are
  PaperArgs')."""
  flags = tuple((k, v) for k, v in {**TINY, 'controller': controller_dir
                                    }.items()
                if k not in ('n_agents', 'actors', 'envs_per_actor',
                             'progress'))
  copies = TINY['envs_per_actor']
  return [paper_plan.Cell('table1', 'transport', 'hrl', 2, 0, 2 * STEPS,
                          zero_shot=(3,), flags=flags, copies=copies),
          paper_plan.Cell('table1', 'transport', 'hrl', 2, 1, 2 * STEPS,
                          flags=flags, copies=copies)]


def _args(tmp_path, **overrides):
  values = dict(results=str(tmp_path / 'results'), runs=str(tmp_path / 'runs'),
                partial=str(tmp_path / 'partial'),
                actors=0, episodes=2, eval_envs=2, progress=False,
                baselines=BASELINES)
  return paper.PaperArgs(**{**values, **overrides})


def _rows(path):
  with open(path) as f:
    return list(csv.DictReader(f))


def _evaluation(cell, n_agents, successes, env_steps=20_000_000, **figures):
  """An eval JSON as `paper.evaluate_cell` writes it, with these
  per-episode successes and `figures` (and from seed 1 on, transport's
  start figures)."""
  episodes = [{'return': 100.0 * s, 'success': float(s),
               **{k: v[i] for k, v in figures.items()}}
              for i, s in enumerate(successes)]
  if cell.seed >= 1:
    for i, episode in enumerate(episodes):
      episode.update(start_agent_cylinder=2.0 + i, start_cylinder_target=4.0)
  model = {'task': cell.task, 'n_agents': n_agents, 'stage': cell.stage,
           'agent': cell.agent, 'seed': cell.seed, 'update': 7,
           'env_steps': env_steps, 'episodes': episodes}
  return {'cell': cell.name, 'n_agents': n_agents, 'env_steps': env_steps,
          'marl_eval': marl_eval.layout([model])}


def _commit(cell, args, evaluations, env_steps=20_000_000, **figures):
  """Writes a done cell into args.results: {population: successes}, and
  per-episode `figures` ({name: values}) beside."""
  folder = paper.results_directory(cell, args)
  os.makedirs(folder, exist_ok=True)
  with open(os.path.join(folder, 'metrics.csv'), 'w') as f:
    f.write('update,env_steps,return,success\n1,16,42.0,0.0\n'
            f'2,32,50.0,{cell.seed / 10}\n')
  for n, successes in evaluations.items():
    evaluate.write_json(os.path.join(folder, paper.EVAL_FILE.format(n)),
                        _evaluation(cell, n, successes, env_steps, **figures))


def test_dry_run_prints_every_cell_with_its_status(tmp_path, capsys):
  args = _args(tmp_path)
  first, second = paper_plan.PLAN[:2]
  _commit(first, args, {n: [1] for n in first.populations})
  logdir = paper.run_directory(second, args)
  os.makedirs(os.path.join(logdir, 'checkpoints', 'ckpt_00000003'))
  with open(os.path.join(logdir, 'checkpoints', 'ckpt_00000003',
                         'state.json'), 'w') as f:
    json.dump({'format': 1, 'iteration': 3,  # A run from before orbax.
               'env_steps': 1_500_000, 'species': []}, f)
  paper.main(['--dry-run', '--results', args.results, '--runs', args.runs,
              '--partial', args.partial])  # Not the repository's stashes.
  lines = capsys.readouterr().out.splitlines()
  assert len(lines) == len(paper_plan.PLAN) + 2  # Header and total.
  for cell, line in zip(paper_plan.PLAN, lines[1:]):
    assert line.startswith(cell.path + ' ') and 'coop-train' in line
  assert ' done ' in lines[1] and 'partial 1.50M/12M' in lines[2]
  assert all(' todo ' in line for line in lines[3:-1])
  assert lines[-1].startswith(f'{len(paper_plan.PLAN)} cells, ~')
  # Every command is the cell's own TrainArgs, through coop-train's parser.
  for cell in paper_plan.PLAN:
    words = paper.command(cell, args).split()
    assert words[0] == 'coop-train'
    assert cli.parse(config_lib.TrainArgs, words[1:]) == dataclasses.replace(
        paper.train_args(cell, args), progress=True)


def test_a_flat_cell_is_estimated_at_its_own_rate():
  by_path = {cell.path: cell for cell in paper_plan.PLAN}
  hrl = by_path['corridor/hrl/n4/s0']
  flat = by_path['corridor/flat/n4/s0']
  assert (hrl.budget, hrl.ants) == (flat.budget, flat.ants)
  training = lambda cell: paper_plan.estimated_seconds(  # pylint: disable=g-long-lambda
      cell, hrl.budget, episodes=0)  # HRL cells evaluate more populations.
  assert training(flat) == pytest.approx(
      training(hrl) / paper_plan.VARIANT_SPEED['flat'])
  assert training(by_path['corridor/no_memory/n4/s0']) == pytest.approx(
      training(hrl))


def _fake_run(logdir, train_args, env_steps):
  """A run directory whose one checkpoint (format 1) saved `train_args`."""
  os.makedirs(os.path.join(logdir, 'checkpoints', 'ckpt_00000003'))
  with open(os.path.join(logdir, 'checkpoints', 'ckpt_00000003',
                         'state.json'), 'w') as f:
    json.dump({'format': 1, 'iteration': 3, 'env_steps': env_steps,
               'species': [], 'args': train_args.to_dict()}, f)


def test_a_run_of_other_settings_is_not_taken_for_the_cell(tmp_path, capsys):
  """A run left from before the plan changed (here transport trained from
  scratch, where the cell now starts from its push stage) is 'foreign':
  listed with its reason, never trained over, stashed or evaluated."""
  args = _args(tmp_path)
  push, joint = paper_plan.PLAN[:2]
  assert (push.stage, joint.init_from) == ('push', (('ant', push.name),))
  own = paper.train_args(joint, args)
  logdir = paper.run_directory(joint, args)
  _fake_run(logdir, own, joint.budget)
  assert paper.status(joint, args).state == 'trained'
  for started, reason in ((dataclasses.replace(own, init_from=()),
                           'started from scratch'),
                          (dataclasses.replace(own, init_from=(
                              'ant=results/other_probe',)), 'other_probe')):
    shutil.rmtree(logdir)
    _fake_run(logdir, started, joint.budget)
    state = paper.status(joint, args)
    assert state.state == 'foreign' and reason in state.problem
    with pytest.raises(ValueError, match=reason):
      paper.run_cell(joint, args, log=lambda _: None)
    with pytest.raises(ValueError, match=reason):
      paper.stash(joint, args)
    assert not os.path.exists(paper.partial_directory(joint, args))
  _fake_run(paper.run_directory(push, args),
            dataclasses.replace(paper.train_args(push, args), stage='joint'),
            1000)
  assert '--stage' in paper.status(push, args).problem
  paper.main(['--dry-run', '--only', 'transport/hrl/push/n4/s0',
              'transport/hrl/n4/s0', '--results', args.results, '--runs',
              args.runs, '--partial', args.partial])
  lines = capsys.readouterr().out.splitlines()
  assert [line.split()[1] for line in lines[1::2][:2]] == ['foreign'] * 2
  assert lines[2].startswith('  ! ') and 'Move it away' in lines[2]
  assert lines[-1].startswith('2 cells, ~')


def test_out_of_hours_the_running_cell_stops_is_stashed_and_none_starts(
    controller, tmp_path, monkeypatch, capsys):  # pylint: disable=redefined-outer-name
  first, second = plan = [dataclasses.replace(cell, budget=4 * STEPS)
                          for cell in _tiny_plan(controller)]
  monkeypatch.setattr(paper_plan, 'PLAN', plan)
  # The deadlines' clock reads 0 until the update named here ends, then
  # jumps past any deadline.
  clock = {'now': 0.0, 'jump_after': 2}
  monkeypatch.setattr(run_dir, 'clock', lambda: clock['now'])
  real_train = learner_loop.train

  def train(args, deadline=None):
    def on_update(update, *_):
      if update == clock['jump_after']:
        clock['now'] = float('inf')
    return real_train(args, on_update=on_update, deadline=deadline)
  monkeypatch.setattr(learner_loop, 'train', train)
  args = _args(tmp_path)
  argv = _argv(args)

  def run(*flags):
    clock['now'] = 0.0
    with pytest.raises(SystemExit) as exit_info:
      paper.main(argv + list(flags))
    return exit_info.value.code, capsys.readouterr().out

  # Out of time in the first cell's update 2 of 4: stopped and stashed.
  code, out = run('--hours', '2.5')
  assert code == paper.EXIT_OUT_OF_TIME
  assert 'Time limit reached: stopping with a checkpoint.' in out
  stashed = paper.partial_directory(first, args)
  assert (f'{first.path}: out of time (--hours 2.5); stashed in {stashed}'
          in out)
  assert os.listdir(os.path.join(stashed, 'checkpoints')) == ['2']
  assert [int(r['update']) for r in _rows(
      os.path.join(stashed, 'metrics.csv'))] == [1, 2]
  assert not os.path.exists(paper.results_directory(first, args))
  assert not os.path.exists(paper.run_directory(second, args))  # Not begun.
  # The next session has only the stash: the first cell continues from it
  # and ends in time (evaluated and published); time is up before the
  # second one starts.
  shutil.rmtree(args.runs)
  assert paper.status(first, args) == paper.Status('partial', 2 * STEPS)
  clock['jump_after'] = 4
  code, out = run('--hours', '2.5')
  assert code == paper.EXIT_OUT_OF_TIME
  assert paper.status(first, args).state == 'done'
  assert f'Out of time (--hours 2.5) before {second.path}.' in out
  assert not os.path.exists(paper.run_directory(second, args))
  # Out of time before its first update: nothing to stash, and the run
  # directory (its header, the lower layer's copy) goes, so that the next
  # command starts the cell afresh instead of refusing to write over it.
  clock['jump_after'] = 0
  monkeypatch.setattr(run_dir, 'clock', lambda: (
      clock['now'] if os.path.exists(paper.run_directory(second, args))
      else 0.0))
  clock['now'] = float('inf')
  with pytest.raises(SystemExit) as exit_info:
    paper.main(argv + ['--hours', '2.5'])
  assert exit_info.value.code == paper.EXIT_OUT_OF_TIME
  assert 'no update yet, nothing to stash' in capsys.readouterr().out
  assert not os.path.exists(paper.run_directory(second, args))
  assert not os.path.exists(paper.partial_directory(second, args))
  assert paper.status(second, args).state == 'todo'


PAST_HOURS = 2.5 * 3600 + 1
"""1 s past `--hours 2.5` (--finish-within's minutes count from --hours)."""


def _hours_pass_after(monkeypatch, update, signal_after=None):
  """The deadlines' clock reads 0 until `update` ends, then `PAST_HOURS`;
  SIGINT as update `signal_after` ends. Returns the clock: {'now': its
  reading, 'after': update, 'signal_after': signal_after}, to change."""
  clock = {'now': 0.0, 'after': update, 'signal_after': signal_after}
  monkeypatch.setattr(run_dir, 'clock', lambda: clock['now'])
  real_train = learner_loop.train

  def train(args, deadline=None):
    def on_update(done, *_):
      if done == clock['after']:
        clock['now'] = PAST_HOURS
      if done == clock['signal_after']:
        os.kill(os.getpid(), signal.SIGINT)
    return real_train(args, on_update=on_update, deadline=deadline)
  monkeypatch.setattr(learner_loop, 'train', train)
  return clock


def _argv(args):
  """coop-paper's flags for `_args`' folders and machine settings."""
  return [f'--{k}={v}' for k, v in dataclasses.asdict(args).items()
          if k in ('results', 'runs', 'partial', 'actors', 'episodes',
                   'eval_envs', 'baselines')] + ['--no-progress']


def test_a_cell_that_fits_in_finish_within_trains_on_past_hours(
    controller, tmp_path, monkeypatch, capsys):  # pylint: disable=redefined-outer-name
  first, second = plan = [dataclasses.replace(cell, budget=4 * STEPS)
                          for cell in _tiny_plan(controller)]
  monkeypatch.setattr(paper_plan, 'PLAN', plan)
  clock = _hours_pass_after(monkeypatch, 3)
  args = _args(tmp_path)
  argv = _argv(args) + ['--hours', '2.5']
  with pytest.raises(ValueError, match='--finish-within .*--hours'):
    paper.run_plan(dataclasses.replace(args, finish_within=5.0))
  # Minutes enough at its pace: the first cell ends in the extra time and
  # is published; the second does not start.
  with pytest.raises(SystemExit) as exit_info:
    paper.main(argv + ['--finish-within', '30'])
  out = capsys.readouterr().out
  assert exit_info.value.code == paper.EXIT_OUT_OF_TIME
  assert (f'{first.path}: out of time at {3 * STEPS / 1e6:.2f}M of '
          f'{4 * STEPS / 1e6:g}M; the rest fits in --finish-within 30: '
          'trains on') in out
  assert paper.status(first, args).state == 'done'
  assert [int(r['update']) for r in _rows(os.path.join(
      paper.results_directory(first, args), 'metrics.csv'))] == [1, 2, 3, 4]
  assert f'Out of time (--hours 2.5) before {second.path}.' in out
  # Too few minutes for the rest: stopped and stashed as without it.
  clock['now'] = 0.0
  with pytest.raises(SystemExit) as exit_info:
    paper.main(argv + ['--finish-within', '1e-6'])
  out = capsys.readouterr().out
  assert exit_info.value.code == paper.EXIT_OUT_OF_TIME
  assert 'trains on' not in out
  assert f'{second.path}: out of time (--hours 2.5); stashed in' in out
  assert paper.status(second, args) == paper.Status('partial', 3 * STEPS)


def test_a_signal_past_hours_stashes_the_cell_with_its_exit_status(
    controller, tmp_path, monkeypatch, capsys):  # pylint: disable=redefined-outer-name
  first = dataclasses.replace(_tiny_plan(controller)[0], budget=6 * STEPS)
  monkeypatch.setattr(paper_plan, 'PLAN', [first])
  # Past --hours after update 3; trains on in --finish-within's minutes
  # until SIGINT in update 4.
  clock = _hours_pass_after(monkeypatch, 3, signal_after=4)
  args = _args(tmp_path)
  argv = _argv(args) + ['--hours', '2.5', '--finish-within', '30']
  with pytest.raises(SystemExit) as exit_info:
    paper.main(argv)
  out = capsys.readouterr().out
  assert exit_info.value.code == 128 + signal.SIGINT
  assert 'trains on' in out
  stashed = paper.partial_directory(first, args)
  assert (f'{first.path}: stopped by SIGINT with --hours up; stashed in '
          f'{stashed}: commit it') in out
  assert os.listdir(os.path.join(stashed, 'checkpoints')) == ['4']
  assert paper.status(first, args) == paper.Status('partial', 4 * STEPS)
  # Next time it trains to its budget in time, and a signal interrupts its
  # evaluation once --hours are up: the trained cell is stashed too.
  clock.update(now=0.0, after=None, signal_after=None)

  def interrupted(*_):
    clock['now'] = PAST_HOURS
    raise KeyboardInterrupt
  monkeypatch.setattr(paper, 'evaluate_cell', interrupted)
  with pytest.raises(KeyboardInterrupt):
    paper.main(argv)
  assert (f'{first.path}: interrupted; stashed in {stashed}: commit it'
          in capsys.readouterr().out)
  assert os.listdir(os.path.join(stashed, 'checkpoints')) == ['6']
  shutil.rmtree(args.runs)
  assert paper.status(first, args) == paper.Status('trained', 6 * STEPS)


def test_a_deadline_stops_once_and_leaves_the_first_signal_graceful():
  with run_dir.GracefulStop() as stop:
    assert not stop.requested and stop.reason is None
  with run_dir.GracefulStop(deadline=run_dir.clock() - 1) as stop:
    assert stop.requested and stop.reason == run_dir.DEADLINE
    os.kill(os.getpid(), signal.SIGTERM)  # Still graceful: no interrupt.
    assert stop.requested and stop.reason == run_dir.DEADLINE
    with pytest.raises(KeyboardInterrupt):
      os.kill(os.getpid(), signal.SIGTERM)  # The second one interrupts.


def test_quick_runs_keep_off_the_plans_folders(tmp_path):
  for folder in ('results', 'runs', 'partial'):
    values = dict(results=str(tmp_path / 'r'), runs=str(tmp_path / 'u'),
                  partial=str(tmp_path / 'p'), budget=100)
    del values[folder]  # That one at its default.
    with pytest.raises(ValueError, match='--budget runs'):
      paper.run_plan(paper.PaperArgs(**values), log=pytest.fail)


def test_a_cells_update_is_the_same_whatever_the_actors(tmp_path,
                                                        monkeypatch):
  """--actors splits the plan's copies per update, so a cell run on more
  cores is still the cell; a split that is not even is refused before
  anything starts."""
  cell = paper_plan.PLAN[0]
  for actors, per_actor in ((0, 32), (1, 32), (2, 16), (8, 4), (32, 1)):
    train = paper.train_args(cell, _args(tmp_path, actors=actors))
    assert (train.actors, train.envs_per_actor) == (actors, per_actor)
    assert train.num_actors * train.envs_per_actor == paper_plan.COPIES
  # The default is coop-train's own (2 x 16): its command omits both.
  assert '--envs-per-actor' not in paper.command(cell, paper.PaperArgs())
  monkeypatch.setattr(actor_pool, 'init_ray',
                      lambda *a, **k: pytest.fail('Ray started'))
  with pytest.raises(ValueError, match=r'--actors 14 cannot split the 32 .*'
                     r'use one of 1, 2, 4, 8, 16, 32'):
    paper.run_plan(_args(tmp_path, actors=14), log=pytest.fail)
  # So do a cell's status and --stash, rather than calling a run of the
  # cell another cell's.
  cell_args = _args(tmp_path, actors=14)
  _fake_run(paper.run_directory(cell, cell_args),
            paper.train_args(cell, _args(tmp_path)), 1_000_000)
  assert paper.status(cell, _args(tmp_path)).state == 'partial'
  for call in (paper.status, paper.stash):
    with pytest.raises(ValueError, match='^--actors 14 cannot split'):
      call(cell, cell_args)


def test_a_cells_flags_cannot_make_it_another_run(tmp_path):
  """Cell.flags are merged into the cell's TrainArgs last, so one naming a
  field the cell or coop-paper sets (here --actors' split) is refused."""
  cell = paper_plan.PLAN[0]
  for flag, value in (('envs_per_actor', 8), ('seed', 7), ('stage', 'push'),
                      ('logdir', '/tmp/elsewhere')):
    bad = dataclasses.replace(cell, flags=cell.flags + ((flag, value),))
    with pytest.raises(ValueError, match=f'flags set {flag}, which'):
      paper.train_args(bad, _args(tmp_path))


def test_the_plan_is_the_papers():
  plan = paper_plan.PLAN
  assert len({c.name for c in plan}) == len(plan)
  # HRL's rows first; then every experiment's first seed before any
  # ablation's third, and the figures' seed 0 before their seed 1.
  kinds = [(c.experiment, c.agent == 'hrl', c.seed) for c in plan]
  hrl_rows = [k[:2] == ('table1', True) for k in kinds]
  assert hrl_rows == sorted(hrl_rows, reverse=True)
  third = min(i for i, k in enumerate(kinds) if k[0] == 'table1'
              and not k[1] and k[2] == 2)
  for experiment in ('mappo', 'scaling'):
    seeds = [k[2] for k in kinds if k[0] == experiment]
    assert seeds == sorted(seeds) and seeds[0] == 0
    assert min(i for i, k in enumerate(kinds) if k[0] == experiment) < third
  # Every figure's seed-0 cell before that, every seed-1 and -2 cell after.
  assert all(k[2] == 0 for k in kinds[:third] if k[0] != 'table1')
  assert all(k[2] > 0 for k in kinds[third:] if k[0] != 'table1')
  hrl = [c for c in plan if c.experiment == 'table1' and c.agent == 'hrl'
         and not c.stage]
  assert sorted({(c.task, c.n_agents) for c in hrl}) == [
      ('corridor', 4), ('ravine', 2), ('transport', 4)]
  assert {c.seed for c in hrl} == set(range(5))
  assert all(sorted(c.populations) == [2, 3, 4, 5] for c in hrl)
  by_name = {c.name: c for c in plan}
  names = [c.name for c in plan]
  for joint in [c for c in plan if c.task in ('ravine', 'transport')
                and not c.stage]:  # Its stages come first and feed it.
    assert joint.init_from
    for _, stage in joint.init_from:
      assert names.index(stage) < names.index(joint.name)
      assert by_name[stage].stage and not by_name[stage].zero_shot
    if joint.task == 'transport':  # 15M steps a model, its stage included.
      (species, push), = joint.init_from
      assert species == 'ant' and by_name[push].stage == 'push'
      assert joint.budget + by_name[push].budget == paper_plan.BUDGET
  for cell in plan:  # The crossers' commands start with a small std.
    flags = dict(cell.flags)
    if (cell.stage == 'crossers' and hierarchy_config.HierarchyConfig(
        agent=cell.agent).uses_commands):
      assert paper.train_args(cell, paper.PaperArgs()).hierarchy == (
          dataclasses.replace(hierarchy_config.HierarchyConfig(
              agent=cell.agent, seed=cell.seed), **dict(
                  paper_plan.CROSSERS_FLAGS)))
    else:
      assert 'initial_action_std' not in flags, cell.name
    # `flat` updates cover a tenth of the env steps: a tenth the saves.
    assert paper.train_args(cell, paper.PaperArgs()).checkpoint_every == (
        10 if cell.agent == 'flat' else 1), cell.name
    if cell.stage == 'pushers':
      assert cell.budget == paper_plan.STAGE_BUDGET
    if cell.stage == 'crossers':  # They train longer.
      assert cell.budget == paper_plan.CROSSERS_BUDGET > paper_plan.STAGE_BUDGET
  ablations = [c for c in plan if c.agent in ('flat', 'no_memory')]
  assert {c.seed for c in ablations} == {0, 1, 2}
  assert [c.agent for c in plan[:len(hrl) + 10]].count('flat') == 0
  versus = {(c.agent, c.n_agents) for c in plan if c.experiment == 'mappo'}
  assert versus == {('hrl', 6), ('hrl', 7), ('mappo', 6), ('mappo', 7)}
  scaling = {c.n_agents for c in plan if c.experiment == 'scaling'}
  assert scaling == {2, 3, 5}
  args = paper.PaperArgs()
  assert {c.path for c in paper.selected(dataclasses.replace(
      args, only=('ravine/hrl/n2/s0',)))} == {'ravine/hrl/n2/s0'}
  assert len(paper.selected(dataclasses.replace(
      args, only=('ravine/hrl',)))) == 15
  with pytest.raises(ValueError, match='selects no cell'):
    paper.selected(dataclasses.replace(args, only=('ravine/nothing',)))


def test_the_plan_skips_done_cells_and_resumes_a_partial_one(
    controller, tiny_run, tmp_path, monkeypatch):  # pylint: disable=redefined-outer-name
  plan = _tiny_plan(controller)
  args = _args(tmp_path)
  partial, done = plan
  # A run killed after update 1 of 2, with the cell's settings, stashed
  # at the end of a session; the next session has only the stash.
  shutil.copytree(tiny_run, paper.run_directory(partial, args))
  assert paper.status(partial, args) == paper.Status('partial', STEPS)
  assert paper.stash(done, args) is None  # Nothing to stash.
  stashed = paper.stash(partial, args)
  assert sorted(os.listdir(stashed)) == ['checkpoints', 'controller',
                                         'metrics.csv']
  shutil.rmtree(args.runs)
  assert paper.status(partial, args) == paper.Status('partial', STEPS)
  _commit(done, args, {2: [1, 0]})
  assert paper.status(done, args).state == 'done'
  paper.run_plan(args, plan, log=lambda line: None)
  logdir = paper.run_directory(partial, args)
  assert [int(r['update']) for r in _rows(
      os.path.join(logdir, 'metrics.csv'))] == [1, 2]
  assert not os.path.exists(paper.run_directory(done, args))  # Skipped.
  folder = paper.results_directory(partial, args)
  assert sorted(os.listdir(folder)) == ['checkpoints', 'controller',
                                        'eval_n2.json', 'eval_n3.json',
                                        'metrics.csv']
  assert os.listdir(os.path.join(folder, 'checkpoints')) == ['2']
  assert paper.status(partial, args).state == 'done'
  assert not os.path.exists(stashed)  # Published: the stash is spent.
  for n in (2, 3):
    with open(os.path.join(folder, f'eval_n{n}.json')) as f:
      figures = json.load(f)
    assert (figures['n_agents'], figures['update'], figures['env_steps'],
            figures['episodes']) == (n, 2, 2 * STEPS, 2)
    # Its cost: 2 copies of n Ants, stepped until the longer of their
    # episodes (TINY's time limit at the most) ended.
    longest = round(TINY['time_limit'] / paper_plan.CONTROL_TIMESTEP)
    assert figures['eval_seconds'] > 0
    assert figures['eval_ant_steps'] % (2 * n) == 0
    assert 0 < figures['eval_ant_steps'] <= 2 * n * longest
    marl_eval.check(figures['marl_eval'])
    assert list(figures['marl_eval']['coop_suite']) == [f'transport_n{n}']
  # The committed copy is the final checkpoint's policy: it evaluates on
  # its own exactly as the run's checkpoint, and resumes nothing.
  published = checkpoints.resolve(folder)
  assert checkpoints.read_state(published)['policy_only']
  assert 'opt_state' not in checkpoints.saved_learner(published,
                                                      'ant')['state']
  out = evaluate.evaluate(evaluate.EvalArgs(checkpoint=(folder,), episodes=1,
                                            envs=1))
  assert out['models'][0]['update'] == 2
  full = evaluate.evaluate(evaluate.EvalArgs(checkpoint=(logdir,),
                                             episodes=1, envs=1))
  assert out['models'][0]['episodes'] == full['models'][0]['episodes']
  zero_shot = [evaluate.evaluate(evaluate.EvalArgs(
      checkpoint=(path,), episodes=1, envs=1, n_agents=3))['models'][0]
               for path in (folder, logdir)]
  assert zero_shot[0]['episodes'] == zero_shot[1]['episodes']
  with pytest.raises(ValueError, match='policy only'):
    checkpoints.restore(published, {})
  # Nothing left to do: nothing logged, and Ray not even started.
  monkeypatch.setattr(actor_pool, 'init_ray',
                      lambda *a, **k: pytest.fail('Ray started'))
  paper.run_plan(dataclasses.replace(args, actors=2), plan, log=pytest.fail)


def test_a_large_metrics_csv_is_committed_gzipped_and_resumes_plain(
    controller, tiny_run, tmp_path, monkeypatch):  # pylint: disable=redefined-outer-name
  # A `flat` run's metrics.csv passes 5 MB; its stash and published copy
  # keep it gzipped, read as the plain file, and a resume writes plain.
  partial, done = _tiny_plan(controller)
  args = _args(tmp_path)
  logdir = paper.run_directory(partial, args)
  shutil.copytree(tiny_run, logdir)
  with open(os.path.join(logdir, 'metrics.csv'), 'rb') as f:
    plain = f.read()
  assert paper.stash(partial, args)  # Small: kept plain.
  assert os.path.exists(os.path.join(paper.partial_directory(partial, args),
                                     'metrics.csv'))
  monkeypatch.setattr(run_dir, 'PACK_ABOVE', len(plain) - 1)
  stashed = paper.stash(partial, args)
  assert sorted(os.listdir(stashed)) == ['checkpoints', 'controller',
                                         'metrics.csv.gz']
  assert run_dir.read_metrics(stashed) == run_dir.read_metrics(logdir)
  with open(os.path.join(stashed, 'metrics.csv.gz'), 'rb') as f:
    packed = f.read()
  assert paper.stash(partial, args) == stashed  # The same bytes again.
  with open(os.path.join(stashed, 'metrics.csv.gz'), 'rb') as f:
    assert f.read() == packed
  shutil.rmtree(args.runs)
  assert paper.unstash(partial, args)
  assert sorted(os.listdir(logdir)) == ['checkpoints', 'controller',
                                        'metrics.csv']
  with open(os.path.join(logdir, 'metrics.csv'), 'rb') as f:
    assert f.read() == plain
  _commit(done, args, {2: [1, 0]})
  paper.run_plan(args, [partial, done], log=lambda line: None)
  folder = paper.results_directory(partial, args)
  assert 'metrics.csv.gz' in os.listdir(folder)
  assert 'metrics.csv' not in os.listdir(folder)
  assert paper.is_done(partial, args)
  assert [r['update'] for r in run_dir.read_metrics(folder)] == [1, 2]
  assert [r['update'] for r in _rows(os.path.join(logdir, 'metrics.csv'))
          ] == ['1', '2']
  assert [r['update'] for r in plot._read_runs([folder], ['env_steps'])[0]
          ] == [1, 2]


def _plan_cells(*paths):
  by_path = {cell.path: cell for cell in paper_plan.PLAN}
  return [by_path[path] for path in paths]


def test_dry_run_estimates_at_the_pace_of_the_done_cells(tmp_path):
  """Each variant's remaining cells at the median Ant steps/s of its done
  cells (metrics.csv's last row); a variant without any at hrl's; a done
  cell without wall times counts for nothing."""
  args = _args(tmp_path)
  cells = _plan_cells('corridor/hrl/n4/s0', 'corridor/hrl/n4/s1',
                      'corridor/hrl/n4/s2', 'corridor/flat/n4/s0',
                      'corridor/hrl/n4/s3', 'corridor/flat/n4/s1',
                      'corridor/mappo/n6/s0')
  for cell, wall in zip(cells[:4], (100, 200, 400, 800)):
    _commit(cell, args, {n: [1] for n in cell.populations})
    with open(os.path.join(paper.results_directory(cell, args),
                           'metrics.csv'), 'w') as f:
      f.write(f'update,env_steps,wall_time\n1,4000,{wall / 2}\n'
              f'2,8000,{wall}\n')
  _commit(cells[4], args, {n: [1] for n in cells[4].populations})
  paces = paper.done_pace(paper.done_runs(args, cells))
  assert paces == {'hrl': [320.0, 160.0, 80.0], 'flat': [40.0]}
  rates = paper.estimate_rates(paces, ['mappo'])
  assert rates == {'hrl': 160.0, 'flat': 40.0, 'mappo': 160.0}
  assert not paper.estimate_rates({'flat': [40.0]}, ['hrl'])  # Constants.
  lines = paper.dry_run(args, cells).splitlines()
  total = 0.0
  for cell, line in zip(cells[5:], lines[6:]):
    seconds = paper_plan.estimated_seconds(cell, paper.budget(cell, args),
                                           args.episodes, rates[cell.agent])
    assert f'~{seconds / 3600:6.1f} h' in line
    total += seconds
  assert lines[-1] == (
      f'7 cells, ~{total / 3600:.0f} h of cell time to go at the pace of the '
      "done cells (Ant steps/s, median of the variant's: hrl 160 of 3, flat "
      "40 of 1, mappo at hrl's; as they ran, beside what ran with them)")


def test_dry_run_measures_the_pace_of_the_cells_running_now(tmp_path):
  """A claimed cell's metrics.csv gives its pace over its last 10 min of
  updates; the total is also given at the running cells' pace. A cell
  whose metrics.csv is stale, or that nobody claims, gives none."""
  crossers, corridor = cells = _plan_cells('ravine/hrl/crossers/n2/s1',
                                           'corridor/hrl/n4/s1')
  args = _args(tmp_path)
  logdir = paper.run_directory(crossers, args)
  os.makedirs(logdir)
  # 1,000 env steps/s for 300 s, then 5,000 for the last 600 s.
  with open(os.path.join(logdir, 'metrics.csv'), 'w') as f:
    f.write('update,env_steps,wall_time,success\n')
    steps = 0
    for update, wall in enumerate(range(0, 1000, 100)):
      steps += 100 * (1_000 if wall <= 300 else 5_000) if wall else 0
      f.write(f'{update + 1},{steps},{wall},\n')
  pace = 5_000 / paper_plan.estimated_rate(crossers)
  total = sum(paper_plan.estimated_seconds(c, paper.budget(c, args))
              for c in cells)
  with paper.claim(crossers, args):
    lines = paper.dry_run(args, cells).splitlines()
    assert lines[3] == ('  pace: 5,000 env steps/s over its last 10 min of '
                        f'updates, {pace:.2f}x the estimate')
    assert lines[-1] == (f'~{total / pace / 3600:.1f} h at the pace of the '
                         f'cell running now ({pace:.2f}x the estimate; the '
                         'rest run as many at a time on the same machines)')
    assert not any('pace:' in line for line in lines[4:-1])
    old = time.time() - paper.PACE_WINDOW - 60
    os.utime(os.path.join(logdir, 'metrics.csv'), (old, old))
    lines = paper.dry_run(args, cells).splitlines()
    assert lines[2].startswith('  running:')
    assert not any('pace:' in line or 'at the pace' in line for line in lines)
  os.utime(os.path.join(logdir, 'metrics.csv'))  # Fresh, unclaimed.
  assert 'pace:' not in paper.dry_run(args, cells)
  # Too little to measure: no rows, two rows, no steps made.
  for text in ('update,env_steps,wall_time\n',
               'update,env_steps,wall_time\n1,10,1\n2,20,2\n',
               'update,env_steps,wall_time\n1,10,1\n2,10,2\n3,10,3\n'):
    with open(os.path.join(logdir, 'metrics.csv'), 'w') as f:
      f.write(text)
    assert paper.measured_pace(crossers, args) is None


def test_finishes_within_judges_this_runs_pace_and_the_done_evaluations(
    tmp_path, monkeypatch):
  """The rest of the training at the pace of the updates past where this
  process resumed it, the evaluations at the done cells' measured pace;
  the fit is exact to the second (a minutes/seconds slip fails it)."""
  crossers, corridor = _plan_cells('ravine/hrl/crossers/n2/s1',
                                   'corridor/hrl/n4/s0')
  args = _args(tmp_path, episodes=100)
  logdir = paper.run_directory(crossers, args)
  os.makedirs(logdir)
  # An earlier session: 1,000 env steps/s up to 1M steps; this one (resumed
  # at 1M): 4,000 env steps/s, over 3 updates.
  with open(os.path.join(logdir, 'metrics.csv'), 'w') as f:
    f.write('update,env_steps,wall_time\n'
            '1,800000,800\n2,1000000,1000\n'
            '3,1400000,1100\n4,1800000,1200\n5,2200000,1300\n')
  budget = paper.budget(crossers, args)
  left = budget - 2_200_000
  # No done evaluation measured: its 100 episodes (2 Ants, each at its
  # full length) go at the training's pace too.
  full_length = 100 * paper_plan.EPISODE_SECONDS / paper_plan.CONTROL_TIMESTEP
  assert crossers.populations == (2,) and crossers.ants == 2
  exact = left / 4_000 + full_length / 4_000
  assert paper.finishes_within(crossers, args, 2_200_000, exact + 1e-6,
                               since_steps=1_000_000)
  assert not paper.finishes_within(crossers, args, 2_200_000, exact - 1,
                                   since_steps=1_000_000)
  # Every row, the first session's with them: a slower pace, no fit.
  assert not paper.finishes_within(crossers, args, 2_200_000, exact + 1e-6)
  # Fewer than 3 rows past the resume: no pace, no fit.
  assert not paper.finishes_within(crossers, args, 2_200_000, 1e9,
                                   since_steps=1_400_000)
  # A done cell trained at 1,000 env steps/s (4,000 Ant steps/s) over its
  # last 10 min, whose evaluations measured 0.5, 0.25 and 0.3 of that (one
  # without a wall time counts for nothing): their median share of the
  # training's pace for the evaluations, each episode at its full length.
  _commit(corridor, args, {n: [1] for n in corridor.populations})
  folder = paper.results_directory(corridor, args)
  with open(os.path.join(folder, 'metrics.csv'), 'w') as f:
    f.write('update,env_steps,wall_time\n1,1000,1\n2,2000,2\n3,3000,3\n')
  for n, measured in zip(corridor.populations, (
      (100, 200_000), (100, 100_000), (None, 100_000), (100, 120_000))):
    path = os.path.join(folder, paper.EVAL_FILE.format(n))
    with open(path) as f:
      figures = json.load(f)
    figures.update(eval_seconds=measured[0], eval_ant_steps=measured[1])
    evaluate.write_json(path, figures)
  shares = paper.eval_shares(paper.done_runs(args, [corridor]), args)
  assert sorted(shares) == [0.25, 0.3, 0.5]
  assert paper.eval_share(shares) == 0.3
  slower = left / 4_000 + full_length / (4_000 * 0.3)
  assert paper.finishes_within(crossers, args, 2_200_000, slower + 1e-6,
                               since_steps=1_000_000)
  assert not paper.finishes_within(crossers, args, 2_200_000, slower - 1,
                                   since_steps=1_000_000)
  # A done cell whose evaluations did not measure themselves: its metrics
  # are not read (only the running cell's and the measured one's are).
  other, = _plan_cells('corridor/hrl/n4/s1')
  _commit(other, args, {n: [1] for n in other.populations})
  read = []
  read_metrics = run_dir.read_metrics
  monkeypatch.setattr(run_dir, 'read_metrics',
                      lambda folder: read.append(folder) or read_metrics(
                          folder))
  assert paper.finishes_within(crossers, args, 2_200_000, slower + 1e-6,
                               since_steps=1_000_000)
  assert read == [logdir, folder]
  assert paper.dry_run(args, [crossers, corridor]).splitlines()[-1] == (
      '  evaluations (every episode at its full length) at 0.30x the '
      "training's Ant steps/s: the median of 3 done ones that measured "
      "themselves, each against its cell's last 10 min of training")
  monkeypatch.setattr(paper, 'eval_shares', lambda runs, args: [0.5])
  assert paper.dry_run(args, [crossers, corridor]).splitlines()[-1] == (
      '  evaluations (every episode at its full length) at 0.50x the '
      "training's Ant steps/s: the one done evaluation that measured "
      "itself, against its cell's last 10 min of training")


class _FakeCellProcess:
  """A cell's process as `paper.run_concurrently` sees it: a child that
  sleeps `seconds` (or until the file `until` exists, if sooner) and exits
  with `status` (143 on SIGTERM)."""

  def __init__(self, seconds, status=0, until=None):
    self._child = subprocess.Popen([sys.executable, '-c', (
        'import os, signal, sys, time\n'
        'signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))\n'
        'print("ready", flush=True)\n'
        f'end = time.monotonic() + {seconds}\n'
        f'while time.monotonic() < end and not ({until!r} and '
        f'os.path.exists({until!r})):\n'
        '  time.sleep(0.01)\n'
        f'sys.exit({status})')], stdout=subprocess.PIPE, text=True)
    assert self._child.stdout.readline() == 'ready\n'  # Its handler is in.
    self.pid = self._child.pid

  @property
  def exitcode(self):
    return self._child.poll()


def test_concurrent_cells_fill_their_slots_and_wait_for_their_stages(
    tmp_path, monkeypatch):
  monkeypatch.setattr(paper, 'POLL_SECONDS', 0.05)
  pushers, crossers, joint, corridor = cells = _plan_cells(
      'ravine/hrl/pushers/n2/s1', 'ravine/hrl/crossers/n2/s1',
      'ravine/hrl/n2/s1', 'corridor/hrl/n4/s1')
  # The crossers outlast the pushers by far: on a busy machine too, the
  # corridor takes the pushers' slot before the joint cell can start.
  seconds = {pushers: 0.3, crossers: 3.0, joint: 0.1, corridor: 0.2}
  args = _args(tmp_path, concurrent=2)
  started, lines = {}, []

  def start(cell, own, deadline):
    running = [c for c, p in started.items() if p.exitcode is None]
    assert len(running) < 2  # Never more than --concurrent at once.
    if cell == joint:  # Only once both its stages have ended.
      assert started[pushers].exitcode == 0 == started[crossers].exitcode
    # Each process trains its one cell as coop-paper would, no bars.
    assert (own.concurrent, own.progress, own.results, deadline) == (
        1, False, args.results, None)
    started[cell] = _FakeCellProcess(seconds[cell])
    return started[cell]

  assert paper.run_concurrently(args, cells, lines.append, None,
                                start=start) is None
  # The corridor took the slot the pushers left, as the joint cell waited.
  assert list(started) == [pushers, crossers, corridor, joint]
  assert all(p.exitcode == 0 for p in started.values())
  starts = [f'{c.path}: starts in a process of its own' for c in started]
  assert lines == [*starts[:2], f'{joint.path}: waits for its stage cells',
                   *starts[2:]]


def test_processes_sharing_the_runs_pass_over_each_others_cells(
    tmp_path, monkeypatch, capsys):
  """Another coop-paper (here: a claim held in this process, which flock
  tells apart as another open file) runs the pushers stage: this one passes
  it over, and the joint cell too unless the stage is published meanwhile;
  every other cell runs under its claim, and no claim is left behind."""
  pushers, crossers, joint, corridor = cells = _plan_cells(
      'ravine/hrl/pushers/n2/s1', 'ravine/hrl/crossers/n2/s1',
      'ravine/hrl/n2/s1', 'corridor/hrl/n4/s1')
  args = _args(tmp_path)
  ran = []

  def run_cell(cell, args, log, deadline, publishes=None):
    with pytest.raises(paper.CellTaken, match=f'^{cell.path}: run by another'):
      with paper.claim(cell, args):
        pass  # Held by the process that runs it.
    ran.append(cell)
    if cell == crossers and publishes:  # The other process ends meanwhile.
      _commit(publishes, args, {2: [1, 0]})
  holder = f'{os.getpid()} {socket.gethostname()}'
  taken = (f'{pushers.path}: run by another coop-paper (pid, host: '
           f'{holder}); passed over')
  with paper.claim(pushers, args):
    # --dry-run names the holder (and the probe leaves the claim held).
    text = paper.dry_run(args, cells).splitlines()
    assert text[2] == f'  running: coop-paper pid, host {holder}'
    assert text[1].startswith(pushers.path)
    assert not any('running' in line for line in text[3:])
    with pytest.raises(paper.CellTaken):
      with paper.claim(pushers, args):
        pass
    monkeypatch.setattr(paper, 'run_cell', run_cell)
    lines = []
    assert paper.run_plan(args, cells, lines.append) == paper.ELSEWHERE
    assert ran == [crossers, corridor]
    assert lines == [taken, f'{joint.path}: starts from '
                     'ravine_hrl_pushers_n2_s1, which another coop-paper '
                     'runs; passed over']
    ran, lines = [], []
    monkeypatch.setattr(paper, 'run_cell', functools.partial(
        run_cell, publishes=pushers))
    # Nothing is left undone: the passed-over cell was published.
    assert paper.run_plan(args, cells, lines.append) is None
    assert ran == [crossers, joint, corridor] and lines == [taken]
    # --stash leaves a cell that another process runs alone.
    paper.main([f'--results={args.results}', f'--runs={args.runs}',
                f'--partial={args.partial}', '--stash',
                f'--only={pushers.path}'])
    assert capsys.readouterr().out.splitlines()[0] == (
        f'{pushers.path}: run by another coop-paper (pid, host: {holder}): '
        'not stashed')
  assert os.listdir(os.path.join(args.runs, paper.CLAIMS)) == []
  assert 'running' not in paper.dry_run(args, cells)
  # A cell that fails lets go of its claim.
  def failing(cell, *_):
    raise ValueError(f'{cell.path} failed')
  monkeypatch.setattr(paper, 'run_cell', failing)
  with pytest.raises(ValueError, match=f'{crossers.path} failed'):
    paper.run_plan(args, [crossers], log=lambda line: None)
  with paper.claim(crossers, args):
    pass
  # Its exit status says: run it again once the others have ended.
  monkeypatch.setattr(paper, 'run_plan', lambda *a, **k: paper.ELSEWHERE)
  with pytest.raises(SystemExit) as exit_info:
    paper.main([f'--results={args.results}', f'--runs={args.runs}',
                f'--partial={args.partial}', '--actors=0'])
  assert exit_info.value.code == paper.EXIT_RUN_ELSEWHERE == 3
  assert 'run by other coop-paper processes' in capsys.readouterr().out


def test_concurrent_cells_pass_over_cells_run_elsewhere(tmp_path,
                                                        monkeypatch):
  monkeypatch.setattr(paper, 'POLL_SECONDS', 0.05)
  pushers, crossers, joint, corridor = cells = _plan_cells(
      'ravine/hrl/pushers/n2/s1', 'ravine/hrl/crossers/n2/s1',
      'ravine/hrl/n2/s1', 'corridor/hrl/n4/s1')
  started, lines = [], []

  def start(cell, own, deadline, seconds=0.1, until=None):
    started.append(cell)  # The pushers' process finds them claimed.
    return _FakeCellProcess(seconds, paper.EXIT_RUN_ELSEWHERE
                            if cell == pushers else 0, until=until)
  args = _args(tmp_path, concurrent=2)
  assert paper.run_concurrently(args, cells, lines.append, None,
                                start=start) == paper.ELSEWHERE
  assert started == [pushers, crossers, corridor]
  assert (f'{joint.path}: starts from ravine_hrl_pushers_n2_s1, which '
          'another coop-paper runs; passed over') in lines
  # Published by the other process while the crossers trained here: the
  # joint cell starts once both stages are in, and nothing is left. The
  # crossers train until the corridor has taken the pushers' slot (on a
  # busy machine both 0.1 s processes could end before one look).
  started, lines = [], []
  corridor_started = tmp_path / 'corridor_started'

  def start_publishing(cell, own, deadline):
    if cell == crossers:
      _commit(pushers, args, {2: [1, 0]})
      return start(cell, own, deadline, 60, str(corridor_started))
    if cell == corridor:
      corridor_started.touch()
    return start(cell, own, deadline)
  assert paper.run_concurrently(args, cells, lines.append, None,
                                start=start_publishing) is None
  assert started == [pushers, crossers, corridor, joint]


def test_concurrent_cells_stop_together(tmp_path, monkeypatch):
  monkeypatch.setattr(paper, 'POLL_SECONDS', 0.05)
  first, second, third = cells = _plan_cells(
      'corridor/hrl/n4/s1', 'corridor/hrl/n4/s2', 'corridor/hrl/n4/s3')
  args = _args(tmp_path, concurrent=2, hours=1.0)
  lines = []

  # Out of --hours: the running cell's process stops and stashes itself
  # (exit status 75) and no other starts.
  clock = {'now': 0.0}
  monkeypatch.setattr(run_dir, 'clock', lambda: clock['now'])

  # The cells' processes stash themselves only once the loop has seen the
  # deadline (a busy machine may take longer to start the second than a
  # fixed sleep would give the first).
  seen = str(tmp_path / 'deadline_seen')

  def start(cell, own, deadline):
    assert deadline == 3600.0
    clock['now'] = 4000.0
    return _FakeCellProcess(30, paper.EXIT_OUT_OF_TIME, until=seen)

  def log(line):
    lines.append(line)
    if line.startswith('Out of time'):
      open(seen, 'w').close()
  assert paper.run_concurrently(args, cells, log, 3600.0,
                                start=start) == run_dir.DEADLINE
  assert lines == [f'{first.path}: starts in a process of its own',
                   f'{second.path}: starts in a process of its own',
                   f'Out of time (--hours 1) before {third.path}.']
  monkeypatch.undo()
  monkeypatch.setattr(paper, 'POLL_SECONDS', 0.05)

  # A signal goes on to every running cell (each stops after its update:
  # here exit status 143), and no other starts.
  started = []

  def start_then_signal(cell, own, deadline):
    started.append(_FakeCellProcess(30))
    if len(started) == 2:
      threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
    return started[-1]
  assert paper.run_concurrently(args, cells, lambda line: None, None,
                                start=start_then_signal) == 'SIGTERM'
  assert [p.exitcode for p in started] == [143, 143]

  # A cell that fails: the other one runs to its end, none starts after,
  # and the failure is raised.
  started = []

  def start_failing(cell, own, deadline):
    started.append(_FakeCellProcess(0.05 if cell == first else 0.5,
                                    1 if cell == first else 0))
    return started[-1]
  lines = []
  with pytest.raises(paper.CellFailed,
                     match=f'^{first.path} \\(exit status 1\\) failed'):
    paper.run_concurrently(args, cells, lines.append, None,
                           start=start_failing)
  assert [p.exitcode for p in started] == [1, 0]
  assert lines[-1] == (f'{first.path} (exit status 1): failed; no other '
                       'cell starts')
  # How a cell's process ended, from its exit status: a stop is one only
  # for the signals passed on; after one, dying by it is its stop too.
  for stopped in (None, run_dir.DEADLINE, paper.ELSEWHERE, 'SIGINT',
                  'SIGTERM'):
    assert paper._ended(paper.exit_status(stopped), None) == stopped  # pylint: disable=protected-access
  for status in (1, 2, -9, -15, 128 + signal.SIGKILL):
    assert paper._ended(status, None) == ''  # pylint: disable=protected-access
  for status in (1, -2, -15):
    assert paper._ended(status, 'SIGTERM') == 'SIGTERM'  # pylint: disable=protected-access
  assert paper._ended(2, 'SIGTERM') == ''  # pylint: disable=protected-access
  assert paper._failure(first, -9) == f'{first.path} (killed by SIGKILL)'  # pylint: disable=protected-access


def test_concurrent_cells_need_one_ray_or_none(tmp_path, monkeypatch):
  """Each process would start a Ray of its own: refused before anything
  starts, unless they all join one cluster."""
  monkeypatch.delenv('RAY_ADDRESS', raising=False)
  monkeypatch.setattr(paper, 'run_concurrently', lambda *a: 'ran')
  with pytest.raises(ValueError, match='--concurrent 2 .* --actors 0'):
    paper.run_plan(_args(tmp_path, concurrent=2, actors=2), log=pytest.fail)
  for overrides in ({'actors': 0}, {'actors': 2, 'ray_address': 'h:6379'}):
    assert paper.run_plan(_args(tmp_path, concurrent=2, **overrides),
                          log=pytest.fail) == 'ran'
  monkeypatch.setenv('RAY_ADDRESS', 'h:6379')
  assert paper.run_plan(_args(tmp_path, concurrent=2, actors=2),
                        log=pytest.fail) == 'ran'


def test_a_failed_concurrent_cell_is_one_line_and_exit_status_1(
    tmp_path, monkeypatch, capsys):
  def failing(*_):
    raise paper.CellFailed('corridor/hrl/n4/s1 (killed by SIGKILL) failed '
                           '(its error, if any, is above).')
  monkeypatch.setattr(paper, 'run_concurrently', failing)
  with pytest.raises(SystemExit) as exit_info:
    paper.main([f'--results={tmp_path}/r', f'--runs={tmp_path}/u',
                f'--partial={tmp_path}/p', '--actors=0', '--concurrent=2'])
  assert exit_info.value.code == 1
  assert capsys.readouterr().err == (
      'coop-paper: error: corridor/hrl/n4/s1 (killed by SIGKILL) failed '
      '(its error, if any, is above).\n')


def _share_compilation_cache(monkeypatch):
  """Child processes (a cell's own, a script's) compile into the suite's
  XLA cache (conftest.py) through the environment."""
  import jax  # pylint: disable=g-import-not-at-top
  for name in ('jax_compilation_cache_dir',
               'jax_persistent_cache_min_compile_time_secs',
               'jax_persistent_cache_min_entry_size_bytes'):
    monkeypatch.setenv(name.upper(), str(getattr(jax.config, name)))


def test_a_concurrent_cell_trains_and_publishes_in_its_own_process(
    controller, tiny_run, tmp_path, capfd, monkeypatch):  # pylint: disable=redefined-outer-name
  _share_compilation_cache(monkeypatch)
  partial, done = plan = _tiny_plan(controller)
  args = _args(tmp_path, concurrent=2)
  shutil.copytree(tiny_run, paper.run_directory(partial, args))
  _commit(done, args, {2: [1, 0]})
  assert paper.run_plan(args, plan, log=print) is None
  out = capfd.readouterr().out
  assert f'{partial.path}: starts in a process of its own' in out
  assert f'{done.path}: starts' not in out  # Done: skipped.
  assert f'{partial.path}: done, results in' in out  # Said by its process.
  assert paper.status(partial, args).state == 'done'
  assert [int(r['update']) for r in _rows(os.path.join(
      paper.results_directory(partial, args), 'metrics.csv'))] == [1, 2]


# A cell's process, with `paper`, `cell` and `args` given: records which
# of the project's modules its evaluation imports (those it did not hold
# when its training ended), then runs the cell as coop-paper does.
_IMPORTS_AT_EVALUATION = """
import json, sys
project = ('agents', 'coop_suite', 'runners')
held = lambda: {m for m in sys.modules if m.split('.')[0] in project}
evaluate_cell, imported = paper.evaluate_cell, []
def recorded(*args, **kwargs):
  before = held()
  out = evaluate_cell(*args, **kwargs)
  imported.extend(sorted(held() - before))
  return out
paper.evaluate_cell = recorded
assert paper.run_cell(cell, args, log=lambda line: None) is None
print(json.dumps(imported))
"""


def test_a_cell_evaluates_with_the_code_it_trained_with(
    controller, tiny_run, tmp_path, monkeypatch):  # pylint: disable=redefined-outer-name
  """Its evaluation imports nothing after its training: code edited on
  disk while a cell trains (a pull into the checkout) cannot give it an
  evaluation module newer than the modules it trained with."""
  _share_compilation_cache(monkeypatch)
  cell = _tiny_plan(controller)[0]
  args = _args(tmp_path)
  shutil.copytree(tiny_run, paper.run_directory(cell, args))  # 1 update of 2.
  script = (f'from runners import paper, paper_plan\n'
            f'cell = paper_plan.{cell!r}\nargs = paper.{args!r}\n'
            + _IMPORTS_AT_EVALUATION)
  done = subprocess.run([sys.executable, '-c', script], cwd=REPO,
                        capture_output=True, text=True, timeout=300)
  assert done.returncode == 0, done.stderr[-3000:]
  assert json.loads(done.stdout.strip().splitlines()[-1]) == []
  assert paper.status(cell, args).state == 'done'


def test_report_rebuilds_the_tables_from_committed_results(tmp_path, capsys,
                                                          monkeypatch):
  args = _args(tmp_path, episodes=4)
  hrl = [c for c in paper_plan.PLAN if (c.experiment, c.task, c.agent) ==
         ('table1', 'transport', 'hrl') and not c.stage]
  _commit(hrl[0], args, {4: [1, 1, 0, 0], 2: [0, 0, 0, 1], 3: [1] * 4,
                         5: [0] * 4})
  _commit(hrl[1], args, {4: [1, 0, 0, 0], 2: [0] * 4, 3: [1] * 4,
                         5: [0] * 4})
  # Seed 0's push stage is committed, seed 1's is not (its steps read '?').
  (_, push), = hrl[0].init_from
  _commit(next(c for c in paper_plan.PLAN if c.name == push), args,
          {4: [0] * 4}, env_steps=3_000_000)
  # An unfinished corridor run committed as a stash.
  corridor = next(c for c in paper_plan.PLAN if c.path == 'corridor/hrl/n4/s0')
  _fake_run(paper.partial_directory(corridor, args),
            paper.train_args(corridor, args), 8_040_000)
  text = paper_report.report(args)
  # 3 of 8 episodes: 37.5% +- std(ddof=1) / sqrt(8) = 18.3; the models'
  # rates 50% and 25%: +- 12.5 between them.
  row = next(line for line in text.splitlines()
             if line.startswith('| transport (4 Ants) | HRL |'))
  assert row == ('| transport (4 Ants) | HRL | 37.5% +- 18.3 | +- 12.5 | 2/5 '
                 '| 20M + ?/20M + 3M | 76.8% +- 5.3 | 55% +- 5 | 54% +- 5 |')
  assert ('| transport | 2 Ants | 12.5% +- 12.5 | +- 12.5 | 2/5 | '
          '20M + ?/20M + 3M | 12.8% +- 5.6 | 12% +- 3 | 12% +- 3 |') in text
  assert '| corridor (4 Ants) | HRL | not run |  | 0/5 |' in text
  # The committed push stage in the stages' table, at its own task; stages
  # with no committed model are left out.
  assert ('| transport | HRL | push | 4 Ants | 0.0% +- 0.0 |  | 1/5 | 3M |'
          in text)
  assert '| ravine | HRL | pushers |' not in text
  assert '| 4 | 37.5% +- 18.3 | +- 12.5 | 2/3 |' in text  # Fig. 4a.
  assert ('coop-train --seed 1 --actors 0 --envs-per-actor 32 --total-steps '
          '12000000 --logdir') in text
  assert ('coop-train --seed 1 --actors 0 --envs-per-actor 32 --total-steps '
          '3000000 --logdir') in text
  assert '# transport/hrl/n4/s1 (done)' in text
  assert '# corridor/hrl/n4/s0 (stashed at 8.04M/15M)' in text
  assert '# corridor/hrl/n4/s1 (not run)' in text
  # Into a marked block of a markdown file, again and again.
  docs = tmp_path / 'results.md'
  docs.write_text('# Results\n\nBefore.\n')
  images = tmp_path / 'images'
  for _ in range(2):
    paper.main(cli.command_line(args, 'coop-paper').split()[1:] + [
        '--report', '--docs', str(docs), '--json', str(tmp_path / 'all.json'),
        '--figures', str(images)])
    written = docs.read_text()
    assert written.startswith('# Results\n\nBefore.\n')
    assert written.count(paper_report.BEGIN) == 1
    assert text.strip().split('### Commands')[0].strip() in written
  # The learning curves of what is committed, linked from the page: Table
  # 1's transport (HRL's two models), Fig. 4a (4 Ants) and Fig. 5 from the
  # model whose episodes record their start (seed 1); nothing else.
  assert sorted(os.listdir(images)) == ['fig4a_transport_populations.png',
                                        'fig5_transport_starts.png',
                                        'table1_transport.png']
  assert '](images/table1_transport.png)' in written
  assert imageio.v2.imread(images / 'table1_transport.png').ndim == 3
  data = json.loads((tmp_path / 'all.json').read_text())
  marl_eval.check(data)
  assert sorted(data['coop_suite']) == [  # The push stage is its own task.
      *[f'transport_n{n}' for n in (2, 3, 4, 5)], 'transport_push_n4']
  assert sorted(data['coop_suite']['transport_n4']['hrl']) == ['seed_0',
                                                               'seed_1']
  assert 'Wrote the tables' in capsys.readouterr().out
  # A transport model's curve begins with its committed push stage.
  from runners import plot  # pylint: disable=g-import-not-at-top
  drawn = {}
  monkeypatch.setattr(plot, 'plot_groups', lambda groups, columns, out,
                      title: drawn.setdefault(os.path.basename(out), groups))
  paper_report.figures(args, paper_plan.PLAN, str(images))
  results = [paper.results_directory(c, args) for c in hrl[:2]]
  assert drawn['table1_transport.png']['HRL'] == [
      f'{os.path.join(args.results, push)}+{results[0]}', results[1]]
  # The ravine's pushers stage acts with pushers only (its crossers are
  # markers), and says so.
  pushers = next(c for c in paper_plan.PLAN if c.stage == 'pushers')
  _commit(pushers, args, {2: [1, 1, 1, 0]}, env_steps=10_000_000)
  assert ('| ravine | HRL | pushers | 2 pushers (2 markers) | 75.0% +- 25.0 '
          '|  | 1/5 | 10M |') in paper_report.report(args)
  # Fig. 4b, c: beside success, the Ants through an episode, ours and the
  # references' (their per-episode figures in results/baselines).
  mappo = next(c for c in paper_plan.PLAN if (c.experiment, c.agent,
                                              c.n_agents) == ('mappo',
                                                              'mappo', 6))
  _commit(mappo, args, {6: [0, 1, 0, 0]}, crossed=[2, 6, 3, 1])
  through = []
  for policy in ('greedy', 'oracle'):
    with open(os.path.join(BASELINES, f'corridor_n6_{policy}.json')) as f:
      episodes = [e['crossed'] for e in json.load(f)['per_episode']]
    through.append(f'{sum(episodes) / len(episodes):.2f}')
  row = next(line for line in paper_report.report(args).splitlines()
             if line.startswith('| 6 | MAPPO (`mappo`) |'))
  assert row.split(' | ')[7] == '3.00 +- 1.08'  # std(ddof=1) / sqrt(4).
  assert row.split(' | ')[-1] == ' / '.join(through) + ' |'
  # An older evaluation without the figure: left blank, not an error.
  _commit(mappo, args, {6: [0, 1, 0, 0]})
  row = next(line for line in paper_report.report(args).splitlines()
             if line.startswith('| 6 | MAPPO (`mappo`) |'))
  assert row.split(' | ')[6:8] == ['25 +- 25', '']
  assert '| 7 | IPPO (`hrl`) | not run |  | 0/3 |  |  |  |' in text
  # Runs end a few steps past their budget: the same figure is given once.
  _commit(next(c for c in paper_plan.PLAN if c.stage == 'pushers'
               and c.agent == pushers.agent and c.seed == pushers.seed + 1),
          args, {2: [1, 1, 1, 1]}, env_steps=10_001_024)
  assert ('| ravine | HRL | pushers | 2 pushers (2 markers) | 87.5% +- 12.5 '
          '| +- 12.5 | 2/5 | 10M |') in paper_report.report(args)


def test_a_reference_replays_coop_evals_episodes_and_pairs(tiny_run, tmp_path,
                                                          capsys):
  """`runners.baselines --envs` plays the episodes `coop-eval --envs` does
  (each copy's share in turn from `copy_seeds`): coop-compare pairs them,
  checking transport's recorded starts episode by episode."""
  model = tmp_path / 'model.json'
  evaluate.main(['--checkpoint', tiny_run, '--episodes', '5', '--envs', '2',
                 '--seeds', '7', '--json', str(model)])
  assert evaluate.shares(5, 2) == [3, 2]
  args = dict(task='transport', n_agents=2, policy='random', episodes=5,
              seed=7, time_limit=TINY['time_limit'], progress=False)
  reference = tmp_path / 'reference.json'
  reference.write_text(json.dumps(baselines.play(
      baselines.BaselineArgs(**args, envs=2))))
  capsys.readouterr()
  out = compare.compare(compare.CompareArgs(
      evaluations=(str(model), str(reference))))
  assert out['models'][-1]['episodes'] == 5
  assert baselines.played_on(json.loads(reference.read_text())) == (
      'coop-eval --seeds 7 --envs 2')
  # One copy's episodes are another start: the pairing check refuses them.
  one_copy = tmp_path / 'one_copy.json'
  one_copy.write_text(json.dumps(baselines.play(
      baselines.BaselineArgs(**args, envs=1))))
  with pytest.raises(ValueError, match='start_agent_cylinder of episode'):
    compare.compare(compare.CompareArgs(
        evaluations=(str(model), str(one_copy))))
  # A fresh environment per episode (the tables' references) cannot pair.
  fresh = tmp_path / 'fresh.json'
  fresh.write_text(json.dumps(baselines.play(
      baselines.BaselineArgs(**{**args, 'episodes': 1}))))
  with pytest.raises(ValueError, match='fresh.json: a random reference on '
                     'seeds 7-7, a fresh environment per episode'):
    compare.load([str(model), str(fresh)])


def test_eval_json_follows_marl_eval_layout(tiny_run, tmp_path, capsys):
  path = tmp_path / 'eval.json'
  checkpoint = checkpoints.resolve(tiny_run)
  evaluate.main(['--checkpoint', tiny_run, checkpoint, '--episodes', '3',
                 '--envs', '2', '--json', str(path)])
  assert f'marl-eval JSON: {path}' in capsys.readouterr().out
  data = json.loads(path.read_text())
  marl_eval.check(data)
  # The README's layout, level by level.
  runs = data['coop_suite']['transport_n2']['hrl']
  assert list(runs) == ['seed_0', 'seed_0_2']
  for run in runs.values():
    assert list(run) == ['step_1', 'absolute_metrics']
    step = run['step_1']
    assert step['step_count'] == STEPS
    metrics = sorted(k for k in step if k != 'step_count')
    assert {'return', 'success'} <= set(metrics)
    assert all(len(step[k]) == 3 for k in metrics)
    assert all(v in (0.0, 1.0) for v in step['success'])
    assert sorted(run['absolute_metrics']) == metrics
  # A probe's runs are named apart, in algorithm_name's order; coop-compare
  # still pairs them with the protocol's episodes.
  probe = tmp_path / 'probe.json'
  evaluate.main(['--checkpoint', tiny_run, '--episodes', '3', '--envs', '2',
                 '--option', 'target_radius=1.5', '--reset-memory', 'ant',
                 '--time-limit', '0.8', '--stochastic', '--json', str(probe)])
  played = json.loads(probe.read_text())
  marl_eval.check(played)
  assert list(played['coop_suite']['transport_n2']) == [
      'hrl+stochastic+reset_memory=ant+time_limit=0.8+target_radius=1.5']
  capsys.readouterr()
  compared = compare.compare(compare.CompareArgs(
      evaluations=(str(path), str(probe))))
  assert compared['models'][-1]['episodes'] == 3
  # What check() refuses.
  broken = json.loads(path.read_text())
  run = broken['coop_suite']['transport_n2']['hrl']['seed_0']
  run['step_1']['step_count'] = 1.5
  with pytest.raises(ValueError, match='step_count must be an int'):
    marl_eval.check(broken)
  run['step_1']['step_count'] = 16
  run['step_2'] = run.pop('absolute_metrics')
  with pytest.raises(ValueError, match='last entry'):
    marl_eval.check(broken)
  run['absolute_metrics'] = run.pop('step_2')
  run['step_1']['success'] = []
  with pytest.raises(ValueError, match='non-empty list'):
    marl_eval.check(broken)
