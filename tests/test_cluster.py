"""`coop-train --ray-address` on a two-node Ray cluster started on loopback.

The cluster is this test's own: a head and one more node of 1 CPU each
(`ray.cluster_utils.Cluster`, Ray's multi-node test harness), its own temp
directory and ports, token authentication as Ray documents it
(RAY_AUTH_MODE=token and the token in RAY_AUTH_TOKEN on every node and the
driver). Teardown stops only its processes. Ray's cluster mode would take
the machine's address; with RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 (and the
constant patched in this process) every node, and the driver, stay on
127.0.0.1.
"""
import csv
import os
import secrets
import shutil
import sys
import tempfile

import psutil
import pytest

from runners import actor_pool
from runners import config as config_lib
from runners import learner_loop
from runners import train
from tests import test_train

pytestmark = pytest.mark.filterwarnings('ignore:os.fork:RuntimeWarning')
_ENV = {'RAY_AUTH_MODE': 'token', 'RAY_AUTH_TOKEN': None,
        'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0',
        'RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S': '0'}


def _reload_auth():
  """Makes this process read RAY_AUTH_MODE and its token again."""
  from ray._raylet import AuthenticationTokenLoader  # pylint: disable=g-import-not-at-top
  from ray._raylet import Config  # pylint: disable=g-import-not-at-top
  Config.initialize('')
  AuthenticationTokenLoader.instance().reset_cache()


@pytest.fixture
def cluster(monkeypatch):
  """A head and one more node on 127.0.0.1 with a fresh token; yields
  (cluster, {raylet pid: node id})."""
  if sys.platform != 'linux':
    pytest.skip('Ray supports multi-node clusters on Linux only.')
  import ray  # pylint: disable=g-import-not-at-top
  import ray._private.utils  # pylint: disable=g-import-not-at-top
  from ray import cluster_utils  # pylint: disable=g-import-not-at-top
  from ray._private import ray_constants  # pylint: disable=g-import-not-at-top
  assert not ray.is_initialized(), 'Ray is already running in this process.'
  saved = {k: os.environ.get(k) for k in _ENV}
  os.environ.update({**_ENV, 'RAY_AUTH_TOKEN': secrets.token_hex(32)})
  _reload_auth()
  monkeypatch.setattr(ray_constants, 'ENABLE_RAY_CLUSTER', False)
  # Not /tmp/ray/ray_current_cluster: another Ray's `auto` must not find us.
  monkeypatch.setattr(ray._private.utils, 'write_ray_address',
                      lambda *args, **kwargs: None)
  temp_dir = tempfile.mkdtemp(prefix='coop-ray-')  # Short: socket paths.
  nodes = None
  try:
    nodes = cluster_utils.Cluster(
        initialize_head=True, shutdown_at_exit=False,
        head_node_args=dict(node_ip_address='127.0.0.1', num_cpus=1,
                            include_dashboard=False, include_log_monitor=False,
                            temp_dir=temp_dir))
    nodes.add_node(node_ip_address='127.0.0.1', num_cpus=1)
    raylets = {
        node.all_processes[ray_constants.PROCESS_TYPE_RAYLET][0].process.pid:
            node.node_id
        for node in [nodes.head_node, *nodes.worker_nodes]}
    yield nodes, raylets
  finally:
    ray.shutdown()
    if nodes is not None:
      nodes.shutdown()
    shutil.rmtree(temp_dir, ignore_errors=True)
    for key, value in saved.items():
      if value is None:
        os.environ.pop(key, None)
      else:
        os.environ[key] = value
    _reload_auth()


def _node_of(pid, raylets):
  """The node whose raylet started process `pid`."""
  for parent in psutil.Process(pid).parents():
    if parent.pid in raylets:
      return raylets[parent.pid]
  raise AssertionError(f'Process {pid} is not a worker of this cluster.')


def test_training_spreads_actors_over_two_nodes(cluster, tmp_path):
  nodes, raylets = cluster
  host, _ = nodes.address.split(':')
  assert host == '127.0.0.1'
  actor_nodes = []

  def on_update(update, row, pool):
    del update, row
    actor_nodes.append([_node_of(pid, raylets) for pid in pool.pids()])

  args = config_lib.train_args(**{
      **test_train.TINY, 'task': 'transport', 'actors': 2,
      'logdir': str(tmp_path / 'run'), 'ray_address': nodes.address,
      'total_steps': 4 * test_train.STEPS})  # 2 updates of 2 actors.
  summary = learner_loop.train(args, on_update)
  assert summary['update'] == 2
  with open(tmp_path / 'run' / 'metrics.csv') as f:
    assert len(list(csv.DictReader(f))) == 2
  # One actor per node (the shipped controller reached both in the spec).
  assert [sorted(n) for n in actor_nodes] == [sorted(raylets.values())] * 2


def test_unreachable_address_is_one_line(tmp_path, capsys):
  with pytest.raises(SystemExit) as stop:
    train.main(['--ray-address', f'127.0.0.1:{_free_port()}', '--logdir',
                str(tmp_path / 'run'), '--total-steps', '1'])
  assert stop.value.code == 2
  lines = capsys.readouterr().err.strip().splitlines()
  assert len(lines) == 1, lines
  assert lines[0].startswith('coop-train: error: --ray-address 127.0.0.1:')
  assert 'no Ray cluster answers there' in lines[0]
  assert issubclass(actor_pool.ClusterUnreachable, ConnectionError)


def _free_port():
  import socket  # pylint: disable=g-import-not-at-top
  with socket.socket() as s:
    s.bind(('127.0.0.1', 0))
    return s.getsockname()[1]


def test_a_local_ray_that_does_not_start_is_one_line(tmp_path, capsys,
                                                     monkeypatch):
  """Ray's own 30 s wait for its node (exceeded on 2 cores beside two
  trainings) ends coop-train with one line that names --actors 0; Ray's
  other errors pass through as they are."""
  import ray  # pylint: disable=g-import-not-at-top
  message = ('The current node timed out during startup. This could happen '
             'because some of the raylet failed to startup or the GCS has '
             'become overloaded.')

  def init(*args, **kwargs):
    raise Exception(message)  # pylint: disable=broad-exception-raised
  monkeypatch.setattr(ray, 'is_initialized', lambda: False)
  monkeypatch.setattr(ray, 'init', init)
  monkeypatch.delenv('RAY_ADDRESS', raising=False)
  with pytest.raises(SystemExit) as stop:
    train.main(['--logdir', str(tmp_path / 'run'), '--total-steps', '1',
                '--no-progress'])
  assert stop.value.code == 2
  lines = capsys.readouterr().err.strip().splitlines()
  assert len(lines) == 1, lines
  assert lines[0].startswith(
      "coop-train: error: Ray's local instance did not start: " + message)
  assert lines[0].endswith('--actors 0.')
  message = 'something else'
  with pytest.raises(Exception, match='^something else$'):
    actor_pool.init_ray()
