"""Every CLI comes from its dataclass through tyro: nested configs as flat
flags, command lines that parse back to the same arguments, range errors
as one line, resume checks from field metadata, old flat configs."""
import ast
import dataclasses
import inspect
import json
import math
import os
import re
import shutil
import subprocess
import sys
import textwrap

import pytest

from agents import fields
from agents.hierarchy import config as hierarchy_config
from runners import baselines
from runners import cli
from runners import config as config_lib
from runners import eval_lowlevel
from runners import evaluate
from runners import learner_loop
from runners import paper
from runners import pretrain_lowlevel
from runners import train
from runners import video

_ROOT = os.path.join(os.path.dirname(__file__), '..')
# A run stored before the agent's config was nested (flat TrainArgs): the
# calibrated transport run's stash at 6.75M steps (commit 46eba16).
_OLD_RUN = os.path.join(_ROOT, 'tests', 'data', 'flat_config_run')
_OLD_STATE = os.path.join(_OLD_RUN, 'checkpoints', 'ckpt_00000659',
                          'state.json')
_CLIS = (config_lib.TrainArgs, evaluate.EvalArgs, video.VideoArgs,
         pretrain_lowlevel.Args, eval_lowlevel.LowLevelEvalArgs,
         baselines.BaselineArgs, paper.PaperArgs)


def _leaf_names(cls):
  for field in dataclasses.fields(cls):
    if dataclasses.is_dataclass(field.type):
      yield from _leaf_names(field.type)
    else:
      yield field.name


def _field_docs(cls):
  """{field: its docstring} of `cls` and its nested config dataclasses,
  read from the source (the string literal under each field), as tyro
  reads them."""
  body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
  docs = {}
  for node, after in zip(body, body[1:]):
    if (isinstance(node, ast.AnnAssign) and isinstance(after, ast.Expr)
        and isinstance(after.value, ast.Constant)
        and isinstance(after.value.value, str)):
      docs[node.target.id] = after.value.value
  for field in dataclasses.fields(cls):
    if dataclasses.is_dataclass(field.type):
      docs.update(_field_docs(field.type))
  return docs


def _letters(text):
  """Only letters and digits: the help's boxes, wrapping and markup
  (and a number wrapped at its comma) fall away."""
  return re.sub(r'[^0-9A-Za-z]', '', text)


def _old_state():
  with open(_OLD_STATE) as f:
    return json.load(f)


@pytest.mark.parametrize('argv', [
    '--task transport --n-agents 4 --agent mappo --actors 2 '
    '--init-from pusher=PATH --stage joint',
    '--task ravine --stage joint --init-from pusher=RUN_A crosser=RUN_B',
    '--task transport --stage push --seed 2 --total-steps 3000000',
    '--task corridor --agent no_memory --actors 8 --envs-per-actor 16',
    '--actors 0 --total-steps 307200 --critic stop_gradient --seed 3 '
    '--learning-rate 0.001 --upper-layer-sizes 16 16 --no-normalize-values '
    '--no-keep-best --target-kl 0 --time-limit 20',
])
def test_documented_flags_parse_and_print_back(argv):
  args = cli.parse(config_lib.TrainArgs, argv.split())
  line = cli.command_line(args, 'coop-train')
  assert cli.parse(config_lib.TrainArgs, line.split()[1:]) == args
  flat = config_lib.flat_dict(args.to_dict())  # As JSON, lists.
  assert config_lib.train_args(**flat) == args


def test_the_stage_reaches_the_task_that_has_it():
  """The curriculum stage is a task option of transport and the ravine; a
  task without stages refuses one rather than ignoring it."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  def options(argv):
    return cli.parse(config_lib.TrainArgs, argv.split()).env_options()
  assert options('--task transport') == {}  # The joint stage: as ever.
  assert options('--task transport --stage push') == {'stage': 'push'}
  assert options('--task ravine --stage pushers') == {'stage': 'pushers',
                                                      'n_pushers': 2}
  with pytest.raises(ValueError, match='stage'):
    coop_suite.load('corridor', 4, **options('--task corridor --stage push'))
  # Each stage its own default run directory, named as coop-paper's cells.
  assert cli.parse(config_lib.TrainArgs, '--task transport --stage push'.split()
                   ).logdir == 'runs/transport_hrl_push_n4_s0'
  assert cli.parse(config_lib.TrainArgs, ['--task', 'transport']
                   ).logdir == 'runs/transport_hrl_n4_s0'


def test_the_agent_config_is_nested_not_copied():
  args = cli.parse(config_lib.TrainArgs,
                   ['--agent', 'flat', '--seed', '7', '--flat-sizes', '32',
                    '--adam-epsilon', '1e-6'])
  assert args.hierarchy == hierarchy_config.HierarchyConfig(
      agent='flat', seed=7, flat_sizes=(32,), adam_epsilon=1e-6)
  assert (args.agent, args.seed) == ('flat', 7)
  assert args.logdir == 'runs/transport_flat_n4_s7'
  own = {f.name for f in dataclasses.fields(config_lib.TrainArgs)}
  agent = {f.name for f in dataclasses.fields(hierarchy_config.HierarchyConfig)}
  assert not own & agent  # Flags without a prefix must be unique.


@pytest.mark.parametrize('cls', _CLIS, ids=lambda c: c.__module__)
def test_help_shows_every_flag_with_its_docstring(cls, capsys):
  with pytest.raises(SystemExit) as exit_info:
    cli.parse(cls, ['--help'])
  assert exit_info.value.code == 0
  text = ' '.join(capsys.readouterr().out.split())
  docs = _field_docs(cls)
  for name in _leaf_names(cls):
    assert fields.flag(name) in text, name
    # Every flag has a docstring, and the help shows its first sentence.
    assert docs.get(name, '').strip(), f'{name} has no docstring'
    first = docs[name].strip().split('. ')[0]
    assert _letters(first) in _letters(text), (name, first)
  if cls is config_lib.TrainArgs:
    assert '--learning-rate FLOAT' in text and 'Adam step size' in text
    assert '--keep-best, --no-keep-best' in text


@pytest.mark.parametrize('main,argv,message', [
    (train.main, ['--learning-rate', '-1'],
     '--learning-rate must be > 0, got -1.0.'),
    (train.main, ['--agent', 'feudal'], "--agent must be one of ('hrl', "),
    (train.main, ['--discount', '1.5'], '--discount must be in [0, 1]'),
    (train.main, ['--actors', '-1'], '--actors must be >= 0'),
    (train.main, ['--init-from', 'pusher'],
     "--init-from takes SPECIES=PATH pairs (e.g. pusher=runs/ravine_pushers)"
     ", got 'pusher'."),
    (train.main, ['--init-from', 'a=x', 'a=y'], "--init-from names 'a' twice."),
    (train.main, ['--time-limit', 'inf'],
     "--time-limit must be 0 (the task's default), or > 0, got inf."),
    (video.main, ['--fps', '0', '--png', 'x.png'], '--fps must be >= 1'),
    (video.main, ['--policy', 'best', '--png', 'x.png'], '--policy'),
    (evaluate.main, ['--checkpoint', 'x', '--n-agents', '-2'],
     '--n-agents must be 0 (the training one), or >= 1, got -2.'),
    (evaluate.main, ['--checkpoint', 'x', '--strip', 'x.png'],
     '--strip needs --video FILE.mp4'),
    (evaluate.main, ['--checkpoint', 'x', '--option', 'target_radius'],
     "--option takes KEY=VALUE pairs (e.g. target_radius=1.5), got "
     "'target_radius'."),
    (evaluate.main, ['--checkpoint', 'x', '--option', 'stage=push'],
     '--option stage: use --stage.'),
    (evaluate.main, ['--checkpoint', 'x', '--option', 'seed=3'],
     '--option seed: use --seeds'),
    (evaluate.main, ['--checkpoint', 'x', '--option', 'a=1', 'a=2'],
     "--option names 'a' twice."),
    (pretrain_lowlevel.main, ['--discount', '2'], '--discount'),
    (eval_lowlevel.main, ['--episodes', '0'], '--episodes'),
])
def test_a_value_out_of_range_is_one_line_naming_the_flag(main, argv,
                                                          message, capsys):
  with pytest.raises(SystemExit) as exit_info:
    main(argv)
  assert exit_info.value.code == 2
  err = capsys.readouterr().err.strip()
  assert len(err.splitlines()) == 1 and ': error: ' in err, err
  assert message in err


def test_range_checker():
  assert 0.5 in fields.UNIT and 1.5 not in fields.UNIT
  assert float('nan') not in fields.POSITIVE
  assert float('inf') not in fields.POSITIVE
  assert 2**32 not in fields.SEED and 2**32 - 1 in fields.SEED
  assert -1 in fields.equal(-1, 'no limit') | fields.NON_NEGATIVE
  with pytest.raises(ValueError, match=r'--critic-sizes must be >= 1, got '
                     r'\[8, 0\]'):
    hierarchy_config.HierarchyConfig(critic_sizes=(8, 0))


def test_resumable_fields_are_marked_in_their_metadata():
  marked = {f.name for f in dataclasses.fields(config_lib.TrainArgs)
            if f.metadata.get('resumable')}
  assert marked == {
      'actors', 'envs_per_actor', 'total_steps', 'logdir', 'ray_address',
      'resume', 'resume_from', 'checkpoint_every', 'keep_checkpoints',
      'keep_best', 'max_actor_restarts', 'progress', 'controller', 'window',
      'init_from'}
  saved = config_lib.train_args(task='corridor', seed=2).to_dict()
  config_lib.check_resumable(saved, config_lib.train_args(
      task='corridor', seed=2, actors=8, total_steps=5, window=10))
  for change, flag in ((dict(n_agents=3), '--n-agents'),
                       (dict(learning_rate=1e-3), '--learning-rate'),
                       (dict(agent='mappo'), '--agent')):
    with pytest.raises(ValueError, match=f'{flag} \\(run: '):
      config_lib.check_resumable(saved, config_lib.train_args(
          task='corridor', seed=2, logdir='runs/corridor_hrl_n4_s2',
          **change))


def test_an_old_flat_config_loads_passes_the_resume_check_and_plays(
    tmp_path):
  state = _old_state()
  assert 'hierarchy' not in state['args']  # The flat form.
  args = config_lib.TrainArgs.from_dict(state['args'])
  assert args.hierarchy == hierarchy_config.HierarchyConfig(
      **state['agent_config'])
  assert (args.task, args.agent, args.seed, args.total_steps) == (
      'transport', 'hrl', 0, 15_000_000)
  assert config_lib.TrainArgs.from_dict(args.to_dict()) == args
  assert config_lib.TrainArgs.from_dict(json.loads(json.dumps(
      args.to_dict()))) == args
  # Resuming it: the same settings pass, another agent setting is named.
  run = str(tmp_path / 'run')
  shutil.copytree(_OLD_RUN, run)
  resumed = dataclasses.replace(args, logdir=run, resume=True, actors=1)
  assert learner_loop.check_run_directory(resumed).startswith(run)
  with pytest.raises(ValueError, match='--entropy-cost'):
    learner_loop.check_run_directory(dataclasses.replace(
        resumed, hierarchy=dataclasses.replace(args.hierarchy,
                                               entropy_cost=0.1)))
  # Evaluating it: its networks restore from the old state.
  spec, config, models, _ = evaluate.load_model(
      run, evaluate.EvalArgs(checkpoint=(run,), n_agents=2))
  assert spec.n_agents == 2 and config == args.hierarchy
  assert set(models) == {'ant'}
  out = evaluate.evaluate(evaluate.EvalArgs(
      checkpoint=(run,), n_agents=2, episodes=1, envs=1, time_limit=1.0))
  assert out['models'][0]['update'] == 659
  assert math.isfinite(out['return']) and out['episodes'] == 1
  assert evaluate.EvalArgs(checkpoint=('x',), option=(
      'start_distance=[1, 2.5]', 'success=any')).task_options() == {
          'start_distance': (1, 2.5), 'success': 'any'}
  # --option plays it on a changed task: a target as large as the arena,
  # held for a step, is reached at once, which 1 s of the real task is not.
  easy = evaluate.evaluate(evaluate.EvalArgs(
      checkpoint=(run,), n_agents=2, episodes=1, envs=1, time_limit=1.0,
      option=('target_radius=100', 'hold_time=0.05')))
  assert (out['success'], easy['success']) == (0.0, 1.0)
  assert easy['models'][0]['options'] == {'target_radius': 100,
                                          'hold_time': 0.05}
  assert easy['figures']['reached'] == 1.0
  for option, message in (
      ('no_such_option=1', 'Unknown option'),
      ('start_distance=2', r'must be a \(low, high\) pair'),
      ('start_distance=[3,2]', 'low <= high')):
    with pytest.raises(ValueError, match=f'--option: .*{message}'):
      evaluate.load_model(run, evaluate.EvalArgs(checkpoint=(run,),
                                                 option=(option,)))
  # --policy-from takes a species' policy from another checkpoint: that
  # one's parameters, if it drives the task alike and has the species.
  other = str(tmp_path / 'other')
  shutil.copytree(_OLD_RUN, other)
  state_file = os.path.join(other, 'checkpoints', 'ckpt_00000659',
                            'state.json')
  with open(state_file) as f:
    state = json.load(f)
  _, _, models, loaded = evaluate.load_model(run, evaluate.EvalArgs(
      checkpoint=(run,), policy_from=(f'ant={other}',)))
  assert loaded['policy_from'] == {'ant': os.path.dirname(state_file)}
  # The policy is read from there: without its parameters it cannot load.
  os.rename(os.path.join(os.path.dirname(state_file), 'ant.msgpack'),
            str(tmp_path / 'ant.msgpack'))
  with pytest.raises(ValueError, match='other.*ant.msgpack cannot be read'):
    evaluate.load_model(run, evaluate.EvalArgs(
        checkpoint=(run,), policy_from=(f'ant={other}',)))
  os.rename(str(tmp_path / 'ant.msgpack'),
            os.path.join(os.path.dirname(state_file), 'ant.msgpack'))
  keys = list(state['species'][0]['observation_keys'])

  def rewrite(name, observation_keys=keys, command_period=0.5):
    """The other checkpoint with its one species named `name` (its
    parameters' file renamed alike), reading `observation_keys`."""
    directory = os.path.dirname(state_file)
    os.rename(os.path.join(directory, f'{state["species"][0]["name"]}'
                           '.msgpack'),
              os.path.join(directory, f'{name}.msgpack'))
    state['species'][0].update(name=name,
                               observation_keys=list(observation_keys))
    state['args']['command_period'] = command_period
    with open(state_file, 'w') as f:
      json.dump(state, f)

  def refused(name, message):
    with pytest.raises(ValueError, match=f'--policy-from {name}=.*{message}'):
      evaluate.load_model(run, evaluate.EvalArgs(
          checkpoint=(run,), policy_from=(f'{name}={other}',)))
  refused('pusher', r"no policy for species 'pusher' there \(it has "
                    r"\['ant'\]\)")
  rewrite('pusher')  # A species the evaluated task (transport) lacks.
  refused('pusher', r"the evaluated task has no species 'pusher' \(it has "
                    r"\['ant'\]\)")
  rewrite('ant', observation_keys=['proprioception'])
  refused('ant', r"it reads the observations \['proprioception'\]")
  rewrite('ant', command_period=1.0)
  refused('ant', r'command period \(s\) is 1.0 there, 0.5 in ')
  rewrite('ant')
  with open(os.path.join(other, 'controller', 'config.json'), 'a') as f:
    f.write('\n')  # Another file, to the byte.
  refused('ant', 'another lower layer than')


def test_the_clis_check_their_flags_without_jax_or_mujoco():
  """Argument classes import light: --help and bad flags answer at once."""
  code = ('import sys; import runners.config, runners.pretrain_lowlevel, '
          'runners.eval_lowlevel, agents.lowlevel; '
          'print(sorted(m for m in ("jax", "mujoco", "dm_control") '
          'if m in sys.modules))')
  out = subprocess.run([sys.executable, '-c', code], check=True,
                       capture_output=True, text=True, cwd=_ROOT).stdout
  assert out.strip() == '[]'
