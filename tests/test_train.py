"""coop-train and coop-eval on tiny budgets: every variant learns in one
process, checkpoints resume, Ray actors collect and survive `kill -9`."""
import concurrent.futures
import csv
import dataclasses
import os
import re
import shutil
import signal
import threading
import time
import types

import imageio
import jax
import numpy as np
import pytest

import coop_suite
from coop_suite import camera
from agents import normalization
from agents import observations as obs_lib
from agents.hierarchy import builder as hierarchy_builder
from agents.hierarchy import config as hierarchy_config
from agents.lowlevel import controller as controller_lib
from agents.networks import policy_value
from agents.ppo import config as ppo_config
from runners import actor_pool
from runners import checkpoints
from runners import cli
from runners import config as config_lib
from runners import envs as envs_lib
from runners import evaluate
from runners import learner_loop
from runners import rollout
from runners import run_dir
from runners import train
from runners import video as video_lib

# 2 copies x 4 commands of 0.1 s (2 control steps): 16 env steps/update.
TINY = dict(n_agents=2, actors=0, envs_per_actor=2, command_period=0.1,
            sequence_length=4, num_minibatches=2, num_epochs=1,
            upper_layer_sizes=(16,), middle_layer_size=8, head_sizes=(8,),
            critic_sizes=(8,), flat_sizes=(16,), time_limit=0.8,
            progress=False)
STEPS = 16
# Ray and ffmpeg start processes with fork + exec, which JAX's fork warning
# cannot tell from a bare fork.
pytestmark = pytest.mark.filterwarnings('ignore:os.fork:RuntimeWarning')
VARIANT_TASKS = {'hrl': 'transport', 'no_memory': 'corridor',
                 'flat': 'ravine', 'mappo': 'ravine'}


@pytest.fixture(scope='module')
def controller(tmp_path_factory):
  """A tiny random lower layer in the shipped format."""
  directory = str(tmp_path_factory.mktemp('controller'))
  spec = coop_suite.load('walk_to_target').observation_spec()[0]
  keys = obs_lib.observation_keys(spec)
  sizes = obs_lib.observation_sizes(spec, keys)
  networks = policy_value.make_policy_value_networks(sum(sizes), 8, (8,), (8,))
  run_dir.write_directory(directory, controller_lib.files(
      networks.init(jax.random.PRNGKey(0))['policy'],
      normalization.init(sum(sizes)),
      {'paradigm': 'position', 'observation_keys': list(keys),
       'observation_sizes': list(sizes), 'action_size': 8,
       'ppo_config': dataclasses.asdict(ppo_config.PPOConfig(
           policy_hidden=(8,), value_hidden=(8,)))}))
  return directory


def _args(logdir, controller, **overrides):
  values = {**TINY, 'task': 'transport', 'logdir': str(logdir),
            'controller': controller, 'total_steps': 2 * STEPS, **overrides}
  if values['task'] == 'ravine':
    values.update(n_agents=1, n_pushers=1)
  return config_lib.train_args(**values)


def _argv(controller, total_steps):  # pylint: disable=redefined-outer-name
  """The flags of `_args` for the CLI (without --task and --logdir)."""
  args = config_lib.train_args(**TINY, controller=controller,
                               total_steps=total_steps)
  return cli.command_line(args, 'coop-train',
                          skip=('task', 'logdir')).split()[1:]


def _rows(logdir):
  with open(os.path.join(logdir, 'metrics.csv')) as f:
    return list(csv.DictReader(f))


def _fresh_learner(checkpoint, species):
  """A newly built learner of `species` with the checkpoint's settings."""
  state = checkpoints.read_state(checkpoint)
  config = hierarchy_config.HierarchyConfig(**state['agent_config'])
  saved = next(s for s in state['species'] if s['name'] == species)
  builder = hierarchy_builder.HierarchyBuilder(config, saved['species_id'])
  return builder.make_learner(builder.make_networks(
      saved['observation_size'], saved['action_size'],
      saved['global_state_size']))


def _restored_learner(checkpoint, species='ant'):
  learner = _fresh_learner(checkpoint, species)
  learner.restore(checkpoints.saved_learner(checkpoint, species))
  return learner


def _learner_params(checkpoint, species):
  """(initial params, checkpointed params) of one species."""
  learner = _fresh_learner(checkpoint, species)
  initial = jax.device_get(learner.get_variables(['params'])[0])
  learner.restore(checkpoints.saved_learner(checkpoint, species))
  return initial, jax.device_get(learner.get_variables(['params'])[0])


@pytest.fixture(scope='module')
def hrl_run(tmp_path_factory, controller):
  """Two updates of 'hrl' through the real CLI, in one process."""
  logdir = str(tmp_path_factory.mktemp('runs') / 'hrl')
  train.main(['--task', 'transport', '--logdir', logdir,
              *_argv(controller, 2 * STEPS)])
  return logdir


def test_a_stage_the_task_lacks_is_refused_before_the_run_starts(
    controller, tmp_path, capsys):
  logdir = tmp_path / 'pushers'
  with pytest.raises(SystemExit) as exit_info:
    train.main(['--task', 'transport', '--stage', 'pushers', '--logdir',
                str(logdir), *_argv(controller, STEPS)])
  assert exit_info.value.code == 2
  out, err = capsys.readouterr()
  assert "stage 'pushers'" in err
  assert 'Writing to' not in out  # Refused before the run was started.
  assert not logdir.exists()


@pytest.mark.parametrize('agent', sorted(VARIANT_TASKS))
def test_variant_trains_in_process(agent, controller, hrl_run, tmp_path):
  # 'flat' acts every control step: 8 env steps per update.
  total = 2 * (STEPS // 2 if agent == 'flat' else STEPS)
  if agent == 'hrl':
    logdir = hrl_run
  else:
    logdir = str(tmp_path / agent)
    learner_loop.train(_args(logdir, controller, agent=agent,
                             task=VARIANT_TASKS[agent], total_steps=total))
  rows = _rows(logdir)
  assert [int(r['update']) for r in rows] == [1, 2]
  assert int(rows[-1]['env_steps']) == total
  losses = [k for k in rows[0] if k.startswith('learner/')]
  assert losses and all(np.isfinite(float(r[k])) for r in rows for k in losses)
  last = checkpoints.resolve(logdir)
  species = [s['name'] for s in checkpoints.read_state(last)['species']]
  assert species == (['crosser', 'pusher'] if VARIANT_TASKS[agent] == 'ravine'
                     else ['ant'])
  for name in species:
    initial, trained = _learner_params(last, name)
    moved = [not np.array_equal(a, b) for a, b in
             zip(jax.tree.leaves(initial), jax.tree.leaves(trained))]
    assert all(moved), (agent, name)
  if agent in ('no_memory', 'flat'):  # Nothing carried to reset.
    with pytest.raises(ValueError, match='--reset-memory:.*carries no memory'):
      evaluate.evaluate(evaluate.EvalArgs(checkpoint=(logdir,), episodes=1,
                                          envs=1, reset_memory=tuple(species)))
  if agent == 'no_memory':  # Refused before the first model plays.
    heard = []
    with pytest.raises(ValueError, match='--reset-memory: ant.s policy in '
                       f'{re.escape(logdir)} .*carries no memory'):
      evaluate.evaluate(evaluate.EvalArgs(checkpoint=(hrl_run, logdir),
                                          episodes=1, envs=1,
                                          reset_memory=('ant',)),
                        log=heard.append)
    assert not heard


def test_checkpoints_keep_the_newest_and_resume_continues(controller, hrl_run,
                                                          tmp_path):
  logdir = str(tmp_path / 'resumed')
  shutil.copytree(hrl_run, logdir)
  first = checkpoints.read_state(checkpoints.resolve(logdir))
  assert (first['update'], first['env_steps']) == (2, 2 * STEPS)
  with pytest.raises(FileExistsError, match='--resume'):
    learner_loop.train(_args(logdir, controller))
  with pytest.raises(ValueError, match='--agent'):
    learner_loop.train(_args(logdir, controller, agent='no_memory',
                             resume=True))
  summary = learner_loop.train(_args(logdir, controller, resume=True,
                                     total_steps=5 * STEPS))
  assert (summary['update'], summary['env_steps']) == (5, 5 * STEPS)
  assert [int(r['update']) for r in _rows(logdir)] == [1, 2, 3, 4, 5]
  kept = checkpoints.list_checkpoints(logdir)
  assert [os.path.basename(p) for p in kept] == ['3', '4', '5']
  state = checkpoints.read_state(kept[-1])
  assert state['episodes'] > first['episodes']
  assert state['args']['total_steps'] == 5 * STEPS
  # The learner went on from its checkpoint, not afresh: 5 updates of 4
  # commands x 4 rows (2 copies x 2 agents) in its counter and statistics
  # (a fresh start at update 2 would hold 3 and 3 x 16).
  learner = _restored_learner(kept[-1])
  assert int(learner.state.update) == 5
  assert float(learner.state.value_normalizer.count) == 5 * 4 * 4
  # The run's lower layer travels with it.
  assert sorted(os.listdir(os.path.join(logdir, 'controller'))) == sorted(
      controller_lib.FILES)


def test_a_run_spends_its_budget_when_episodes_end_inside_a_command(
    controller, tmp_path):
  # Episodes of 0.75 s end after 15 control steps, inside a command of 2:
  # that command takes 1 step, so 2 updates take fewer than the nominal 32
  # and the run goes on (a run that stopped short of its budget was taken
  # by coop-paper for an unfinished one).
  logdir = str(tmp_path / 'short')
  summary = learner_loop.train(_args(logdir, controller, time_limit=0.75,
                                     total_steps=2 * STEPS))
  steps = [int(r['env_steps']) for r in _rows(logdir)]
  assert steps[1] < 2 * STEPS <= steps[-1], steps
  assert summary['update'] == len(steps) == 3
  assert checkpoints.read_state(checkpoints.resolve(logdir))['update'] == 3


def test_best_checkpoint_holds_the_best_full_window(controller, tmp_path,
                                                   capsys):
  # Episodes of 0.8 s are 2 updates: with a window of 2 episodes it is
  # full from update 2 on (both copies have ended one episode).
  logdir = str(tmp_path / 'best')
  learner_loop.train(_args(logdir, controller, window=2,
                           total_steps=6 * STEPS))
  rows = _rows(logdir)[1:]
  scores = [(float(r['success']), float(r['return'])) for r in rows]
  winner = rows[scores.index(max(scores))]  # First of equal scores.
  best = os.path.join(logdir, 'checkpoints', checkpoints.BEST)
  state = checkpoints.read_state(checkpoints.resolve(best))
  assert state['update'] == int(winner['update'])
  assert tuple(state['best_score']) == max(scores)
  assert checkpoints.list_checkpoints(logdir)[-1].endswith('6')
  # The newest checkpoint carries the score, so a resumed run continues it.
  newest = checkpoints.read_state(checkpoints.resolve(logdir))
  assert tuple(newest['best_score']) == max(scores)
  evaluate.main(['--checkpoint', best, '--episodes', '1', '--envs', '1'])
  assert 'success rate' in capsys.readouterr().out


def test_a_rollout_reports_its_cpu_time_apart_from_its_wall_time(
    controller, tmp_path, monkeypatch):
  """`Rollout.cpu_seconds` is the actor's CPU time, not its wall time: a
  rollout that waits 100 ms per command shows the waits in `seconds` only."""
  args = _args(tmp_path, controller)
  spec, _, learners = learner_loop.fresh_learners(args)
  variables = learner_loop.actor_variables(learners)
  worker = rollout.RolloutWorker(spec, args.hierarchy, 0, 0, 2)
  worker.collect(variables, 0)  # Compilation.
  step = rollout.EnvBatch.step

  def waiting_step(self, actions):
    time.sleep(0.1)
    return step(self, actions)
  monkeypatch.setattr(rollout.EnvBatch, 'step', waiting_step)
  result = worker.collect(variables, 1)
  worker.close()
  waits = 0.1 * args.hierarchy.sequence_length
  assert result.env_steps == STEPS
  assert 0 < result.cpu_seconds < result.seconds - 0.8 * waits


def test_species_learners_in_threads_learn_what_they_learn_in_turn(
    controller, tmp_path):
  """The ravine's two species updated at the same time (`step_learners`
  with an executor) end with the parameters and metrics of updating them
  one after the other."""
  args = _args(tmp_path, controller, task='ravine')
  spec, _, learners = learner_loop.fresh_learners(args)
  assert len(learners) == 2
  worker = rollout.RolloutWorker(spec, args.hierarchy, 0, 0, 2)
  results = [worker.collect(learner_loop.actor_variables(learners), 0)]
  worker.close()
  start = {name: learner.save() for name, learner in learners.items()}

  def two_updates(threads=None):
    """From `start`: the rows and the parameters after two updates."""
    for name, learner in learners.items():
      learner.restore(start[name])
    rows = [learner_loop.step_learners(learners, results, threads)
            for _ in range(2)]
    return rows, jax.device_get(learner_loop.actor_variables(learners))
  rows, variables = two_updates()
  with concurrent.futures.ThreadPoolExecutor(2) as threads:
    threaded_rows, threaded = two_updates(threads)
  assert threaded_rows == rows
  assert list(rows[1]) == [k for name in learners for k in rows[1]
                           if k.startswith(f'learner/{name}/')]
  for a, b in zip(*map(jax.tree.leaves, (variables, threaded))):
    np.testing.assert_array_equal(a, b)


def test_missing_controller_says_how_to_make_one(tmp_path):
  with pytest.raises(FileNotFoundError, match='coop-pretrain-lowlevel'):
    envs_lib.read_controller('position', str(tmp_path))


@pytest.fixture(scope='module')
def ray_cluster():
  import ray  # pylint: disable=g-import-not-at-top
  assert actor_pool.init_ray(num_cpus=2)
  yield ray
  ray.shutdown()


def test_ray_actors_survive_kill_minus_9(ray_cluster, controller, tmp_path):
  del ray_cluster
  killed = []
  # Rollouts of 32 commands x 5 control steps (~0.1 s or more) are still
  # running 20 ms after a collect starts, so the kill lands mid-rollout.
  slow = dict(actors=2, envs_per_actor=1, command_period=0.25,
              sequence_length=32, time_limit=1.0)  # Whole periods.
  per_update = 2 * 1 * 32 * 5

  def kill_one_actor(update, row, pool):
    if update == 2:
      pids = pool.pids()
      assert len(set(pids)) == 2 and os.getpid() not in pids
      collect = pool.collect

      def collect_and_kill(*args, **kwargs):
        if not killed:  # The next collect only.
          timer = threading.Timer(0.02, os.kill, (pids[1], signal.SIGKILL))
          timer.start()
          killed.append(timer)
        return collect(*args, **kwargs)
      pool.collect = collect_and_kill

  summary = learner_loop.train(
      _args(tmp_path / 'ray', controller, total_steps=5 * per_update,
            **slow),
      on_update=kill_one_actor)
  killed[0].join()
  assert summary['update'] == summary['updates'] == 5
  assert summary['env_steps'] == 5 * per_update
  assert summary['restarts'] == 1
  rows = _rows(tmp_path / 'ray')
  assert [int(r['update']) for r in rows] == [1, 2, 3, 4, 5]
  assert int(rows[-1]['restarts']) == 1


def test_evaluation_prints_success_rate_and_films(hrl_run, tmp_path, capsys):
  video = tmp_path / 'episode.mp4'
  evaluate.main(['--checkpoint', hrl_run, '--episodes', '3', '--seeds', '0',
                 '1', '--envs', '2', '--n-agents', '3', '--video', str(video),
                 '--width', '64', '--height', '48'])
  out = capsys.readouterr().out
  assert 'transport with 3 agents' in out
  assert 'success rate 0.0% +- 0.0% (standard error over 6 episodes)' in out
  assert video.stat().st_size > 0


def test_the_filmed_episode_is_the_first_evaluated_one(hrl_run, tmp_path):
  args = evaluate.EvalArgs(checkpoint=[hrl_run], time_limit=1.0)
  spec, config, models, _ = evaluate.load_model(hrl_run, args)
  video = str(tmp_path / 'e.mp4')
  played = evaluate.play(spec, config, models, 5, 3, 2, video=video,
                         size=(64, 48))
  assert played == evaluate.play(spec, config, models, 5, 3, 2)
  assert len({e['return'] for e in played}) == 3  # Three other episodes.
  with imageio.get_reader(video) as reader:
    # The first observation, then 1 s of 50 ms steps: one episode.
    assert reader.count_frames() == 1 + 20
    first = reader.get_data(0).astype(float)
  # Of the two copies' first frames, the film's is the first copy's (the
  # mp4 is lossy: the nearer one).
  starts = []
  for copy_seed in evaluate.copy_seeds(5, 2):
    bare = []
    env = spec.make(copy_seed, wrap_raw=lambda e: bare.append(e) or e)  # pylint: disable=cell-var-from-loop
    env.reset()
    starts.append(camera.render(bare[0], camera.FramingCamera(), 64, 48))
    env.close()
  distances = [np.abs(first - start).mean() for start in starts]
  assert distances[0] < distances[1], distances
  video_lib.write_strip(video, str(tmp_path / 'strip.png'), count=3)
  assert imageio.imread(tmp_path / 'strip.png').shape == (24, 3 * 32, 3)


def test_reset_memory_acts_from_the_initial_carry_at_every_command(
    hrl_run, monkeypatch):
  from agents.hierarchy import acting  # pylint: disable=g-import-not-at-top
  args = evaluate.EvalArgs(checkpoint=[hrl_run], time_limit=1.0)
  spec, config, models, _ = evaluate.load_model(hrl_run, args)
  select = acting.HierarchyActor.select_action
  calls = []

  def spy(self, observation, reset, global_state=None):
    action, extras = select(self, observation, reset, global_state)
    calls.append((self, np.array(observation), np.array(reset), action))
    return action, extras
  monkeypatch.setattr(acting.HierarchyActor, 'select_action', spy)

  def replayed_from_initial_carry(played_calls):
    """Each command's action again, from the initial carry."""
    same = []
    for actor, observation, _, action in played_calls:
      actor.carry = actor._networks.initial_carry(len(observation))  # pylint: disable=protected-access
      again, _ = select(actor, observation, np.zeros(len(observation), bool))
      same.append(np.allclose(again, action, atol=1e-5))
    return same

  kept = evaluate.play(spec, config, models, 5, 2, 2)
  kept_calls, calls[:] = list(calls), []
  probed = evaluate.play(spec, config, models, 5, 2, 2, reset_memory=['ant'])
  assert len(probed) == 2 and len(calls) == len(kept_calls) > 2
  assert all(reset.all() for _, _, reset, _ in calls)
  assert all(replayed_from_initial_carry(calls))
  # Without it the carry matters: mid-episode commands act otherwise.
  assert not kept_calls[1][2].any()
  assert not all(replayed_from_initial_carry(kept_calls[1:]))
  assert [e['return'] for e in probed] != [e['return'] for e in kept]
  out = evaluate.evaluate(dataclasses.replace(
      args, episodes=1, envs=1, reset_memory=('ant',)))
  assert out['models'][0]['reset_memory'] == ['ant']
  with pytest.raises(ValueError, match=r"no species \['crosser'\]"):
    evaluate.evaluate(dataclasses.replace(args, reset_memory=('crosser',)))


def test_reset_memory_resets_the_named_species_only():
  names = ('crosser', 'pusher')
  resets = {}

  class Actor:

    def __init__(self, name):
      self.name = name

    def select_action(self, observation, reset, global_state):
      resets[self.name] = np.array(reset)
      return np.zeros((len(observation), 2)), {}
  reset = np.array([True, False, False])
  batch = types.SimpleNamespace(
      rows={n: (np.zeros((3, 4)), reset, None) for n in names})
  models = {n: (types.SimpleNamespace(global_state_size=None),)
            for n in names}
  evaluate._act({n: Actor(n) for n in names}, batch, models, ('crosser',))  # pylint: disable=protected-access
  assert resets['crosser'].all()
  assert resets['pusher'].tolist() == reset.tolist()
  # Each species is judged by its own policy's variant (--policy-from).
  builders = {n: types.SimpleNamespace(
      config=hierarchy_config.HierarchyConfig(agent=agent))
              for n, agent in zip(names, ('hrl', 'no_memory'))}
  models = {n: (None, builders[n]) for n in names}
  evaluate.check_reset_memory(('crosser',), models, 'run', {'pusher': 'b'})
  with pytest.raises(ValueError, match="pusher's policy in b is agent "
                     "'no_memory'"):
    evaluate.check_reset_memory(names, models, 'run', {'pusher': 'b'})
  with pytest.raises(ValueError, match=r"no species \['ant'\] in run"):
    evaluate.check_reset_memory(('ant',), models, 'run', {})


def test_the_stability_figures_are_logged_and_checkpointed(hrl_run):
  rows = _rows(hrl_run)
  for name in ('value_loss', 'approx_kl', 'learning_rate', 'action_std',
               'grad_norm', 'explained_variance'):
    values = [float(r[f'learner/ant/{name}']) for r in rows]
    assert all(np.isfinite(values)), name
  # The std floor holds (softplus + 0.1), the rate stays within its bounds.
  assert all(float(r['learner/ant/action_std']) > 0.1 for r in rows)
  assert all(0 < float(r['learner/ant/learning_rate']) <= 1e-2 for r in rows)
  # The value statistics travel in the checkpoint: 2 updates of 4
  # commands x 4 rows (2 copies x 2 agents).
  learner = _restored_learner(checkpoints.resolve(hrl_run))
  assert float(learner.state.value_normalizer.count) == 2 * 4 * 4
  assert int(learner.state.update) == 2


def test_the_trace_is_the_first_evaluated_episode_in_numbers(hrl_run,
                                                            tmp_path):
  args = evaluate.EvalArgs(checkpoint=[hrl_run], time_limit=1.0)
  spec, config, models, _ = evaluate.load_model(hrl_run, args)
  trace = tmp_path / 'deep' / 'e.csv'
  played = evaluate.play(spec, config, models, 5, 3, 2, trace=str(trace))
  assert played == evaluate.play(spec, config, models, 5, 3, 2)
  with open(trace, newline='') as f:
    rows = list(csv.DictReader(f))
  # The first observation, then 1 s of 50 ms steps: one episode.
  assert [round(float(r['time']), 3) for r in rows] == [
      round(0.05 * i, 3) for i in range(21)]
  assert float(rows[-1]['return']) == pytest.approx(played[0]['return'])
  assert float(rows[0]['return']) == 0.0
  assert float(rows[0]['reward/cylinder_target']) == 0.0
  assert float(rows[-1]['reward/cylinder_target']) == pytest.approx(
      played[0]['reward/cylinder_target'])
  n = spec.n_agents
  columns = list(rows[0])
  # Transport tracks its cylinder and target zone after the Ants.
  assert columns[1:3 * n + 7] == [f'{name}_{axis}' for name in (
      [f'agent{i}' for i in range(n)] + ['point0', 'point1'])
                                  for axis in 'xyz']
  # The first row is the first copy's start, not the second's.
  starts = []
  for copy_seed in evaluate.copy_seeds(5, 2):
    bare = []
    env = spec.make(copy_seed, wrap_raw=lambda e: bare.append(e) or e)  # pylint: disable=cell-var-from-loop
    env.reset()
    starts.append(bare[0].task.tracked_positions(bare[0].physics))
    env.close()
  first = np.array([[float(rows[0][f'{name}_{axis}']) for axis in 'xyz']
                    for name in [f'agent{i}' for i in range(n)]
                    + ['point0', 'point1']])
  np.testing.assert_allclose(first, starts[0])
  assert not np.allclose(first, starts[1])
  # The Ants moved during the episode.
  last = np.array([float(rows[-1][f'agent0_{axis}']) for axis in 'xy'])
  assert np.linalg.norm(last - first[0, :2]) > 0.01
  # Reward terms (absent before the first reward) keep the last row's
  # order: after the return, before the task's progress.
  assert (columns.index('return') < columns.index('reward/cylinder_target')
          < columns.index('cylinder_target_distance'))
  # coop-eval --trace alone says how the traced episode ended.
  out = evaluate.evaluate(dataclasses.replace(
      args, episodes=1, seeds=(5,), trace=str(tmp_path / 'alone.csv')))
  assert out['recorded_success'] is False
  assert (tmp_path / 'alone.csv').stat().st_size > 0


def test_the_first_transport_run_still_evaluates(capsys):
  """The shipped checkpoint of the first layout (format 1) loads."""
  best = os.path.join(os.path.dirname(__file__), '..', 'results',
                      'transport_hrl_n4_s0', 'checkpoints', 'best')
  evaluate.main(['--checkpoint', best, '--episodes', '1', '--envs', '1'])
  assert 'update 4115' in capsys.readouterr().out


@pytest.fixture(scope='module')
def ravine_stages(tmp_path_factory, controller):
  """Tiny runs of the ravine's two pretraining stages: {species: run dir}."""
  runs = {}
  for stage, species in (('pushers', 'pusher'), ('crossers', 'crosser')):
    logdir = tmp_path_factory.mktemp('stages') / stage
    learner_loop.train(_args(logdir, controller, task='ravine', stage=stage))
    runs[species] = str(logdir)
  return runs


def _joint_learners(args):
  return learner_loop.fresh_learners(args)[2]


def test_init_from_starts_each_species_from_its_stage_run(
    controller, ravine_stages, tmp_path):
  args = _args(tmp_path / 'joint', controller, task='ravine', stage='joint',
               init_from=tuple(f'{s}={d}' for s, d in ravine_stages.items()))
  learners = _joint_learners(args)
  fresh = {n: jax.device_get(l.state) for n, l in learners.items()}
  learner_loop.initialize_from_runs(args, learners)
  for species, run in ravine_stages.items():
    checkpoint = checkpoints.resolve(run)
    saved = _joint_learners(args)[species]
    saved.restore(checkpoints.saved_learner(checkpoint, species))
    got, want = jax.device_get(learners[species].state), jax.device_get(
        saved.state)
    for name in ('params', 'normalizer', 'value_normalizer'):
      jax.tree.map(np.testing.assert_array_equal, getattr(got, name),
                   getattr(want, name))
    assert int(want.update) > 0 and int(got.update) == 0  # Fresh optimiser.
    jax.tree.map(np.testing.assert_array_equal, got.opt_state,
                 fresh[species].opt_state)
  # A published result (the stage's policy only) hands on the same.
  published = {s: str(tmp_path / f'published_{s}') for s in ravine_stages}
  for species, run in ravine_stages.items():
    checkpoints.write_policy(checkpoints.resolve(run), published[species])
  from_policies = _joint_learners(args)
  learner_loop.initialize_from_runs(dataclasses.replace(
      args, init_from=tuple(f'{s}={d}' for s, d in published.items())),
                                    from_policies)
  for species in ravine_stages:
    jax.tree.map(np.testing.assert_array_equal,
                 jax.device_get(from_policies[species].state),
                 jax.device_get(learners[species].state))
  # And through the whole run: it trains on from there.
  learner_loop.train(args)
  assert len(_rows(args.logdir)) == 2


def test_init_from_refuses_what_does_not_fit(controller, ravine_stages,
                                              hrl_run, tmp_path):
  joint = dict(task='ravine', stage='joint')
  cases = [
      ((f'ant={ravine_stages["pusher"]}',), ValueError, "no species 'ant'"),
      ((f'crosser={ravine_stages["pusher"]}',), ValueError,
       r"has species \['pusher'\], not 'crosser'"),
      ((f'pusher={hrl_run}',), ValueError, "is a 'transport' run"),
      ((f'pusher={tmp_path / "missing"}',), FileNotFoundError,
       'No checkpoint'),
  ]
  for init_from, error, match in cases:
    args = _args(tmp_path / 'joint', controller, init_from=init_from, **joint)
    with pytest.raises(error, match=match):
      learner_loop.initialize_from_runs(args, _joint_learners(args))
  with pytest.raises(ValueError, match='SPECIES=PATH'):
    _args(tmp_path / 'x', controller, init_from=('pusher',), **joint)
  # Another network: named, not silently loaded.
  args = _args(tmp_path / 'joint', controller, middle_layer_size=16,
               init_from=(f'pusher={ravine_stages["pusher"]}',), **joint)
  with pytest.raises(ValueError, match=r'\(pusher\).*(structure|shapes)'):
    learner_loop.initialize_from_runs(args, _joint_learners(args))


def test_resume_at_another_batch_size_keeps_the_step_budget(controller,
                                                             tmp_path):
  logdir = tmp_path / 'run'
  learner_loop.train(_args(logdir, controller, total_steps=2 * STEPS))
  # One copy instead of two: half the steps per update; 16 steps left.
  learner_loop.train(_args(logdir, controller, total_steps=3 * STEPS,
                           envs_per_actor=1, resume=True))
  rows = _rows(logdir)
  assert [int(r['env_steps']) for r in rows] == [
      STEPS, 2 * STEPS, 2 * STEPS + STEPS // 2, 3 * STEPS]
