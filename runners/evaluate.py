"""Evaluates trained checkpoints: `coop-eval`.

    coop-eval --checkpoint runs/transport_hrl_n4_s0 --episodes 100 --seeds 0 1 2
    coop-eval --checkpoint runs/m0 runs/m1 runs/m2 --n-agents 6   # zero-shot
    coop-eval --checkpoint runs/transport_hrl_n4_s0 --video transport.mp4
    coop-eval --checkpoint runs/m0 runs/m1 --seeds 1000 --json eval.json
    coop-eval --checkpoint runs/ravine_hrl_crossers_n2_s0 \
        --option stone_in_path_probability=1 stone_start_probability=1 \
        'stone_start_offset=[-0.5,0]'
    coop-eval --checkpoint runs/ravine_hrl_crossers_n2_s0 --stage joint \
        --policy-from pusher=runs/ravine_hrl_pushers_n2_s0
    coop-eval --checkpoint runs/transport_hrl_n4_s0 --reset-memory ant

`--checkpoint` takes run directories (their newest checkpoint) or checkpoint
directories; several are several trained models (the paper: 5 models x 100
episodes). For each model and each seed, `--episodes` episodes are played
with the policy's mean (`--stochastic` samples), spread over `--envs` copies
that each play a fixed share, so short episodes are not over-represented.

Prints the success rate and mean return with their standard errors over all
models x seeds x episodes (and, for several models, the spread between
models), then the means of the task's other episode figures (e.g. the
ravine's `crossed` and `fallen`). The task and agent count default to the
training ones; any other count works (one policy per species, fixed-size
exteroception); `--option` sets any field of the task's config, e.g. to
play a curriculum stage from chosen starts, and `--policy-from` plays a
species with another checkpoint's policy, e.g. to compose curriculum
stages, and `--reset-memory` starts the GRU afresh at every command (a
probe of what a recurrent policy draws from its memory). `--video`
films the first evaluated episode (first model, first seed, first copy) as
it is played, headless, one frame per control step, with
`coop_suite.camera.FramingCamera`; `--trace` writes the same episode's
positions and figures per control step to a CSV. `--json` writes every
episode's figures in marl-eval's layout (`runners.marl_eval`).
"""
import collections
import csv
import dataclasses
import json
import os
import sys
from typing import Any, Sequence

import numpy as np

from agents import fields
from runners import cli
from runners import config as config_lib
from runners import marl_eval
from runners import paper_plan

os.environ.setdefault('MUJOCO_GL', 'egl')


_TRAINING = fields.equal(0, 'the training one')


@dataclasses.dataclass(frozen=True)
class EvalArgs:
  """What to evaluate (every field is a `coop-eval` flag)."""

  checkpoint: tuple[str, ...] = ()
  """Run or checkpoint directories, one per trained model."""
  task: str = ''
  """Task; empty for the training task."""
  n_agents: int = fields.field(0, _TRAINING | fields.COUNT)
  """Agents (ravine: crossers); 0 for the training count."""
  episodes: int = fields.field(100, fields.COUNT)
  """Episodes per model and seed."""
  seeds: tuple[int, ...] = fields.field((paper_plan.EVAL_SEED,), fields.SEED)
  """Evaluation seeds: each seeds the copies' environments
  (`copy_seeds`) and the action noise. The default is the published
  figures' (`coop-paper`'s): the same seeds and `--envs` start the same
  episodes (which play alike on the same platform), so a figure from the
  defaults compares with docs/results.md."""
  envs: int = fields.field(10, fields.COUNT)
  """Environment copies stepped together. The same seeds give the same
  episodes only with the same count: the networks' float32 outputs round
  differently with the batch's size, and contacts amplify that."""
  stochastic: bool = False
  """Sample commands instead of taking the policy's mean."""
  reset_memory: tuple[str, ...] = ()
  """Species whose middle layer (GRU) starts from its initial state at
  every command, as at an episode's first: a memory probe, the trained
  recurrent policy with what it carries between commands taken away
  (`ant`; the ravine's `crosser`, `pusher` or both; `hrl` and `mappo`
  only, the variants that carry one). Kept in each model's figures that
  `evaluate` returns and in the `--json` file's algorithm name
  (`hrl+reset_memory=crosser`, `marl_eval.algorithm_name`)."""
  stage: str = ''
  """Curriculum stage of the task (ravine: joint, pushers, crossers;
  transport: joint, push); empty for the training one."""
  n_pushers: int = fields.field(0, _TRAINING | fields.COUNT)
  """Ravine pushers; 0 for the training count."""
  time_limit: float = fields.field(0.0, config_lib.TIME_LIMIT)
  """Episode length (s); 0 for the training one."""
  controller: str = ''
  """Lower layer folder; empty for the run's own copy (else the shipped
  weights)."""
  video: str = ''
  """mp4 file to film the first evaluated episode into; empty for none."""
  json: str = ''
  """Also write every episode's figures to this file in marl-eval's JSON
  layout (runners.marl_eval; docs/training.md, "Evaluation")."""
  width: int = fields.field(640, fields.COUNT)
  """Video width in pixels."""
  height: int = fields.field(480, fields.COUNT)
  """Video height in pixels."""
  trace: str = ''
  """CSV file to write the first evaluated episode (the filmed one with
  --video) into, a row per control step from the first observation:
  `time` (s), each agent's torso position `agent<i>_x`, `_y`, `_z` (m,
  world frame, in the task's agent order: the ravine's crossers first),
  the task's other tracked points `point<j>_x`, `_y`, `_z`
  (`Task.tracked_positions`: transport's cylinder and target zone, the
  corridor's slit exit, the ravine's stone), then the episode's figures so
  far (`Task.episode_metrics`: success, return, reward terms and the
  task's progress, e.g. the ravine's `crossed` and `bridge_error`; the
  task's own figures: `flat`'s locomotion terms, which its wrapper adds to
  the played return, are not in them). Empty for none."""
  strip: str = ''
  """With --video: also this PNG, the filmed episode's frames at 0, 1/4,
  1/2, 3/4 and its end side by side at half size (a still for docs)."""
  option: tuple[str, ...] = ()
  """Task options of the evaluation, KEY=VALUE each, VALUE read as JSON
  (`1`, `true`, `[-0.5,0]`; else as text): any field of the task's config
  (docs/tasks.md) over the training run's, e.g. `stone_in_path_probability=1
  stone_start_probability=1 stone_start_offset=[-0.5,0]` plays the ravine's
  crossers stage with the stone across one crosser's path and that crosser
  starting 0-0.5 m before the near edge. Task, agents, stage, pushers and
  time limit have their own flags. Saved with each model's figures."""
  policy_from: tuple[str, ...] = ()
  """Play these species with another checkpoint's policy, SPECIES=PATH
  pairs (PATH a run or checkpoint directory, as --checkpoint): e.g. the
  ravine's curriculum stages composed before their joint run, `--checkpoint
  CROSSERS_RUN --stage joint --policy-from pusher=PUSHERS_RUN`. Both must
  drive the same lower layer at the same command period and read the
  species' observations alike, and the evaluated task must have the
  species. Saved with each model's figures."""

  def __post_init__(self):
    if not self.checkpoint:
      raise ValueError('Give at least one --checkpoint DIR.')
    if not self.seeds:
      raise ValueError('Give at least one seed to --seeds.')
    if self.strip and not self.video:
      raise ValueError('--strip needs --video FILE.mp4 (it is cut from it).')
    fields.check(self)
    self.task_options()
    self.policy_sources()

  def task_options(self) -> dict[str, Any]:
    """`--option`'s KEY=VALUE pairs as `coop_suite.load` options (JSON
    lists become tuples); raises ValueError on a malformed or repeated
    pair (`fields.pairs`) or a key with a flag of its own. Whether the task
    has the option is checked when the task is known (`load_model`)."""
    options = {}
    for key, text in fields.pairs(
        self.option, 'option', 'KEY=VALUE pairs (e.g. target_radius=1.5)'
    ).items():
      if not key.isidentifier():
        raise ValueError(f'--option {key!r}: not an option name.')
      if key in _OWN_FLAGS:
        raise ValueError(f'--option {key}: use {_OWN_FLAGS[key]}.')
      try:
        value = json.loads(text)
      except ValueError:
        value = text
      options[key] = tuple(value) if isinstance(value, list) else value
    return options

  def policy_sources(self) -> dict[str, str]:
    """`--policy-from` as {species: path} (`fields.pairs`)."""
    return fields.pairs(self.policy_from, 'policy_from',
                        'SPECIES=PATH pairs (e.g. pusher=runs/ravine_pushers)')


# `coop_suite.load` arguments that are evaluation flags of their own.
_OWN_FLAGS = {'task': '--task', 'n_agents': '--n-agents', 'stage': '--stage',
              'n_pushers': '--n-pushers', 'time_limit': '--time-limit',
              'seed': '--seeds (they seed the copies)'}


def load_model(path: str, args: EvalArgs):
  """(EnvSpec, HierarchyConfig, {species: (Species, builder, networks,
  learner)}, state) of the checkpoint at `path`, set up for the evaluation
  task; the species of `--policy-from` come from their own checkpoints."""
  from agents.hierarchy import config as hierarchy_config  # pylint: disable=g-import-not-at-top
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  from runners import envs as envs_lib  # pylint: disable=g-import-not-at-top
  checkpoint = checkpoints.resolve(path)
  state = checkpoints.read_state(checkpoint)
  train = config_lib.TrainArgs.from_dict(state['args'])
  overrides = {'task': args.task, 'n_agents': args.n_agents,
               'stage': args.stage, 'n_pushers': args.n_pushers,
               'time_limit': args.time_limit}
  train = dataclasses.replace(
      train, **{k: v for k, v in overrides.items() if v})
  config = hierarchy_config.HierarchyConfig(**state['agent_config'])
  files = _controller_files(checkpoint, train.paradigm, config, args)
  options = {**train.env_options(), **args.task_options()}
  if args.option:
    import coop_suite  # pylint: disable=g-import-not-at-top
    try:
      coop_suite.check_options(train.task, train.n_agents, **options)
    except (TypeError, ValueError) as e:
      raise ValueError(f'--option: {e}') from e
  spec = envs_lib.EnvSpec(train.task, train.n_agents, options,
                          config.uses_commands, train.command_period, files,
                          config.adds_locomotion_terms)
  parameters = checkpoints.saved_learners(
      checkpoint, [s['name'] for s in state['species']])  # Read once.
  models = {s['name']: _load_policy(checkpoint, state, config, s,
                                    parameters[s['name']])
            for s in state['species']}
  borrowed = {}
  if args.policy_from:
    env = spec.make(0)  # The evaluated task's species layout.
    try:
      layout = {s.name: s for s in envs_lib.species_layout(env, config)}
    finally:
      env.close()
  for name, other_path in args.policy_sources().items():
    other = checkpoints.resolve(other_path)
    other_state = checkpoints.read_state(other)
    other_train = config_lib.TrainArgs.from_dict(other_state['args'])
    other_config = hierarchy_config.HierarchyConfig(
        **other_state['agent_config'])
    where = f'--policy-from {name}={other_path}'
    ours = (config.uses_commands, config.adds_locomotion_terms,
            train.command_period, files)
    theirs = (other_config.uses_commands, other_config.adds_locomotion_terms,
              other_train.command_period,
              _controller_files(other, other_train.paradigm, other_config,
                                args))
    for what, a, b in zip(('uses_commands', 'adds_locomotion_terms',
                           'command period (s)'), ours, theirs):
      if a != b:
        raise ValueError(f'{where}: {what} is {b} there, {a} in {path}.')
    if ours[3] != theirs[3]:
      raise ValueError(f'{where}: another lower layer than {path}\'s.')
    saved = [s for s in other_state['species'] if s['name'] == name]
    if not saved:
      has = sorted(s['name'] for s in other_state['species'])
      raise ValueError(f'{where}: no policy for species {name!r} there (it '
                       f'has {has}).')
    if name not in layout:
      raise ValueError(f'{where}: the evaluated task has no species '
                       f'{name!r} (it has {sorted(layout)}).')
    if tuple(saved[0]['observation_keys']) != layout[name].observation_keys:
      # The copies observe as the --checkpoint's agent reads the task.
      raise ValueError(
          f'{where}: it reads the observations '
          f'{list(saved[0]["observation_keys"])}, {path}\'s agent '
          f'{list(layout[name].observation_keys)}.')
    # Its own noise stream: the evaluated layout's index, not its run's.
    models[name] = _load_policy(
        other, other_state, other_config,
        {**saved[0], 'species_id': layout[name].species_id},
        checkpoints.saved_learner(other, name))
    borrowed[name] = other
  return spec, config, models, {**state, 'checkpoint': checkpoint,
                                'policy_from': borrowed}


def _controller_files(checkpoint, paradigm, config, args):
  """The lower layer a checkpoint's commands drive (`--controller`, else
  the run's own copy, else the shipped weights); None without commands."""
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  from runners import envs as envs_lib  # pylint: disable=g-import-not-at-top
  if not config.uses_commands:
    return None
  copy = os.path.join(checkpoints.run_directory(checkpoint), 'controller')
  return envs_lib.read_controller(paradigm, args.controller or (
      copy if os.path.exists(os.path.join(copy, 'config.json')) else ''))


def _load_policy(checkpoint, state, config, saved, parameters):
  """(Species, builder, networks, learner) of the species `saved` (one of
  `state['species']`) of the checkpoint (its `state`, agent `config`), its
  learner set from `parameters` (`checkpoints.saved_learner`)."""
  from agents.hierarchy import builder as hierarchy_builder  # pylint: disable=g-import-not-at-top
  from runners import envs as envs_lib  # pylint: disable=g-import-not-at-top
  species = envs_lib.Species(**{**saved, 'agents': tuple(saved['agents']),
                                'observation_keys': tuple(
                                    saved['observation_keys'])})
  builder = hierarchy_builder.HierarchyBuilder(config, species.species_id)
  networks = builder.make_networks(species.observation_size,
                                   species.action_size,
                                   species.global_state_size)
  learner = builder.make_learner(networks)
  source = f'{checkpoint} ({species.name})'
  if state.get('policy_only'):  # Parameters and statistics are all it has.
    learner.initialize_from(parameters, source=source)
  else:
    learner.restore(parameters, source=source)
  return species, builder, networks, learner


def _actors(batch, models, seed, deterministic):
  actors = {}
  for s in batch.species:
    if s.name not in models:
      raise ValueError(f'The checkpoint has no policy for species {s.name!r}'
                       f' (it has {sorted(models)}).')
    trained, builder, networks, learner = models[s.name]
    if s.observation_size != trained.observation_size:
      raise ValueError(
          f'{s.name}: this task gives {s.observation_size} observation '
          f'features, the policy was trained on {trained.observation_size}.')
    actors[s.name] = builder.make_actor(
        networks, learner, actor_id=seed, action_bounds=s.action_bounds,
        deterministic=deterministic)
  return actors


def check_reset_memory(reset_memory: Sequence[str], models, path: str,
                       borrowed: dict[str, str]) -> None:
  """Refuses a `--reset-memory` species that `models` (`load_model`'s, of
  the checkpoint `path`) lacks or whose policy carries no memory between
  commands: its own variant's, so a `--policy-from` species (`borrowed`:
  name -> its checkpoint) is judged by the checkpoint it comes from."""
  unknown = sorted(set(reset_memory) - set(models))
  if unknown:
    raise ValueError(f'--reset-memory: no species {unknown} in {path} '
                     f'(it has {sorted(models)}).')
  for name in reset_memory:
    config = models[name][1].config
    if not config.recurrent:
      raise ValueError(
          f'--reset-memory: {name}\'s policy in {borrowed.get(name, path)} '
          f'is agent {config.agent!r}, which carries no memory between '
          'commands (hrl and mappo do).')


def _act(actors, batch, models, reset_memory=()):
  actions = {}
  for name, actor in actors.items():
    observation, reset, _ = batch.rows[name]
    if name in reset_memory:  # Every command starts from the initial carry.
      reset = np.ones_like(reset)
    size = models[name][0].global_state_size
    # The centralised critic is not needed to act: zeros of its size.
    state = None if size is None else np.zeros((len(reset), size),
                                               np.float32)
    actions[name] = actor.select_action(observation, reset, state)[0]
  return actions


def copy_seeds(seed: int, num_envs: int) -> np.ndarray:
  """The environment seeds of the `num_envs` copies that `play` plays
  from the evaluation seed `seed`."""
  return np.random.SeedSequence([seed]).generate_state(num_envs) >> 1


def shares(episodes: int, num_envs: int) -> list[int]:
  """How many of `episodes` each of `num_envs` copies plays in `play`, in
  turn from its seed (`copy_seeds`); the first copies take the remainder.
  A copy's k-th episode starts from the same state whatever plays it: the
  cooperative tasks draw their starts at reset and nothing else from their
  seed (`runners.baselines --envs` plays the references on them)."""
  return [episodes // num_envs + (e < episodes % num_envs)
          for e in range(num_envs)]


def play(spec, config, models, seed: int, episodes: int, num_envs: int,
         deterministic: bool = True, video: str = '', size=(640, 480),
         trace: str = '', reset_memory: Sequence[str] = ()) -> list[dict]:
  """`episodes` episode metric dicts, `num_envs` copies playing fixed
  shares, the first copy's first. With `video`, that first episode is
  filmed into the mp4 `video` at `size` (width, height) as it is played:
  the film is an evaluated episode, not a replay (a batch of another size
  rounds the networks' outputs differently, so a replay could diverge).
  With `trace`, the same episode's positions and figures per control step
  go to that CSV (`EvalArgs.trace`). The species in `reset_memory` act from
  their initial carry at every command (`EvalArgs.reset_memory`)."""
  from runners import rollout  # pylint: disable=g-import-not-at-top
  num_envs = min(num_envs, episodes)
  recording = []

  def record_first(env):
    if (video or trace) and not recording:
      env = _Recording(env, video, size, trace)
      recording.append(env)
    return env
  batch = rollout.EnvBatch(spec, config, copy_seeds(seed, num_envs),
                           global_state=False, wrap_raw=record_first)
  quota = shares(episodes, num_envs)
  results = [[] for _ in range(num_envs)]
  try:
    actors = _actors(batch, models, seed, deterministic)
    while any(len(r) < q for r, q in zip(results, quota)):
      _, ended, _ = batch.step(_act(actors, batch, models, reset_memory))
      for episode in ended:
        if len(results[episode['env']]) < quota[episode['env']]:
          results[episode['env']].append(episode)
  finally:
    batch.close()
  return [e for r in results for e in r]


def copy_steps(episodes: list[dict]) -> int:
  """The control steps of all copies that played `play`'s `episodes`:
  every copy steps until the busiest one has played its share, so the
  copies times that one's steps (the work done, the copies that finished
  first stepping on idle)."""
  steps = collections.Counter()
  for episode in episodes:
    steps[episode['env']] += episode.get('control_steps', 0)
  return len(steps) * max(steps.values(), default=0)


class _Recording:
  """A bare environment that films itself into the mp4 `video` and/or
  writes its positions and figures into the CSV `trace` (either may be
  empty), each state once, until its first episode ends."""

  def __init__(self, env, video, size, trace):
    self._env, self._size = env, size
    self._writer = None
    if video:
      from coop_suite import camera  # pylint: disable=g-import-not-at-top
      from runners import video as video_lib  # pylint: disable=g-import-not-at-top
      self._camera, self._render = camera.FramingCamera(), camera.render
      self._writer = video_lib.open_video(video,
                                          round(1 / env.control_timestep()))
    self._trace = trace
    self._rows = []  # The trace's; written when the episode ends.
    self.done = False

  def __getattr__(self, name):
    return getattr(self._env, name)

  def _record(self):
    if self.done:
      return
    if self._writer:
      self._writer.append_data(self._render(self._env, self._camera,
                                            *self._size))
    if self._trace:
      self._add_row()

  def _add_row(self):
    task, physics = self._env.task, self._env.physics
    points = np.asarray(task.tracked_positions(physics), dtype=float)
    row = {'time': round(float(physics.data.time), 6)}
    for i, xyz in enumerate(points):
      name = f'agent{i}' if i < task.n_agents else f'point{i - task.n_agents}'
      row.update(zip((f'{name}_x', f'{name}_y', f'{name}_z'), map(float, xyz)))
    row.update({k: float(v) for k, v in task.episode_metrics(physics).items()})
    self._rows.append(row)

  def reset(self):
    timestep = self._env.reset()
    self._record()
    return timestep

  def step(self, action, observe=True):
    return self._recorded(self._env.step(action, observe=observe))

  def step_outcome(self, observe=True):
    # A command layer steps in two phases (`CoopEnvironment.step_physics`
    # passes through); a step is recorded once its outcome is known.
    return self._recorded(self._env.step_outcome(observe))

  def _recorded(self, timestep):
    self._record()
    if timestep.last() and not self.done:
      self.done = True
      self._finish()
    return timestep

  def _finish(self):
    if self._writer:
      self._writer.close()
    if self._trace:
      # Reward terms are summed from the first reward on: 0 before it.
      # The columns in the order of the last row, which has them all.
      names = list(dict.fromkeys(
          k for row in reversed(self._rows) for k in row))
      os.makedirs(os.path.dirname(os.path.abspath(self._trace)),
                  exist_ok=True)
      with open(self._trace, 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=names)
        writer.writeheader()
        for row in self._rows:
          writer.writerow({k: row.get(k, 0.0 if k.startswith('reward/')
                                      else '') for k in names})

  def close(self):
    if not self.done:
      self._finish()
    self._env.close()


def mean_and_error(values):
  """(mean, standard error of the mean) of `values`; the error is 0 for one
  value."""
  values = np.asarray(values, np.float64)
  error = values.std(ddof=1) / np.sqrt(len(values)) if len(values) > 1 else 0.
  return float(values.mean()), float(error)


def evaluate(args: EvalArgs, log=None) -> dict:
  """Plays every model x seed; returns the figures that `main` prints,
  and under 'models' each model's episodes (`metrics.episode_figures`)
  and the control steps its copies were stepped (`copy_steps`).

  `log(line)` hears the progress (one line per model and seed).
  """
  from runners import metrics as metrics_lib  # pylint: disable=g-import-not-at-top
  log = log or (lambda line: None)
  per_model, episodes, description = [], [], None
  recorded = None
  # Every model loads and is checked before the first one plays.
  loaded = [load_model(path, args) for path in args.checkpoint]
  for path, (_, _, models, state) in zip(args.checkpoint, loaded):
    check_reset_memory(args.reset_memory, models, path, state['policy_from'])
  for index, (spec, config, models, state) in enumerate(loaded):
    description = (f'{spec.task} with {spec.n_agents} agents, agent '
                   f'{config.agent}')
    played, stepped = [], 0
    for seed in args.seeds:
      # The first model's first episode is filmed and traced (`play`).
      first = not (index or played)
      video = args.video if first else ''
      played += play(spec, config, models, seed, args.episodes, args.envs,
                     not args.stochastic, video, (args.width, args.height),
                     args.trace if first else '', args.reset_memory)
      stepped += copy_steps(played[-args.episodes:])
      if first and (args.video or args.trace):
        recorded = bool(played[0]['success'])
      if video and args.strip:
        from runners import video as video_lib  # pylint: disable=g-import-not-at-top
        video_lib.write_strip(args.video, args.strip)
      log(f'model {index + 1}/{len(args.checkpoint)}, seed {seed}: '
          f'{args.episodes} episodes, success '
          f'{100 * np.mean([e["success"] for e in played[-args.episodes:]]):.1f}%')
    episodes += played
    per_model.append({'checkpoint': state['checkpoint'],
                      'update': state['update'],
                      'env_steps': state['env_steps'],
                      'success': float(np.mean([e['success']
                                                for e in played])),
                      'task': spec.task, 'n_agents': spec.n_agents,
                      'stage': spec.options.get('stage', ''),
                      'agent': config.agent,
                      'seed': config.seed,
                      'options': args.task_options(),
                      'stochastic': args.stochastic,
                      'time_limit': args.time_limit,
                      'n_pushers': args.n_pushers,
                      'controller': args.controller,
                      'reset_memory': list(args.reset_memory),
                      'policy_from': state['policy_from'],
                      'copy_steps': stepped,
                      'episodes': [metrics_lib.episode_figures(e)
                                   for e in played]})
  success, success_se = mean_and_error([e['success'] for e in episodes])
  ret, ret_se = mean_and_error([e['return'] for e in episodes])
  out = {'description': description, 'episodes': len(episodes),
         'success': success, 'success_se': success_se, 'return': ret,
         'return_se': ret_se, 'figures': task_figures(per_model),
         'models': per_model, 'recorded_success': recorded}
  if len(per_model) > 1:
    out['success_se_models'] = mean_and_error(
        [m['success'] for m in per_model])[1]
  return out


def task_figures(models) -> dict[str, float]:
  """Means over every evaluated episode of the task's own figures (the
  ones every episode has, besides success, return and reward terms), in
  `metrics.episode_keys` order."""
  from runners import metrics as metrics_lib  # pylint: disable=g-import-not-at-top
  episodes = [e for m in models for e in m['episodes']]
  shared = set.intersection(*(set(e) for e in episodes))
  keys = [k for k in metrics_lib.episode_keys(episodes[0]) if k in shared
          and k not in ('return', 'success') and not k.startswith('reward/')]
  return {k: float(np.mean([e[k] for e in episodes])) for k in keys}


def main(argv=None):
  log = lambda line: print(line, file=sys.stderr, flush=True)
  args, out = cli.run(EvalArgs, lambda args: evaluate(args, log=log), argv,
                      'coop-eval', __doc__.splitlines()[0])
  print(f'{out["description"]}: {len(args.checkpoint)} model(s) x '
        f'{len(args.seeds)} seed(s) x {args.episodes} episodes')
  for name, source in out['models'][0]['policy_from'].items():
    print(f'{name}: the policy of {source}')
  if args.reset_memory:
    print('memory reset to the initial carry at every command: '
          + ', '.join(args.reset_memory))
  if args.option:
    print('task options: ' + ', '.join(
        f'{k}={v!r}' for k, v in args.task_options().items()))
  for model in out['models']:
    print(f'  {model["checkpoint"]} (update {model["update"]}, '
          f'{model["env_steps"]} env steps): success '
          f'{100 * model["success"]:.1f}%')
  line = (f'success rate {100 * out["success"]:.1f}% +- '
          f'{100 * out["success_se"]:.1f}% (standard error over '
          f'{out["episodes"]} episodes)')
  if 'success_se_models' in out:
    line += f', +- {100 * out["success_se_models"]:.1f}% between models'
  print(line)
  print(f'mean return {out["return"]:.2f} +- {out["return_se"]:.2f}')
  if out['figures']:
    print('means: ' + ', '.join(f'{k} {v:.3g}'
                                for k, v in out['figures'].items()))
  recorded = 'succeeded' if out['recorded_success'] else 'failed'
  if args.video:
    print(f'video: {args.video} (the filmed episode {recorded})')
  if args.trace:
    print(f'trace: {args.trace} (the traced episode {recorded})')
  print(json.dumps({k: out[k] for k in ('success', 'success_se', 'return',
                                         'return_se', 'episodes')}))
  if args.json:
    write_json(args.json, marl_eval.layout(out['models']))
    print(f'marl-eval JSON: {args.json}')


def write_json(path: str, data) -> None:
  """Writes `data` as JSON to `path` whole (a temporary file renamed into
  place), creating its folder."""
  from runners import run_dir  # pylint: disable=g-import-not-at-top
  run_dir.write_file(path, json.dumps(data, indent=1) + '\n')


if __name__ == '__main__':
  main()
