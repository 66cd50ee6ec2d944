"""Pretrains the lower layer (walker controller): `coop-pretrain-lowlevel`.

    coop-pretrain-lowlevel --paradigm position
    coop-pretrain-lowlevel --paradigm velocity --total-steps 8000000
    coop-pretrain-lowlevel --paradigm position --resume
    coop-pretrain-lowlevel --paradigm position --export-only \
        --export-dir agents/lowlevel/weights/position

A front of `coop-train`: these flags stand for a run of the 'lowlevel' agent
on one Ant (`train_args`) with Brax's Ant PPO settings, which the one
training loop runs (`runners.learner_loop`: the same actors, run directory,
metrics, checkpoints and resumption as every cooperative run). A flag that
is also coop-train's has its name and meaning (`--actors`, `--total-steps`,
`--sequence-length`, `--flat-sizes`, ...), so errors and resume checks name
the flags given here; `--num-envs` (all copies) is this command's own.

At the end (also after Ctrl-C / SIGTERM, which stop after the current update
with a checkpoint) the policy of the newest checkpoint is exported as a
controller (`agents.lowlevel.files`) into `--export-dir` (default
`<logdir>/controller`); `--export-only` exports it without training.

Position paradigm: `walk_to_target` (reward 5/(1+d) to a target 2-6 m away,
seen as a heading-frame offset); velocity paradigm: `walk_velocity` (track a
planar velocity command). Both add the paper's alive/up/cost terms.

Position-paradigm default: the target is NOT redrawn when reached
(`resample_on_reach=False`) and episodes last 10 s. With redraws, reaching a
target swaps ~3.3/step (5/(1+0.5)) for ~1/step (a new target 2-6 m away), so
the return-maximising policy hovers just outside the reach radius; a fixed
target instead teaches "walk there, then stand on it", which is what a
position command asks of the lower layer.
"""
import dataclasses
import glob
import json
import os
from typing import Any

from agents import fields
from agents.lowlevel.paradigms import PARADIGMS
from runners import cli
from runners import config as config_lib

# Brax's settings that are no flags here: a constant learning rate, raw
# value targets, the distribution's own std floor, Brax's gradient clip.
_FIXED = dict(agent='lowlevel', n_agents=1, keep_best=False, target_kl=0.0,
              normalize_values=False, min_action_std=1e-3, max_grad_norm=0.5)


@dataclasses.dataclass(frozen=True)
class Args:
  """Pretraining run settings (every field is a CLI flag)."""

  paradigm: str = fields.field('position', fields.one_of(*PARADIGMS))
  """'position' (walk_to_target) or 'velocity' (walk_velocity)."""
  seed: int = 0
  """Seed of the networks, the action noise and the environments."""
  total_steps: int = fields.field(12_000_000, fields.COUNT)
  """Control steps over all environment copies; training stops at the first
  update that reaches it. The shipped position controller reached 100%
  success by 1M steps and was stopped at 11.3M (docs/results.md)."""
  num_envs: int = fields.field(128, fields.COUNT)
  """Environment copies, all stepped with one update's parameters."""
  actors: int = fields.field(2, fields.NON_NEGATIVE)
  """Ray actors that step the copies, num_envs / actors each with its own
  copy of the policy (0: all in this process, without Ray)."""
  sequence_length: int = fields.field(32, fields.COUNT)
  """Control steps per copy in one rollout; a PPO update uses
  num_envs * sequence_length steps collected with one update's
  parameters."""
  logdir: str = ''
  """Run directory; default runs/lowlevel_<paradigm>."""
  ray_address: str = ''
  """Join this Ray cluster (as coop-train --ray-address); empty starts a
  local Ray instance."""
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
  flat_sizes: tuple[int, ...] = fields.field((256, 256), fields.COUNT)
  """Hidden layer widths of the policy and of the value MLP (coop-train's
  flat networks)."""

  def __post_init__(self):
    fields.check(self)
    if not self.logdir:
      object.__setattr__(self, 'logdir', f'runs/lowlevel_{self.paradigm}')
    if not self.export_dir:
      object.__setattr__(self, 'export_dir',
                         os.path.join(self.logdir, 'controller'))
    object.__setattr__(self, 'flat_sizes', tuple(self.flat_sizes))
    if self.num_envs % self.num_minibatches:
      raise ValueError(f'--num-envs {self.num_envs} must be divisible by '
                       f'--num-minibatches {self.num_minibatches}.')
    # The rest (same flags, same words), --actors' split among them.
    self.train_args()

  def task(self) -> str:
    return PARADIGMS[self.paradigm].task

  def train_args(self) -> config_lib.TrainArgs:
    """The `coop-train` run these flags stand for."""
    return config_lib.train_args(
        **_FIXED, task=self.task(), paradigm=self.paradigm,
        actors=self.actors,
        envs_per_actor=config_lib.envs_per_actor(
            self.num_envs, self.actors, f'--num-envs {self.num_envs}',
            copies_flag='--num-envs', multiple_of=self.num_minibatches),
        total_steps=self.total_steps, seed=self.seed, logdir=self.logdir,
        ray_address=self.ray_address, resume=self.resume,
        checkpoint_every=self.checkpoint_every,
        keep_checkpoints=self.keep_checkpoints, progress=self.progress,
        time_limit=self.time_limit or (
            10.0 if self.paradigm == 'position' else 0.0),
        resample_on_reach=self.resample_on_reach,
        sequence_length=self.sequence_length, num_epochs=self.num_epochs,
        num_minibatches=self.num_minibatches,
        learning_rate=self.learning_rate, entropy_cost=self.entropy_cost,
        discount=self.discount, gae_lambda=self.gae_lambda,
        reward_scaling=self.reward_scaling, flat_sizes=self.flat_sizes)


def check_not_an_old_run(logdir: str) -> None:
  """Raises ValueError for a run directory of the pretraining loop that
  came before the one training loop (checkpoint files, not directories)."""
  old = glob.glob(os.path.join(glob.escape(logdir), 'checkpoints',
                               'ckpt_*.msgpack'))
  if old or os.path.exists(os.path.join(logdir, 'run_config.json')):
    raise ValueError(
        f'{logdir} holds a pretraining run of an older coop-suite (its '
        'run_config.json, checkpoints/ckpt_*.msgpack), which this version '
        'can neither resume nor export; a controller/ it exported still '
        'loads. Start a new run with another --logdir (docs/lowlevel.md).')


def export(args: Args, checkpoint: str) -> dict[str, Any]:
  """Writes the policy of a 'lowlevel' checkpoint to `args.export_dir` as a
  controller (`agents.lowlevel.files`, written whole); returns its config."""
  import coop_suite  # pylint: disable=g-import-not-at-top
  from agents import observations as obs_lib  # pylint: disable=g-import-not-at-top
  from agents.lowlevel import controller as controller_lib  # pylint: disable=g-import-not-at-top
  from agents.ppo import config as ppo_config  # pylint: disable=g-import-not-at-top
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  from runners import evaluate  # pylint: disable=g-import-not-at-top
  from runners import run_dir  # pylint: disable=g-import-not-at-top
  spec, config, models, state = evaluate.load_model(
      checkpoint, evaluate.EvalArgs(checkpoint=(checkpoint,)))
  if config.agent != 'lowlevel' or args.task() != spec.task:
    raise ValueError(f'{checkpoint} trained agent {config.agent!r} on '
                     f'{spec.task!r}, not the {args.paradigm}-paradigm lower '
                     f'layer (agent lowlevel on {args.task()!r}).')
  (species, _, _, learner), = models.values()
  params, normalizer = learner.get_variables(['params', 'normalizer'])
  # The 'flat' module's policy MLP is `policy_value`'s policy, by name.
  policy = {'params': params['params']['policy']}
  ppo = ppo_config.PPOConfig(
      **{f.name: getattr(config, f.name)
         for f in dataclasses.fields(ppo_config.PPOConfig)
         if hasattr(config, f.name)},
      policy_hidden=config.flat_sizes, value_hidden=config.flat_sizes)
  task_config = coop_suite.TASKS[spec.task][1](**spec.options)
  env = spec.make(0)  # The sizes of the keys the policy reads.
  sizes = obs_lib.observation_sizes(env.observation_spec()[0],
                                    species.observation_keys)
  env.close()
  update = state['update']
  config_json = {
      'paradigm': args.paradigm, 'task': spec.task,
      'observation_keys': list(species.observation_keys),
      'observation_sizes': list(sizes),
      'action_size': species.action_size,
      'ppo_config': dataclasses.asdict(ppo),
      'env_config': dataclasses.asdict(task_config),
      'agent_config': state['agent_config'],
      'training': {
          'update': update, 'env_steps': state['env_steps'],
          'wall_time': state['wall_time'], 'seed': config.seed,
          'checkpoint': os.path.abspath(checkpoint),
          'final_metrics': run_dir.logged_row(
              checkpoints.run_directory(checkpoint), update)}}
  run_dir.write_directory(args.export_dir,
                          controller_lib.files(policy, normalizer, config_json))
  return config_json


def train(args: Args) -> dict[str, Any]:
  """Trains (unless --export-only) and exports; returns the controller's
  config.json contents."""
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  from runners import learner_loop  # pylint: disable=g-import-not-at-top
  from runners import run_dir  # pylint: disable=g-import-not-at-top
  check_not_an_old_run(args.logdir)
  if args.export_only:
    checkpoint = checkpoints.resolve(args.logdir)
  else:
    checkpoint = learner_loop.train(args.train_args())['checkpoint']
  with run_dir.RunLock(args.logdir):  # The run's one writer, as training.
    return export(args, checkpoint)


def main(argv=None):
  args, exported = cli.run(Args, train, argv, 'coop-pretrain-lowlevel',
                           __doc__.splitlines()[0])
  training = exported['training']
  print(json.dumps({'update': training['update'],
                    'env_steps': training['env_steps'],
                    'return': training['final_metrics'].get('return')}))
  print(f'controller: {args.export_dir}')


if __name__ == '__main__':
  main()
