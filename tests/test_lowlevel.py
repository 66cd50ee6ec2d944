"""The lower layer: pretraining CLI, controller, CommandWrapper.

Everything runs on tiny budgets: a 2-update pretraining run with 16-unit
networks supplies the controller that the other tests load.
"""
import csv
import dataclasses
import json
import os
from unittest import mock

import dm_env
import numpy as np
import pytest

import coop_suite
from coop_suite.tasks import exteroception
from agents import lowlevel
from agents import observations as obs_lib
from agents.lowlevel import controller as controller_lib
from runners import checkpoints
from runners import cli
from runners import config as config_lib
from runners import envs as envs_lib
from runners import evaluate
from runners import pretrain_lowlevel
from runners import run_dir

# Ray starts processes with fork + exec, which JAX's fork warning cannot
# tell from a bare fork.
pytestmark = pytest.mark.filterwarnings('ignore:os.fork:RuntimeWarning')
TINY = ['--num-envs', '8', '--sequence-length', '8', '--actors', '0',
        '--flat-sizes', '16', '--num-minibatches', '2',
        '--checkpoint-every', '1', '--no-progress']


# --- Observations ---------------------------------------------------------------


def test_flatten_key_order_and_shapes():
  env = coop_suite.load('walk_to_target', 1, seed=0)
  observation = env.reset().observation[0]
  keys = obs_lib.observation_keys(observation)
  assert keys[-1] == 'command/target' and keys[0] == 'proprio/angular_velocity'
  assert list(keys[:-1]) == sorted(keys[:-1])
  flat = obs_lib.flatten(observation, keys)
  assert flat.shape == (36,) and flat.dtype == np.float32
  np.testing.assert_allclose(flat[-2:], observation['command/target'],
                             rtol=1e-6)
  stacked = {k: np.stack([v, v]) for k, v in observation.items()}
  np.testing.assert_array_equal(obs_lib.flatten(stacked, keys), [flat, flat])
  # Parts of other types: each value as its own float32 cast gives it.
  mixed = {'a': np.array([0.1, 1e-40, 3e38]), 'b': np.float32([0.1]),
           'c': np.array([True]), 'd': [2, 3]}
  np.testing.assert_array_equal(
      obs_lib.flatten(mixed, ('a', 'b', 'c', 'd')),
      np.concatenate([np.asarray(mixed[k], np.float32) for k in 'abcd']))
  with pytest.raises(KeyError, match="no 'e'"):
    obs_lib.flatten(mixed, ('a', 'e'))
  with pytest.raises(ValueError, match='command'):
    obs_lib.observation_keys({'proprio/a': 0})


# --- Pretraining: the one training loop, then a controller ------------------


@pytest.fixture(scope='module')
def tiny_run(tmp_path_factory):
  """A 2-update position run (8 envs x 8 steps) in process, then --resume
  to 3 with the copies in one Ray actor."""
  logdir = str(tmp_path_factory.mktemp('pretrain') / 'run')
  argv = ['--paradigm', 'position', '--logdir', logdir, *TINY]
  pretrain_lowlevel.main(argv + ['--total-steps', '128'])
  with open(os.path.join(logdir, 'metrics.csv')) as f:
    first_rows = list(csv.DictReader(f))
  checkpoints_before = sorted(os.listdir(os.path.join(logdir, 'checkpoints')))
  pretrain_lowlevel.main(argv + ['--total-steps', '192', '--resume',
                                   '--actors', '1'])
  return logdir, first_rows, checkpoints_before


def test_pretrain_is_a_lowlevel_run_of_the_training_loop(tiny_run):
  logdir, first_rows, checkpoints_before = tiny_run
  assert [int(r['env_steps']) for r in first_rows] == [64, 128]
  assert checkpoints_before == ['1', '2']
  for row in first_rows:
    assert np.isfinite(float(row['learner/ant/total_loss']))
    assert float(row['wall_time']) > 0
  with open(os.path.join(logdir, 'metrics.csv')) as f:
    rows = list(csv.DictReader(f))
  assert [int(r['update']) for r in rows] == [1, 2, 3]
  assert int(rows[-1]['env_steps']) == 192
  # The last three are kept.
  assert sorted(os.listdir(os.path.join(logdir, 'checkpoints'))) == [
      '1', '2', '3']
  assert any(n.startswith('events.out.tfevents') for n in os.listdir(logdir))
  # The run is coop-train's, with the Brax-like settings of the flags.
  state = checkpoints.read_state(checkpoints.resolve(logdir))
  assert state['agent_config']['agent'] == 'lowlevel'
  assert state['args']['actors'] == 1  # The resumed update's Ray actor.
  assert state['args']['task'] == 'walk_to_target'
  assert state['args']['time_limit'] == 10.0
  assert state['agent_config']['target_kl'] == 0.0
  assert state['agent_config']['state_dependent_std'] is True
  assert state['species'][0]['observation_keys'] == list(
      lowlevel.load('position').observation_keys)
  # The export: the shipped format, from the final checkpoint.
  with open(os.path.join(logdir, 'controller', 'config.json')) as f:
    config = json.load(f)
  assert config['training']['update'] == 3
  assert config['training']['env_steps'] == 192
  assert config['env_config']['resample_on_reach'] is False
  assert config['env_config']['time_limit'] == 10.0
  assert config['ppo_config']['discount'] == 0.97
  assert config['ppo_config']['policy_hidden'] == [16]


def test_pretrain_refuses_what_it_cannot_continue(tiny_run, tmp_path,
                                                  capsys):
  logdir = tiny_run[0]
  argv = ['--paradigm', 'position', '--logdir', logdir, *TINY]
  old = tmp_path / 'old'  # A run directory of the loop before this one.
  os.makedirs(old / 'checkpoints')
  (old / 'run_config.json').write_text('{}')
  (old / 'checkpoints' / 'ckpt_00000001.msgpack').write_bytes(b'')
  cases = [(['--total-steps', '64'], '--resume'),
           (['--resume', '--learning-rate', '1e-3'], '--learning-rate'),
           (['--resume', '--sequence-length', '4'], '--sequence-length'),
           (['--flat-sizes', '0'], '--flat-sizes must be >= 1'),
           (['--actors', '3'], '--actors 3 cannot split --num-envs 8 evenly; '
            'use one of 1, 2, 4, 8, or 0 (one process), or --num-envs 12 with '
            '--actors 3.'),
           (['--resume', '--logdir', str(old)], 'older coop-suite'),
           (['--export-only', '--logdir', str(old)], 'older coop-suite')]
  for more, match in cases:
    with pytest.raises(SystemExit) as exit_info:
      pretrain_lowlevel.main(argv + more)
    assert exit_info.value.code == 2
    assert match in capsys.readouterr().err
  # One writer per run directory, as coop-train.
  with run_dir.RunLock(logdir):
    with pytest.raises(SystemExit):
      pretrain_lowlevel.main(argv + ['--resume', '--total-steps', '256'])
  assert 'being written by another run' in capsys.readouterr().err


def test_export_only_writes_the_newest_checkpoints_policy(tiny_run,
                                                            tmp_path):
  logdir = tiny_run[0]
  pretrain_lowlevel.main(['--paradigm', 'position', '--logdir', logdir,
                            '--export-only', '--export-dir', str(tmp_path)])
  with open(tmp_path / 'config.json') as f:
    training = json.load(f)['training']
  assert training['update'] == 3 and training['env_steps'] == 192
  assert training['final_metrics']['env_steps'] == 192
  assert np.isfinite(training['final_metrics']['learner/ant/total_loss'])
  exported = lowlevel.load('position', str(tmp_path))
  # The controller acts as the checkpoint's policy does (its mean).
  spec, config, models, _ = evaluate.load_model(
      logdir, evaluate.EvalArgs(checkpoint=(logdir,)))
  _, builder, networks, learner = models['ant']
  actor = builder.make_actor(networks, learner, deterministic=True)
  observation = coop_suite.load('walk_to_target', 1, seed=0).reset(
      ).observation[0]
  flat = obs_lib.flatten(observation, exported.observation_keys)[None]
  np.testing.assert_allclose(
      exported(observation), actor.select_action(flat, np.ones(1, bool))[0][0],
      rtol=1e-5, atol=1e-6)
  assert config.agent == 'lowlevel' and spec.task == 'walk_to_target'
  with pytest.raises(ValueError, match='velocity-paradigm'):
    pretrain_lowlevel.export(pretrain_lowlevel.Args(
        paradigm='velocity', export_dir=str(tmp_path)),
                               checkpoints.resolve(logdir))


def test_the_lowlevel_agent_reads_only_locomotion_tasks():
  from agents.hierarchy import config as hierarchy_config  # pylint: disable=g-import-not-at-top
  from runners import envs as envs_lib  # pylint: disable=g-import-not-at-top
  with pytest.raises(ValueError, match='walk_to_target or walk_velocity'):
    envs_lib.species_layout(coop_suite.load('transport', 2),
                            hierarchy_config.HierarchyConfig(agent='lowlevel'))


def test_the_documented_commands_parse():
  """Every coop-pretrain-lowlevel command of docs/lowlevel.md is valid."""
  doc = os.path.join(os.path.dirname(__file__), '..', 'docs', 'lowlevel.md')
  with open(doc) as f:
    text = f.read().replace('\\\n', ' ')
  commands = [line.split('#')[0].split()[1:] for line in text.splitlines()
              if line.startswith('coop-pretrain-lowlevel ')]
  assert len(commands) >= 4
  for argv in commands:
    args = cli.parse(pretrain_lowlevel.Args, argv)
    assert args.train_args().agent == 'lowlevel'
  # The coop-train run that the defaults stand for, as the page says.
  argv, = [line.split()[1:] for line in text.splitlines()
           if line.startswith('coop-train --task walk_to_target')]
  documented = cli.parse(config_lib.TrainArgs, argv)
  assert documented == pretrain_lowlevel.Args().train_args()


# --- Controller -------------------------------------------------------------------


@pytest.fixture(scope='module')
def controller(tiny_run):
  return lowlevel.load('position', os.path.join(tiny_run[0], 'controller'))


def test_controller_acts_in_bounds_single_and_batched_agree(controller):
  env = coop_suite.load('walk_to_target', 1, seed=3)
  observations = []
  timestep = env.reset()
  for _ in range(4):
    observations.append(timestep.observation[0])
    timestep = env.step([controller(timestep.observation[0])])
  single = np.stack([controller(o) for o in observations])
  assert single.shape == (4, 8) and single.dtype == np.float32
  assert np.all(np.abs(single) <= 1.0)
  np.testing.assert_allclose(controller.batch(observations), single,
                             rtol=1e-5, atol=1e-6)
  stacked = {k: np.stack([o[k] for o in observations])
             for k in observations[0]}
  np.testing.assert_allclose(controller.batch(stacked), single, rtol=1e-5,
                             atol=1e-6)
  # One agent's dict goes through the same flattening as `act`'s rows.
  np.testing.assert_array_equal(
      controller(observations[0]),
      controller.act(obs_lib.flatten(observations[0],
                                     controller.observation_keys)[None])[0])
  with pytest.raises(dataclasses.FrozenInstanceError):
    controller.paradigm = 'velocity'


def test_controller_loading_checks_paradigm_and_files(tiny_run, tmp_path):
  with pytest.raises(ValueError, match="not 'velocity'"):
    lowlevel.load('velocity', os.path.join(tiny_run[0], 'controller'))
  with pytest.raises(FileNotFoundError, match='params.msgpack'):
    lowlevel.load('position', str(tmp_path))
  with pytest.raises(ValueError, match='paradigm'):
    lowlevel.load('running')


# --- CommandWrapper -------------------------------------------------------------


class _Recorder:
  """Delegates to a controller and records what the wrapper fed it."""

  def __init__(self, controller):
    self._controller = controller
    self.inputs = []

  def __getattr__(self, name):
    return getattr(self._controller, name)

  def act(self, flat):
    self.inputs.append(_unflatten(self._controller, flat))
    return self._controller.act(flat)


def _unflatten(controller, flat):
  """A controller's flat inputs [B, D] -> {key: [B, k]}."""
  ends = np.cumsum(controller.config['observation_sizes'])
  return dict(zip(controller.observation_keys,
                  np.split(np.array(flat, np.float64), ends[:-1], axis=1)))


def test_command_wrapper_specs_and_episode_boundaries(controller):
  # 0.6 s episodes, 0.25 s commands: 5 + 5 low-level steps, then 2 (early end).
  env = lowlevel.CommandWrapper(
      coop_suite.load('transport', 4, seed=0, time_limit=0.6), controller,
      command_period=0.25)
  assert env.low_level_steps == 5 and env.control_timestep() == 0.25
  specs = env.action_spec()
  assert len(specs) == 4 and specs[0].shape == (2,)
  assert specs[0].minimum == -3.0 and specs[0].maximum == 3.0
  assert env.observation_spec() == env.env.observation_spec()
  for _ in range(2):  # Two episodes: the wrapper resets after LAST.
    timestep = env.reset()
    assert timestep.first()
    assert 'extero/cylinder' in timestep.observation[0]
    types = []
    while not timestep.last():
      timestep = env.step(np.full((4, 2), 1.0))
      types.append(timestep.step_type)
      assert len(timestep.reward) == 4
      assert all(isinstance(r, np.float32) for r in timestep.reward)
    assert types == [dm_env.StepType.MID, dm_env.StepType.MID,
                     dm_env.StepType.LAST]
    assert float(timestep.discount) == 1.0  # Time limit, not a failure.
    assert env.episode_metrics()['control_steps'] == 12
  assert env.step(np.zeros((4, 2))).first()  # Auto-reset like composer.
  with pytest.raises(ValueError, match=r'\(4, 2\)'):
    env.step(np.zeros((3, 2)))
  with pytest.raises(ValueError, match='NaN'):
    env.step(np.full((4, 2), np.nan))
  with pytest.raises(ValueError, match='multiple'):
    lowlevel.CommandWrapper(env.env, controller, command_period=0.07)


def test_step_without_observing_skips_mid_observations_only():
  env = coop_suite.load('transport', 2, seed=0, time_limit=0.1)  # 2 steps.
  env.reset()
  mid = env.step(np.zeros((2, 8)), observe=False)
  assert mid.mid() and mid.observation is None
  assert len(mid.reward) == 2
  last = env.step(np.zeros((2, 8)), observe=False)
  assert last.last()  # The episode's last observation is always there.
  assert set(last.observation[0]) == set(env.observation_spec()[0])


@pytest.mark.parametrize('task, n_agents, paradigm', [
    ('transport', 3, 'position'), ('walk_velocity', 1, 'velocity')])
def test_command_wrapper_matches_stepping_on_full_observations(
    task, n_agents, paradigm):
  """The wrapper's fast path (proprioception read from the task, the
  exteroception skipped between commands) changes no number."""
  controller = lowlevel.load(paradigm)
  wrapped = lowlevel.CommandWrapper(
      coop_suite.load(task, n_agents, seed=5, time_limit=1.2), controller)
  reference = coop_suite.load(task, n_agents, seed=5, time_limit=1.2)
  rng = np.random.default_rng(0)
  timestep, expected = wrapped.reset(), reference.reset()
  while not timestep.last():  # 2.4 command periods: ends mid-period.
    commands = rng.uniform(-1, 1, (n_agents, 2))
    timestep = wrapped.step(commands)
    world = wrapped.world_commands  # This period's commands, world frame.
    total = np.zeros(n_agents)
    for _ in range(wrapped.low_level_steps):
      observations = expected.observation
      torso = reference.physics.data.xpos[reference.task._torso_ids]  # pylint: disable=protected-access
      yaw = [w.heading(reference.physics) for w in reference.task.walkers]
      cos, sin = np.cos(yaw), np.sin(yaw)
      delta = world - torso[:, :2] if paradigm == 'position' else world
      command = np.stack([cos * delta[:, 0] + sin * delta[:, 1],
                          cos * delta[:, 1] - sin * delta[:, 0]], axis=1)
      inputs = {k: np.stack([o[k] for o in observations])
                for k in controller.observation_keys
                if k != controller.command_key}
      inputs[controller.command_key] = command
      expected = reference.step(controller.batch(inputs))
      total += np.asarray(expected.reward, np.float64)
      if expected.last():
        break
    np.testing.assert_allclose(timestep.reward, total, rtol=1e-6)
    for got, want in zip(timestep.observation, expected.observation):
      assert got.keys() == want.keys()
      for key in got:
        np.testing.assert_allclose(got[key], want[key], rtol=1e-6,
                                   atol=1e-9, err_msg=key)
  assert expected.last()


def test_command_wrapper_feeds_heading_frame_commands(controller):
  recorder = _Recorder(controller)
  env = lowlevel.CommandWrapper(coop_suite.load('transport', 2, seed=1),
                                recorder, command_period=0.5)
  env.reset()
  command = np.array([[2.0, -1.0], [9.0, 0.5]])  # Agent 1's x is clipped.
  start = env._frames()  # pylint: disable=protected-access
  clipped = np.array([[2.0, -1.0], [3.0, 0.5]])
  target = start.position[:, :2] + np.stack(  # Heading frame -> world.
      [start.cos * clipped[:, 0] - start.sin * clipped[:, 1],
       start.sin * clipped[:, 0] + start.cos * clipped[:, 1]], axis=1)
  env.step(command)
  np.testing.assert_allclose(env.world_commands, target, atol=1e-9)
  fed = recorder.inputs
  assert len(fed) == 10
  # At issue time the offset to the world target is the command itself...
  np.testing.assert_allclose(fed[0]['command/target'],
                             [[2.0, -1.0], [3.0, 0.5]], atol=1e-9)
  # ...and it then follows the agent, to the same world target throughout.
  frames = env._frames()  # pylint: disable=protected-access
  np.testing.assert_allclose(
      frames.to_heading_frame(env.world_commands),
      _unflatten(controller, env.controller_input())['command/target'],
      rtol=1e-6)
  # The agents moved, so the offset they were fed changed with them.
  assert not np.allclose(fed[-1]['command/target'], fed[0]['command/target'])
  assert fed[0]['proprio/joints_pos'].shape == (2, 8)


def _as_velocity(controller, directory):
  """The tiny position network relabelled as a velocity controller, written
  to `directory`; (its files, the loaded controller)."""
  config = dict(controller.config)
  config['paradigm'] = 'velocity'
  config['observation_keys'] = [k.replace('command/target', 'command/velocity')
                                for k in controller.observation_keys]
  files = controller_lib.files(controller.params, controller.normalizer,
                               config)
  run_dir.write_directory(directory, files)
  return files, lowlevel.load('velocity', directory)


@pytest.mark.parametrize('paradigm', ['position', 'velocity'])
def test_controller_input_equals_the_per_key_formula(controller, paradigm,
                                                     tmp_path):
  # The compiled input writer against the numpy route it replaced, from the
  # per-key features: bit for bit, on the rows of a larger array too.
  if paradigm == 'velocity':
    controller = _as_velocity(controller, str(tmp_path))[1]
  env = lowlevel.CommandWrapper(coop_suite.load('transport', 3, seed=2),
                                controller, command_period=0.25)
  env.reset()
  rng = np.random.default_rng(0)
  for _ in range(3):
    env.step(rng.uniform(-3, 3, (3, 2)))
    frames = env._frames()  # pylint: disable=protected-access
    if paradigm == 'position':
      command = frames.to_heading_frame(env.world_commands)
    else:
      command = exteroception.rotate_to_heading(env.world_commands,
                                                frames.cos, frames.sin)
    features = env.task.features(env.physics, ('proprio',))
    expected = np.concatenate(
        [command if key == controller.command_key else features[key]
         for key in controller.observation_keys], axis=1).astype(np.float32)
    np.testing.assert_array_equal(env.controller_input(), expected)
    rows = np.full((7, controller.observation_size), np.nan, np.float32)
    env.controller_input(out=rows[2:5])
    np.testing.assert_array_equal(rows[2:5], expected)
    assert np.isnan(rows[:2]).all() and np.isnan(rows[5:]).all()


def test_command_wrapper_velocity_paradigm(controller, tmp_path):
  files, velocity = _as_velocity(controller, str(tmp_path))
  # The bytes a run carries load as the directory does (no directory).
  assert controller_lib.read_files(str(tmp_path)) == files
  from_bytes = controller_lib.from_files(files)
  flat = np.linspace(-1, 1, velocity.observation_size)[None]
  np.testing.assert_array_equal(from_bytes.act(flat), velocity.act(flat))
  with pytest.raises(ValueError, match='not .position.'):
    envs_lib.read_controller('position', str(tmp_path))
  recorder = _Recorder(velocity)
  env = lowlevel.CommandWrapper(coop_suite.load('corridor', 2, seed=0),
                                recorder, command_period=0.1)
  assert env.action_spec()[0].maximum == 1.0
  env.reset()
  env.step(np.array([[0.6, 0.0], [3.0, 4.0]]))  # Norm clipped to 1 m/s.
  first = recorder.inputs[0]['command/velocity']
  np.testing.assert_allclose(first[0], [0.6, 0.0], atol=1e-9)
  np.testing.assert_allclose(np.linalg.norm(first[1]), 1.0, atol=1e-9)
  # World-fixed: the world command's norm stays the commanded speed.
  np.testing.assert_allclose(np.linalg.norm(env.world_commands, axis=1),
                             [0.6, 1.0], atol=1e-9)


# --- CLI helpers and evaluation -------------------------------------------------


def test_cli_documents_every_flag_from_field_docstrings(capsys):
  from runners import cli  # pylint: disable=g-import-not-at-top
  with pytest.raises(SystemExit):
    cli.parse(pretrain_lowlevel.Args, ['--help'])
  help_text = ' '.join(capsys.readouterr().out.split())
  for field in dataclasses.fields(pretrain_lowlevel.Args):
    assert '--' + field.name.replace('_', '-') in help_text
  assert 'Control steps per copy in one rollout' in help_text
  assert 'Rewards are multiplied by this inside PPO' in help_text
  args = cli.parse(pretrain_lowlevel.Args,
                   ['--paradigm', 'velocity', '--flat-sizes', '32', '32',
                    '--no-progress'])
  assert args.flat_sizes == (32, 32) and not args.progress
  assert args.logdir == 'runs/lowlevel_velocity'
  with pytest.raises(ValueError, match='paradigm'):
    pretrain_lowlevel.Args(paradigm='running')


def test_eval_lowlevel_reports_means_and_errors(tiny_run):
  from runners import eval_lowlevel  # pylint: disable=g-import-not-at-top
  results = eval_lowlevel.evaluate(eval_lowlevel.LowLevelEvalArgs(
      controller=os.path.join(tiny_run[0], 'controller'), episodes=2,
      time_limit=0.5))
  assert set(results) >= {'success', 'final_distance', 'fall', 'return'}
  mean, se = results['final_distance']
  assert mean > 0 and np.isfinite(se)


def test_shipped_position_controller_walks_to_targets():
  from runners import eval_lowlevel  # pylint: disable=g-import-not-at-top
  results = eval_lowlevel.evaluate(eval_lowlevel.LowLevelEvalArgs(episodes=5))
  assert results['fall'][0] == 0.0
  assert results['success'][0] >= 0.8, results


def test_shipped_velocity_controller_tracks_commands():
  from runners import eval_lowlevel  # pylint: disable=g-import-not-at-top
  results = eval_lowlevel.evaluate(eval_lowlevel.LowLevelEvalArgs(
      paradigm='velocity', episodes=3, time_limit=10.0))
  assert results['fall'][0] == 0.0
  assert results['velocity_cosine'][0] >= 0.85, results
  assert results['speed_error'][0] <= 0.3, results
  # A zero command: it stays within a few centimetres and does not fall.
  assert results['stand_drift'][0] <= 0.3 and results['stand_fall'][0] == 0


def _batch_and_copies_alone(**train_args):
  """An `EnvBatch` of two copies (environment seeds 3 and 4) of a run with
  `train_args`, and the same two copies built alone, all reset."""
  from runners import config as config_lib  # pylint: disable=g-import-not-at-top
  from runners import learner_loop  # pylint: disable=g-import-not-at-top
  from runners import rollout  # pylint: disable=g-import-not-at-top
  args = config_lib.train_args(task='transport', n_agents=2, **train_args)
  spec = learner_loop.environment_spec(args)
  alone = [spec.make(seed) for seed in (3, 4)]
  for env in alone:
    env.reset()
  return rollout.EnvBatch(spec, args.hierarchy, [3, 4]), alone


def _step_alone_and_compare(batch, alone, actions, steps):
  """Steps each copy alone with its two rows of `actions` and asserts the
  batch's `steps` hold the same rewards, discounts and next observations
  (the reset's where the episode ended); returns the episode metrics of
  the copies whose episode ended ({copy: metrics})."""
  ended = {}
  for e, env in enumerate(alone):
    timestep = env.step(actions[2 * e:2 * e + 2])
    if timestep.last():
      ended[e] = env.episode_metrics()
    np.testing.assert_array_equal(steps['ant'].reward[2 * e:2 * e + 2],
                                  timestep.reward)
    np.testing.assert_array_equal(steps['ant'].discount[2 * e],
                                  timestep.discount)
    observation = env.reset().observation if timestep.last() else (
        timestep.observation)
    for got, want in zip(batch._observations[e], observation):  # pylint: disable=protected-access
      for key in want:
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)
  return ended


def test_copies_in_lockstep_step_exactly_as_each_copy_alone():
  """`EnvBatch` runs its copies' command periods in lockstep with one
  lower-layer call per low-level step; every observation, reward and
  discount equals stepping each copy alone with `CommandWrapper.step`,
  through an episode that ends mid-period and the reset after it."""
  batch, alone = _batch_and_copies_alone(time_limit=1.2)
  calls = []
  act = batch.envs[0].controller.act
  batch._controller = mock.Mock(act=lambda x: calls.append(x.shape) or act(x))  # pylint: disable=protected-access
  rng = np.random.default_rng(0)
  ended = 0
  for _ in range(4):  # 1.2 s episodes of 0.5 s commands: 10 + 10 + 4 steps.
    commands = rng.uniform(-3, 3, (4, 2))
    steps, episodes, _ = batch.step({'ant': commands})
    ended += len(episodes)
    _step_alone_and_compare(batch, alone, commands, steps)
  assert ended == 2
  assert calls[:10] == [(4, batch.envs[0].controller.observation_size)] * 10
  assert len(calls) == 10 + 10 + 4 + 10


def test_flat_copies_stepped_in_phases_step_as_each_copy_alone():
  """Joint-action copies (`FlatEnv`, the 'flat' variant) go through
  `EnvBatch` in the two phases of a step; rewards (locomotion terms
  included), discounts, observations and episode metrics equal each copy
  stepped alone, through the time limit and the reset after it."""
  batch, alone = _batch_and_copies_alone(agent='flat', time_limit=0.3)
  rng = np.random.default_rng(0)
  ended = []
  for _ in range(8):  # 0.3 s episodes of 50 ms steps: 6 steps each.
    actions = rng.uniform(-1, 1, (4, 8))
    steps, episodes, _ = batch.step({'ant': actions})
    ended += episodes
    alone_ended = _step_alone_and_compare(batch, alone, actions, steps)
    assert sorted(alone_ended) == [m['env'] for m in episodes]
    for m in episodes:
      assert m['reward/alive'] != 0.0  # The locomotion terms are in.
      assert m == {**alone_ended[m['env']], 'env': m['env']}
  assert len(ended) == 2
