"""The ML's GRU scan unrolled: the learner's update with nn.scan(unroll=k).

    python results/benchmarks/learner_unroll_2026-11-27/learner_unroll.py transport 1,4,32

A prototype (wraps flax.linen.scan; not in the library): one learner per
unroll from the same initial state, each compiled under its own unroll,
the same rollout of one actor (taken twice: the 2-actor batch) given to
each; prints the parameters' largest difference after one update and the
seconds of further updates in alternating order (ROUNDS env, default 5).
"""
import sys, time, os
sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..', '..', '..'))
import numpy as np, jax
import flax.linen as nn
UNROLL = [1]
_orig = nn.scan
def scan(*a, **k):
  k.setdefault('unroll', UNROLL[0]); return _orig(*a, **k)
nn.scan = scan
from runners import config as config_lib, learner_loop, rollout
task = sys.argv[1] if len(sys.argv) > 1 else 'transport'
unrolls = [int(u) for u in (sys.argv[2] if len(sys.argv) > 2 else '1,4,8,32').split(',')]
kw = dict(task=task, n_agents=4, actors=2, progress=False)
if task == 'ravine': kw.update(n_agents=2)
args = config_lib.train_args(**kw)
spec, _, _ = learner_loop.fresh_learners(args)
learner_sets = {}
worker = None
for u in unrolls:
  UNROLL[0] = u
  learner_sets[u] = learner_loop.fresh_learners(args)[2]
  if worker is None:
    worker = rollout.RolloutWorker(spec, args.hierarchy, 0, 0, args.envs_per_actor)
    result = worker.collect(learner_loop.actor_variables(learner_sets[u]), 0)
    worker.close()
  t = time.perf_counter(); learner_loop.step_learners(learner_sets[u], [result, result], None)
  print('unroll', u, 'compile+update', round(time.perf_counter() - t, 2), flush=True)
base = unrolls[0]
for u in unrolls[1:]:
  for sp in learner_sets[u]:
    a = jax.tree_util.tree_leaves(learner_sets[base][sp].get_variables(['params'])[0])
    b = jax.tree_util.tree_leaves(learner_sets[u][sp].get_variables(['params'])[0])
    print('unroll', u, sp, 'max |param diff| after one update', max(float(np.max(np.abs(np.asarray(x) - np.asarray(y)))) for x, y in zip(a, b)))
secs = {u: [] for u in unrolls}
for r in range(int(os.environ.get('ROUNDS', 5))):
  for u in (unrolls if r % 2 == 0 else unrolls[::-1]):
    t = time.perf_counter(); learner_loop.step_learners(learner_sets[u], [result, result], None); secs[u].append(time.perf_counter() - t)
  print(r, {u: round(v[-1], 3) for u, v in secs.items()}, flush=True)
print({u: round(float(np.median(v)), 3) for u, v in secs.items()}, 'ratio to', base, {u: round(float(np.median(np.divide(secs[base], v))), 2) for u, v in secs.items()})
