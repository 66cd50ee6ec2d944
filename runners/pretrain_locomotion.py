"""Pretrains the lower layer (walker controller) with PPO on one Ant.

    python -m runners.pretrain_locomotion --paradigm position
    python -m runners.pretrain_locomotion --paradigm velocity --total-env-steps 8000000
    python -m runners.pretrain_locomotion --paradigm position --resume
    python -m runners.pretrain_locomotion --paradigm position --export-only \
        --export-dir agents/lowlevel/weights/position

Position paradigm: `walk_to_target` (reward 5/(1+d) to a target 2-6 m away,
seen as a heading-frame offset); velocity paradigm: `walk_velocity` (track a
planar velocity command). Both add the paper's alive/up/cost terms.

Writes to `--logdir` (default `runs/lowlevel_<paradigm>`): `metrics.csv` and
TensorBoard events (one row per PPO update: env steps, wall time, episode
figures over the last 100 episodes, losses), `run_config.json`,
`checkpoints/` (the last few, orbax steps as `coop-train` writes them;
`--resume` continues from the newest) and, at the end, the exported
controller in `controller/` (see `agents.lowlevel.controller`, written
whole). Ctrl-C or SIGTERM stops after the current
update, with a checkpoint and the export; a second one stops at once.

Position-paradigm default: the target is NOT redrawn when reached
(`resample_on_reach=False`) and episodes last 10 s. With redraws, reaching a
target swaps ~3.3/step (5/(1+0.5)) for ~1/step (a new target 2-6 m away), so
the return-maximising policy hovers just outside the reach radius; a fixed
target instead teaches "walk there, then stand on it", which is what a
position command asks of the lower layer.
"""
import collections
import dataclasses
import json
import os
import sys
import time
from typing import Any

import numpy as np

from agents import fields
from runners import checkpoints
from runners import cli
from runners import run_dir
from runners import vector_env

TASKS = {'position': 'walk_to_target', 'velocity': 'walk_velocity'}
LOSS_METRICS = ('total_loss', 'policy_loss', 'value_loss', 'entropy',
                'approx_kl', 'clip_fraction', 'grad_norm')
EPISODE_METRICS = {
    'position': ('success', 'targets_reached', 'target_distance', 'failure',
                 'reward/distance'),
    'velocity': ('velocity_cosine', 'speed_error', 'mean_speed_still',
                 'failure', 'reward/velocity'),
}
SUCCESS_METRIC = {'position': 'success', 'velocity': 'velocity_cosine'}
WALKER = 'walker'
"""The learner's name in checkpoints (`runners.checkpoints`)."""


@dataclasses.dataclass(frozen=True)
class Args:
  """Pretraining run settings (every field is a CLI flag)."""

  paradigm: str = fields.field('position', fields.one_of(*TASKS))
  """'position' (walk_to_target) or 'velocity' (walk_velocity)."""
  seed: int = 0
  """Seed of the networks, the action noise and the environments (copy i gets
  seed + i)."""
  total_env_steps: int = fields.field(12_000_000, fields.COUNT)
  """Control steps over all environment copies; training stops at the first
  update that reaches it. The shipped position controller reached 100%
  success by 1M steps and was stopped at 11.3M (docs/results.md)."""
  num_envs: int = fields.field(128, fields.COUNT)
  """Environment copies stepped per control step."""
  num_workers: int = 2
  """Processes stepping the copies (0: in this process)."""
  unroll_length: int = fields.field(32, fields.COUNT)
  """Control steps per copy in one rollout; a PPO update uses
  num_envs * unroll_length steps collected with one parameter version."""
  logdir: str = ''
  """Run directory; default runs/lowlevel_<paradigm>."""
  checkpoint_every: int = fields.field(50, fields.COUNT)
  """Write a checkpoint every this many updates (and at the end)."""
  keep_checkpoints: int = fields.field(3, fields.COUNT)
  """Checkpoints kept (older ones are deleted)."""
  resume: bool = False
  """Continue from the newest checkpoint in logdir."""
  export_dir: str = ''
  """Where the trained controller goes; default <logdir>/controller."""
  export_only: bool = False
  """Do not train: export the controller from the newest checkpoint."""
  progress: bool = True
  """Show progress: a tqdm bar with steps/s on a terminal, else one line
  every 30 s (readable in a log file)."""
  time_limit: float = 0.0
  """Episode length (s); 0 picks 10 s (position) or the task's 20 s
  (velocity)."""
  resample_on_reach: bool = False
  """Position paradigm: draw a new target when one is reached (see module
  docstring for why the default is no)."""
  learning_rate: float = 3e-4
  """Adam step size."""
  discount: float = 0.97
  """PPO discount per control step (0.05 s): a ~1.7 s horizon, as Brax Ant."""
  gae_lambda: float = 0.95
  """GAE lambda."""
  num_epochs: int = 4
  """SGD passes over each rollout."""
  num_minibatches: int = 8
  """Minibatches per epoch (num_envs must divide by it)."""
  entropy_cost: float = 1e-2
  """Entropy bonus weight."""
  reward_scaling: float = 0.1
  """Rewards are multiplied by this inside PPO (the logged returns are not)."""
  hidden: tuple[int, ...] = (256, 256)
  """Hidden layer widths of the policy and of the value MLP."""

  def __post_init__(self):
    fields.check(self)
    self.ppo_config()  # Checks the PPO fields.
    if not self.logdir:
      object.__setattr__(self, 'logdir', f'runs/lowlevel_{self.paradigm}')
    if not self.export_dir:
      object.__setattr__(self, 'export_dir',
                         os.path.join(self.logdir, 'controller'))

  def task(self) -> str:
    return TASKS[self.paradigm]

  def env_options(self) -> dict[str, Any]:
    """coop_suite.load options of the training environment."""
    options = {}
    if self.time_limit > 0:
      options['time_limit'] = self.time_limit
    elif self.paradigm == 'position':
      options['time_limit'] = 10.0
    if self.paradigm == 'position':
      options['resample_on_reach'] = self.resample_on_reach
    return options

  def ppo_config(self):
    from agents.ppo import config as ppo_config  # pylint: disable=g-import-not-at-top
    return ppo_config.PPOConfig(
        learning_rate=self.learning_rate, discount=self.discount,
        gae_lambda=self.gae_lambda, num_epochs=self.num_epochs,
        num_minibatches=self.num_minibatches, entropy_cost=self.entropy_cost,
        reward_scaling=self.reward_scaling, seed=self.seed,
        policy_hidden=self.hidden, value_hidden=self.hidden)


def env_config(args: Args) -> dict[str, Any]:
  """The training task's full config (defaults + overrides) as a dict."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  options = args.env_options()
  config_cls = coop_suite.TASKS[args.task()][1]
  return dataclasses.asdict(config_cls(**options))


def run_config(args: Args) -> dict[str, Any]:
  """What must match for `--resume` to continue the same run."""
  return {'task': args.task(), 'paradigm': args.paradigm,
          'num_envs': args.num_envs, 'unroll_length': args.unroll_length,
          'ppo_config': dataclasses.asdict(args.ppo_config()),
          'env_config': env_config(args)}


def episode_summary(episodes, names):
  """Means over the episodes in the window ([] -> NaN)."""
  out = {'episodes': len(episodes)}
  for name in ('return', 'length') + tuple(names):
    values = [float(e[name]) for e in episodes if name in e]
    out[name] = float(np.mean(values)) if values else float('nan')
  return out


# --- Training ----------------------------------------------------------------


def _flat_timestep(step, n_agents):
  """VectorStep [N, A, ...] -> the actor's [N * A, ...] timestep."""
  return vector_env.VectorStep(
      step_type=np.repeat(step.step_type, n_agents),
      reward=step.reward.reshape(-1),
      discount=np.repeat(step.discount, n_agents),
      truncation=np.repeat(step.truncation, n_agents),
      observation=step.observation.reshape(-1, step.observation.shape[-1]),
      final_observation=None, episodes=step.episodes)


def export(args, learner, envs_info, counters, summary=None):
  """Writes the controller (policy params, normaliser, configs)."""
  from agents.lowlevel import controller as controller_lib  # pylint: disable=g-import-not-at-top
  params, normalizer = learner.get_variables(['params', 'normalizer'])
  config = run_config(args)
  run_dir.write_directory(args.export_dir, controller_lib.files(
      params['policy'], normalizer, {
      'paradigm': args.paradigm,
      'task': args.task(),
      'observation_keys': list(envs_info['keys']),
      'observation_sizes': list(envs_info['sizes']),
      'action_size': envs_info['action_size'],
      'ppo_config': config['ppo_config'],
      'env_config': config['env_config'],
      'training': {**counters, 'seed': args.seed,
                   'final_metrics': summary or {}},
  }))


def _prepare_logdir(args: Args) -> bool:
  """Checks or writes run_config.json; returns whether the run resumes."""
  config = run_config(args)
  config_path = os.path.join(args.logdir, 'run_config.json')
  resuming = args.resume or args.export_only
  if resuming:
    with open(config_path) as f:
      saved = json.load(f)
    if json.loads(json.dumps(config)) != saved:
      raise ValueError(f'{config_path} differs from these arguments; resume '
                       'with the settings the run started with.')
  elif os.path.exists(os.path.join(args.logdir, 'metrics.csv')):
    raise FileExistsError(f'{args.logdir} already holds a run: pass --resume '
                          'or choose another --logdir.')
  else:
    os.makedirs(args.logdir, exist_ok=True)
    with open(config_path, 'w') as f:
      json.dump(config, f, indent=2)
  return resuming


def train(args: Args) -> dict[str, Any]:
  """Runs (or resumes) the pretraining; returns the last logged row.

  One writer per run directory (`run_dir.RunLock`), as `coop-train`.
  """
  with run_dir.RunLock(args.logdir):
    return _train(args)


def _train(args: Args) -> dict[str, Any]:
  from agents.ppo import builder as ppo_builder  # pylint: disable=g-import-not-at-top

  resuming = _prepare_logdir(args)
  ppo_config = args.ppo_config()
  if args.num_envs % ppo_config.num_minibatches:
    raise ValueError(f'--num-envs {args.num_envs} must be divisible by '
                     f'--num-minibatches {ppo_config.num_minibatches}.')
  builder = ppo_builder.PPOBuilder(ppo_config)
  env_fn = vector_env.make_env_fn(args.task(), **args.env_options())
  with vector_env.VectorEnv(env_fn, 1) as probe:  # Observation layout only.
    info = {'keys': probe.observation_keys, 'sizes': probe.observation_sizes,
            'action_size': int(np.prod(probe.action_shape))}
  networks = builder.make_networks(sum(info['sizes']), info['action_size'])
  learner = builder.make_learner(networks)
  counters = {'update': 0, 'env_steps': 0, 'wall_time': 0.0}
  if resuming:
    saved = checkpoints.restore(checkpoints.resolve(args.logdir),
                                {WALKER: learner})
    counters = {k: saved[k] for k in counters}
    checkpoints.discard_after(args.logdir, counters['update'])
  if args.export_only:
    export(args, learner, info, counters,
           summary=run_dir.logged_row(args.logdir, counters['update']))
    return counters

  names = EPISODE_METRICS[args.paradigm]
  log = run_dir.MetricsLog(
      args.logdir, ['update', 'env_steps', 'wall_time', 'sps', 'episodes',
                    'return', 'length', *names, *LOSS_METRICS],
      resume_update=counters['update'] if resuming else None)
  # A resumed run starts new episodes with new seeds (no replayed episodes).
  envs = vector_env.VectorEnv(
      env_fn, args.num_envs,
      seed=args.seed + args.num_envs * counters['update'],
      num_workers=args.num_workers)
  actor = builder.make_actor(networks, learner, actor_id=counters['update'])
  try:
    with run_dir.GracefulStop() as stop:
      row = _loop(args, envs, actor, learner, log, counters, stop)
  finally:
    envs.close()
    log.close()
  export(args, learner, info, counters, summary=row)
  return row


def _loop(args, envs, actor, learner, log, counters, stop):
  """Collect a rollout, update, log, checkpoint; until done or stopped."""
  import jax  # pylint: disable=g-import-not-at-top
  import tqdm  # pylint: disable=g-import-not-at-top
  names = EPISODE_METRICS[args.paradigm]
  success = SUCCESS_METRIC[args.paradigm]
  window = collections.deque(maxlen=100)
  steps_per_update = args.num_envs * args.unroll_length * envs.n_agents
  interactive = sys.stderr.isatty()
  bar = tqdm.tqdm(total=args.total_env_steps, initial=counters['env_steps'],
                  unit='step', unit_scale=True, dynamic_ncols=True,
                  disable=not (args.progress and interactive))
  last_print = time.time()
  row = {}
  start_wall = time.time() - counters['wall_time']
  timestep = _flat_timestep(envs.reset(), envs.n_agents)
  actor.observe_first(timestep)
  with bar:
    while (counters['env_steps'] < args.total_env_steps
           and not stop.requested):
      tick = time.time()
      for _ in range(args.unroll_length):
        action = actor.select_action(timestep.observation)
        step = envs.step(action)
        window.extend(step.episodes)
        timestep = _flat_timestep(step, envs.n_agents)
        actor.observe(action, timestep)
      metrics = learner.step(actor.take_rollout())
      actor.update()
      metrics = {k: float(v) for k, v in jax.device_get(metrics).items()}
      counters['update'] += 1
      counters['env_steps'] += steps_per_update
      counters['wall_time'] = time.time() - start_wall
      summary = episode_summary(list(window), names)
      row = {'update': counters['update'], 'env_steps': counters['env_steps'],
             'wall_time': round(counters['wall_time'], 2),
             'sps': round(steps_per_update / (time.time() - tick), 1),
             **summary, **{k: metrics.get(k) for k in LOSS_METRICS}}
      log.write(row)
      postfix = {'return': f'{summary["return"]:.1f}',
                 success: f'{summary[success]:.2f}',
                 'sps': f'{row["sps"]:.0f}'}
      bar.update(steps_per_update)
      bar.set_postfix(postfix, refresh=False)
      if args.progress and not interactive and time.time() - last_print > 30:
        last_print = time.time()
        print(f'update {counters["update"]} env_steps {counters["env_steps"]}'
              f' wall {counters["wall_time"]:.0f}s '
              + ' '.join(f'{k} {v}' for k, v in postfix.items()), flush=True)
      if (counters['update'] % args.checkpoint_every == 0 or stop.requested
          or counters['env_steps'] >= args.total_env_steps):
        checkpoints.save(args.logdir, {WALKER: learner},
                         {'iteration': counters['update'], **counters},
                         args.keep_checkpoints)
  return row


def main(argv=None):
  args = cli.parse(Args, argv, description=__doc__.splitlines()[0])
  try:
    row = train(args)
  except cli.user_errors() as e:
    cli.fail('coop-pretrain-lowlevel', e)
  print(json.dumps({k: row.get(k) for k in ('update', 'env_steps', 'return')}))
  print(f'controller: {args.export_dir}')


if __name__ == '__main__':
  main()
