"""The composer fast path (`coop_suite.fast`) against plain composer stepping.

`fast_path=False` runs composer's own observation updater and step, computes
every observable on its own (nothing cached per state) and casts the height
rays with MuJoCo's `mj_multiRay`. Both must give the very same numbers, bit
for bit, on every task: the fast path only takes Python out of the step.
"""

import numpy as np
import pytest

import coop_suite

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
