"""Difficulty references for the cooperative tasks: random, greedy, oracle.

    python -m runners.baselines --task transport --n-agents 4 --policy greedy --episodes 100

Every reference drives the Ants through `CommandWrapper` and the shipped
position controller (the frozen lower layer), as the learned upper layers do,
so a learned policy is judged against what the same legs allow:

* `random`: a uniformly random command per agent and command period.
* `greedy`: memoryless, and each agent reads only its own observation's
  `extero/*` entries, what the upper layer reads (no other agent's view, no
  world state). It is the best hand-written reactive rule we know per task
  (transport: walk behind the cylinder, then push through it towards the
  target; corridor: walk for the slit; ravine: pushers slide the stone
  towards the nearest crosser, crossers walk straight for the finish line).
* `oracle`: reads the whole world state and keeps memory across commands:
  a coordinating plan (transport: push from behind on the true state and
  brake for the target from the cylinder's speed; corridor: one at a time
  in a fixed order; ravine: pushers bring the stone under the waiting
  crosser, the crossers wait, then cross one by one).

A learned result is printed beside these (docs/baselines.md): the greedy
figure is what reacting alone achieves, the oracle's what the task allows
within its time limit.
"""
import dataclasses
import json
import os
from typing import Any

import numpy as np

from agents import fields
from runners import cli
from runners import config as config_lib

os.environ.setdefault('MUJOCO_GL', 'egl')

POLICIES = ('random', 'greedy', 'oracle')
TASKS = ('transport', 'corridor', 'ravine')

# Geometry of an Ant for the references' plans (m).
ANT_REACH = 0.75
"""From an Ant's torso centre to the tips of its legs."""
ANT_WIDTH = 1.15
"""Lateral spacing of two Ants walking side by side without tangling."""
PUSH_AHEAD = 2.5
"""How far ahead (m) a pushing Ant's command is: beyond reach, so that it
keeps walking into the object."""


def clip_norm(vectors, bound):
  """Scales each row of `vectors` [n, 2] down to a norm of at most `bound`,
  keeping its direction (the wrapper's per-axis clip would turn it)."""
  vectors = np.asarray(vectors, np.float64)
  norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
  return vectors * np.minimum(1.0, bound / np.maximum(norm, 1e-9))


def detour(agent, goal, centre, clearance):
  """Where to walk next from `agent` to `goal` without crossing the disc of
  radius `clearance` around `centre` (all [2], any one frame, m): the goal
  itself when the straight line clears the disc, else a point on the disc's
  rim, up to ~50 degrees further round towards the goal."""
  a, d = agent - centre, goal - agent
  s = np.clip(-np.dot(a, d) / max(np.dot(d, d), 1e-9), 0.0, 1.0)
  if np.linalg.norm(a + s * d) >= clearance:
    return goal
  g = goal - centre
  start = np.arctan2(a[1], a[0])
  turn = np.angle(np.exp(1j * (np.arctan2(g[1], g[0]) - start)))
  angle = start + np.sign(turn) * min(abs(turn), 0.9)
  radius = max(clearance, min(np.linalg.norm(a), clearance + 0.5))
  return centre + radius * np.array([np.cos(angle), np.sin(angle)])


def _perp(v):
  return np.array([-v[1], v[0]])


class Random:
  """Uniform random commands in [-bound, bound]^2 per agent."""

  def __init__(self, env, random_state):
    self._bound = float(np.max(env.action_spec()[0].maximum))
    self._rng = random_state

  def __call__(self, env, observation):
    return self._rng.uniform(-self._bound, self._bound, (env.n_agents, 2))


# --- Transport ---------------------------------------------------------------


def push_or_approach(agent, centre, target, radius):
  """One agent's next goal in transport, in any one frame (m): walk round to
  behind the cylinder (centre `centre`, radius `radius`) on the side away
  from `target`, then walk through its centre towards the target.

  Agents that are not yet behind all head for the same point on the line,
  so the pushers end up in file behind the cylinder: the formation that
  pushed it fastest (docs/tasks.md). Returns (goal [2], behind: bool).
  """
  to_target = target - centre
  p = to_target / max(np.linalg.norm(to_target), 1e-9)
  rel = agent - centre
  behind = bool(np.dot(rel, p) < -(radius + 0.1)
                and abs(p[0] * rel[1] - p[1] * rel[0]) < radius + 0.4)
  if behind:
    return centre + PUSH_AHEAD * p, True
  return detour(agent, centre - (radius + ANT_REACH + 0.2) * p, centre,
                radius + ANT_REACH + 0.1), False


class TransportGreedy:
  """Each agent on its own `extero/cylinder` and `extero/target` (heading
  frame, the agent at the origin): `push_or_approach`, and stand once the
  cylinder is near the target's centre."""

  STOP = 0.4
  """Stand once the cylinder's centre is this close to the target's (m)."""

  def __init__(self, env, random_state):
    del random_state
    self._radius = env.task.cylinder.radius

  def __call__(self, env, observation):
    return np.stack([self._command(o) for o in observation])

  def _command(self, obs):
    c, t = obs['extero/cylinder'], obs['extero/target']
    if np.linalg.norm(t - c) < self.STOP:
      return np.zeros(2)
    return clip_norm(push_or_approach(np.zeros(2), c, t, self._radius)[0], 3.0)


class TransportOracle:
  """World state and memory: the greedy rule's walk-round-and-push geometry
  (`push_or_approach`) on the true state, with braking: pushing stops when
  the cylinder's predicted stopping point (its speed, which a memoryless
  policy cannot see, and the floor's friction) reaches the target, and
  resumes if it comes to rest short of it.

  `GATHER` adds the textbook plan: agents behind the cylinder wait there
  until the whole team is (or, after `PATIENCE`, half of it), then all push
  together. On the calibrated task it measured worse (docs/baselines.md):
  forces add up, so waiting only loses time; it stays off by default.
  """

  GATHER = False
  PATIENCE = 3.0
  """With `GATHER`: push with half the team after waiting this long (s)."""

  def __init__(self, env, random_state):
    del random_state
    task = env.task
    self._radius = task.cylinder.radius
    self._friction = task.config.cylinder_friction
    self._zone = task.config.target_radius
    self._period = env.control_timestep()
    self._pushing = not self.GATHER
    self._waited = 0.0

  def __call__(self, env, observation):
    task, physics = env.task, env.physics
    frames = task.frames(physics)
    agents = frames.position[:, :2]
    centre = task.cylinder.position(physics)[:2].copy()
    velocity = physics.data.cvel[task.cylinder.body_id][3:5]
    target = task.arena.target_position
    distance = np.linalg.norm(target - centre)
    line = (target - centre) / max(distance, 1e-9)
    speed = max(0.0, float(np.dot(velocity, line)))
    coast = speed ** 2 / (2 * 9.81 * max(self._friction, 1e-3))
    if distance < min(0.5 * self._zone, coast + 0.3):
      return np.zeros((env.n_agents, 2))  # Let it slide to rest.
    plans = [push_or_approach(a, centre, target, self._radius) for a in agents]
    goals = np.stack([goal for goal, _ in plans])
    behind = np.array([b for _, b in plans])
    if not self._pushing:
      self._waited += self._period
      self._pushing = behind.all() or (self._waited > self.PATIENCE
                                       and behind.mean() >= 0.5)
    if not self._pushing:
      goals[behind] = agents[behind]  # Wait in place for the others.
    return clip_norm(frames.to_heading_frame(goals), 3.0)


# --- Corridor ------------------------------------------------------------------


def _own_world(obs, key):
  """An agent's own heading-frame offset `obs[key]` [2] in the world frame,
  through its own `extero/self_pose` (x, y, cos, sin): still only what the
  upper layer reads."""
  from coop_suite import kernels  # pylint: disable=g-import-not-at-top
  x, y, cos, sin = obs['extero/self_pose']
  dx, dy = kernels.rotate(cos, sin, *obs[key][:2])
  return np.array([x + dx, y + dy])


def _to_own_heading(obs, world):
  """World point `world` [2] -> the agent's heading-frame offset."""
  from coop_suite import kernels  # pylint: disable=g-import-not-at-top
  x, y, cos, sin = obs['extero/self_pose']
  return np.array(kernels.to_heading(cos, sin, world[0] - x, world[1] - y))


class CorridorGreedy:
  """Each agent on its own `extero/slit` and `extero/target`: walk to the
  slit's mouth, through the slit, on to the finish line (everyone at once)."""

  def __init__(self, env, random_state):
    del env, random_state

  def __call__(self, env, observation):
    return np.stack([self._command(o) for o in observation])

  @staticmethod
  def _command(obs):
    entrance, exit_ = obs['extero/slit'][0:2], obs['extero/slit'][2:4]
    target = obs['extero/target']
    axis = (exit_ - entrance) / max(np.linalg.norm(exit_ - entrance), 1e-9)
    if obs['extero/crossed'][0] > 0.5 or np.dot(-entrance, axis) > 0:
      goal = target + axis  # In or past the slit: on over the line.
    elif np.linalg.norm(entrance - 0.6 * axis) > 0.5:
      goal = entrance - 0.6 * axis  # To the slit's mouth.
    else:
      goal = exit_ + 2.0 * axis
    return clip_norm(goal, 3.0)


class CorridorOracle:
  """World state and memory: one agent at a time, the one in the middle of
  the start arc first, then outwards. The others hold their start places,
  except the next in line, which waits 2 m before the slit's mouth once the
  one before has passed that point; it goes in when the one before has
  passed the slit's exit. Agents through the
  slit walk on to spread out beyond the finish line."""

  STAGING = 2.0
  """The next agent in line waits this far before the slit's mouth (m)."""

  def __init__(self, env, random_state):
    del random_state
    arena = env.task.arena
    self._entrance = np.asarray(arena.slit_entrance, np.float64)
    self._exit = np.asarray(arena.slit_exit, np.float64)
    self._axis = (self._exit - self._entrance) / np.linalg.norm(
        self._exit - self._entrance)
    self._finish_x = arena.finish_x
    self._queue = None
    self._starts = None
    self._turn = 0

  def __call__(self, env, observation):
    frames = env.task.frames(env.physics)
    agents = frames.position[:, :2]
    n, axis = len(agents), self._axis
    if self._queue is None:  # Centre first: least off the slit's axis.
      offset = (agents - self._entrance) @ _perp(axis)
      self._queue = np.argsort(np.abs(offset), kind='stable')
      self._starts = agents.copy()
    through = (agents - self._exit) @ axis > 0.3
    while self._turn < n and through[self._queue[self._turn]]:
      self._turn += 1
    mouth = self._entrance - 0.6 * axis
    goals = self._starts.copy()  # Hold the start place by default.
    # The next in line stages only once the one whose turn it is has passed
    # the staging point: staged earlier, it stands in that one's way.
    ahead_of_staging = self._turn >= n or (
        (agents[self._queue[self._turn]] - self._entrance) @ axis
        > -self.STAGING + 0.8)
    for rank, agent in enumerate(self._queue):
      if through[agent]:
        lateral = (rank - (n - 1) / 2) * 1.8
        goals[agent] = (self._finish_x + 1.0, lateral)
      elif rank == self._turn:
        close = np.linalg.norm(agents[agent] - mouth) < 0.6 or (
            (agents[agent] - self._entrance) @ axis > -0.3)
        goals[agent] = self._exit + 2.0 * axis if close else mouth
      elif rank == self._turn + 1 and ahead_of_staging:
        goals[agent] = self._entrance - self.STAGING * axis
    return clip_norm(frames.to_heading_frame(goals), 3.0)


# --- Ravine --------------------------------------------------------------------


class RavineGreedy:
  """Each agent on its own exteroception. Crossers walk straight for the
  finish line. Pushers (in the trench) slide the stone along it towards the
  nearest crosser's y: from behind the stone when on the right side of it,
  else they stay put (the stone fills the trench: they cannot pass it)."""

  def __init__(self, env, random_state):
    del random_state
    self._crosser = [s == 'crosser' for s in env.task.species]
    self._half = env.task.config.stone_length / 2

  def __call__(self, env, observation):
    return np.stack([
        self._cross(o) if crosser else self._push(o)
        for o, crosser in zip(observation, self._crosser)])

  @staticmethod
  def _cross(obs):
    return clip_norm(obs['extero/finish'], 3.0)

  def _push(self, obs):
    stone = _own_world(obs, 'extero/stone')
    crosser = _own_world(obs, 'extero/nearest_crosser')
    me = obs['extero/self_pose'][:2]
    gap = crosser[1] - stone[1]
    if abs(gap) < 0.2:
      return np.zeros(2)
    direction = np.sign(gap)
    if np.sign(stone[1] - me[1]) != direction:
      return np.zeros(2)  # On the far side: cannot get behind the stone.
    behind = stone[1] - direction * (self._half + ANT_REACH + 0.1)
    if abs(me[1] - behind) > 0.5 and direction * (behind - me[1]) > 0:
      goal = np.array([stone[0], behind])
    else:
      goal = np.array([stone[0], stone[1] + direction * PUSH_AHEAD])
    return clip_norm(_to_own_heading(obs, goal), 3.0)


class RavineOracle:
  """World state and memory: crossers go one at a time, nearest to the
  ravine first. The pushers bring the stone under the crosser whose turn it
  is (the one on the stone's far side waits); that crosser waits at the edge
  until the stone is in place and at rest, then walks straight across; the
  others stand until their turn. The pusher on the stone's far side keeps
  ahead of it, out of its way."""

  TOLERANCE = 0.25
  """Stone in place: |stone_y - crosser_y| below this (m)."""

  def __init__(self, env, random_state):
    del random_state
    task = env.task
    self._arena = task.arena
    self._crossers = np.flatnonzero([s == 'crosser' for s in task.species])
    self._pushers = np.flatnonzero([s == 'pusher' for s in task.species])
    self._half = task.config.stone_length / 2
    self._queue = None
    self._crossing = False

  def __call__(self, env, observation):
    task, physics, arena = env.task, env.physics, self._arena
    frames = task.frames(physics)
    agents = frames.position[:, :2]
    stone = task.stone.position(physics)[:2]
    stone_speed = np.linalg.norm(physics.data.cvel[task.stone.body_id][3:5])
    goals = agents.copy()  # Stand by default.
    if self._queue is None:
      gaps = arena.near_edge_x - agents[self._crossers, 0]
      self._queue = list(self._crossers[np.argsort(gaps)])
    while self._queue and agents[self._queue[0], 0] > arena.finish_x:
      self._queue.pop(0)
      self._crossing = False
    if self._queue:
      turn = self._queue[0]
      wait = np.array([arena.near_edge_x - 0.9, agents[turn, 1]])
      gap = agents[turn, 1] - stone[1]
      if not self._crossing:
        in_place = abs(gap) < self.TOLERANCE and stone_speed < 0.1
        near_edge = np.linalg.norm(agents[turn] - wait) < 0.5
        self._crossing = in_place and near_edge
      # Straight across: the stone is barely longer than an Ant is wide.
      goals[turn] = ((arena.finish_x + 1.0, agents[turn, 1]) if self._crossing
                     else wait)
      for pusher in self._pushers:
        goals[pusher] = self._push(agents[pusher], stone, gap)
    for crosser in self._crossers:
      if agents[crosser, 0] > arena.far_edge_x:
        goals[crosser] = (arena.finish_x + 1.5, agents[crosser, 1])
    return clip_norm(frames.to_heading_frame(goals), 3.0)

  def _push(self, pusher, stone, gap):
    if abs(gap) < 0.5 * self.TOLERANCE:
      return pusher  # Stand.
    direction = np.sign(gap)
    if np.sign(stone[1] - pusher[1]) != direction:
      # On the far side: keep out of the stone's way, ahead of it.
      clear = stone[1] + direction * (self._half + ANT_REACH + 1.5)
      if direction * (clear - pusher[1]) > 0:
        return np.array([stone[0], clear])
      return pusher
    behind = stone[1] - direction * (self._half + ANT_REACH + 0.1)
    if direction * (behind - pusher[1]) > 0.5:
      return np.array([stone[0], behind])
    # Push for as far as the stone still has to go, no further.
    return np.array([stone[0], pusher[1] + direction * min(
        PUSH_AHEAD, abs(gap) + ANT_REACH)])


REFERENCES = {
    'transport': {'random': Random, 'greedy': TransportGreedy,
                  'oracle': TransportOracle},
    'corridor': {'random': Random, 'greedy': CorridorGreedy,
                 'oracle': CorridorOracle},
    'ravine': {'random': Random, 'greedy': RavineGreedy,
               'oracle': RavineOracle},
}
"""Task -> policy name -> class(env, random_state), called with (env,
observation) once per command period, returning commands [n_agents, 2]."""


@dataclasses.dataclass(frozen=True)
class BaselineArgs:
  """What to play (every field is a flag)."""

  task: str = fields.field('transport', fields.one_of(*REFERENCES))
  """Task: transport, corridor or ravine."""
  n_agents: int = 4
  """Agents (ravine: crossers; the pushers are --n-pushers)."""
  policy: str = fields.field('greedy', fields.one_of(*POLICIES))
  """Reference policy: random, greedy or oracle."""
  episodes: int = fields.field(100, fields.COUNT)
  """Episodes to play."""
  seed: int = fields.field(1000, fields.SEED)
  """Seed of the first episode; episode i uses seed + i (with --envs, the
  evaluation seed)."""
  envs: int = fields.field(0, fields.NON_NEGATIVE)
  """0: each episode is a fresh environment (the tables of
  docs/baselines.md). E > 0: the episodes `coop-eval --seeds <seed> --envs
  E` plays (E copies seeded by `evaluate.copy_seeds`, each playing its
  share in turn), so `coop-compare` pairs the reference with evaluated
  models episode by episode."""
  time_limit: float = fields.field(0.0, config_lib.TIME_LIMIT)
  """Episode length (s); 0 keeps the task's default."""
  command_period: float = fields.field(0.5, fields.POSITIVE)
  """Seconds between commands."""
  n_pushers: int = 2
  """Ravine only: number of pushers."""
  json: str = ''
  """Also write the figures (and every episode's metrics) to this file."""
  progress: bool = True
  """Show a progress bar."""
  report: str = ''
  """Instead of playing, print the markdown tables of every result JSON in
  this folder (e.g. results/baselines), one table per task."""

  def __post_init__(self):
    fields.check(self)

  def env_options(self) -> dict[str, Any]:
    options = {}
    if self.time_limit > 0:
      options['time_limit'] = self.time_limit
    if self.task == 'ravine':
      options['n_pushers'] = self.n_pushers
    return options


def play(args: BaselineArgs, **task_options) -> dict:
  """Plays `args.episodes` episodes of the reference policy.

  `task_options` go to `coop_suite.load` after `args`' own (calibration
  sweeps use them). Returns success with its standard error, "ever reached"
  where the task reports it, the mean return and every episode's metrics.
  """
  import coop_suite  # pylint: disable=g-import-not-at-top
  from agents import lowlevel  # pylint: disable=g-import-not-at-top
  from runners import evaluate  # pylint: disable=g-import-not-at-top
  import tqdm  # pylint: disable=g-import-not-at-top
  controller = lowlevel.load('position')
  options = {**args.env_options(), **task_options}
  reference = REFERENCES[args.task][args.policy]
  if args.envs:  # coop-eval's episodes: each copy plays its share in turn.
    copies = evaluate.copy_seeds(args.seed, min(args.envs, args.episodes))
    plays = [(seed, k, [int(seed), k]) for seed, share in zip(
        copies, evaluate.shares(args.episodes, len(copies)))
             for k in range(share)]
  else:  # A fresh environment per episode.
    plays = [(args.seed + episode, 0, args.seed + episode)
             for episode in range(args.episodes)]
  episodes, env = [], None
  for seed, k, policy_seed in tqdm.tqdm(
      plays, disable=not args.progress, desc=f'{args.task} {args.policy}',
      leave=False):
    if k == 0:
      if env is not None:
        env.close()
      env = lowlevel.CommandWrapper(
          coop_suite.load(args.task, args.n_agents, seed=int(seed), **options),
          controller, args.command_period)
    if not episodes:
      config = dataclasses.asdict(env.task.config)
    policy = reference(env, np.random.RandomState(policy_seed))
    timestep = env.reset()
    while not timestep.last():
      timestep = env.step(policy(env, timestep.observation))
    episodes.append(env.episode_metrics())
  env.close()
  success, success_se = evaluate.mean_and_error(
      [e['success'] for e in episodes])
  out = {'task': args.task, 'n_agents': args.n_agents, 'policy': args.policy,
         'episodes': len(episodes),
         **({'eval_seed': args.seed, 'envs': len(copies)} if args.envs else
            {'seeds': [args.seed, args.seed + args.episodes - 1]}),
         'success': success, 'success_se': success_se,
         'return': float(np.mean([e['return'] for e in episodes])),
         'task_options': {k: v for k, v in options.items()
                          if k not in config},
         'config': config}
  if 'reached' in episodes[0]:
    out['reached'], out['reached_se'] = evaluate.mean_and_error(
        [e['reached'] for e in episodes])
  out['per_episode'] = episodes
  return out


def results_path(folder: str, task: str, n_agents: int, policy: str) -> str:
  """Where a cell's JSON is kept: <folder>/<task>_n<N>_<policy>.json."""
  return os.path.join(folder, f'{task}_n{n_agents}_{policy}.json')


def read_results(folder: str) -> dict[str, dict[tuple[int, str], dict]]:
  """Every result JSON in `folder`: {task: {(n_agents, policy): figures}}."""
  table = {}
  for name in sorted(os.listdir(folder)):
    if name.endswith('.json'):
      with open(os.path.join(folder, name)) as f:
        out = json.load(f)
      table.setdefault(out['task'], {})[(out['n_agents'], out['policy'])] = out
  return table


def played_on(out: dict) -> str:
  """Which episodes the result `out` played: 'seeds 1000-1099' (a fresh
  environment each) or 'coop-eval --seeds 1000 --envs 10'."""
  if 'eval_seed' in out:
    return f'coop-eval --seeds {out["eval_seed"]} --envs {out["envs"]}'
  return f'seeds {out["seeds"][0]}-{out["seeds"][1]}'


def paired_figures(out: dict, path: str = 'reference') -> tuple[str, dict]:
  """(task name, {figure: one value per episode}) of the result `out`,
  for `coop-compare`; `out` must have played coop-eval's episodes
  (`--envs`), else ValueError naming `path`."""
  from runners import marl_eval  # pylint: disable=g-import-not-at-top
  if 'eval_seed' not in out:
    raise ValueError(
        f'{path}: a {out.get("policy")} reference on {played_on(out)}, a '
        'fresh environment per episode: not the episodes coop-eval plays; '
        're-play it with `python -m runners.baselines ... --seed 1000 --envs '
        '10` (coop-eval\'s --seeds and --envs) to pair it')
  per_episode = out['per_episode']
  names = [k for k, v in per_episode[0].items()
           if isinstance(v, (bool, int, float))]
  figures = {k: [float(e[k]) for e in per_episode] for k in names}
  stage = out.get('task_options', {}).get('stage', '')
  return marl_eval.task_name(out['task'], out['n_agents'], stage), figures


def population_unit(task: str) -> str:
  """What a task's agent count counts, for table headers."""
  return 'crossers' if task == 'ravine' else 'Ants'


def success_cell(figures: dict) -> str:
  """A result's success as a table cell: '54% +- 5'."""
  return f'{100 * figures["success"]:.0f}% +- {100 * figures["success_se"]:.0f}'


def report(folder: str) -> str:
  """Markdown: per task, success +- standard error for each population
  (rows) and reference (columns), "ever reached" in brackets where the task
  reports it, and the episodes and seeds behind each cell."""
  lines = []
  for task, cells in read_results(folder).items():
    counts = sorted({n for n, _ in cells})
    policies = [p for p in POLICIES if any(p == q for _, q in cells)]
    unit = population_unit(task)
    lines += [f'### {task}', '',
              f'| {unit} | ' + ' | '.join(policies) + ' | episodes (seeds) |',
              '|---|' + '---|' * (len(policies) + 1)]
    for n in counts:
      row, runs = [], set()
      for policy in policies:
        out = cells.get((n, policy))
        if out is None:
          row.append('')
          continue
        cell = success_cell(out)
        if 'reached' in out:
          cell += f' ({100 * out["reached"]:.0f}%)'
        row.append(cell)
        runs.add(f'{out["episodes"]} '
                 f'({played_on(out).removeprefix("seeds ")})')
      lines.append(f'| {n} | ' + ' | '.join(row) + f' | {", ".join(runs)} |')
    lines.append('')
  return '\n'.join(lines)


def main(argv=None):
  args, out = cli.run(BaselineArgs,
                      lambda a: report(a.report) if a.report else play(a),
                      argv, 'python -m runners.baselines',
                      __doc__.splitlines()[0])
  if args.report:
    print(out)
    return
  line = (f'{args.policy} on {args.task} with {args.n_agents} agents, '
          f'{played_on(out)}: success '
          f'{100 * out["success"]:.1f}% +- {100 * out["success_se"]:.1f}%')
  if 'reached' in out:
    line += f' (ever reached {100 * out["reached"]:.1f}%)'
  print(line + f', mean return {out["return"]:.1f}')
  if args.json:
    with open(args.json, 'w') as f:
      json.dump(out, f, indent=1)


if __name__ == '__main__':
  main()
