"""The compiled feature kernels against plain numpy on real physics states.

The kernels replaced numpy code with the same floating-point operations in
the same order, so the shipped controllers see the very same numbers: these
tests compare bit for bit (`assert_array_equal`), not within a tolerance.
"""

import mujoco
import numpy as np
import pytest

import coop_suite
from coop_suite import kernels
from coop_suite.entities import ant as ant_lib
from coop_suite.fast import raycast
from coop_suite.tasks import exteroception


def _states(task, n_agents, steps=30, **options):
  """An environment stepped with random actions, yielding at each step."""
  env = coop_suite.load(task, n_agents, seed=1, **options)
  env.reset()
  rng = np.random.RandomState(0)
  for _ in range(steps):
    env.step(rng.uniform(-1, 1, (env.n_agents, 8)))
    yield env


def _numpy_frames(env):
  ids = env.task._torso_ids  # pylint: disable=protected-access
  xmat = env.physics.data.xmat[ids]
  cos, sin = xmat[:, 0], xmat[:, 3]
  norm = np.hypot(cos, sin)
  norm[norm == 0] = 1.0
  return env.physics.data.xpos[ids], cos / norm, sin / norm


def _numpy_rotate(delta, cos, sin):
  return np.stack([cos * delta[..., 0] + sin * delta[..., 1],
                   cos * delta[..., 1] - sin * delta[..., 0]], -1)


def test_frames_and_proprioception_match_numpy():
  for env in _states("transport", 3):
    frames = env.task.frames(env.physics)
    position, cos, sin = _numpy_frames(env)
    np.testing.assert_array_equal(frames.position, position)
    np.testing.assert_array_equal(frames.cos, cos)
    np.testing.assert_array_equal(frames.sin, sin)

    walkers, data = env.task.walkers, env.physics.data
    # pylint: disable=protected-access
    xmat = np.stack([data.xmat[w._torso_id].reshape(3, 3) for w in walkers])
    free = np.stack([data.qvel[w._free_dof_adr:w._free_dof_adr + 6]
                     for w in walkers])
    expected = {
        "joints_pos": np.stack([data.qpos[w._joint_qpos_adr]
                                for w in walkers]),
        "joints_vel": np.stack([data.qvel[w._joint_dof_adr]
                                for w in walkers]),
        "torso_height": position[:, 2:3],
        "gravity": xmat[:, 2, :],
        "velocity": np.einsum("nji,nj->ni", xmat, free[:, :3]),
        "angular_velocity": free[:, 3:],
        "prev_action": np.stack([w.prev_action for w in walkers]),
    }
    got = env.task.features(env.physics, ("proprio",))
    assert set(ant_lib.PROPRIOCEPTION_KEYS) == set(expected)
    for name, value in expected.items():
      np.testing.assert_array_equal(got[f"proprio/{name}"], value, name)


@pytest.mark.parametrize("n,k,species", [
    (1, 1, None), (2, 1, None), (4, 1, None), (4, 2, None), (3, 3, None),
    (6, 4, None), (4, 1, [0, 0, 1, 1]), (5, 3, [1, 0, 1, 1, 0]),
    (3, 2, [0, 1, 2])])
def test_nearest_teammates_match_numpy(n, k, species):
  """Each agent's k nearest agents of its own species (one species where
  None), as numpy sorts them."""
  rng = np.random.RandomState(n * 10 + k)
  yaw = rng.uniform(-np.pi, np.pi, n)
  frames = exteroception.AgentFrames(rng.uniform(-5, 5, (n, 3)), np.cos(yaw),
                                   np.sin(yaw))
  offsets, mask = exteroception.nearest_teammates(frames, k, species)
  species = np.zeros(n) if species is None else np.asarray(species)
  xy = frames.position[:, :2]
  delta = xy[None] - xy[:, None]
  dist2 = np.einsum("ijk,ijk->ij", delta, delta)
  np.fill_diagonal(dist2, np.inf)
  dist2[species[:, None] != species[None]] = np.inf
  order = np.argsort(dist2, axis=1, kind="stable")
  for i in range(n):
    m = min(k, int(np.sum(species == species[i])) - 1)
    expected = np.zeros((k, 2))
    expected[:m] = _numpy_rotate(delta[i, order[i, :m]], frames.cos[i],
                                 frames.sin[i])
    np.testing.assert_array_equal(offsets[i], expected.reshape(-1))
    np.testing.assert_array_equal(mask[i], np.arange(k) < m)


@pytest.mark.parametrize("species", [[0, 0], [0.5, 0.5, 0, 1], ["a"] * 4])
def test_nearest_teammates_refuse_species_of_the_wrong_form(species):
  frames = exteroception.AgentFrames(np.zeros((4, 3)), np.ones(4),
                                   np.zeros(4))
  with pytest.raises(ValueError, match="species must be 4 integers"):
    exteroception.nearest_teammates(frames, 1, species)


@pytest.mark.parametrize("task,options", [
    ("ravine", {}), ("transport", {}), ("corridor", {}),
    ("ravine", {"stage": "crossers"})])
def test_heights_match_mujoco_multi_ray(task, options):
  """Bit-identical to one `mujoco.mj_multiRay` per agent over every geom of
  the model, on terrain with a trench and a stone (pushers stand inside the
  trench), a cylinder, walls."""
  sampler = exteroception.HeightSampler(3, 0.6)
  local_dirs, scale, origin_height, no_hit = sampler.ray_args
  saw_relief = False
  rng = np.random.RandomState(2)
  for env in _states(task, 4, steps=10, **options):
    # The agents, and more viewpoints on and around the task's objects.
    real = env.task.frames(env.physics)
    points = env.task.tracked_positions(env.physics)
    points = np.concatenate([real.position, points + rng.uniform(
        -0.8, 0.8, points.shape)])
    yaw = rng.uniform(-np.pi, np.pi, len(points))
    frames = exteroception.AgentFrames(points, np.cos(yaw), np.sin(yaw))
    got = sampler(env.physics, frames)
    for i in range(len(frames.cos)):
      c, s = frames.cos[i], frames.sin[i]
      lx, ly, lz = local_dirs.T
      dirs = np.stack([c * lx - s * ly, s * lx + c * ly, lz], -1)
      origin = np.array([*frames.position[i, :2], origin_height])
      dist = np.empty(len(local_dirs))
      mujoco.mj_multiRay(env.physics.model.ptr, env.physics.data.ptr, origin,
                         dirs.ravel(), sampler.geom_group, 1, -1,
                         np.zeros(len(dist), np.int32), dist, None, len(dist),
                         100.0)
      expected = np.where(dist >= 0, np.maximum(
          origin_height - dist / scale, no_hit), no_hit)
      np.testing.assert_array_equal(got[i], expected)
    saw_relief |= bool(np.any(np.abs(got) > 0.3))
  assert saw_relief, "no ray met a trench, prop or wall: test not exercised"


def test_heights_refuse_terrain_they_cannot_ray_cast():
  model = mujoco.MjModel.from_xml_string("""
      <mujoco><asset><hfield name="h" nrow="3" ncol="3" size="1 1 1 1"/>
      </asset><worldbody><geom name="hills" type="hfield" hfield="h"/>
      </worldbody></mujoco>""")
  sampler = exteroception.HeightSampler(3, 0.6)
  with pytest.raises(ValueError, match="hills.*HFIELD.*primitive"):
    raycast.terrain_geoms(model, sampler.geom_group)


def test_heading_offsets_match_numpy_and_check_shapes():
  rng = np.random.RandomState(3)
  yaw = rng.uniform(-np.pi, np.pi, 4)
  frames = exteroception.AgentFrames(rng.uniform(-5, 5, (4, 3)), np.cos(yaw),
                                   np.sin(yaw))
  origin, cos, sin = frames.position[:, :2], frames.cos, frames.sin
  point = rng.uniform(-5, 5, 2)
  per_agent = rng.uniform(-5, 5, (4, 2))
  several = rng.uniform(-5, 5, (4, 3, 2))
  np.testing.assert_array_equal(frames.to_heading_frame(point),
                                _numpy_rotate(point - origin, cos, sin))
  np.testing.assert_array_equal(frames.to_heading_frame(per_agent),
                                _numpy_rotate(per_agent - origin, cos, sin))
  np.testing.assert_array_equal(
      frames.to_heading_frame(several),
      _numpy_rotate(several - origin[:, None], cos[:, None], sin[:, None]))
  for bad in (np.zeros(3), np.zeros((3, 2)), np.zeros((5, 1, 2)),
              np.zeros((4, 2, 3)), np.zeros((1, 1, 1, 2))):
    with pytest.raises(ValueError, match="world points"):
      frames.to_heading_frame(bad)


def test_observations_are_not_overwritten_by_later_steps():
  """Kernels return new arrays: an observation kept from one step must not
  change when the environment steps on (replay buffers keep them)."""
  env = coop_suite.load("transport", 2, seed=0)
  env.reset()
  first = env.step(np.ones((2, 8))).observation
  kept = [{k: v.copy() for k, v in agent.items()} for agent in first]
  for _ in range(5):
    env.step(-np.ones((2, 8)))
  for agent, copy in zip(first, kept):
    for key, value in copy.items():
      np.testing.assert_array_equal(agent[key], value, key)


def test_clip_finite_and_add_rewards_match_numpy():
  rng = np.random.RandomState(4)
  low, high = -np.ones(8), np.linspace(0.5, 1.0, 8)
  values = rng.uniform(-2, 2, (5, 8))
  np.testing.assert_array_equal(kernels.clip_finite(values, low, high),
                                np.minimum(np.maximum(values, low), high))
  for bad in (np.nan, np.inf, -np.inf):
    broken = values.copy()
    broken[3, 2] = bad
    assert kernels.clip_finite(broken, low, high) is None

  terms = rng.uniform(-5, 5, (4, 3))
  sums, returns = rng.uniform(size=(4, 3)), rng.uniform(size=3)
  expected_sums, expected_returns = sums + terms, returns.copy()
  total = np.zeros(3)
  for term in terms:  # The order `CoopTask.get_reward` used to add them in.
    total += term
  expected_returns += total
  got = kernels.add_rewards(terms, sums, returns)
  np.testing.assert_array_equal(got, total.astype(np.float32))
  np.testing.assert_array_equal(sums, expected_sums)
  np.testing.assert_array_equal(returns, expected_returns)


def _offsets(frames, points):
  """[n, m, 2] heading-frame offsets to per-agent world points [n, m, 2]."""
  delta = points - frames.position[:, None, :2]
  return _numpy_rotate(delta, frames.cos[:, None], frames.sin[:, None])


def test_task_measure_kernels_match_numpy():
  """Each task's compiled `measure` against the numpy it replaced."""
  inverse = lambda scale, d: scale / (1.0 + d)  # pylint: disable=unnecessary-lambda-assignment
  for env in _states("transport", 3):
    task, physics = env.task, env.physics
    frames = task.frames(physics)
    cfg = task.config
    cylinder = physics.data.xpos[task.cylinder.body_id, :2]
    target = task.arena.target_position
    goals = np.stack([cylinder, target])
    distance, speed, shaping, offsets = task._measure(physics)  # pylint: disable=protected-access
    assert distance == np.sqrt(np.sum((cylinder - target)**2))
    velocity = physics.data.cvel[task.cylinder.body_id, 3:5]
    assert speed == np.sqrt(velocity[0]**2 + velocity[1]**2)
    to_goals = np.sqrt(np.sum((frames.position[:, None, :2] - goals)**2, -1))
    np.testing.assert_array_equal(shaping, np.stack([
        np.full(3, inverse(cfg.cylinder_target_scale, distance)),
        inverse(cfg.agent_cylinder_scale, to_goals[:, 0]),
        inverse(cfg.agent_target_scale, to_goals[:, 1])]))
    np.testing.assert_array_equal(offsets, _offsets(
        frames, np.broadcast_to(goals, (3, 2, 2))).reshape(3, 4))

  for env in _states("corridor", 3):
    task, physics = env.task, env.physics
    frames, arena = task.frames(physics), task.arena
    past, agent_target, offsets = task._measure(physics)  # pylint: disable=protected-access
    target = np.array([arena.finish_x, 0.0])
    np.testing.assert_array_equal(past, frames.position[:, 0] > arena.finish_x)
    np.testing.assert_array_equal(agent_target, inverse(
        task.config.agent_target_scale,
        np.sqrt(np.sum((frames.position[:, :2] - target)**2, -1))))
    points = np.broadcast_to(
        np.stack([arena.slit_entrance, arena.slit_exit, target]), (3, 3, 2))
    expected = _offsets(frames, points)
    np.testing.assert_array_equal(offsets[:, 0:4],
                                  expected[:, :2].reshape(3, 4))
    np.testing.assert_array_equal(offsets[:, 4], arena.slit_width)
    np.testing.assert_array_equal(offsets[:, 5:7], expected[:, 2])

  for stage in ("joint", "pushers"):
    for env in _states("ravine", 2, stage=stage):
      task, physics = env.task, env.physics
      frames, arena, cfg = task.frames(physics), task.arena, task.config
      nearest, error, shaping, offsets = task._measure(physics)  # pylint: disable=protected-access
      crosser = np.array([s == "crosser" for s in task.species])
      if stage == "pushers":
        candidates, standing = task._markers, np.ones(2, bool)  # pylint: disable=protected-access
      else:
        candidates = frames.position[crosser, :2]
        done = task._fallen | task._crossed  # pylint: disable=protected-access
        standing = ~done[crosser]
      gap = np.abs(arena.near_edge_x - candidates[:, 0]) + 1e3 * ~standing
      np.testing.assert_array_equal(nearest, candidates[np.argmin(gap)])
      stone = physics.data.xpos[task.stone.body_id, :2]
      assert error == abs(stone[1] - nearest[1])
      x = frames.position[:, 0]
      np.testing.assert_array_equal(shaping, np.stack([
          np.where(crosser, 0.0, inverse(cfg.bridge_scale, error)),
          np.where(crosser, inverse(cfg.destination_scale,
                                    np.abs(arena.finish_x - x)), 0.0)]))
      y = frames.position[:, 1]
      n = len(y)
      level = lambda edge: np.stack([np.full(n, edge), y], -1)  # pylint: disable=cell-var-from-loop,unnecessary-lambda-assignment
      points = np.stack([np.broadcast_to(stone, (n, 2)),
                         level(arena.near_edge_x), level(arena.far_edge_x),
                         level(arena.finish_x),
                         np.broadcast_to(nearest, (n, 2))], 1)
      expected = _offsets(frames, points)
      np.testing.assert_array_equal(offsets[:, 0:2], expected[:, 0])
      np.testing.assert_array_equal(offsets[:, 2:4], expected[:, 1])
      np.testing.assert_array_equal(offsets[:, 4:6], expected[:, 2])
      np.testing.assert_array_equal(offsets[:, 6:8],
                                    np.tile([arena.width, arena.depth],
                                            (n, 1)))
      np.testing.assert_array_equal(offsets[:, 8:10], expected[:, 3])
      np.testing.assert_array_equal(offsets[:, 10:12], expected[:, 4])
