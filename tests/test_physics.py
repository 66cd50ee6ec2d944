"""Physics sanity: pushes move the cylinder, walls block, the stone bridges.

`conftest.drive` stands in for a walking controller: it pushes each torso
with at most ~120 N, about what an Ant's legs can produce.
"""

import numpy as np

import coop_suite
from coop_suite.tasks import layouts
from tests.conftest import drive


def _place_row(env, xs, ys, yaw=0.0):
  rng = np.random.RandomState(0)
  for walker, x, y in zip(env.task.walkers, xs, ys):
    layouts.place(walker, env.physics, [x, y], yaw, rng)
  env.physics.forward()


def test_pushing_together_moves_the_cylinder_and_one_ant_barely():
  moved = {}
  for n in (1, 3):
    env = coop_suite.load("transport", n, seed=0, time_limit=60)
    env.reset()
    ys = np.linspace(-0.5, 0.5, n) if n > 1 else [0.0]
    _place_row(env, [-1.7] * n, ys)
    cylinder = env.task.cylinder
    layouts.place_prop(cylinder, env.physics, [0.0, 0.0, cylinder.height / 2])
    start = cylinder.position(env.physics).copy()
    drive(env, range(n), [0.6, 0.0], seconds=5.0)
    moved[n] = cylinder.position(env.physics)[0] - start[0]
    upright = env.physics.data.xmat[cylinder._body_id][8]  # pylint: disable=protected-access
    assert upright > 0.99  # Slides, does not tip.
  assert moved[3] > 0.25
  assert moved[1] < 0.5 * moved[3]


def test_slit_passes_one_ant_and_blocks_two_abreast():
  env = coop_suite.load("corridor", 2, seed=0, time_limit=60)
  env.reset()
  arena = env.task.arena
  start_x = arena.wall_x - 2.5
  _place_row(env, [start_x, start_x], [0.0, 8.0])  # Second one far away.
  drive(env, [0], [0.8, 0.0], seconds=8.0)
  assert env.task.walkers[0].torso_position(env.physics)[0] > (
      arena.wall_x + arena.wall_thickness / 2)

  env.reset()
  _place_row(env, [start_x, start_x], [0.75, -0.75])
  drive(env, [0, 1], [0.8, 0.0], seconds=8.0)
  xs = [w.torso_position(env.physics)[0] for w in env.task.walkers]
  assert max(xs) < arena.wall_x + arena.wall_thickness / 2


def test_crosser_walks_over_the_stone_and_falls_where_it_is_not():
  env = coop_suite.load("ravine", 1, stage="crossers", seed=0, time_limit=60)
  arena = env.task.arena
  stone = env.task.stone
  walker = env.task.walkers[0]
  for stone_y, should_cross in ((0.0, True), (5.0, False)):
    env.reset()
    layouts.place_prop(stone, env.physics,
                       [arena.ravine_x, stone_y, -arena.depth / 2])
    _place_row(env, [arena.near_edge_x - 1.5], [0.0])
    drive(env, [0], [0.8, 0.0], seconds=12.0)
    metrics = env.episode_metrics()
    if should_cross:
      assert metrics["success"], metrics
      assert walker.torso_position(env.physics)[2] > 0.2  # On the plane.
    else:
      assert metrics["fallen"] == 1 and not metrics["success"], metrics
      assert walker.torso_position(env.physics)[2] < 0.0  # In the trench.


def test_pushers_cannot_climb_out_of_the_trench():
  env = coop_suite.load("ravine", 1, stage="pushers", n_pushers=1, seed=0,
                        time_limit=60)
  env.reset()
  arena = env.task.arena
  walker = env.task.walkers[0]
  stone_y = env.task.stone.position(env.physics)[1]
  y = -4.0 if stone_y > 0 else 4.0
  layouts.place(walker, env.physics, [arena.ravine_x, y], 0.0,
                np.random.RandomState(0), ground_z=-arena.depth)
  drive(env, [0], [0.8, 0.0], seconds=6.0)
  position = walker.torso_position(env.physics)
  assert position[2] < 0.0
  assert abs(position[0] - arena.ravine_x) < arena.width / 2
