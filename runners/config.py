"""The arguments of a cooperative training run: one frozen dataclass.

`TrainArgs` is what `coop-train` parses (every field is a flag, its
docstring the help text, see `runners.cli`) and what a checkpoint stores, so
a run can be resumed or evaluated from its directory alone. The agent's own
hyper-parameters default to `HierarchyConfig`'s; `hierarchy_config()` turns
the args into that config.

Units: `total_steps` counts low-level environment steps (control steps of
`control_timestep` = 0.05 s of one environment copy, all its agents
together); the policy acts once per `command_period` seconds ('flat': every
control step).
"""
import dataclasses
import math
import os
import re
from typing import Any

from agents.hierarchy import config as hierarchy_config_lib

_H = hierarchy_config_lib.HierarchyConfig()
PARADIGMS = ('position', 'velocity')
# Fields of TrainArgs passed on to HierarchyConfig unchanged.
HIERARCHY_FIELDS = (
    'agent', 'seed', 'sequence_length', 'num_epochs', 'num_minibatches',
    'learning_rate', 'entropy_cost', 'discount', 'gae_lambda',
    'reward_scaling', 'upper_layer_sizes', 'middle_layer_size', 'head_sizes',
    'critic_sizes', 'flat_sizes', 'critic', 'normalize_values', 'target_kl',
    'min_action_std', 'max_grad_norm')
# Fields that may change when a run is resumed (the rest must match).
RESUMABLE_CHANGES = ('actors', 'envs_per_actor', 'total_steps', 'logdir',
                     'ray_address', 'resume', 'resume_from',
                     'checkpoint_every',
                     'keep_checkpoints', 'keep_best', 'max_actor_restarts',
                     'progress', 'controller', 'window', 'init_from')


@dataclasses.dataclass(frozen=True)
class TrainArgs:
  """A cooperative training run (every field is a `coop-train` flag)."""

  task: str = 'transport'
  """Task: transport, corridor or ravine (any coop_suite task works)."""
  n_agents: int = 4
  """Agents per environment (ravine: crossers; pushers are --n-pushers)."""
  agent: str = 'hrl'
  """Variant: hrl (default), no_memory, flat, mappo, or lowlevel (the lower
  layer itself, on walk_to_target or walk_velocity: coop-pretrain-lowlevel)."""
  actors: int = 2
  """Actor processes on Ray; 0 runs the same actor and learner in this
  process without Ray (debugging, tests)."""
  envs_per_actor: int = 16
  """Environment copies each actor steps (one batched policy call each).
  With 2 actors, 4 agents and --sequence-length 32: 4,096 commands per
  update."""
  total_steps: int = 20_000_000
  """Low-level environment steps to train for (0.05 s control steps of one
  environment copy), rounded up to whole iterations."""
  seed: int = 0
  """Seed of the networks, the action noise and the environments."""
  logdir: str = ''
  """Run directory; default runs/<task>_<agent>_n<n_agents>_s<seed>."""
  ray_address: str = ''
  """Join this Ray cluster: 'auto' or its head's HOST:6379, run on one of
  its nodes (docs/training.md, "Running on a Ray cluster"); empty joins
  $RAY_ADDRESS if set, else starts a local Ray instance owned by this
  command."""
  resume: bool = False
  """Continue from the newest checkpoint in logdir that reads completely."""
  resume_from: str = ''
  """Continue from this checkpoint directory of the run (e.g.
  <logdir>/checkpoints/ckpt_00000004); implies --resume, and --logdir
  defaults to its run."""
  paradigm: str = 'position'
  """Command paradigm of the lower layer: position or velocity."""
  controller: str = ''
  """Folder of a lower-layer controller (agents.lowlevel.save); empty uses
  the weights shipped for --paradigm."""
  command_period: float = 0.5
  """Seconds between two commands of the middle layer."""
  stage: str = 'joint'
  """Ravine only: curriculum stage joint, pushers or crossers."""
  init_from: tuple[str, ...] = ()
  """Start species from other runs, as SPECIES=PATH pairs (the ravine's
  curriculum: pusher=RUN_A crosser=RUN_B); PATH is a run directory (its
  newest complete checkpoint) or a checkpoint directory. Each named species
  takes that run's parameters and normalisers with a fresh optimiser; a
  resumed run continues from its own checkpoint instead."""
  n_pushers: int = 2
  """Ravine only: number of pushers."""
  resample_on_reach: bool = False
  """walk_to_target only: draw a new target when one is reached (the lower
  layer learns on fixed targets, docs/lowlevel.md)."""
  time_limit: float = 0.0
  """Episode length in seconds; 0 keeps the task's default."""
  checkpoint_every: int = 1
  """Write a checkpoint every this many iterations (and at the end)."""
  keep_checkpoints: int = 3
  """Checkpoints kept; older ones are deleted."""
  keep_best: bool = True
  """Also keep, in checkpoints/best/, the iteration whose full episode window
  had the highest success rate (then return): PPO on these tasks can fall
  back after a peak (docs/results.md)."""
  max_actor_restarts: int = 3
  """Times Ray restarts each dead actor process (-1: without limit)."""
  progress: bool = True
  """Progress bar on a terminal, else one line every 30 s."""
  window: int = 100
  """Logged episode figures are means over the last this many episodes."""

  # The agent (HierarchyConfig; defaults are its own).
  sequence_length: int = _H.sequence_length
  """T, commands per training sequence and per actor rollout."""
  num_epochs: int = _H.num_epochs
  """PPO epochs over each iteration's data."""
  num_minibatches: int = _H.num_minibatches
  """Minibatches per epoch; each species' agent count over all actors and
  copies must divide by it."""
  learning_rate: float = _H.learning_rate
  """Adam step size."""
  entropy_cost: float = _H.entropy_cost
  """Entropy bonus weight."""
  discount: float = _H.discount
  """Discount per command ('flat': per control step)."""
  gae_lambda: float = _H.gae_lambda
  """GAE lambda."""
  reward_scaling: float = _H.reward_scaling
  """Rewards are multiplied by this inside PPO (logged returns are not)."""
  upper_layer_sizes: tuple[int, ...] = _H.upper_layer_sizes
  """Upper layer MLP widths."""
  middle_layer_size: int = _H.middle_layer_size
  """Middle layer GRU size (no_memory: MLP width)."""
  head_sizes: tuple[int, ...] = _H.head_sizes
  """Hidden widths of the command and value heads."""
  critic_sizes: tuple[int, ...] = _H.critic_sizes
  """mappo: centralised critic widths."""
  flat_sizes: tuple[int, ...] = _H.flat_sizes
  """flat: policy and value MLP widths."""
  critic: str = _H.critic
  """Critic structure: separate (own upper and middle layer), stop_gradient
  (value head on the policy's features, no gradient into them) or shared
  (the first run's layout)."""
  normalize_values: bool = _H.normalize_values
  """The critic predicts standardised returns (running statistics)."""
  target_kl: float = _H.target_kl
  """KL target of the adaptive learning rate; 0 keeps it constant."""
  min_action_std: float = _H.min_action_std
  """Floor of the command's std (pre-tanh units)."""
  max_grad_norm: float = _H.max_grad_norm
  """Gradients are rescaled to at most this global L2 norm."""

  def __post_init__(self):
    if self.paradigm not in PARADIGMS:
      raise ValueError(f'--paradigm must be one of {PARADIGMS}, got '
                       f'{self.paradigm!r}.')
    if self.resume_from:
      object.__setattr__(self, 'resume', True)
    if not self.logdir and self.resume_from:
      object.__setattr__(self, 'logdir', os.path.dirname(os.path.dirname(
          os.path.abspath(self.resume_from))))
    if not self.logdir:
      object.__setattr__(self, 'logdir', f'runs/{self.task}_{self.agent}_'
                         f'n{self.n_agents}_s{self.seed}')
    for name in ('envs_per_actor', 'total_steps', 'checkpoint_every',
                 'keep_checkpoints', 'window'):
      if getattr(self, name) < 1:
        raise ValueError(f'--{name.replace("_", "-")} must be >= 1, got '
                         f'{getattr(self, name)}.')
    if self.actors < 0:
      raise ValueError(f'--actors must be >= 0, got {self.actors}.')
    if not 0 <= self.seed < 2**32:
      raise ValueError(f'--seed must be in [0, 2**32), got {self.seed}.')
    if not (math.isfinite(self.command_period) and self.command_period > 0):
      raise ValueError('--command-period must be a finite number of seconds '
                       f'> 0, got {self.command_period}.')
    check_time_limit(self.time_limit)
    object.__setattr__(self, 'init_from', tuple(self.init_from))
    self.init_sources()  # Checks the pairs.
    if self.max_actor_restarts < -1:
      raise ValueError('--max-actor-restarts must be >= 0, or -1 for '
                       f'without limit, got {self.max_actor_restarts}.')
    for name in ('upper_layer_sizes', 'head_sizes', 'critic_sizes',
                 'flat_sizes'):
      object.__setattr__(self, name, tuple(getattr(self, name)))
    hierarchy_config(self)  # Checks the agent's fields, naming the flag.

  def init_sources(self) -> dict[str, str]:
    """`init_from` as {species: path}; ValueError naming the bad pair."""
    sources = {}
    for pair in self.init_from:
      species, _, path = str(pair).partition('=')
      if not species or not path:
        raise ValueError(f'--init-from takes SPECIES=PATH pairs (e.g. '
                         f'pusher=runs/ravine_pushers), got {pair!r}.')
      if species in sources:
        raise ValueError(f'--init-from names species {species!r} twice.')
      sources[species] = path
    return sources

  @property
  def num_actors(self) -> int:
    """Actors that collect (the in-process path has one)."""
    return max(1, self.actors)

  def env_options(self) -> dict[str, Any]:
    """`coop_suite.load` keyword options of the training task."""
    options = {}
    if self.time_limit > 0:
      options['time_limit'] = float(self.time_limit)
    if self.task == 'ravine':
      options.update(stage=self.stage, n_pushers=self.n_pushers)
    if self.task == 'walk_to_target':
      options['resample_on_reach'] = self.resample_on_reach
    return options

  def to_dict(self) -> dict[str, Any]:
    """JSON-able dict (tuples become lists)."""
    return json_safe(dataclasses.asdict(self))

  @classmethod
  def from_dict(cls, values: dict[str, Any]) -> 'TrainArgs':
    """The inverse of `to_dict`; unknown keys (older runs) are dropped."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in values.items() if k in names})


def check_time_limit(seconds: float, flag: str = '--time-limit') -> None:
  """Raises ValueError unless `seconds` is 0 (the task's default episode
  length) or a finite number of seconds > 0."""
  if not (seconds == 0 or (math.isfinite(seconds) and seconds > 0)):
    raise ValueError(f'{flag} must be 0 (the task\'s default) or a finite '
                     f'number of seconds > 0, got {seconds}.')


def hierarchy_config(args: TrainArgs) -> hierarchy_config_lib.HierarchyConfig:
  """The agent's config (one per species; species ids are folded in later)."""
  try:
    return hierarchy_config_lib.HierarchyConfig(
        **{name: getattr(args, name) for name in HIERARCHY_FIELDS})
  except ValueError as e:
    message = re.sub(r'HierarchyConfig\.(\w+)',
                     lambda m: '--' + m.group(1).replace('_', '-'), str(e))
    raise ValueError(message) from None


def check_resumable(saved: dict[str, Any], args: TrainArgs) -> None:
  """Raises ValueError naming the flags that differ from the saved run."""
  current = args.to_dict()
  differ = sorted(k for k in current if k not in RESUMABLE_CHANGES
                  and k in saved and saved[k] != current[k])
  if differ:
    flags = ', '.join(f'--{k.replace("_", "-")} (run: {saved[k]!r}, now: '
                      f'{current[k]!r})' for k in differ)
    raise ValueError(f'Cannot resume {args.logdir} with other settings: '
                     f'{flags}.')


def json_safe(value):
  """Tuples -> lists, recursively (what json round trips give back)."""
  if isinstance(value, dict):
    return {k: json_safe(v) for k, v in value.items()}
  if isinstance(value, (list, tuple)):
    return [json_safe(v) for v in value]
  return value
