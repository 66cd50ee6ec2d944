"""Ray as `coop-train` starts it: nothing reachable from outside the
machine."""
import os
import time

import psutil
import pytest

from runners import actor_pool

# Ray starts its processes with fork + exec, which JAX's fork warning cannot
# tell from a bare fork.
pytestmark = pytest.mark.filterwarnings('ignore:os.fork:RuntimeWarning')


def _listening(pids):
  return [c for c in psutil.net_connections('inet')
          if c.status == psutil.CONN_LISTEN and c.pid in pids]


def test_local_ray_listens_on_loopback_only():
  import ray  # pylint: disable=g-import-not-at-top
  assert actor_pool.init_ray(num_cpus=1), 'Ray was already running.'
  try:
    @ray.remote(num_cpus=1)
    def worker_pid():
      return os.getpid()

    worker = ray.get(worker_pid.remote())  # A worker process serves too.
    time.sleep(1.0)  # Agents finish starting their servers.
    me = psutil.Process()
    pids = {me.pid, *(p.pid for p in me.children(recursive=True))}
    assert worker in pids
    sockets = _listening(pids)
    assert {c.pid for c in sockets} > {me.pid, worker}  # GCS, raylet...
    exposed = [(c.laddr.ip, c.laddr.port) for c in sockets
               if c.laddr.ip not in ('127.0.0.1', '::1', '::ffff:127.0.0.1')]
    # Ray's autoscaler monitor and dashboard head still serve Prometheus
    # metrics (whenever prometheus_client is installed); on loopback too.
    assert not exposed, exposed
  finally:
    ray.shutdown()
