"""The paper's experiments as data: cells, their budgets, the paper's figures.

A cell is one training run: task x variant x population x seed (a
curriculum stage is a cell of its own), with its budget in environment
steps (0.05 s control steps of one environment copy), its training flags
(`TrainArgs` fields) and the populations its final checkpoint is evaluated
at (its own, then the zero-shot ones). `PLAN` lists them in the order they
are worth running (`runners.paper` trains them in that order):

1. Table 1, `hrl`: 5 seeds on transport (4 Ants: `--stage push`, then the
   paper's whole reward `--init-from ant=...`), corridor (4 Ants) and
   ravine (2 crossers + 2 pushers: `--stage pushers`, `--stage crossers`,
   then `--stage joint --init-from pusher=... crosser=...`), seed by seed
   across the tasks so that every row has a model early; each model is also
   evaluated zero-shot at the other populations of Table 2 (2/3/5 Ants;
   ravine, trained with 2 crossers: 3/4/5 crossers).
2. Table 1, ablations: `no_memory` and `flat`, 3 seeds each, through the
   same curricula on transport and the ravine (the paper gives the
   ablations the same curriculum).
3. Scaling: IPPO (`hrl`) against MAPPO (`mappo`) on the corridor with 6
   and 7 Ants, 3 seeds (Fig. 4b, c); transport trained with 2, 3 and 5 Ants,
   3 seeds (Fig. 4a; 4 Ants are Table 1's first 3 seeds).
"""
import dataclasses
import fnmatch
from typing import Any, Optional

from agents.hierarchy import config as hierarchy_config

BUDGET = 15_000_000
"""Environment steps per trained model: the stable learner's evidence
budget (the issue that stabilised it asked for at most 15M on transport;
about 2.6 h on the 2-core development machine). One cell's, except on
transport, whose push stage takes `PUSH_BUDGET` of it."""
STAGE_BUDGET = 10_000_000
"""Environment steps of the ravine's pushers stage."""
CROSSERS_BUDGET = 20_000_000
"""Environment steps of the ravine's crossers stage: its reverse curriculum
(`RavineConfig.stone_start_offset`) teaches walking on from past the near
edge first and stepping onto the stone from further back later: seed 0
crossed from 0-0.5 m before the edge in 0.00 of the episodes at 3.3M
steps and 0.75 at 10M, from 0.5-1.5 m in 0.00 and 0.09; at ~11M it began
to go to the stone and cross on it from every start tried (training
windows' crossings 0.3 -> 1.7 of 2 an episode by 20M; 81% success on its
stage at 20M; docs/results.md)."""
CROSSERS_FLAGS = (('initial_action_std', 0.25),)
"""The ravine's crossers stage's own training flags: its commands start with
a std of 0.25 pre-tanh (~0.75 m), not the default ~0.79 (~1.7 m), which
around a fresh policy's ~zero mean walked every crosser starting on the
stone off its ends (20 of 20 episodes). A crosser commanded towards the
finish crossed in 27-32 of 32 episodes with 0.3-1.5 m of command noise
(docs/results.md, "Ravine, seed 0"): a smaller start, not a proven
need."""
FLAT_FLAGS = (('checkpoint_every', 10),)
"""`flat` cells' own training flags: a checkpoint every 10 updates, i.e.
every 10,240 env steps, as a commanded variant's every update. A `flat`
update covers 1,024 env steps (~0.7 s beside another cell), and each
save cost ~36 ms of CPU and ~24 ms of the loop's wait (docs/performance.md,
"`flat` cells checkpoint every 10 updates"): 3% of the wall time went
between updates, orbax's threads took ~5% of a core, and 3.8 MB were
written an update. Saving every 10 updates cut the time between updates
to 0.9%, with no measurable change in the cell's rate.
The cadence changes no update: a stop saves, and a crash loses at most 10
updates (`flat` cells trained before 28 November 2026, 15:00, saved every
update)."""
PUSH_BUDGET = 3_000_000
"""Environment steps of transport's push stage, taken from the model's
`BUDGET`: a transport model trains 15M steps in all (push 3M, then the
joint run 12M). Without the agent-target term seeds gather at the cylinder
within 0.5M steps and move it to the target from ~1.2M (docs/results.md)."""
COPIES = 32
"""Environment copies every cell collects per update, i.e. the batch of
its PPO update: `coop-train`'s default 2 actors x 16 copies. `coop-paper`
splits them evenly over its `--actors` (`envs_per_actor` = 32 / actors),
so a cell trains the same algorithm on 2 cores and on a cluster; only the
copies' random streams differ."""
EPISODES = 100
"""Evaluation episodes per model and population (the paper: 100)."""
EVAL_SEED = 1000
"""First evaluation seed (`coop-eval --seeds 1000`); training never uses it."""
EPISODE_SECONDS = 40.0
"""Episode length of the three tasks (docs/tasks.md), for time estimates."""
CONTROL_TIMESTEP = 0.05
AGENT_STEPS_PER_SECOND = 6_400.0
"""Estimated Ant steps per second of a run where no `hrl` cell is done
(`coop-paper --dry-run` otherwise takes the done cells' pace,
`runners.paper.estimate_rates`): 1,600 env steps/s with 4 Ants
(`hrl`, 2 actors, the 2-core AMD EPYC development machine: corridor/hrl/n4/s0
averaged 1,640 beside other work; docs/paper.md); a cell with k Ants per
copy is estimated at 6,400 / k env steps/s."""
VARIANT_SPEED = {'flat': 0.45}
"""A variant's throughput as a share of `AGENT_STEPS_PER_SECOND` (1 where
absent). `flat` decides every control step (8 joint actions an Ant, no
lower layer): an update covers 1,024 env steps instead of a commanded
variant's 10,240, so per env step its learner does ten times the work and
its actors pay the per-update costs ten times. Corridor with 4 Ants on the
2-core AMD EPYC with nothing else running, `coop-train --task corridor
--agent flat` (defaults, 52 updates after start-up): 894 env steps/s,
against 1,950-2,100 for `hrl` in corridor/hrl/n4/s3's idle stretches the
same morning (0.43-0.46). `no_memory` and `mappo` ran at or above `hrl`'s
rate in short probes (corridor, 4 and 6 Ants)."""
POPULATIONS = (2, 3, 4, 5)
"""The columns of Table 2 (ravine: crossers)."""

# The paper's figures: success rate and standard error in %, 5 models x 100
# episodes (the CoRL 2024 paper's Tables 1 and 2).
PAPER_TABLE1 = {
    ('transport', 'hrl'): (76.8, 5.3), ('transport', 'flat'): (0.0, 0.0),
    ('transport', 'no_memory'): (9.6, 3.2),
    ('corridor', 'hrl'): (88.4, 4.8), ('corridor', 'flat'): (0.0, 0.0),
    ('corridor', 'no_memory'): (12.0, 4.1),
    ('ravine', 'hrl'): (50.4, 4.4), ('ravine', 'flat'): (0.0, 0.0),
    ('ravine', 'no_memory'): (5.4, 4.2),
}
PAPER_TABLE2 = {
    'transport': {2: (12.8, 5.6), 3: (39.8, 4.5), 4: (76.8, 5.3),
                  5: (82.2, 4.5)},
    'corridor': {2: (97.1, 1.8), 3: (93.6, 2.2), 4: (88.4, 4.8),
                 5: (73.5, 2.5)},
    'ravine': {2: (50.4, 4.4), 3: (36.2, 7.8), 4: (22.3, 5.1),
               5: (10.9, 3.3)},
}
PAPER_FIGURE4 = {
    'mappo': 'Fig. 4b, c: reward curves only; MAPPO\'s "grows slower and '
             'ultimately does not converge" with 6 and 7 Ants',
    'scaling': 'Fig. 4a: reward curves only; "the final reward increments '
               'as the number of agents rises"',
}
VARIANT_NAMES = {'hrl': 'HRL', 'flat': 'No Hierarchy (`flat`)',
                 'no_memory': 'No Spatiotemporal Memory (`no_memory`)',
                 'mappo': 'MAPPO (`mappo`)'}


@dataclasses.dataclass(frozen=True)
class Cell:
  """One training run of the plan and the evaluations of its final
  checkpoint."""

  experiment: str
  """'table1', 'mappo' (IPPO vs MAPPO) or 'scaling' (Fig. 4a)."""
  task: str
  agent: str
  """Variant: hrl, no_memory, flat or mappo."""
  n_agents: int
  """Ants (ravine: crossers, beside TrainArgs' 2 pushers)."""
  seed: int
  budget: int
  """Environment steps to train for."""
  stage: str = ''
  """Curriculum stage: ravine pushers or crossers, transport push, or ''
  for the joint run."""
  init_from: tuple[tuple[str, str], ...] = ()
  """(species, cell name) pairs: the joint run starts from these stage
  cells' committed final checkpoints (`--init-from`)."""
  zero_shot: tuple[int, ...] = ()
  """Other populations its final checkpoint is evaluated at."""
  flags: tuple[tuple[str, Any], ...] = ()
  """Other `TrainArgs` fields of the run (name, value); not those the
  cell's own fields or coop-paper's options set (`paper.train_args`
  refuses them)."""
  copies: int = COPIES
  """Environment copies per update, whatever the actors (`COPIES`)."""

  @property
  def name(self) -> str:
    """Directory name: <task>_<agent>[_<stage>]_n<N>_s<seed>."""
    stage = f'_{self.stage}' if self.stage else ''
    return f'{self.task}_{self.agent}{stage}_n{self.n_agents}_s{self.seed}'

  @property
  def path(self) -> str:
    """What `--only` matches: task/agent[/stage]/n<N>/s<seed>."""
    parts = [self.task, self.agent, self.stage, f'n{self.n_agents}',
             f's{self.seed}']
    return '/'.join(p for p in parts if p)

  @property
  def populations(self) -> tuple[int, ...]:
    """Populations evaluated: its own first, then the zero-shot ones."""
    return (self.n_agents, *self.zero_shot)

  @property
  def ants(self) -> int:
    """Ants per environment copy (the ravine adds its 2 pushers, except
    in the crossers stage)."""
    pushers = 2 if self.task == 'ravine' and self.stage != 'crossers' else 0
    return self.n_agents + pushers

  def ants_at(self, n_agents: int) -> int:
    """Ants per copy evaluated with `n_agents` (its population, or a
    zero-shot one; the ravine's pushers stay)."""
    return self.ants - self.n_agents + n_agents

  def matches(self, patterns) -> bool:
    """Whether `--only` patterns select it: a pattern matches the cell's
    path, a prefix of it (`transport/hrl`) or its name; `*` is a wildcard."""
    return not patterns or any(
        fnmatch.fnmatch(self.path, p) or fnmatch.fnmatch(self.path, p + '/*')
        or fnmatch.fnmatch(self.name, p) for p in patterns)


def trained(experiment, task, agent, n_agents, seed, zero_shot=(),
            budget=BUDGET, flags=()) -> list[Cell]:
  """The cells of one trained model: one run, or its curriculum: on
  transport the push stage then the joint run from it (`budget` in all), on
  the ravine pushers, crossers, then the joint run from both."""
  if task == 'transport':
    push = Cell(experiment, task, agent, n_agents, seed, PUSH_BUDGET,
                stage='push', flags=flags)
    return [push, Cell(experiment, task, agent, n_agents, seed,
                       budget - PUSH_BUDGET, init_from=(('ant', push.name),),
                       zero_shot=zero_shot, flags=flags)]
  if task != 'ravine':
    return [Cell(experiment, task, agent, n_agents, seed, budget,
                 zero_shot=zero_shot, flags=flags)]
  crossers = (CROSSERS_FLAGS if hierarchy_config.HierarchyConfig(
      agent=agent).uses_commands else ())  # Its std is the commands'.
  stages = [Cell(experiment, task, agent, n_agents, seed, steps,
                 stage=stage, flags=flags + extra)
            for stage, steps, extra in (
                ('pushers', STAGE_BUDGET, ()),
                ('crossers', CROSSERS_BUDGET, crossers))]
  joint = Cell(experiment, task, agent, n_agents, seed, budget,
               init_from=(('pusher', stages[0].name),
                          ('crosser', stages[1].name)),
               zero_shot=zero_shot, flags=flags)
  return [*stages, joint]


TABLE1_TASKS = (('transport', 4), ('corridor', 4), ('ravine', 2))


def _zero_shot(n_agents):
  return tuple(n for n in POPULATIONS if n != n_agents)


def _ablations(seed: int) -> list[Cell]:
  """Table 1's `no_memory` then `flat` cells of one seed, task by task."""
  plan = []
  for agent in ('no_memory', 'flat'):
    flags = FLAT_FLAGS if agent == 'flat' else ()
    for task, n in TABLE1_TASKS:
      plan += trained('table1', task, agent, n, seed, flags=flags)
  return plan


def _figures(seed: int) -> list[Cell]:
  """The figures' cells of one seed: IPPO (`hrl`) and MAPPO on the
  corridor with 6 and 7 Ants (Fig. 4b, c), then transport trained with 2,
  3 and 5 Ants (Fig. 4a)."""
  plan = []
  for n in (6, 7):
    for agent in ('hrl', 'mappo'):
      plan += trained('mappo', 'corridor', agent, n, seed)
  for n in (2, 3, 5):
    plan += trained('scaling', 'transport', 'hrl', n, seed)
  return plan


def paper_plan() -> list[Cell]:
  """Every cell of the paper's experiments, most valuable first: Table 1's
  HRL rows (seeds 0-4), its ablations' seeds 0 and 1, the figures' seed 0,
  then the ablations' seed 2 and the figures' seeds 1 and 2. So every
  experiment has a first seed before any ablation has a third: one curve
  shows a figure's shape, a third seed narrows a row already measured."""
  plan = []
  for seed in range(5):
    for task, n in TABLE1_TASKS:
      plan += trained('table1', task, 'hrl', n, seed, _zero_shot(n))
  plan += _ablations(0) + _ablations(1) + _figures(0) + _ablations(2)
  return plan + _figures(1) + _figures(2)


PLAN = paper_plan()


def estimated_seconds(cell: Cell, steps: int, episodes: int = EPISODES,
                      ant_rate: Optional[float] = None,
                      eval_share: Optional[float] = None) -> float:
  """Estimated wall time (s) of `steps` training steps of `cell` at
  `estimated_rate` plus the evaluations of its final checkpoint, every
  episode at its full length (one that succeeds ends sooner), at
  `eval_share` times that rate (e.g. the done cells' measured share), else
  at that rate."""
  rate = estimated_rate(cell, ant_rate) * cell.ants
  steps_per_episode = EPISODE_SECONDS / CONTROL_TIMESTEP
  evaluations = sum(episodes * steps_per_episode * cell.ants_at(n)
                    for n in cell.populations)
  return steps * cell.ants / rate + evaluations / (rate * (eval_share or 1.0))


def estimated_rate(cell: Cell, ant_rate: Optional[float] = None) -> float:
  """The estimated training rate of `cell` in env steps/s: `ant_rate`
  (Ant steps/s, e.g. the pace of the variant's done cells that
  `coop-paper --dry-run` measures), else `AGENT_STEPS_PER_SECOND` times the
  variant's `VARIANT_SPEED`, over the Ants of a copy."""
  if ant_rate is None:
    ant_rate = variant_rate(cell.agent)
  return ant_rate / cell.ants


def variant_rate(agent: str, hrl_rate: float = AGENT_STEPS_PER_SECOND
                 ) -> float:
  """Ant steps/s of `agent`'s cells from `hrl`'s (`hrl_rate`): times the
  variant's `VARIANT_SPEED`."""
  return hrl_rate * VARIANT_SPEED.get(agent, 1.0)
