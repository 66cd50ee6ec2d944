"""The composer fast path (`coop_suite.fast`) against plain composer stepping.

`fast_path=False` runs composer's own observation updater and step, computes
every observable on its own (nothing cached per state) and casts the height
rays with MuJoCo's `mj_multiRay`. Both must give the very same numbers, bit
for bit, on every task: the fast path only takes Python out of the step.
"""

import numpy as np
import pytest

import coop_suite
from coop_suite import environment

# Every task, the ravine in each of its stages; short episodes so that the
# time limit's LAST step and the next reset are covered too.
_CASES = [("transport", 2, {}), ("corridor", 2, {}),
          ("ravine", 1, {"stage": "joint"}),
          ("ravine", 2, {"stage": "pushers"}),
          ("ravine", 1, {"stage": "crossers"}),
          ("walk_to_target", 1, {}), ("walk_velocity", 1, {})]


def _rollout(task, n_agents, options, fast_path, phases=False):
  """Two episodes of fixed-seed random actions: every timestep's fields,
  the global state, and the episode metrics at each episode's end. With
  `phases`, each step is `step_physics` then `step_outcome`."""
  env = coop_suite.load(task, n_agents, seed=5, time_limit=0.6,
                        fast_path=fast_path, **options)
  rng = np.random.RandomState(11)
  record = []
  for _ in range(2):
    timestep = env.reset()
    record.append(timestep)
    while not timestep.last():
      action = rng.uniform(-1, 1, (env.n_agents, 8))
      if phases:
        env.step_physics(action)
        timestep = env.step_outcome()
      else:
        timestep = env.step(action)
      record.append((timestep, env.task.global_state(env.physics)))
    record.append(env.episode_metrics())
  return record


def _assert_identical(fast, plain, where):
  if isinstance(fast, dict):
    assert fast.keys() == plain.keys(), where
    for key in fast:
      _assert_identical(fast[key], plain[key], f"{where}/{key}")
  elif isinstance(fast, (list, tuple)):
    assert len(fast) == len(plain), where
    for i, (a, b) in enumerate(zip(fast, plain)):
      _assert_identical(a, b, f"{where}[{i}]")
  else:
    a, b = np.asarray(fast), np.asarray(plain)
    assert (a.dtype, a.shape) == (b.dtype, b.shape), where
    assert a.tobytes() == b.tobytes(), (where, fast, plain)


def test_fast_path_is_plain_composer_bit_for_bit():
  for task, n_agents, options in _CASES:
    fast = _rollout(task, n_agents, options, fast_path=True)
    plain = _rollout(task, n_agents, options, fast_path=False)
    assert len(fast) == 2 * (1 + 12 + 1), (task, len(fast))  # 0.6 s / 50 ms.
    _assert_identical(fast, plain, f"{task} {options}")


def test_a_step_in_its_two_phases_is_the_step():
  for task, n_agents, options in _CASES[:3]:
    whole = _rollout(task, n_agents, options, fast_path=True)
    for fast_path in (True, False):
      phases = _rollout(task, n_agents, options, fast_path, phases=True)
      _assert_identical(phases, whole, f"{task} {options} {fast_path}")


@pytest.mark.parametrize("fast_path", [True, False])
def test_the_phases_refuse_to_run_out_of_order(fast_path):
  env = coop_suite.load("transport", 2, seed=0, time_limit=0.1,
                        fast_path=fast_path)
  env.reset()
  with pytest.raises(RuntimeError, match="step_physics"):
    env.step_outcome()
  action = np.zeros((2, 8))
  env.step_physics(action)
  env.step_outcome()
  with pytest.raises(RuntimeError, match="step_physics"):
    env.step_outcome()  # One outcome per physics step.
  env.step_physics(action)
  assert env.step_outcome().last()
  with pytest.raises(RuntimeError, match="reset"):
    env.step_physics(action)
  env.reset()
  env.step_physics(action)  # A step begun and abandoned by a reset...
  env.reset()
  with pytest.raises(RuntimeError, match="step_physics"):
    env.step_outcome()  # ...leaves nothing to end.


def _copies(task, n_agents, options, fast_path=True, seeds=(5, 6, 7)):
  envs = [coop_suite.load(task, n_agents, seed=s, time_limit=0.6,
                          fast_path=fast_path, **options) for s in seeds]
  for env in envs:
    env.reset()
  return envs


@pytest.fixture
def compiled_calls(monkeypatch):
  """The number of copies whose controls each compiled call wrote."""
  from coop_suite.fast import stepping  # pylint: disable=g-import-not-at-top
  calls = []
  kernel = stepping._write_controls  # pylint: disable=protected-access

  def counted(addresses, *args):
    calls.append(len(addresses))
    return kernel(addresses, *args)
  monkeypatch.setattr(stepping, "_write_controls", counted)
  return calls


@pytest.mark.parametrize("fast_path", [True, False])
def test_copies_stepped_together_step_as_each_copy_alone(fast_path,
                                                         compiled_calls):
  """`LockstepPhysics` steps the physics of many copies in one compiled call
  (the fast path) or copy by copy (plain composer): every timestep and the
  episode metrics equal each copy stepped alone, with a copy left out of
  some steps, through the time limit and the reset after it."""
  for task, n_agents, options in _CASES:
    together = _copies(task, n_agents, options, fast_path)
    alone = _copies(task, n_agents, options, fast_path)
    physics = environment.LockstepPhysics(together)
    rng = np.random.RandomState(3)
    compiled_calls.clear()
    together_calls = []
    for step in range(30):
      active = [0, 2] if step % 3 == 1 else [0, 1, 2]
      together_calls.append(len(active))
      n = together[0].n_agents  # The ravine's pushers come on top.
      actions = rng.uniform(-1.5, 1.5, (len(active), n, 8)).astype(
          np.float32 if step % 2 else np.float64)
      physics.step_physics(actions, active)
      for e, action in zip(active, actions):
        got, want = together[e].step_outcome(), alone[e].step(action)
        _assert_identical(got, want, f"{task} {options} step {step} copy {e}")
        if got.last():
          _assert_identical(together[e].episode_metrics(),
                            alone[e].episode_metrics(), f"{task} metrics")
          _assert_identical(together[e].reset(), alone[e].reset(), task)
    assert together[1].task.episode_metrics(together[1].physics)[
        "control_steps"] > 0
    if fast_path:  # Together in one call; alone, one call a step.
      assert [c for c in compiled_calls if c > 1] == together_calls, task
      assert compiled_calls.count(1) == sum(together_calls), task
    else:
      assert not compiled_calls


def test_copies_stepped_together_keep_the_copy_by_copy_errors():
  together = _copies("transport", 2, {})
  physics = environment.LockstepPhysics(together)
  actions = np.zeros((3, 2, 8))
  actions[1, 1, 4] = np.nan
  with pytest.raises(ValueError, match=r"agents \[1\] contain NaN"):
    physics.step_physics(actions)
  with pytest.raises(ValueError, match="2 actions"):
    physics.step_physics(np.zeros((2, 2, 8)))
  for env in together:  # A clean start, then one copy runs out of time.
    env.reset()
  together[2].physics.data.time = 0.6
  physics.step_physics(np.zeros((3, 2, 8)))
  assert [env.step_outcome().last() for env in together] == [
      False, False, True]
  with pytest.raises(RuntimeError, match="reset"):
    physics.step_physics(np.zeros((3, 2, 8)))
  physics.step_physics(np.zeros((2, 2, 8)), [0, 1])  # The others go on.


@pytest.mark.parametrize("shape, error", [
    ((3, 3, 8), "Expected actions for 2 agents, got 3"),
    ((3, 2, 7), r"agent 0 has shape \(7,\); expected \(8,\)"),
    ((3, 2, 9), r"agent 0 has shape \(9,\)")])
def test_actions_of_a_wrong_shape_get_the_copy_by_copy_error(shape, error,
                                                             compiled_calls):
  together = _copies("transport", 2, {})
  controls = [env.physics.data.ctrl.copy() for env in together]
  with pytest.raises(ValueError, match=error):
    environment.LockstepPhysics(together).step_physics(np.zeros(shape))
  assert not compiled_calls  # Nothing written past any buffer.
  for env, before in zip(together, controls):
    np.testing.assert_array_equal(env.physics.data.ctrl, before)


def test_other_actions_than_one_float_array_go_copy_by_copy(compiled_calls):
  """Integer actions or a list of per-copy lists are valid copy by copy;
  together they are stepped copy by copy, with the same numbers."""
  together, alone = _copies("transport", 2, {}), _copies("transport", 2, {})
  physics = environment.LockstepPhysics(together)
  for actions, each in ((np.ones((3, 2, 8), np.int64), np.ones((2, 8))),
                        ([[[0.5] * 8] * 2] * 3, np.full((2, 8), 0.5))):
    physics.step_physics(actions)
    for together_env, alone_env in zip(together, alone):
      _assert_identical(together_env.step_outcome(), alone_env.step(each),
                        str(type(actions)))
  assert compiled_calls == [1] * 12  # Each copy on its own (and alone).


def test_a_fatal_error_in_one_copy_leaves_those_before_it_stepped(
    monkeypatch):
  """A `mujoco.FatalError` in one copy's substeps propagates; the copies
  stepped before it are complete (their warnings checked)."""
  import mujoco  # pylint: disable=g-import-not-at-top
  together = _copies("transport", 2, {})
  physics = environment.LockstepPhysics(together)
  together[0].physics.data.qvel[:] = 1e30  # Diverges.

  def fatal():
    raise mujoco.FatalError("mj_stackAlloc: out of memory")
  monkeypatch.setattr(together[1]._stepper, "compiled_substeps", fatal)  # pylint: disable=protected-access
  with pytest.raises(mujoco.FatalError, match="out of memory"):
    physics.step_physics(np.zeros((3, 2, 8)))
  assert together[0].step_outcome().last()
  assert together[0].physics_diverged


def test_a_copy_that_diverges_ends_its_own_episode_only(compiled_calls):
  together = _copies("transport", 2, {})
  physics = environment.LockstepPhysics(together)
  together[1].physics.data.qvel[:] = 1e30
  physics.step_physics(np.zeros((3, 2, 8)))
  assert compiled_calls == [3]
  steps = [env.step_outcome() for env in together]
  assert [s.last() for s in steps] == [False, True, False]
  assert [env.physics_diverged for env in together] == [False, True, False]
  assert float(steps[1].discount) == 0.0


def test_a_task_with_its_own_controls_is_stepped_in_python(compiled_calls):
  """A task that overrides `before_step` gets no compiled physics phase
  (`compiled_controls()` is None): its own hook runs, copy by copy."""
  from coop_suite.tasks import transport  # pylint: disable=g-import-not-at-top

  class Doubled(transport.Transport):
    def before_step(self, physics, action, random_state):
      super().before_step(physics, action, random_state)
      physics.data.ctrl[:] *= 0.5

  env = coop_suite.load("transport", 2, seed=0)
  task = Doubled(2)
  assert task.compiled_controls() is None
  assert env.task.compiled_controls() is not None
  env.task.before_step = lambda *args: None  # Replaced on the instance.
  assert env.task.compiled_controls() is None
  custom = environment.CoopEnvironment(task, 1.0, np.random.RandomState(0))
  custom.reset()
  environment.LockstepPhysics([custom]).step_physics(np.ones((1, 2, 8)))
  np.testing.assert_array_equal(custom.physics.data.ctrl, 0.5)
  assert not compiled_calls
