"""The environment contract of DESIGN.md section 2, for every task."""

import dm_env
import numpy as np
import pytest

import coop_suite

CASES = [("transport", 1), ("transport", 4), ("transport", 7),
         ("corridor", 1), ("corridor", 5), ("ravine", 1), ("ravine", 3),
         ("walk_to_target", 1), ("walk_velocity", 1)]


def _species_count(env):
  return len(env.task.species)


@pytest.mark.parametrize("task,n_agents", CASES)
def test_specs_match_observations(task, n_agents):
  env = coop_suite.load(task, n_agents, seed=0)
  n = _species_count(env)
  action_specs = env.action_spec()
  assert isinstance(action_specs, list) and len(action_specs) == n
  for spec in action_specs:
    assert spec.shape == (8,)
    np.testing.assert_array_equal(spec.minimum, -1.0)
    np.testing.assert_array_equal(spec.maximum, 1.0)
  obs_specs = env.observation_spec()
  assert isinstance(obs_specs, list) and len(obs_specs) == n
  assert len(env.reward_spec()) == n

  timestep = env.reset()
  assert timestep.step_type == dm_env.StepType.FIRST
  for _ in range(3):
    timestep = env.step(np.random.uniform(-1, 1, (n, 8)))
  assert len(timestep.observation) == n
  for spec, observation in zip(obs_specs, timestep.observation):
    assert set(spec) == set(observation)
    for key, value in observation.items():
      assert key.split("/")[0] in ("proprio", "extero", "command"), key
      spec[key].validate(value)
  assert len(timestep.reward) == n
  for reward, spec in zip(timestep.reward, env.reward_spec()):
    assert np.shape(reward) == ()
    assert np.asarray(reward).dtype == spec.dtype
    assert np.isfinite(reward)
  env.discount_spec().validate(np.asarray(timestep.discount, np.float32))


@pytest.mark.parametrize("task", ["transport", "corridor", "ravine"])
def test_exteroception_size_does_not_depend_on_population(task):
  sizes = []
  for n_agents in (1, 2, 5):
    env = coop_suite.load(task, n_agents, seed=0)
    spec = env.observation_spec()[0]
    sizes.append({k: v.shape for k, v in spec.items()})
  assert sizes[0] == sizes[1] == sizes[2]


def test_observation_groups():
  """Locomotion tasks expose commands; cooperative ones exteroception."""
  walk = coop_suite.load("walk_to_target").observation_spec()[0]
  assert "command/target" in walk
  assert not any(k.startswith("extero/") for k in walk)
  velocity = coop_suite.load("walk_velocity").observation_spec()[0]
  assert "command/velocity" in velocity
  transport = coop_suite.load("transport", 4).observation_spec()[0]
  assert not any(k.startswith("command/") for k in transport)
  for key in ("extero/teammates", "extero/teammates_mask", "extero/heights",
              "extero/cylinder", "extero/target", "proprio/joints_pos"):
    assert key in transport
  assert set(k for k in walk if k.startswith("proprio/")) == set(
      k for k in transport if k.startswith("proprio/"))


def test_teammate_mask_pads_missing_neighbours():
  alone = coop_suite.load("transport", 1, seed=0, k_neighbours=2).reset()
  np.testing.assert_array_equal(alone.observation[0]["extero/teammates_mask"],
                                [0.0, 0.0])
  np.testing.assert_array_equal(alone.observation[0]["extero/teammates"], 0.0)
  pair = coop_suite.load("transport", 2, seed=0, k_neighbours=2).reset()
  np.testing.assert_array_equal(pair.observation[0]["extero/teammates_mask"],
                                [1.0, 0.0])


def test_nearest_teammate_is_egocentric():
  env = coop_suite.load("transport", 3, seed=0)
  timestep = env.reset()
  physics = env.task.walkers
  positions = np.array([w.torso_position(env.physics)[:2] for w in physics])
  yaw = env.task.walkers[0].heading(env.physics)
  distances = np.linalg.norm(positions[1:] - positions[0], axis=1)
  nearest = positions[1 + int(np.argmin(distances))] - positions[0]
  rotation = np.array([[np.cos(yaw), np.sin(yaw)], [-np.sin(yaw), np.cos(yaw)]])
  np.testing.assert_allclose(timestep.observation[0]["extero/teammates"],
                             rotation @ nearest, atol=1e-9)


def test_teammates_are_of_ones_own_species():
  """In the joint ravine a pusher's teammate is the other pusher and a
  crosser's the other crosser, as in their stage tasks (one species each),
  however near an agent of the other species is."""
  env = coop_suite.load("ravine", 2, n_pushers=2, seed=0)
  observation = env.reset().observation
  frames = env.task.frames(env.physics)
  xy, yaw = frames.position[:, :2], np.arctan2(frames.sin, frames.cos)
  for i, other in ((0, 1), (1, 0), (2, 3), (3, 2)):  # crossers, pushers
    c, s = np.cos(yaw[i]), np.sin(yaw[i])
    np.testing.assert_allclose(
        observation[i]["extero/teammates"],
        np.array([[c, s], [-s, c]]) @ (xy[other] - xy[i]), atol=1e-9)
  alone = coop_suite.load("ravine", 1, n_pushers=1, seed=0).reset()
  for agent in alone.observation:  # No teammate of one's own species.
    np.testing.assert_array_equal(agent["extero/teammates_mask"], 0.0)


def test_species_and_agent_order():
  env = coop_suite.load("ravine", 3, n_pushers=2, seed=0)
  assert env.task.species == ("crosser",) * 3 + ("pusher",) * 2
  pushers_only = coop_suite.load("ravine", 3, stage="pushers", seed=0)
  assert pushers_only.task.species == ("pusher", "pusher")
  crossers_only = coop_suite.load("ravine", 2, stage="crossers", seed=0)
  assert crossers_only.task.species == ("crosser", "crosser")
  assert coop_suite.load("corridor", 2).task.species == ("ant", "ant")


def test_same_seed_same_episode_and_different_seed_differs():
  def rollout(seed):
    env = coop_suite.load("transport", 3, seed=seed)
    rng = np.random.RandomState(0)
    first = env.reset().observation
    out = [np.concatenate([v.ravel() for v in agent.values()])
           for agent in first]
    for _ in range(10):
      timestep = env.step(rng.uniform(-1, 1, (3, 8)))
    out += [np.concatenate([v.ravel() for v in agent.values()])
            for agent in timestep.observation]
    return np.concatenate(out), np.array(timestep.reward)

  a, reward_a = rollout(7)
  b, reward_b = rollout(7)
  c, _ = rollout(8)
  np.testing.assert_array_equal(a, b)
  np.testing.assert_array_equal(reward_a, reward_b)
  assert not np.allclose(a, c)


def test_episode_metrics_report_reward_terms():
  env = coop_suite.load("transport", 2, seed=0)
  env.reset()
  total = np.zeros(2)
  for _ in range(5):
    total += np.array(env.step(np.zeros((2, 8))).reward, dtype=np.float64)
  metrics = env.episode_metrics()
  assert metrics["success"] is False
  terms = [k for k in metrics if k.startswith("reward/")]
  assert {"reward/cylinder_target", "reward/agent_cylinder",
          "reward/agent_target", "reward/success"} <= set(terms)
  assert metrics["return"] == pytest.approx(np.mean(total), rel=1e-5)
  assert sum(metrics[k] for k in terms) == pytest.approx(metrics["return"],
                                                         rel=1e-6)


def test_reward_terms_that_change_shape_are_refused():
  """The compiled reward sum trusts the shapes it is given: a task whose
  terms change in mid-episode (or are not per agent) must fail loudly."""
  env = coop_suite.load("transport", 2, seed=0)
  env.reset()
  env.step(np.zeros((2, 8)))
  terms = env.task._reward_terms  # pylint: disable=protected-access
  env.task._reward_terms = lambda physics: {**terms(physics), "extra": np.ones(2)}  # pylint: disable=protected-access
  with pytest.raises(RuntimeError, match="extra"):
    env.step(np.zeros((2, 8)))
  env = coop_suite.load("transport", 2, seed=0)
  env.reset()
  env.task._reward_terms = lambda physics: {"alive": np.ones(3)}  # pylint: disable=protected-access
  with pytest.raises(RuntimeError, match=r"each \[2\]"):
    env.step(np.zeros((2, 8)))


def test_global_state_has_fixed_size():
  env = coop_suite.load("transport", 4, seed=0)
  env.reset()
  state = env.task.global_state(env.physics)
  assert state.shape == (4 * 7 + 4,)
  env.step(np.zeros((4, 8)))
  assert env.task.global_state(env.physics).shape == state.shape


def test_sixteen_ants_in_a_pile_fit_the_constraint_memory():
  """The arena is sized per agent (4 MiB + `memory_mb_per_agent` each;
  the first assertion is what fails if that sizing goes) and holds a real
  pile: 16 Ants dropped onto each other touch through many contacts
  without MuJoCo's overflow warnings. The pile used ~0.5 MiB of the 20
  when written, so the warnings are a sanity check with a wide margin, not
  a test of the margin."""
  import mujoco  # pylint: disable=g-import-not-at-top
  env = coop_suite.load("transport", 16, seed=0)
  env.reset()
  physics = env.physics
  model, data = physics.model.ptr, physics.data.ptr
  assert model.narena == (4 + 16) * 2**20  # 1 MiB per agent by default.
  for i, walker in enumerate(env.task.walkers):  # A tower over 2 x 2 spots.
    walker.set_pose(physics, position=[0.15 * (i % 2), 0.15 * (i // 2 % 2),
                                       0.5 + 0.45 * i])
  rng = np.random.RandomState(0)
  root = model.body_rootid
  peak_use = peak_touching = 0
  for _ in range(80):
    env.step(rng.uniform(-1, 1, (16, 8)))
    peak_use = max(peak_use, data.maxuse_arena)
    bodies = [root[model.geom_bodyid[data.contact.geom1[:data.ncon]]],
              root[model.geom_bodyid[data.contact.geom2[:data.ncon]]]]
    peak_touching = max(peak_touching, int(np.sum(
        (bodies[0] != bodies[1]) & (bodies[0] != 0) & (bodies[1] != 0))))
  assert peak_touching >= 30  # A pile formed (65 when written).
  warnings = data.warning
  assert warnings[mujoco.mjtWarning.mjWARN_CNSTRFULL].number == 0
  assert warnings[mujoco.mjtWarning.mjWARN_CONTACTFULL].number == 0
  assert not env.physics_diverged
  assert 0 < peak_use < model.narena


def _episode_observations(env, steps=4):
  rng = np.random.RandomState(5)
  observations = [env.reset().observation]
  for _ in range(steps):
    observations.append(env.step(rng.uniform(-1, 1, (env.n_agents, 8)))
                        .observation)
  return observations


def test_disabled_and_buffered_observables_keep_composer_semantics():
  """The fast observation path must agree with composer's own rules: a
  disabled observable disappears from spec and observation, and a
  non-default one (here buffered) falls back to composer's updater."""
  reference = _episode_observations(coop_suite.load("transport", 3, seed=2))

  env = coop_suite.load("transport", 3, seed=2)
  for agent in env.task.observables:
    agent["extero/heights"].enabled = False
  observations = _episode_observations(env)
  assert "extero/heights" not in env.observation_spec()[0]
  for got, expected in zip(observations, reference):
    for agent_got, agent_expected in zip(got, expected):
      assert set(agent_got) == set(agent_expected) - {"extero/heights"}
      for key, value in agent_got.items():
        np.testing.assert_array_equal(value, agent_expected[key], key)

  env = coop_suite.load("transport", 3, seed=2)
  for agent in env.task.observables:
    agent["proprio/joints_pos"].buffer_size = 2
  observations = _episode_observations(env)
  assert not env._observation_updater.lean  # pylint: disable=protected-access
  for got, expected in zip(observations[1:], reference[1:]):
    for agent_got, agent_expected in zip(got, expected):
      assert agent_got["proprio/joints_pos"].shape == (2, 8)
      np.testing.assert_array_equal(agent_got["proprio/joints_pos"][-1],
                                    agent_expected["proprio/joints_pos"])
      np.testing.assert_array_equal(agent_got["extero/heights"],
                                    agent_expected["extero/heights"])
