"""docs/extending.md's worked example, `examples/rendezvous.py`, works as the
page says: it loads through `coop_suite.load`, gives the same numbers on
the fast path and plain composer, succeeds (and pays its bonus) exactly
when every Ant is in the zone, and trains in-process."""
import csv
import os

import numpy as np
import pytest

import coop_suite
from coop_suite import tasks
from examples import rendezvous
from runners import config as config_lib
from runners import learner_loop
from tests.test_fast_path import _assert_identical
from tests.test_fast_path import _rollout


@pytest.fixture(autouse=True)
def registered():
  rendezvous.register()
  yield
  del tasks.TASKS['rendezvous']


def test_the_example_loads_with_its_options_and_features():
  env = coop_suite.load('rendezvous', 3, seed=0, zone_radius=2.0)
  observation = env.reset().observation
  assert len(observation) == 3
  assert observation[0]['extero/zone'].shape == (2,)
  assert observation[0]['extero/inside'].shape == (1,)
  # The zone is 4 m away, seen in the Ant's own heading frame.
  assert np.linalg.norm(observation[0]['extero/zone']) == pytest.approx(
      4.0, abs=0.5)
  with pytest.raises(ValueError, match='zone_radius'):
    coop_suite.load('rendezvous', 3, zone_radius=-1.0)
  with pytest.raises(ValueError, match='1 to 8 agents'):
    coop_suite.load('rendezvous', 9)


def test_the_example_is_the_same_on_both_step_paths():
  fast = _rollout('rendezvous', 2, {}, fast_path=True)
  plain = _rollout('rendezvous', 2, {}, fast_path=False)
  assert len(fast) == 2 * (1 + 12 + 1)  # 0.6 s episodes of 50 ms steps.
  _assert_identical(fast, plain, 'rendezvous')


@pytest.mark.parametrize('outside', [False, True])
def test_success_needs_every_ant_in_the_zone(outside):
  env = coop_suite.load('rendezvous', 3, seed=1)
  env.reset()
  for i, walker in enumerate(env.task.walkers):
    angle = 2 * np.pi * i / 3
    radius = 1.8 if outside and i == 0 else 0.8  # The zone: 1.5 m.
    walker.set_pose(env.physics, position=[radius * np.cos(angle),
                                           radius * np.sin(angle), 0.6])
  env.task.state_changed()  # The physics was edited by hand.
  timestep = env.step(np.zeros((3, 8)))
  metrics = env.episode_metrics()
  assert metrics['success'] == (0.0 if outside else 1.0)
  assert metrics['inside'] == (2 if outside else 3)
  bonus = metrics['reward/success']
  assert bonus == (0.0 if outside else 100.0)
  assert min(timestep.reward) > (0.0 if outside else 100.0)


def test_the_example_trains_in_process(tmp_path):
  logdir = str(tmp_path / 'run')
  # 2 copies x 4 commands of 0.1 s per update; 0.8 s episodes end in the
  # second update.
  summary = learner_loop.train(config_lib.train_args(
      task='rendezvous', n_agents=2, actors=0, envs_per_actor=2,
      command_period=0.1, sequence_length=4, num_minibatches=2,
      num_epochs=1, upper_layer_sizes=(16,), middle_layer_size=8,
      head_sizes=(8,), critic_sizes=(8,), time_limit=0.8, total_steps=32,
      logdir=logdir, progress=False))
  assert summary['update'] == 2
  with open(os.path.join(logdir, 'metrics.csv')) as f:
    rows = list(csv.DictReader(f))
  assert float(rows[-1]['episodes']) == 2
  assert rows[-1]['inside'] != ''
