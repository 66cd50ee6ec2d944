"""The arguments of a cooperative training run: one frozen dataclass.

`TrainArgs` is what `coop-train` parses (every field is a flag, its
docstring the help text, see `runners.cli`) and what a checkpoint stores, so
a run can be resumed or evaluated from its directory alone. It holds the
agent's config whole (`TrainArgs.hierarchy`, a `HierarchyConfig`), whose
fields are flags of their own names too (`--agent`, `--seed`,
`--learning-rate`). Fields marked `resumable` may change when a run is
resumed; `check_resumable` compares the others. `from_dict` also reads the
flat form that runs stored before the agent's config was nested.

Units: `total_steps` counts low-level environment steps (control steps of
`control_timestep` = 0.05 s of one environment copy, all its agents
together); the policy acts once per `command_period` seconds ('flat': every
control step).
"""
import dataclasses
import math
import os
from typing import Any

from agents import fields
from agents.hierarchy import config as hierarchy_config_lib
from agents.lowlevel.paradigms import PARADIGMS

TIME_LIMIT = fields.equal(0, "the task's default") | fields.above(0)
"""Episode seconds: 0 for the task's default, else finite and > 0."""


def _resumable(default, allowed=None):
  return fields.field(default, allowed, resumable=True)


@dataclasses.dataclass(frozen=True)
class TrainArgs:
  """A cooperative training run (every field is a `coop-train` flag)."""

  task: str = 'transport'
  """Task: transport, corridor or ravine (any coop_suite task works)."""
  n_agents: int = 4
  """Agents per environment (ravine: crossers; pushers are --n-pushers)."""
  hierarchy: hierarchy_config_lib.HierarchyConfig = dataclasses.field(
      default_factory=hierarchy_config_lib.HierarchyConfig)
  """The agent, one config for every species; its fields are flags of
  their own names (--agent, --seed, --learning-rate, ...)."""
  actors: int = _resumable(2, fields.NON_NEGATIVE)
  """Actor processes on Ray; 0 runs the same actor and learner in this
  process without Ray (debugging, tests)."""
  envs_per_actor: int = _resumable(16, fields.COUNT)
  """Environment copies each actor steps (one batched policy call each).
  With 2 actors, 4 agents and --sequence-length 32: 4,096 commands per
  update."""
  total_steps: int = _resumable(20_000_000, fields.COUNT)
  """Low-level environment steps to train for (0.05 s control steps of one
  environment copy), rounded up to whole updates."""
  logdir: str = _resumable('')
  """Run directory; default runs/<task>_<agent>[_<stage>]_n<n_agents>_s<seed>
  (the stage unless joint)."""
  ray_address: str = _resumable('')
  """Join this Ray cluster: 'auto' or its head's HOST:6379, run on one of
  its nodes (docs/training.md, "Running on a Ray cluster"); empty joins
  $RAY_ADDRESS if set, else starts a local Ray instance owned by this
  command."""
  resume: bool = _resumable(False)
  """Continue from the newest checkpoint in logdir that reads completely."""
  resume_from: str = _resumable('')
  """Continue from this checkpoint directory of the run (e.g.
  <logdir>/checkpoints/4); implies --resume, and --logdir
  defaults to its run."""
  paradigm: str = fields.field('position', fields.one_of(*PARADIGMS))
  """Command paradigm of the lower layer: position or velocity."""
  controller: str = _resumable('')
  """Folder of a lower-layer controller (agents.lowlevel.files); empty uses
  the weights shipped for --paradigm."""
  command_period: float = fields.field(0.5, fields.POSITIVE)
  """Seconds between two commands of the middle layer."""
  stage: str = 'joint'
  """Curriculum stage: ravine joint, pushers or crossers; transport joint
  or push (the paper's reward without its agent-target term); other tasks
  have only joint."""
  init_from: tuple[str, ...] = _resumable(())
  """Start species from other runs, as SPECIES=PATH pairs (the curricula:
  transport ant=PUSH_RUN, the ravine pusher=RUN_A crosser=RUN_B); PATH is a
  run directory (its newest complete checkpoint) or a checkpoint directory.
  Each named species takes that run's parameters and normalisers with a
  fresh optimiser; a resumed run continues from its own checkpoint
  instead."""
  n_pushers: int = 2
  """Ravine only: number of pushers."""
  resample_on_reach: bool = False
  """walk_to_target only: draw a new target when one is reached (the lower
  layer learns on fixed targets, docs/lowlevel.md)."""
  time_limit: float = fields.field(0.0, TIME_LIMIT)
  """Episode length in seconds; 0 keeps the task's default."""
  checkpoint_every: int = _resumable(1, fields.COUNT)
  """Write a checkpoint every this many updates (and at the end)."""
  keep_checkpoints: int = _resumable(3, fields.COUNT)
  """Checkpoints kept; older ones are deleted."""
  keep_best: bool = _resumable(True)
  """Also keep the checkpoint of the update whose full episode window had
  the highest success rate (then return), read as <logdir>/checkpoints/best:
  PPO on these tasks can fall back after a peak (docs/results.md)."""
  max_actor_restarts: int = _resumable(
      3, fields.equal(-1, 'without limit') | fields.NON_NEGATIVE)
  """Times Ray restarts each dead actor process (-1: without limit)."""
  progress: bool = _resumable(True)
  """Progress bar on a terminal, else one line every 30 s."""
  window: int = _resumable(100, fields.COUNT)
  """Logged episode figures are means over the last this many episodes."""

  def __post_init__(self):
    fields.check(self)
    if self.resume_from:
      object.__setattr__(self, 'resume', True)
    if not self.logdir and self.resume_from:
      object.__setattr__(self, 'logdir', os.path.dirname(os.path.dirname(
          os.path.abspath(self.resume_from))))
    if not self.logdir:
      stage = '' if self.stage == 'joint' else f'{self.stage}_'
      object.__setattr__(self, 'logdir', f'runs/{self.task}_{self.agent}_'
                         f'{stage}n{self.n_agents}_s{self.seed}')
    object.__setattr__(self, 'init_from', tuple(self.init_from))
    self.init_sources()  # Checks the pairs.

  def init_sources(self) -> dict[str, str]:
    """`init_from` as {species: path}; ValueError naming the bad pair."""
    return fields.pairs(self.init_from, 'init_from',
                        'SPECIES=PATH pairs (e.g. pusher=runs/ravine_pushers)')

  @property
  def agent(self) -> str:
    """The agent's variant (`HierarchyConfig.agent`)."""
    return self.hierarchy.agent

  @property
  def seed(self) -> int:
    """The seed of the networks, the action noise and the environments."""
    return self.hierarchy.seed

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
      options['n_pushers'] = self.n_pushers
    if self.task == 'ravine' or self.stage != 'joint':
      options['stage'] = self.stage  # A task without stages refuses it.
    if self.task == 'walk_to_target':
      options['resample_on_reach'] = self.resample_on_reach
    return options

  def to_dict(self) -> dict[str, Any]:
    """JSON-able dict, the agent's config nested under 'hierarchy' (tuples
    become lists)."""
    return json_safe(dataclasses.asdict(self))

  @classmethod
  def from_dict(cls, values: dict[str, Any]) -> 'TrainArgs':
    """The inverse of `to_dict`; also reads the flat form of runs stored
    before the agent's config was nested. Unknown keys (older runs) are
    dropped."""
    names = _AGENT_NAMES | {f.name for f in dataclasses.fields(cls)}
    return train_args(**{k: v for k, v in flat_dict(values).items()
                         if k in names and k != 'hierarchy'})


_AGENT_NAMES = frozenset(
    f.name for f in dataclasses.fields(hierarchy_config_lib.HierarchyConfig))


def train_args(**values) -> TrainArgs:
  """`TrainArgs` from flat values, the agent's fields among the run's as on
  the command line, e.g. train_args(task='ravine', agent='mappo',
  learning_rate=1e-3); a `hierarchy` value is the config they change."""
  agent = {k: values.pop(k) for k in list(values) if k in _AGENT_NAMES}
  hierarchy = values.pop('hierarchy', hierarchy_config_lib.HierarchyConfig())
  return TrainArgs(**values, hierarchy=dataclasses.replace(hierarchy, **agent))


def envs_per_actor(copies: int, actors: int, what: str,
                   copies_flag: str = '', multiple_of: int = 1) -> int:
  """The environment copies each of `actors` processes steps when they
  share `copies` (0 actors: one process steps them all), for commands that
  fix the copies of an update and let --actors split them. Raises
  ValueError naming the actor counts that split them evenly; `what` says
  whose copies they are ('--num-envs 32'); where the user sets the copies
  too, `copies_flag` (the flag, '--num-envs') makes it also name the
  smallest count of copies above `copies` that --actors splits and that is
  a multiple of `multiple_of` (what else the command asks of the copies,
  e.g. its --num-minibatches)."""
  processes = max(1, actors)
  if copies % processes:
    splits = [n for n in range(1, copies + 1) if copies % n == 0]
    step = math.lcm(processes, multiple_of)
    more = (f', or {copies_flag} {-(-copies // step) * step} with '
            f'--actors {actors}' if copies_flag else '')
    raise ValueError(f'--actors {actors} cannot split {what} evenly; use one '
                     f'of {", ".join(map(str, splits))}, or 0 (one '
                     f'process){more}.')
  return copies // processes


def flat_dict(values: dict[str, Any]) -> dict[str, Any]:
  """A stored `TrainArgs` dict, nested (`to_dict`) or flat (older runs), as
  {field name: value}: the names are unique, as the flags are."""
  return {**{k: v for k, v in values.items() if k != 'hierarchy'},
          **values.get('hierarchy', {})}


def check_resumable(saved: dict[str, Any], args: TrainArgs) -> None:
  """Raises ValueError naming the flags that differ from the saved run's
  `TrainArgs` dict (nested or flat); fields marked `resumable` may differ,
  and so may fields the saved run did not have."""
  saved = flat_dict(saved)
  current = flat_dict(args.to_dict())
  changeable = {f.name for cls in (TrainArgs, type(args.hierarchy))
                for f in dataclasses.fields(cls) if f.metadata.get('resumable')}
  differ = sorted(k for k in current if k not in changeable
                  and k in saved and saved[k] != current[k])
  if differ:
    flags = ', '.join(f'{fields.flag(k)} (run: {saved[k]!r}, now: '
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
