"""The composer fast path: composer's step with less Python, bit for bit.

Four pieces replace parts of plain composer stepping with the same
computation (docs/performance.md has the measurements):

* `LeanUpdater` (`observation.py`): reads every agent's observation in one
  call when every observable has composer's default settings, instead of
  composer's per-observable buffers and schedules.
* `FusedStep` (`stepping.py`): the substeps of a control step in one
  physics call, without dm_control's per-call Python, when no hook runs
  between substeps; for the tasks' own controls (`CoopTask.compiled_controls`)
  the controls written from compiled code instead of composer's hooks, for
  many environment copies at once in `write_controls` and `check_warnings`
  (`coop_suite.environment.LockstepPhysics`).
* `StateCache` (`state_cache.py`): what the task computes from one physics
  state (frames, features, its `measure`) is computed once, not once per
  observable and hook.
* `raycast.py`: MuJoCo's `mju_rayGeom` called from compiled code on the
  terrain geoms only, instead of `mj_multiRay` over every geom.

`coop_suite.load(..., fast_path=False)` switches all four off: composer's
own updater and `Environment.step`, nothing cached, `mj_multiRay`.
`tests/test_fast_path.py` checks that both give the same observations,
rewards, discounts and episode metrics on every task.
"""

from coop_suite.fast.observation import LeanUpdater
from coop_suite.fast.state_cache import StateCache
from coop_suite.fast.stepping import ACTION_DTYPES
from coop_suite.fast.stepping import check_warnings
from coop_suite.fast.stepping import FusedStep
from coop_suite.fast.stepping import write_controls

__all__ = ["ACTION_DTYPES", "FusedStep", "LeanUpdater", "StateCache",
           "check_warnings", "write_controls"]
