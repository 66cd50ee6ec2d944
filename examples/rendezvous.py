"""A new task in one module: Ants meet in a zone (docs/extending.md).

The worked example of docs/extending.md: `n` Ants start on a ring around
a target zone and succeed when all of them stand inside it at once. It
uses only `CoopTask`'s hooks, written in numpy (the suite's own tasks put
the same hooks' arithmetic in one compiled `measure` kernel for speed; that
is an optimisation, not a requirement). Register it, then load it like the
shipped tasks (from the repository's root, where `examples` imports):

    import coop_suite
    from examples import rendezvous
    rendezvous.register()
    env = coop_suite.load("rendezvous", 3, seed=0)

`tests/test_extending.py` checks that it loads, steps on both of the
suite's step paths with the same numbers, succeeds exactly when every Ant
is in the zone, and trains in this process (`learner_loop.train` with
`actors=0`).
"""

import dataclasses

import numpy as np

from coop_suite import arenas
from coop_suite import tasks
from coop_suite.tasks import base
from coop_suite.tasks import layouts
from coop_suite.tasks import rewards


@dataclasses.dataclass(frozen=True)
class RendezvousConfig(base.TaskConfig):
  """Every field becomes a `coop_suite.load` option and is range-checked by
  `TaskConfig` from its name (`*_radius` > 0, `*_distance` >= 0...)."""

  time_limit: float = 20.0
  zone_radius: float = 1.5
  """The zone (m): success when every torso is within it at once."""
  start_distance: float = 4.0
  """The ring's radius around the zone (m)."""
  agent_target_scale: float = 5.0
  """The shaping term `agent_target_scale / (1 + d(agent, zone centre))`,
  paid every step."""
  success_bonus: float = 100.0
  """Paid to every agent on the step the team succeeds."""


class Rendezvous(base.CoopTask):
  """All Ants in the zone at the same time."""

  MIN_AGENTS, MAX_AGENTS = 1, 8
  EXTERO_FEATURES = ("zone", "inside")
  """`extero/zone` (the zone's centre in the agent's heading frame, m) and
  `extero/inside` (1 if this agent is in the zone), beside the shared
  exteroception every task has (teammates, heights)."""

  def __init__(self, n_agents, config=RendezvousConfig()):
    arena = arenas.Floor(size=(15.0, 15.0), target_radius=config.zone_radius,
                         physics_timestep=config.physics_timestep)
    super().__init__(arena, ["ant"] * n_agents, config)

  def _distances(self, physics):
    """[n] each torso's planar distance to the zone's centre (m), computed
    once per physics state however many hooks ask."""
    return self.per_state("distances", lambda: rewards.planar_distance(
        self.frames(physics).position[:, :2], self._arena.target_position))

  def _inside(self, physics):
    """[n] whether each torso is within the zone."""
    return self._distances(physics) <= self._config.zone_radius

  def _exteroception(self, physics, frames):
    zone = np.tile(self._arena.target_position, (self.n_agents, 1))
    return {"zone": frames.to_heading_frame(zone),
            "inside": self._inside(physics)[:, None].astype(np.float64)}

  def _initialize_layout(self, physics, random_state):
    self._arena.set_target(physics, [0.0, 0.0])
    starts = layouts.ring(self.n_agents, [0.0, 0.0],
                          self._config.start_distance, random_state)
    yaws = random_state.uniform(-np.pi, np.pi, self.n_agents)
    for walker, xy, yaw in zip(self._walkers, starts, yaws):
      layouts.place(walker, physics, xy, yaw, random_state)

  def _update_status(self, physics):
    self._success = bool(np.all(self._inside(physics)))

  def _reward_terms(self, physics):
    cfg = self._config
    return {
        "agent_target": rewards.inverse_distance(
            cfg.agent_target_scale, self._distances(physics)),
        "success": self.each_agent(
            cfg.success_bonus if self._success_event else 0.0),
    }

  def _progress(self, physics):
    return {"inside": int(np.sum(self._inside(physics)))}

  def _task_state(self, physics):
    return np.asarray(self._arena.target_position, np.float64)


def register(name="rendezvous", default_agents=3):
  """Adds the task to `coop_suite.tasks.TASKS` in this process.

  Only code in this process sees it (e.g. `runners.learner_loop.train` or
  `runners.train.main([...])` with `actors=0`, after this call). The
  `coop-train` command, and Ray's actor processes, import `coop_suite`
  afresh: for them the entry goes in `coop_suite/tasks/__init__.py`
  (docs/extending.md).
  """
  tasks.TASKS[name] = (Rendezvous, RendezvousConfig, default_agents)
