"""Ravine bridging: pushers move a stone so that crossers can walk over it.

Two species. Crossers start on the near plane; pushers start inside the
trench on either side of the stone. Success when a crosser passes the finish
line. The paper trains this in stages (its appendix "Training pipeline of
Ravine Bridging"), selected with `stage`:

* 'pushers': only the pushers act. The crossers are replaced by `n_agents`
  markers at random places along the near edge; pushers are paid
  5 / (1 + |stone_y - y of the crosser nearest the ravine|).
* 'crossers': only the crossers act, the stone lies at a random place;
  crossers are paid 5 / (1 + |finish_x - x|) and -20 once if they fall in.
* 'joint': everybody acts; both shaping terms stay on and the first crossing
  pays +50 to all agents (and ends the episode with `end_on_success`).
"""

import dataclasses

import numpy as np

from coop_suite import arenas
from coop_suite.entities import Stone
from coop_suite.tasks import base
from coop_suite.tasks import layouts
from coop_suite.tasks import rewards

STAGES = ("joint", "pushers", "crossers")
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
  """Joint stage: paid to all agents when a crosser passes the line."""
  width: float = 2.0
  """Trench width (m)."""
  depth: float = 1.0
  """Trench depth (m), also the stone's height."""
  length: float = 16.0
  """Trench length (m)."""
  stone_length: float = 1.6
  """Stone extent along the trench (m)."""
  stone_mass: float = 12.0
  """Stone mass (kg)."""
  start_gap: float = 2.0
  """Distance from the crossers' start line to the near edge (m)."""
  bridge_tolerance: float = 0.3
  """Pushers stage: the stone is "in place" within this |dy| (m)."""


class Ravine(base.CoopTask):
  """Bridge the ravine with the stone and cross it."""

  MIN_AGENTS, MAX_AGENTS = 1, 8
  TASK_OPTIONS = ("stage", "n_pushers")
  EXTERO_FEATURES = ("stone", "ravine", "finish", "nearest_crosser")

  def __init__(self, n_agents, config=RavineConfig(), stage="joint",
               n_pushers=2):
    if stage not in STAGES:
      raise ValueError(f"Unknown stage {stage!r}; choose one of {STAGES}.")
    if (isinstance(n_pushers, bool) or not isinstance(n_pushers, int)
        or not 1 <= n_pushers <= 4):
      raise ValueError(f"n_pushers must be an integer in [1, 4], got "
                       f"{n_pushers!r}.")
    self.stage = stage
    arena = arenas.RavineArena(width=config.width, depth=config.depth,
                               length=config.length,
                               physics_timestep=config.physics_timestep)
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
    self._markers = np.zeros((n_agents, 2))

  # --- Geometry ----------------------------------------------------------------

  def _crosser_positions(self, physics):
    """World xy [m, 2] of the crossers the pushers serve (real or markers)."""
    if self.stage == "pushers":
      return self._markers
    return physics.data.xpos[self._torso_ids[self._is_crosser], :2]

  def _nearest_crosser(self, physics):
    """World xy of the crosser nearest the ravine that has not fallen in."""
    def compute():
      xy = self._crosser_positions(physics)
      if self.stage == "pushers":
        standing = np.ones(len(xy), dtype=bool)
      else:
        standing = ~self._fallen[self._is_crosser]
      # Fallen crossers no longer need a bridge: push them out of the race.
      gap = np.abs(self._arena.near_edge_x - xy[:, 0]) + 1e3 * ~standing
      return xy[int(np.argmin(gap))]
    return self.per_state("nearest_crosser", physics, compute)

  # --- Hooks -------------------------------------------------------------------

  def _exteroception(self, physics, frames):
    arena = self._arena
    n = self.n_agents
    y = frames.position[:, 1]
    ravine = np.empty((n, 6))
    ravine[:, 0:2] = frames.to_heading_frame(
        np.stack([np.full(n, arena.near_edge_x), y], -1))
    ravine[:, 2:4] = frames.to_heading_frame(
        np.stack([np.full(n, arena.far_edge_x), y], -1))
    ravine[:, 4] = arena.width
    ravine[:, 5] = arena.depth
    return {
        "stone": frames.to_heading_frame(self.stone.position(physics)[:2]),
        "ravine": ravine,
        "finish": frames.to_heading_frame(
            np.stack([np.full(n, arena.finish_x), y], -1)),
        "nearest_crosser": frames.to_heading_frame(
            self._nearest_crosser(physics)),
    }

  def _initialize_layout(self, physics, random_state):
    cfg = self._config
    arena = self._arena
    self._fallen = np.zeros(self.n_agents, dtype=bool)
    self._new_falls = np.zeros(self.n_agents, dtype=bool)
    half = cfg.length / 2 - cfg.stone_length / 2 - 2.0
    stone_y = random_state.uniform(-half, half)
    layouts.place_prop(self.stone, physics,
                       [arena.ravine_x, stone_y, -cfg.depth / 2])
    line_half = max(0.0, cfg.length / 2 - 2.0
                    - (self._n_markers - 1) * layouts.ANT_SPACING / 2)
    crossers = layouts.line(self._n_markers,
                            arena.near_edge_x - cfg.start_gap,
                            random_state.uniform(-line_half, line_half))
    crossers[:, 0] -= random_state.uniform(0, 1.0, self._n_markers)
    self._markers = crossers
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

  def _update_status(self, physics):
    position = physics.data.xpos[self._torso_ids]
    # A crosser has fallen once its torso is below the plane's surface.
    newly = self._is_crosser & (position[:, 2] < _FALLEN_HEIGHT)
    self._new_falls = newly & ~self._fallen
    self._fallen |= newly
    crossed = self._is_crosser & (position[:, 0] > self._arena.finish_x)
    if self.stage == "pushers":
      self._success = False  # Judged at the end; see `_progress`.
    else:
      self._success = bool(np.any(crossed))
      self._failure = bool(np.all(self._fallen[self._is_crosser]))

  def _bridge_error(self, physics):
    return abs(self.stone.position(physics)[1]
               - self._nearest_crosser(physics)[1])

  def _reward_terms(self, physics):
    cfg = self._config
    n = self.n_agents
    pusher = ~self._is_crosser
    terms = {}
    if self.stage in ("pushers", "joint"):
      terms["bridge"] = np.where(pusher, rewards.inverse_distance(
          cfg.bridge_scale, self._bridge_error(physics)), 0.0)
    if self.stage in ("crossers", "joint"):
      x = physics.data.xpos[self._torso_ids, 0]
      terms["destination"] = np.where(self._is_crosser, rewards.inverse_distance(
          cfg.destination_scale, np.abs(self._arena.finish_x - x)), 0.0)
      terms["fall"] = np.where(self._new_falls, cfg.fall_penalty, 0.0)
    if self.stage == "joint":
      terms["success"] = np.full(
          n, cfg.success_bonus if self._success_event else 0.0)
    return terms

  def _progress(self, physics):
    bridge_error = self._bridge_error(physics)
    out = {"bridge_error": float(bridge_error),
           "stone_in_place": bool(bridge_error < self._config.bridge_tolerance),
           "fallen": int(np.sum(self._fallen))}
    if self.stage == "pushers":
      out["success"] = out["stone_in_place"]
    return out

  def _task_state(self, physics):
    return np.concatenate([self.stone.position(physics)[:2],
                           self._nearest_crosser(physics)])

  def tracked_positions(self, physics):
    return np.vstack([super().tracked_positions(physics),
                      self.stone.position(physics)])
