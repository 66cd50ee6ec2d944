"""Ravine bridging: pushers move a stone so that crossers can walk over it.

Two species. Crossers start on the near plane; pushers start inside the
trench on either side of the stone. Success when every crosser has passed the
finish line (`success='all'`, the default: more crossers make the task
harder, as in the paper's Table 2) or when one has (`success='any'`). The paper trains this in stages (its appendix "Training pipeline of
Ravine Bridging"), selected with `stage`:

* 'pushers': only the pushers act. The crossers are replaced by `n_agents`
  markers at random places along the near edge; pushers are paid
  5 / (1 + |stone_y - y of the crosser nearest the ravine|).
* 'crossers': only the crossers act, the stone lies across one crosser's
  path in half of the episodes (`stone_in_path_probability`), anywhere
  otherwise; each crosser starts 0.5-1.5 m before the edge in half of the
  episodes (`edge_start_probability`), and in 70% of the episodes with the
  stone across a crosser's path that crosser starts in front of the
  stone, on it or past it (`stone_start_probability`,
  `stone_start_offset`). Crossers are paid 5 / (1 + |finish_x - x|)
  and -20 once if they fall in. A fallen crosser is out (paid nothing
  more) and the others go on: the episode fails when every crosser has
  fallen (with `success='all'` one that had a fall cannot succeed;
  `crossed` counts the crossings).
* 'joint': everybody acts; both shaping terms stay on and success pays +50
  to all agents (and ends the episode with `end_on_success`).

The pushers serve the crosser nearest the ravine that has neither fallen in
nor crossed yet. `start_stone_y` and `start_crossers_edge` record the
episode's start (the stone's place along the trench; the crossers', or the
markers', mean distance before the near edge, negative past it; m), so that
`coop-compare` can check that two evaluations played the same episodes.
"""

import dataclasses
from typing import NamedTuple

import numba
import numpy as np

from coop_suite import arenas
from coop_suite import kernels
from coop_suite.entities import Stone
from coop_suite.tasks import base
from coop_suite.tasks import layouts
from coop_suite.tasks import rewards

STAGES = ("joint", "pushers", "crossers")
SUCCESS_RULES = ("all", "any")
# A crosser whose torso is this far below the plane (m) has fallen in; on the
# plane or on the stone it rides about 0.55 m above it.
_FALLEN_HEIGHT = -0.1


@dataclasses.dataclass(frozen=True)
class RavineConfig(base.TaskConfig):
  """Ravine settings; reward coefficients follow the paper's table."""

  time_limit: float = 40.0
  bridge_scale: float = 5.0
  """Pushers: coefficient of 5 / (1 + |stone_y - nearest crosser's y|)."""
  destination_scale: float = 5.0
  """Crossers: coefficient of 5 / (1 + |finish_x - x|)."""
  fall_penalty: float = -20.0
  """Crossers: paid once on falling into the trench."""
  success_bonus: float = 50.0
  """Joint stage: paid to all agents on success."""
  success: str = "all"
  """'all': success when every crosser has passed the finish line, failure
  (the episode ends) once one has fallen in (in the crossers stage once all
  have); 'any': success when one crosser has passed it, failure once all
  have fallen in. A fallen crosser earns no destination reward after its
  fall."""
  width: float = 2.0
  """Trench width (m)."""
  depth: float = 1.0
  """Trench depth (m), also the stone's height."""
  length: float = 16.0
  """Trench length (m)."""
  stone_length: float = 3.2
  """Stone extent along the trench (m). The shipped lower layer drifts up to
  ~1 m sideways while stepping onto the stone: with 1.6 m it fell in 8 of 8
  straight crossings of a stone placed exactly under it, with 3.2 m in 1 of
  8 (docs/tasks.md)."""
  stone_mass: float = 12.0
  """Stone mass (kg)."""
  start_gap: float = 2.0
  """Distance from the crossers' start line to the near edge (m)."""
  bridge_tolerance: float = 0.3
  """Pushers stage: the stone is "in place" within this |dy| (m)."""
  stone_in_path_probability: float = 0.5
  """Crossers stage: how often the stone starts across a crosser's path (its
  y within `stone_in_path_distance` of one crosser's start y, the crosser
  drawn at random); otherwise it lies anywhere, as in the other stages.
  The shipped walker crosses a stone within 0.5 m of its line 30 times in
  30 and falls beside one 1.3 m off every time; a stone anywhere is that
  close to one of two crossers in ~18% of episodes, and a crossers stage
  trained so never once crossed (docs/results.md)."""
  stone_in_path_distance: float = 0.3
  """Crossers stage: largest |stone_y - the crosser's y| (m) of a stone
  placed in its path."""
  edge_start_probability: float = 0.5
  """Crossers stage: how often each crosser starts `edge_start_distance`
  before the near edge instead of `start_gap` + 0-1 m (drawn for each
  crosser alone, so a crosser at the edge has the stone in front in some
  episodes and not in others). From 2-3 m back, crossers learned to hold
  before the edge long before a crossing was ever seen; with these starts
  they still did not cross (docs/results.md)."""
  edge_start_distance: tuple = (0.5, 1.5)
  """Crossers stage: range of a crosser's distance (m) from the near edge
  when it starts there (the oracle waits 0.9 m before it)."""
  stone_start_probability: float = 0.7
  """Crossers stage: how often the crosser whose path the stone is across
  starts just in front of the stone, on it or past it instead
  (`stone_start_offset`): a reverse curriculum, since crossing from the
  edge takes ~10 consecutive forward commands that sampled commands never
  strung together (no crossing in 1M steps with crossers at the edge).
  With 0.3 (a crosser on the stone's middle in 15% of the episodes) the
  stage did not learn to cross (0.01 an episode in one run's first
  updates, none after), with the default command noise or a small one: the
  policy learned to hold ~1.4 m before the near edge and, on the stone,
  walked back to that (docs/results.md). A fallen crosser stays in the
  trench, where it can push the stone."""
  stone_start_offset: tuple = (-1.5, 3.0)
  """Crossers stage: range of a stone start's x relative to the near edge
  (m; negative before it): from 1.5 m before the edge, over the stone
  (which spans 0.05 to `width` - 0.05), to 1 m past the far edge; below
  the finish line (2 m past the far edge). Starts on the stone's middle
  only (0.6-1.4 m) left the policy walking back off the stone (no
  crossing in 1.9M steps); from 0.6-3.0 m it crossed from 0.94 of such
  starts at 1.7M steps and all at 3.5M, but never stepped onto the stone
  from 0.5-1.5 m before the edge. With this range seed 0 stepped on from
  0-0.5 m by 10M steps, and from ~11M went to the stone and crossed on it
  from every start tried, the stone up to >6 m to a side included: 81% of
  its stage's episodes at 20M, every crosser across (docs/results.md)."""


class Ravine(base.CoopTask):
  """Bridge the ravine with the stone and cross it."""

  MIN_AGENTS, MAX_AGENTS = 1, 8
  TASK_OPTIONS = ("stage", "n_pushers")
  EXTERO_FEATURES = ("stone", "ravine", "finish", "nearest_crosser")

  def __init__(self, n_agents, config=RavineConfig(), stage="joint",
               n_pushers=2):
    if stage not in STAGES:
      raise ValueError(f"Unknown stage {stage!r}; choose one of {STAGES}.")
    if (isinstance(n_pushers, (bool, np.bool_))
        or not isinstance(n_pushers, (int, np.integer))
        or not 1 <= n_pushers <= 4):
      raise ValueError(f"n_pushers must be an integer in [1, 4], got "
                       f"{n_pushers!r}.")
    n_pushers = int(n_pushers)  # NumPy integers too (e.g. from a sweep).
    if config.success not in SUCCESS_RULES:
      raise ValueError(f"Unknown success rule {config.success!r}; choose one "
                       f"of {SUCCESS_RULES}.")
    self.stage = stage
    arena = arenas.RavineArena(width=config.width, depth=config.depth,
                               length=config.length,
                               physics_timestep=config.physics_timestep)
    finish = arena.finish_x - arena.near_edge_x
    if (stage == "crossers" and config.stone_start_probability > 0
        and config.stone_start_offset[1] >= finish):  # Only there it acts.
      raise ValueError(
          f"RavineConfig.stone_start_offset must end before the finish line "
          f"({finish:g} m past the near edge), got "
          f"{tuple(config.stone_start_offset)!r}.")
    self.stone = Stone(size=(config.stone_length, config.width - 0.1,
                             config.depth), mass=config.stone_mass)
    arena.add_free_entity(self.stone)
    n_crossers = 0 if stage == "pushers" else n_agents
    n_push = 0 if stage == "crossers" else n_pushers
    self._n_markers = n_agents  # Crossers (real or virtual) to serve.
    super().__init__(arena, ["crosser"] * n_crossers + ["pusher"] * n_push,
                     config)
    self._is_crosser = np.array([s == "crosser" for s in self.species])
    self._fallen = np.zeros(self.n_agents, dtype=bool)
    self._crossed = np.zeros(self.n_agents, dtype=bool)
    self._fall_term = np.zeros(self.n_agents)
    self._out = np.zeros(self.n_agents, dtype=bool)
    self._markers = np.zeros((n_agents, 2))
    self._start = (0.0, 0.0)  # See `_progress`.
    # `measure`'s arguments after the stone (the arena does not move).
    self._geometry = (
        float(arena.near_edge_x), float(arena.far_edge_x),
        float(arena.finish_x), float(arena.width), float(arena.depth),
        float(config.bridge_scale), float(config.destination_scale))

  # --- Per-state numbers --------------------------------------------------------

  def _measure(self, physics):
    """`measure` of this physics state (computed once per state, after the
    status update of the step that reached it: the nearest crosser skips
    crossers that have fallen in or crossed)."""
    return self.per_state("measure", lambda: measure(
        self.frames(physics).packed, self._is_crosser,
        self._fallen | self._crossed,
        self._markers, self.stage == "pushers", physics.data.ptr.xpos,
        self.stone.body_id, *self._geometry))

  # --- Hooks -------------------------------------------------------------------

  def _exteroception(self, physics, frames):
    offsets = self._measure(physics).offsets
    return {
        "stone": offsets[:, 0:2],
        "ravine": offsets[:, 2:8],
        "finish": offsets[:, 8:10],
        "nearest_crosser": offsets[:, 10:12],
    }

  def _initialize_layout(self, physics, random_state):
    cfg = self._config
    arena = self._arena
    self._fallen = np.zeros(self.n_agents, dtype=bool)
    self._crossed = np.zeros(self.n_agents, dtype=bool)
    self._fall_term = np.zeros(self.n_agents)
    self._out = np.zeros(self.n_agents, dtype=bool)
    half = cfg.length / 2 - cfg.stone_length / 2 - 2.0
    stone_y = random_state.uniform(-half, half)
    line_half = max(0.0, cfg.length / 2 - 2.0
                    - (self._n_markers - 1) * layouts.ANT_SPACING / 2)
    crossers = layouts.line(self._n_markers,
                            arena.near_edge_x - cfg.start_gap,
                            random_state.uniform(-line_half, line_half))
    crossers[:, 0] -= random_state.uniform(0, 1.0, self._n_markers)
    self._markers = crossers
    if self.stage == "crossers":
      stone_y = self._crossers_stage_starts(crossers, stone_y, random_state)
    self._start = (float(stone_y),
                   float(np.mean(arena.near_edge_x - crossers[:, 0])))
    layouts.place_prop(self.stone, physics,
                       [arena.ravine_x, stone_y, -cfg.depth / 2])
    walkers = iter(self._walkers)
    if self.stage != "pushers":
      for xy, walker in zip(crossers, walkers):
        layouts.place(walker, physics, xy,
                      random_state.uniform(-0.4, 0.4), random_state)
    offset = cfg.stone_length / 2 + 1.0
    for i, walker in enumerate(walkers):
      side = 1.0 if i % 2 == 0 else -1.0
      y = stone_y + side * (offset + (i // 2) * layouts.ANT_SPACING)
      y = np.clip(y, -cfg.length / 2 + 0.8, cfg.length / 2 - 0.8)
      layouts.place(walker, physics, [arena.ravine_x, y],
                    -side * np.pi / 2 + random_state.uniform(-0.3, 0.3),
                    random_state, ground_z=-cfg.depth)

  def _crossers_stage_starts(self, crossers, stone_y, random_state):
    """The crossers stage's own starts (see `RavineConfig`): moves
    `crossers` [n, 2] in place and returns the stone's y. Drawn in this
    stage alone: the other stages' episodes stay those of their seeds."""
    cfg = self._config
    arena = self._arena
    in_path = None  # The crosser whose path the stone is across.
    if (cfg.stone_in_path_probability > 0
        and random_state.uniform() < cfg.stone_in_path_probability):
      in_path = random_state.randint(self._n_markers)
      # Clear of the trench's end walls (crossers start up to 6 m out).
      end = cfg.length / 2 - cfg.stone_length / 2 - 0.2
      stone_y = np.clip(crossers[in_path, 1] + random_state.uniform(
          -cfg.stone_in_path_distance, cfg.stone_in_path_distance),
          -end, end)
    if cfg.edge_start_probability > 0:
      at_edge = (random_state.uniform(size=self._n_markers)
                 < cfg.edge_start_probability)
      crossers[at_edge, 0] = arena.near_edge_x - random_state.uniform(
          *cfg.edge_start_distance, size=int(at_edge.sum()))
    if (in_path is not None and cfg.stone_start_probability > 0
        and random_state.uniform() < cfg.stone_start_probability):
      # In front of the stone, on it or past it, its y already within
      # stone_in_path_distance of the stone's.
      crossers[in_path, 0] = arena.near_edge_x + random_state.uniform(
          *cfg.stone_start_offset)
    return stone_y

  def _update_status(self, physics):
    self._out = self._fallen.copy()  # Fell at an earlier step.
    self._fall_term = update_falls(
        self.frames(physics).packed, self._is_crosser, self._fallen,
        self._crossed, self._arena.finish_x, _FALLEN_HEIGHT,
        self._config.fall_penalty)
    if self.stage == "pushers":
      self._success = False  # Judged at the end; see `_progress`.
      return
    crossed = self._crossed[self._is_crosser]
    fallen = self._fallen[self._is_crosser]
    if self._config.success == "all":
      self._success = bool(crossed.all())
    else:
      self._success = bool(crossed.any())
    # A fall ends the episode for everybody under 'all', except in the
    # crossers stage: there a fallen crosser is out and the others go on.
    # (With one policy for both crossers, a partner walking into the trench
    # beside the stone ended the episode before the crosser on the stone
    # reached the finish line: no crossing was ever seen.)
    if self._config.success == "all" and self.stage != "crossers":
      self._failure = bool(fallen.any())
    else:
      self._failure = bool(fallen.all())

  def _reward_terms(self, physics):
    shaping = self._measure(physics).shaping
    terms = {}
    if self.stage in ("pushers", "joint"):
      terms["bridge"] = shaping[0]
    if self.stage in ("crossers", "joint"):
      # A crosser that has fallen in earns nothing more (the paper's
      # "death"); where a fall ends the episode this changes nothing.
      terms["destination"] = np.where(self._out, 0.0, shaping[1])
      terms["fall"] = self._fall_term
    if self.stage == "joint":
      terms["success"] = self.each_agent(
          self._config.success_bonus if self._success_event else 0.0)
    return terms

  def _progress(self, physics):
    bridge_error = self._measure(physics).bridge_error
    out = {"bridge_error": float(bridge_error),
           "stone_in_place": bool(bridge_error < self._config.bridge_tolerance),
           "fallen": int(np.sum(self._fallen)),
           "crossed": int(np.sum(self._crossed)),
           "start_stone_y": self._start[0],
           "start_crossers_edge": self._start[1]}
    if self.stage == "pushers":
      out["success"] = out["stone_in_place"]
    return out

  def _task_state(self, physics):
    return np.concatenate([self.stone.position(physics)[:2],
                           self._measure(physics).nearest])

  def tracked_positions(self, physics):
    return np.vstack([super().tracked_positions(physics),
                      self.stone.position(physics)])


@numba.njit(cache=True)
def update_falls(frames, is_crosser, fallen, crossed, finish_x, fallen_height,
                 fall_penalty):
  """One step's status: crossers whose torso is below `fallen_height` have
  fallen, those past `finish_x` have crossed (both marked in place, for
  good).

  Args:
    frames: [n, >= 5] the agents' x, y, z, cos, sin (`AgentFrames.packed`).
    is_crosser, fallen, crossed: [n] bools.
    finish_x: the finish line's x (m).
    fallen_height: torso z below which a crosser has fallen in (m).
    fall_penalty: paid once, when a crosser falls.
  Returns:
    fall: [n] `fall_penalty` for the crossers that fell at this step, else 0.
  """
  n = frames.shape[0]
  fall = np.zeros(n)
  for i in range(n):
    if not is_crosser[i]:
      continue
    if frames[i, 2] < fallen_height:
      if not fallen[i]:
        fall[i] = fall_penalty
      fallen[i] = True
    if frames[i, 0] > finish_x:
      crossed[i] = True
  return fall


class Measurement(NamedTuple):
  """What the ravine reads from one state (`measure`)."""

  nearest: np.ndarray
  """[2] world xy of the crosser the pushers serve."""
  bridge_error: float
  """|stone_y - nearest_y| (m)."""
  shaping: np.ndarray
  """[2, n] bridge (pushers; 0 for crossers) and destination (crossers; 0
  for pushers) terms."""
  offsets: np.ndarray
  """[n, 12] in each agent's heading frame: the stone; the near and far
  edges level with the agent, width, depth; the finish line level with the
  agent; the nearest crosser (m)."""


@numba.njit(cache=True)
def measure(frames, is_crosser, done, markers, use_markers, xpos, stone,
            near_edge_x, far_edge_x, finish_x, width, depth, bridge_scale,
            destination_scale):
  """What the ravine reads from one state, for all agents in one compiled
  call (see `transport.measure` for why).

  The crosser the pushers serve is the one nearest the ravine, |near_edge_x
  - x| smallest, among the `markers` ([m, 2] world xy, with `use_markers`:
  the pushers stage) or the crossers that are not `done` (fallen in or
  crossed: they count 1000 m further); ties keep the first.

  Args:
    frames: [n, >= 5] the agents' x, y, z, cos, sin (`AgentFrames.packed`).
    is_crosser, done: [n] bools.
    markers, use_markers: see above.
    xpos: [nbody, 3] MuJoCo's body positions; stone: the stone's body id.
    near_edge_x, far_edge_x, finish_x: the trench's edges and the finish
      line (m); width, depth: the trench's (m).
    bridge_scale, destination_scale: coefficients of 1 / (1 + d) for the
      pushers' bridge error and the crossers' distance to the finish line.
  Returns:
    A `Measurement`.
  """
  n = frames.shape[0]
  best, best_gap = -1, 0.0
  count = markers.shape[0] if use_markers else n
  for j in range(count):
    if use_markers:
      x, standing = markers[j, 0], True
    elif is_crosser[j]:
      x, standing = frames[j, 0], not done[j]
    else:
      continue
    gap = abs(near_edge_x - x) + (0.0 if standing else 1e3)
    if best < 0 or gap < best_gap:
      best, best_gap = j, gap
  if best < 0:
    raise ValueError("The ravine has no crosser for the pushers to serve.")
  nearest = np.empty(2)
  if use_markers:
    nearest[0], nearest[1] = markers[best, 0], markers[best, 1]
  else:
    nearest[0], nearest[1] = frames[best, 0], frames[best, 1]
  sx, sy = xpos[stone, 0], xpos[stone, 1]
  bridge_error = abs(sy - nearest[1])
  shaping = np.zeros((2, n))
  offsets = np.empty((n, 12))
  for i in range(n):
    x, y, cos, sin = frames[i, 0], frames[i, 1], frames[i, 3], frames[i, 4]
    if is_crosser[i]:
      shaping[1, i] = rewards.inverse_distance(destination_scale,
                                               abs(finish_x - x))
    else:
      shaping[0, i] = rewards.inverse_distance(bridge_scale, bridge_error)
    offsets[i, 0], offsets[i, 1] = kernels.to_heading(cos, sin, sx - x,
                                                      sy - y)
    offsets[i, 2], offsets[i, 3] = kernels.to_heading(cos, sin,
                                                      near_edge_x - x, 0.0)
    offsets[i, 4], offsets[i, 5] = kernels.to_heading(cos, sin,
                                                      far_edge_x - x, 0.0)
    offsets[i, 6], offsets[i, 7] = width, depth
    offsets[i, 8], offsets[i, 9] = kernels.to_heading(cos, sin, finish_x - x,
                                                      0.0)
    offsets[i, 10], offsets[i, 11] = kernels.to_heading(
        cos, sin, nearest[0] - x, nearest[1] - y)
  return Measurement(nearest, bridge_error, shaping, offsets)
