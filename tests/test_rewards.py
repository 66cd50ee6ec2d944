"""Reward terms and success on hand-placed states, and episode boundaries."""

import numpy as np
import pytest

import coop_suite
from coop_suite.tasks import layouts
from coop_suite.tasks import locomotion
from coop_suite.tasks import rewards

ZERO = np.zeros((1, 8))


def _zeros(env):
  return np.zeros((env.n_agents, 8))


def test_reward_functions_by_hand():
  # 10 / (1 + 4) = 2.
  assert rewards.inverse_distance(10.0, 4.0) == pytest.approx(2.0)
  # |(3, 4)| = 5.
  assert rewards.planar_distance([3.0, 4.0], [0.0, 0.0]) == pytest.approx(5.0)
  # Command 0.5 m/s along x, moving 0.25 m/s along x: 5 * 0.125 / 0.25 = 2.5.
  assert rewards.velocity_tracking(5.0, [0.25, 0.0], [0.5, 0.0]) == (
      pytest.approx(2.5))
  # Exactly the commanded speed pays the full scale.
  assert rewards.velocity_tracking(5.0, [0.5, 0.0], [0.5, 0.0]) == (
      pytest.approx(5.0))
  # 1.5x too fast: r = 0.75 / 0.5 = 1.5, pays 5 * (2 - 1.5) = 2.5.
  assert rewards.velocity_tracking(5.0, [0.75, 0.0], [0.5, 0.0]) == (
      pytest.approx(2.5))
  # Zero command: standing still pays fully, 0.25 m/s pays half.
  assert rewards.velocity_tracking(5.0, [0.0, 0.0], [0.0, 0.0]) == 5.0
  assert rewards.velocity_tracking(5.0, [0.25, 0.0], [0.0, 0.0]) == (
      pytest.approx(2.5))


def _hold_steps(env):
  """Control steps the cylinder must rest in the zone to count."""
  return int(round(env.task.config.hold_time / env.control_timestep()))


@pytest.mark.parametrize("end_on_success", [False, True])
def test_transport_success_pays_everyone_once(end_on_success):
  env = coop_suite.load("transport", 3, seed=1, end_on_success=end_on_success)
  env.reset()
  task, physics = env.task, env.physics
  target = task.arena.target_position
  layouts.place_prop(task.cylinder, physics, [*target, task.cylinder.height / 2])
  # At rest inside the zone: a success only once held for `hold_time`.
  for _ in range(_hold_steps(env) - 1):
    timestep = env.step(_zeros(env))
    assert timestep.mid() and all(r < 50.0 for r in timestep.reward)
  assert env.episode_metrics()["success"] is False
  assert env.episode_metrics()["reached"] is True
  timestep = env.step(_zeros(env))
  # Success ends the episode only on request; by default the shaping terms
  # keep paying until the time limit (see TaskConfig.end_on_success).
  assert timestep.last() == end_on_success
  assert float(timestep.discount) == (0.0 if end_on_success else 1.0)
  cylinder = task.cylinder.position(physics)[:2]
  for i, reward in enumerate(timestep.reward):
    agent = task.walkers[i].torso_position(physics)[:2]
    expected = (10 / (1 + np.linalg.norm(cylinder - target))
                + 5 / (1 + np.linalg.norm(agent - cylinder))
                + 5 / (1 + np.linalg.norm(agent - target)) + 50)
    assert reward == pytest.approx(expected, rel=1e-5)
  metrics = env.episode_metrics()
  assert metrics["success"] is True
  assert metrics["reward/success"] == 50.0
  if not end_on_success:
    # The bonus is paid once; success stays counted when the cylinder leaves.
    layouts.place_prop(task.cylinder, physics,
                       [*(target + 3.0), task.cylinder.height / 2])
    timestep = env.step(_zeros(env))
    assert timestep.mid() and all(r < 50.0 for r in timestep.reward)
    assert env.episode_metrics()["success"] is True
    assert env.episode_metrics()["reward/success"] == 50.0


def test_transport_cylinder_sliding_through_the_zone_is_no_success():
  env = coop_suite.load("transport", 2, seed=1)
  env.reset()
  task, physics = env.task, env.physics
  target = task.arena.target_position
  layouts.place_prop(task.cylinder, physics, [*target, task.cylinder.height / 2])
  task.cylinder.set_velocity(physics, velocity=[3.0, 0.0, 0.0])
  for _ in range(3 * _hold_steps(env)):
    timestep = env.step(_zeros(env))
  assert timestep.mid()
  metrics = env.episode_metrics()
  assert metrics["reached"] is True and metrics["success"] is False
  assert metrics["cylinder_target_distance"] > task.config.target_radius


def test_transport_reports_where_the_episode_started():
  env = coop_suite.load("transport", 3, seed=4)
  for _ in range(2):  # Each episode its own start.
    env.reset()
    task, physics = env.task, env.physics
    torsos = np.array([w.torso_position(physics)[:2] for w in task.walkers])
    cylinder = task.cylinder.position(physics)[:2]
    target = task.arena.target_position
    env.step(_zeros(env))  # The figures stay those of the start.
    metrics = env.episode_metrics()
    np.testing.assert_allclose(
        metrics["start_agent_cylinder"],
        np.mean(np.linalg.norm(torsos - cylinder, axis=1)), atol=1e-6)
    np.testing.assert_allclose(metrics["start_cylinder_target"],
                               np.linalg.norm(target - cylinder), atol=1e-6)
    lo, hi = task.config.start_distance
    assert lo <= metrics["start_agent_cylinder"] <= hi * 1.5


def test_corridor_reports_where_the_episode_started():
  env = coop_suite.load("corridor", 3, seed=4)
  seen = []
  for _ in range(2):  # Each episode its own start.
    env.reset()
    task, physics = env.task, env.physics
    torsos = np.array([w.torso_position(physics)[:2] for w in task.walkers])
    facing = layouts.face(torsos, task.arena.slit_entrance)
    headings = np.array([w.heading(physics) for w in task.walkers])
    turns = np.angle(np.exp(1j * (headings - facing)))
    env.step(_zeros(env))  # The figure stays that of the start.
    error = env.episode_metrics()["start_heading_error"]
    np.testing.assert_allclose(error, np.mean(np.abs(turns)), atol=1e-6)
    assert 0.0 <= error <= 0.3
    seen.append(error)
  assert seen[0] != seen[1]


@pytest.mark.parametrize("stage", ["joint", "crossers", "pushers"])
def test_ravine_reports_where_the_episode_started(stage):
  env = coop_suite.load("ravine", 2, seed=4, stage=stage)
  seen = []
  for _ in range(2):
    env.reset()
    task, physics = env.task, env.physics
    stone_y = task.stone.position(physics)[1]
    # The crossers, or in the pushers stage the markers that stand in.
    if stage == "pushers":
      crossers = task._markers  # pylint: disable=protected-access
    else:
      crossers = np.array([w.torso_position(physics)[:2]
                           for w in task.walkers[:2]])
    env.step(_zeros(env))
    metrics = env.episode_metrics()
    np.testing.assert_allclose(metrics["start_stone_y"], stone_y, atol=1e-6)
    np.testing.assert_allclose(
        metrics["start_crossers_edge"],
        np.mean(task.arena.near_edge_x - crossers[:, 0]), atol=1e-6)
    seen.append(metrics["start_stone_y"])
  assert seen[0] != seen[1]


def test_transport_push_stage_drops_only_the_agent_target_term():
  """The push stage (the curriculum's first) is the same episode with the
  agent-target term at 0; every other term and figure is unchanged."""
  runs = {}
  for stage in ("joint", "push"):
    env = coop_suite.load("transport", 3, seed=2, stage=stage)
    env.reset()
    rewards_seen = [np.array(env.step(_zeros(env)).reward) for _ in range(5)]
    runs[stage] = env.episode_metrics(), np.array(rewards_seen)
  (joint, joint_rewards), (push, push_rewards) = runs["joint"], runs["push"]
  assert joint["reward/agent_target"] > 0 and push["reward/agent_target"] == 0
  for key in ("reward/cylinder_target", "reward/agent_cylinder",
              "cylinder_target_distance", "start_agent_cylinder"):
    assert push[key] == joint[key]
  np.testing.assert_allclose(
      push["return"], joint["return"] - joint["reward/agent_target"])
  assert np.all(push_rewards < joint_rewards)
  with pytest.raises(ValueError, match="push"):
    coop_suite.load("transport", 3, stage="pushers")


def test_transport_leaving_the_zone_restarts_the_hold():
  env = coop_suite.load("transport", 2, seed=1)
  env.reset()
  task, physics = env.task, env.physics
  target = task.arena.target_position

  def place(xy):
    layouts.place_prop(task.cylinder, physics, [*xy, task.cylinder.height / 2])

  place(target)
  for _ in range(_hold_steps(env) - 2):
    env.step(_zeros(env))
  place(target + 2.0)  # Out for one step...
  env.step(_zeros(env))
  place(target)  # ...and back: the hold starts again.
  for _ in range(_hold_steps(env) - 1):
    env.step(_zeros(env))
  assert env.episode_metrics()["success"] is False
  env.step(_zeros(env))
  assert env.episode_metrics()["success"] is True


@pytest.mark.parametrize("end_on_success", [False, True])
def test_corridor_crossing_pays_all_once_and_success_when_all_crossed(
    end_on_success):
  env = coop_suite.load("corridor", 2, seed=0, end_on_success=end_on_success)
  env.reset()
  task, physics = env.task, env.physics
  rng = np.random.RandomState(0)
  finish = task.arena.finish_x
  layouts.place(task.walkers[0], physics, [finish + 1.0, 0.0], 0.0, rng)
  first = env.step(_zeros(env))
  assert first.mid()
  assert all(r > 50.0 for r in first.reward)
  second = env.step(_zeros(env))
  assert all(r < 50.0 for r in second.reward)  # Paid once per crossing.
  assert env.episode_metrics()["crossed"] == 1
  layouts.place(task.walkers[1], physics, [finish + 1.0, 3.0], 0.0, rng)
  last = env.step(_zeros(env))
  assert last.last() == end_on_success
  assert float(last.discount) == (0.0 if end_on_success else 1.0)
  assert all(r > 50.0 for r in last.reward)
  assert env.episode_metrics()["success"] is True


def _first_crosser_over_the_line(**options):
  """A 2-crosser ravine whose first crosser is placed past the finish line
  and stepped once: (env, timestep, rng)."""
  env = coop_suite.load("ravine", 2, seed=0, **options)
  env.reset()
  rng = np.random.RandomState(0)
  layouts.place(env.task.walkers[0], env.physics,
                [env.task.arena.finish_x + 0.5, 0.0], 0.0, rng)
  return env, env.step(_zeros(env)), rng


def test_ravine_joint_success_when_one_crosses_with_any_pays_pushers_once():
  env, timestep, rng = _first_crosser_over_the_line(success="any")
  task, physics = env.task, env.physics
  assert timestep.mid() and float(timestep.discount) == 1.0
  assert len(timestep.reward) == 4
  assert all(r >= 50.0 for r in timestep.reward)
  # Back before the line: no second bonus, and the success still counts.
  layouts.place(task.walkers[0], physics, [task.arena.finish_x - 1.0, 0.0],
                0.0, rng)
  timestep = env.step(_zeros(env))
  assert all(r < 50.0 for r in timestep.reward)
  assert env.episode_metrics()["success"] is True


def test_ravine_joint_success_needs_every_crosser_by_default():
  env, timestep, rng = _first_crosser_over_the_line()
  task, physics = env.task, env.physics
  assert all(r < 50.0 for r in timestep.reward)
  metrics = env.episode_metrics()
  assert metrics["success"] is False and metrics["crossed"] == 1
  # The first crosser walks back: its crossing still counts. The second
  # crosses: success, paid once to all four agents.
  layouts.place(task.walkers[0], physics, [task.arena.finish_x - 1.0, 0.0],
                0.0, rng)
  layouts.place(task.walkers[1], physics, [task.arena.finish_x + 0.5, 2.0],
                0.0, rng)
  timestep = env.step(_zeros(env))
  assert timestep.mid() and all(r >= 50.0 for r in timestep.reward)
  assert env.episode_metrics()["success"] is True
  timestep = env.step(_zeros(env))
  assert all(r < 50.0 for r in timestep.reward)


def _first_crosser_into_the_trench(env):
  """Resets `env` (a ravine), drops its first crosser into the trench 4 m
  from the stone, steps once and returns the timestep."""
  env.reset()
  task, physics = env.task, env.physics
  stone_y = task.stone.position(physics)[1]
  y = stone_y + 4.0 if stone_y < 0 else stone_y - 4.0
  layouts.place(task.walkers[0], physics, [task.arena.ravine_x, y], 0.0,
                np.random.RandomState(0), ground_z=-task.arena.depth)
  return env.step(_zeros(env))


def test_ravine_all_rule_fails_when_one_crosser_falls():
  for rule, ends in (("all", True), ("any", False)):
    env = coop_suite.load("ravine", 2, seed=0, success=rule)
    timestep = _first_crosser_into_the_trench(env)
    assert timestep.last() is ends, rule
    assert env.episode_metrics()["failure"] is ends, rule


def test_ravine_crossers_stage_a_fallen_crosser_is_out_and_the_other_goes_on():
  env = coop_suite.load("ravine", 2, stage="crossers", seed=0)
  timestep = _first_crosser_into_the_trench(env)
  assert not timestep.last()
  assert env.episode_metrics()["failure"] is False
  assert timestep.reward[0] < -15.0  # The fall, once (-20 + 1.25).
  timestep = env.step(_zeros(env))
  # Out: nothing more, not even the destination term from the trench,
  # which pays more than standing where the other crosser stands.
  assert timestep.reward[0] == 0.0
  assert timestep.reward[1] > 0.5
  task, physics = env.task, env.physics
  stone_y = task.stone.position(physics)[1]
  y = stone_y + 4.0 if stone_y < 0 else stone_y - 4.0
  y += 2.0 if stone_y < 0 else -2.0  # Clear of the first, away from the stone.
  layouts.place(task.walkers[1], physics, [task.arena.ravine_x, y],
                0.0, np.random.RandomState(0), ground_z=-task.arena.depth)
  timestep = env.step(_zeros(env))
  assert timestep.last() and float(timestep.discount) == 0.0
  assert env.episode_metrics()["failure"] is True


def test_ravine_refuses_unknown_success_rule():
  with pytest.raises(ValueError, match="all.*any"):
    coop_suite.load("ravine", 2, success="most")


def test_ravine_fall_penalty_once_and_failure_when_all_fell():
  env = coop_suite.load("ravine", 1, stage="crossers", seed=0)
  timestep = _first_crosser_into_the_trench(env)
  assert timestep.last() and float(timestep.discount) == 0.0
  assert env.episode_metrics()["reward/fall"] == -20.0
  assert env.episode_metrics()["failure"] is True


def test_ravine_pushers_are_paid_for_bridging_the_nearest_crosser():
  env = coop_suite.load("ravine", 3, stage="pushers", seed=0)
  env.reset()
  task, physics = env.task, env.physics
  markers = task._markers  # pylint: disable=protected-access
  nearest = markers[np.argmin(np.abs(task.arena.near_edge_x - markers[:, 0]))]
  timestep = env.step(_zeros(env))
  error = abs(task.stone.position(physics)[1] - nearest[1])
  for reward in timestep.reward:
    assert reward == pytest.approx(5 / (1 + error), rel=1e-5)


def test_walk_to_target_draws_a_new_target_when_reached():
  env = coop_suite.load("walk_to_target", seed=0)
  timestep = env.reset()
  offset = timestep.observation[0]["command/target"]
  assert 2.0 <= np.linalg.norm(offset) <= 6.0
  task, physics = env.task, env.physics
  old = task.arena.target_position.copy()
  layouts.place(task.walker, physics, old, 0.0, np.random.RandomState(0))
  timestep = env.step(ZERO)
  assert env.episode_metrics()["targets_reached"] == 1
  assert not np.allclose(task.arena.target_position, old)
  assert timestep.mid()


def test_walk_to_target_fall_ends_with_zero_discount():
  env = coop_suite.load("walk_to_target", seed=0)
  env.reset()
  walker = env.task.walker
  walker.set_pose(env.physics, position=[0, 0, 0.3],
                  quaternion=[0.0, 1.0, 0.0, 0.0])  # Upside down.
  timestep = env.step(ZERO)
  assert timestep.last() and float(timestep.discount) == 0.0
  assert env.episode_metrics()["failure"] is True


def test_walk_velocity_reward_terms():
  env = coop_suite.load("walk_velocity", seed=3)
  env.reset()
  env.task.set_command(env.physics, [0.5, 0.0])
  timestep = env.step(ZERO)
  velocity = env.task.walker.world_velocity(env.physics)[:2]
  expected_velocity = rewards.velocity_tracking(5.0, velocity, [0.5, 0.0])
  metrics = env.episode_metrics()
  assert metrics["reward/velocity"] == pytest.approx(expected_velocity)
  assert metrics["reward/alive"] == 0.5
  assert metrics["reward/action_cost"] == 0.0
  assert timestep.reward[0] == pytest.approx(
      sum(metrics[k] for k in metrics if k.startswith("reward/")), rel=1e-5)


def test_locomotion_terms_match_each_ants_own_accessors():
  """The vectorised terms (read from the shared proprioception) agree with
  each Ant's own accessors, on states where joints reach their limits."""
  env = coop_suite.load("transport", 3, seed=0)
  env.reset()
  rng = np.random.RandomState(0)
  config = locomotion.LocomotionConfig()
  limits_seen = 0
  for _ in range(40):
    actions = rng.choice([-1.0, 1.0], (3, 8))
    env.step(actions)
    terms = rewards.locomotion_terms(
        env.task.features(env.physics, ("proprio",)), actions,
        env.task.joint_ranges, config)
    for i, walker in enumerate(env.task.walkers):
      upright = walker.upright(env.physics)
      at_limit = walker.joints_at_limit(env.physics)
      limits_seen += at_limit
      energy = np.sum(np.abs(actions[i] * 0.2
                             * walker.joint_velocities(env.physics)))
      assert terms["up"][i] == (0.1 if upright > 0.93 else 0.0)
      assert terms["joint_limit_cost"][i] == -0.1 * at_limit
      assert terms["energy_cost"][i] == pytest.approx(-0.05 * energy)
      assert terms["action_cost"][i] == pytest.approx(-0.005 * 8)
      assert terms["alive"][i] == 0.5
  assert limits_seen > 0, "no joint reached its limit: test not exercised"


def _numpy_locomotion_terms(proprio, actions, joint_ranges, config):
  """The terms as numpy writes them: the compiled kernel's reference."""
  actions = np.asarray(actions, dtype=np.float64)
  upright = proprio["proprio/gravity"][:, 2]
  low, high = joint_ranges[..., 0], joint_ranges[..., 1]
  centre, half = (high + low) / 2, (high - low) / 2
  at_limit = np.sum(np.abs(proprio["proprio/joints_pos"] - centre)
                    > 0.99 * half, axis=-1)
  return {
      "alive": np.full(len(actions), config.alive_bonus),
      "up": np.where(upright > 0.93, config.up_bonus, 0.0),
      "action_cost": -config.action_cost * np.sum(actions**2, axis=-1),
      "energy_cost": -config.energy_cost * np.sum(np.abs(
          actions * 0.2 * proprio["proprio/joints_vel"]), axis=-1),
      "joint_limit_cost": -config.joint_limit_cost * at_limit,
  }


def test_compiled_locomotion_terms_are_numpys_bit_for_bit():
  config = locomotion.LocomotionConfig()
  rng = np.random.default_rng(0)
  env = coop_suite.load("transport", 3, seed=0)
  env.reset()
  states = []
  for _ in range(30):  # Real states, joints at their limits included.
    actions = rng.choice([-1.0, 0.3, 1.0], (3, 8))
    env.step(actions)
    states.append((env.task.features(env.physics, ("proprio",)), actions,
                   env.task.joint_ranges))
  for n in (1, 2, 5):  # And wide random ones, 1 to 5 agents.
    ranges = np.sort(rng.uniform(-1.5, 1.5, (n, 8, 2)), axis=-1)
    states.append(({"proprio/gravity": rng.uniform(-1, 1, (n, 3)),
                    "proprio/joints_pos": rng.uniform(-1.6, 1.6, (n, 8)),
                    "proprio/joints_vel": rng.standard_normal((n, 8))
                                          * np.exp(rng.uniform(-5, 5, (n, 8)))},
                   rng.uniform(-1, 1, (n, 8)), ranges))
  for proprio, actions, ranges in states:
    ours = rewards.locomotion_terms(proprio, actions, ranges, config)
    theirs = _numpy_locomotion_terms(proprio, actions, ranges, config)
    assert list(ours) == list(rewards.LOCOMOTION_TERMS) == list(theirs)
    for name in ours:
      np.testing.assert_array_equal(ours[name], theirs[name], err_msg=name)


def test_flat_rewards_add_the_terms_in_order_to_the_tasks():
  """'flat' (`FlatEnv`): each agent's reward is float32(the task's reward +
  the terms summed in order), its sums the terms' over the episode."""
  from runners import envs  # pylint: disable=g-import-not-at-top
  config = locomotion.LocomotionConfig()
  flat = envs.FlatEnv(coop_suite.load("corridor", 3, seed=4))
  bare = coop_suite.load("corridor", 3, seed=4)
  flat.reset()
  bare.reset()
  rng = np.random.default_rng(1)
  sums = {}
  for _ in range(12):
    actions = rng.uniform(-1.3, 1.3, (3, 8))  # Clipped to [-1, 1].
    ours, theirs = flat.step(actions), bare.step(actions)
    terms = _numpy_locomotion_terms(
        bare.task.features(bare.physics, ("proprio",)),
        np.clip(actions, -1, 1), bare.task.joint_ranges, config)
    total = np.zeros(3)
    for name, value in terms.items():
      total += value
      sums[name] = sums.get(name, 0.0) + value
    assert ours.reward == [np.float32(r + t)
                           for r, t in zip(theirs.reward, total)]
  metrics, task_metrics = flat.episode_metrics(), bare.episode_metrics()
  assert metrics["return"] == pytest.approx(
      task_metrics["return"] + sum(np.mean(v) for v in sums.values()))
  for name, value in sums.items():
    assert metrics[f"reward/{name}"] == float(np.mean(value))


def test_walk_velocity_tracking_figures_cover_only_the_steps_they_apply_to():
  env = coop_suite.load("walk_velocity", seed=3)
  env.reset()
  env.task.set_command(env.physics, [0.5, 0.0])
  env.step(ZERO)
  moving = env.episode_metrics()
  assert "mean_speed_still" not in moving  # No zero command yet.
  assert -1.0 <= moving["velocity_cosine"] <= 1.0
  assert moving["speed_error"] >= 0.0
  env.task.set_command(env.physics, [0.0, 0.0])
  env.step(ZERO)
  both = env.episode_metrics()
  speed = np.linalg.norm(env.task.walker.world_velocity(env.physics)[:2])
  assert both["mean_speed_still"] == pytest.approx(speed)
  assert both["velocity_cosine"] == moving["velocity_cosine"]


@pytest.mark.parametrize("time_limit,steps", [(0.5, 10), (10.0, 200)])
def test_time_limit_is_a_truncation(time_limit, steps):
  env = coop_suite.load("walk_velocity", seed=0, time_limit=time_limit)
  timestep = env.reset()
  count = 0
  while not timestep.last():
    timestep = env.step(ZERO)
    count += 1
  assert count == steps
  assert float(timestep.discount) == 1.0
  assert coop_suite.is_truncation(timestep)


def test_each_agent_shares_one_read_only_zero():
  # Bonus terms are zero on most steps: one shared array, which no caller
  # can change by accident; other values are new arrays.
  task = coop_suite.load("transport", 3, seed=0).task
  zero = task.each_agent(0.0)
  assert zero is task.each_agent(0) and not zero.flags.writeable
  np.testing.assert_array_equal(zero, np.zeros(3))
  bonus = task.each_agent(50)
  assert bonus.flags.writeable and bonus is not task.each_agent(50)
  np.testing.assert_array_equal(bonus, np.full(3, 50.0))
