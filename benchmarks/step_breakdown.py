"""Where one control step's time goes, as fractions of the whole step.

    python benchmarks/step_breakdown.py [--task transport] [--n-agents 4]
    python benchmarks/step_breakdown.py --lockstep [--copies 16]

Runs the real `env.step` with a timer around each piece it calls (action
validation, the controls, which the fast path writes from compiled code,
the physics substeps, the status update, the reward, the observation) and
prints each piece's share of the step, so that the figures do not depend on
how busy the shared machine is.
The pieces are timed where they run, with the caches as the physics leaves
them; timed alone and warm they would look two to three times cheaper.

`--lockstep` does the same for what an actor runs in training: `--copies`
copies stepped in lockstep by `EnvBatch` with the shipped lower layer and
random commands (the lower layer's input and call, the physics phase of
all copies at once, and each copy's outcome phase, `docs/performance.md`).
Run it pinned to one core with the actors' settings, e.g.
`JAX_PLATFORMS=cpu OMP_NUM_THREADS=1
XLA_FLAGS=--xla_cpu_multi_thread_eigen=false taskset -c 1 python ...`.

    python benchmarks/step_breakdown.py --rollout [--checkpoint PATH]

`--rollout` times what an actor's `RolloutWorker.collect` does in training:
the same pieces plus the episodes' resets, the policy's input rows and the
upper and middle layers (acting and recording the trajectory), with a
fresh learner's policy or a trained one (`--checkpoint`, a run or one of
its checkpoints; its task and population), episodes ending as they do in
training. It also replays each rollout's own controls on a bare simulator
(`training_throughput`'s raw loop, episode by episode from each one's start
state) and, alternating with the rollouts, two references, each replayed
the same way: copies made from the same seeds under random commands (what
the lockstep ratio is measured on), and one environment under random joint
actions (the raw rate of `training_throughput.py`'s pipeline rows). So it
prints the rollout / raw on its own trajectories, and how much physics the
policy's trajectories cost against the references'. It re-runs itself
pinned to one core with the actors' settings.
"""

import argparse
import collections
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # pylint: disable=g-import-not-at-top

import coop_suite


def _timed(fn, totals, name):
  """`fn` that adds its own duration to totals[name]."""
  def run(*args, **kwargs):
    start = time.perf_counter()
    try:
      return fn(*args, **kwargs)
    finally:
      totals[name] += time.perf_counter() - start
  return run


def main():
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument("--task", default="transport")
  parser.add_argument("--n-agents", type=int, default=4)
  parser.add_argument("--steps", type=int, default=3000,
                      help="control steps (of each copy with --lockstep)")
  parser.add_argument("--lockstep", action="store_true",
                      help="copies in lockstep with the lower layer")
  parser.add_argument("--copies", type=int, default=16)
  parser.add_argument("--rollout", action="store_true",
                      help="an actor's rollouts with a policy")
  parser.add_argument("--checkpoint", default="",
                      help="--rollout: the policy (a run or a checkpoint); "
                      "a fresh learner's if empty")
  parser.add_argument("--rounds", type=int, default=4,
                      help="--rollout: rollouts timed (after one warm-up)")
  args = parser.parse_args()
  if args.lockstep:
    lockstep(args)
    return
  if args.rollout:
    _pinned_with_actor_settings()
    rollout_breakdown(args)
    return
  from coop_suite.fast import stepping  # pylint: disable=g-import-not-at-top
  env = coop_suite.load(args.task, args.n_agents, seed=0, time_limit=1e9)
  env.reset()
  task = env.task
  totals = collections.defaultdict(float)
  _time_physics(stepping, totals)
  # The controls: written from compiled code on the fast path, else by the
  # task's hook (not replaced on the task, which would leave the fast path).
  stepping.write_controls = _timed(stepping.write_controls, totals,
                                   "controls")
  # pylint: disable=protected-access
  if env._stepper is None or env._stepper.addresses is None:
    task.before_step = _timed(task.before_step, totals, "controls")
  env.validate_action = _timed(env.validate_action, totals,
                               "action validation")
  task.after_step = _timed(task.after_step, totals, "status (after_step)")
  task.get_reward = _timed(task.get_reward, totals, "reward")
  updater = env._observation_updater
  updater.get_observation = _timed(updater.get_observation, totals,
                                   "observation")
  # pylint: enable=protected-access
  actions = np.random.RandomState(0).uniform(-1, 1,
                                             (args.steps, env.n_agents, 8))
  for action in actions[:200]:  # Warm-up: compile, fill the caches.
    env.step(action)
  totals.clear()
  start = time.perf_counter()
  for action in actions:
    env.step(action)
  total = time.perf_counter() - start
  print(f"{args.task} with {env.n_agents} agents: one env.step = 1.00 "
        f"({total / args.steps * 1e6:.0f} us)")
  for name, seconds in totals.items():
    print(f"  {name:24s} {seconds / total:5.2f}")
  rest = 1 - sum(totals.values()) / total
  print(f"  {'rest (composer, timers)':24s} {rest:5.2f}")


def _time_physics(stepping, totals):
  """Times MuJoCo's substeps under "physics substeps", wherever they run:
  after the compiled controls (`FusedStep.compiled_substeps`, with its
  ~1 us of bookkeeping) or in the Python runner."""
  for owner, name in ((stepping.FusedStep, "compiled_substeps"),
                      (stepping.SubstepRunner, "step")):
    setattr(owner, name, _timed(getattr(owner, name), totals,
                                "physics substeps"))


def lockstep_batch(task, n_agents, copies):
  """An actor's `EnvBatch` as training builds it: `copies` copies of `task`
  with the shipped lower layer, episodes too long to end in a measurement."""
  # pylint: disable=g-import-not-at-top
  from runners import config as config_lib
  from runners import learner_loop
  from runners import rollout
  # pylint: enable=g-import-not-at-top
  train_args = config_lib.TrainArgs(
      task=task, n_agents=n_agents, envs_per_actor=copies, logdir="",
      progress=False, total_steps=1, time_limit=1e9)
  return rollout.EnvBatch(learner_loop.environment_spec(train_args),
                          train_args.hierarchy, range(copies),
                          global_state=False)


def lockstep(args):
  """The breakdown of `EnvBatch`'s lockstep steps (see the module doc)."""
  from coop_suite.fast import stepping  # pylint: disable=g-import-not-at-top
  batch = lockstep_batch(args.task, args.n_agents, args.copies)
  (species,) = batch.species  # Every agent commanded alike.
  totals = collections.defaultdict(float)
  _time_lockstep(batch, stepping, totals)
  low_level = batch.envs[0].low_level_steps
  commands = np.random.RandomState(0).uniform(
      -3, 3, (max(1, args.steps // low_level), args.copies * args.n_agents,
              2))
  for command in commands[:3]:  # Warm-up: compile, fill the caches.
    batch.step({species.name: command})
  totals.clear()
  start = time.perf_counter()
  for command in commands:
    batch.step({species.name: command})
  total = time.perf_counter() - start
  steps = len(commands) * low_level * args.copies
  print(f"{args.task} with {args.n_agents} agents, {args.copies} copies in "
        f"lockstep with the lower layer: one control step of one copy = "
        f"1.00 ({total / steps * 1e6:.0f} us)")
  _print_shares(totals, total, _LOCKSTEP_PIECES, "rest (commands, rows)",
                "  ")


_LOCKSTEP_PIECES = ("physics substeps", "physics phase", "lower-layer input",
                    "lower-layer call", "outcome phase")


def _time_lockstep(batch, stepping, totals):
  """Times `batch`'s (an `EnvBatch`) lockstep pieces into `totals`: the
  substeps and the (frozen) controller by class, the physics phase of all
  copies at once, the lower layer's input and the outcome phase per copy
  (the input only where the copies are commanded)."""
  # pylint: disable=protected-access
  commanded = batch._controller is not None
  _time_physics(stepping, totals)
  if commanded:
    controller = type(batch._controller)
    controller.act = _timed(controller.act, totals, "lower-layer call")
  batch._physics.step_physics = _timed(batch._physics.step_physics, totals,
                                       "physics phase")
  for copy in batch.envs:
    if commanded:
      copy.controller_input = _timed(copy.controller_input, totals,
                                     "lower-layer input")
    env = copy.env if commanded else copy
    env.step_outcome = _timed(env.step_outcome, totals, "outcome phase")
  # pylint: enable=protected-access


def _print_shares(totals, total, pieces, rest, indent):
  """Each piece's share of `total` seconds, then the rest's. The physics
  phase's timer holds the substeps' too: it is shown without them."""
  substeps = totals["physics substeps"]
  for name in pieces:
    seconds = totals[name] - (substeps if name == "physics phase" else 0.0)
    label = name + (" (the rest)" if name == "physics phase" else "")
    print(f"{indent}{label:30s} {seconds / total:5.2f}")
  timed = sum(totals.values()) - substeps
  print(f"{indent}{rest:30s} {1 - timed / total:5.2f}")


_ROLLOUT_PIECES = ("episode resets", "policy rows", "upper and middle layers")


def _pinned_with_actor_settings():
  """Re-runs this script pinned to one core with the actors' settings (set
  before numpy, numba and JAX start their threads), unless it already is."""
  import sys  # pylint: disable=g-import-not-at-top
  from runners import actor_pool  # pylint: disable=g-import-not-at-top
  settings = actor_pool.ACTOR_ENV_VARS
  if (len(os.sched_getaffinity(0)) == 1
      and all(os.environ.get(k) == v for k, v in settings.items())):
    return
  cpu = sorted(os.sched_getaffinity(0))[-1]
  os.execvpe("taskset", ["taskset", "-c", str(cpu), sys.executable,
                         *sys.argv], {**os.environ, **settings})


def rollout_breakdown(args):
  """An actor's rollouts, timed piece by piece (see the module doc)."""
  # pylint: disable=g-import-not-at-top
  import training_throughput  # Its raw loop (this script's folder).
  from coop_suite.fast import stepping
  from runners import config as config_lib
  from runners import evaluate
  from runners import learner_loop
  from runners import rollout
  # pylint: enable=g-import-not-at-top
  if args.checkpoint:
    spec, config, models, _ = evaluate.load_model(
        args.checkpoint, evaluate.EvalArgs(checkpoint=(args.checkpoint,)))
    learners = {name: model[3] for name, model in models.items()}
    what = args.checkpoint
  else:
    train_args = config_lib.TrainArgs(
        task=args.task, n_agents=args.n_agents, envs_per_actor=args.copies,
        logdir="", progress=False, total_steps=1)
    spec, _, learners = learner_loop.fresh_learners(train_args)
    config = train_args.hierarchy
    what = "a fresh learner"
  variables = learner_loop.actor_variables(learners)
  worker = rollout.RolloutWorker(spec, config, 0, 0, args.copies)
  worker.collect(variables, 0)  # Warm-up: build, compile, fill the caches.
  # pylint: disable=protected-access
  batch, actors = worker._batch, worker._actors
  # The references, apart from the measured copies: the same seeds under
  # random commands (or joint actions), and one environment under random
  # joint actions with episodes too long to end.
  commanded = rollout.EnvBatch(spec, config, worker._seeds,
                               global_state=False)
  joint = coop_suite.load(spec.task, spec.n_agents, seed=0, **{
      **dict(spec.options), "time_limit": training_throughput.LONG_EPISODE})
  joint.reset()

  def raw_envs(envs):
    return [copy.env if spec.uses_commands else copy for copy in envs]
  recorders = {
      "own": [training_throughput._Controls(env)
              for env in raw_envs(batch.envs)],
      "random commands": [training_throughput._Controls(env)
                          for env in raw_envs(commanded.envs)],
      "random joint actions": [training_throughput._Controls(joint)]}
  totals = collections.defaultdict(float)
  _time_lockstep(batch, stepping, totals)
  batch._compute_rows = _timed(batch._compute_rows, totals, "policy rows")
  for copy in batch.envs:
    copy.reset = _timed(copy.reset, totals, "episode resets")
  for actor in actors.values():
    for name in ("select_action", "observe", "take_rollout"):
      setattr(actor, name, _timed(getattr(actor, name), totals,
                                  "upper and middle layers"))
  # pylint: enable=protected-access
  substeps = joint.task.physics_steps_per_control_step
  rng = np.random.default_rng(0)

  def random_commands():
    for _ in range(config.sequence_length):
      commanded.step({s.name: rng.uniform(
          *(s.action_bounds or (-1.0, 1.0)),
          (len(commanded.rows[s.name][0]), s.action_size))
                      for s in commanded.species})

  def random_joint_actions():
    for action in rng.uniform(-1, 1, (400, joint.n_agents, 8)):
      joint.step(action)
  random_commands()  # Warm-up.
  random_joint_actions()
  out = collections.defaultdict(list)
  timed = collections.defaultdict(float)
  total = steps = episodes = checksum = 0
  for r in range(args.rounds):
    for name, block in (("own", lambda r=r: worker.collect(variables, r + 1)),
                        ("random commands", random_commands),
                        ("random joint actions", random_joint_actions)):
      for recorder in recorders[name]:
        recorder.begin()
      totals.clear()
      start = time.perf_counter()
      result = block()
      seconds = time.perf_counter() - start
      raw = sum(rec.replay_seconds(substeps) for rec in recorders[name])
      out[name].append(sum(rec.steps for rec in recorders[name]) / raw)
      if name == "own":
        for piece, value in totals.items():
          timed[piece] += value
        total += seconds
        steps += result.env_steps
        episodes += len(result.episodes)
        checksum += sum(float(np.abs(controls).sum()) for rec in recorders[name]
                        for _, _, controls in rec.segments)
        out["rollout"].append(result.env_steps / seconds)
        out["rollout / raw own"].append(raw / seconds)
  median = {k: float(np.median(v)) for k, v in out.items()}
  print(f"{spec.task} with {spec.n_agents} agents, {what}: {args.rounds} "
        f"rollouts of {args.copies} copies x {config.sequence_length} "
        f"commands, {episodes} episodes ended (medians over rounds; the "
        f"rollouts' controls sum to {checksum:.6g} in absolute value)")
  print(f"  rollout {median['rollout']:,.0f} env steps/s; raw on its own "
        f"trajectories {median['own']:,.0f} control steps/s: rollout / raw "
        f"{median['rollout / raw own']:.2f}")
  for name in ("random commands", "random joint actions"):
    print(f"  raw on {name}' trajectories {median[name]:,.0f} control "
          f"steps/s: own / that {median['own'] / median[name]:.2f}, "
          f"rollout / that {median['rollout'] / median[name]:.2f}")
  print(f"  one control step of one copy = 1.00 ({total / steps * 1e6:.0f} "
        f"us)")
  _print_shares(timed, total, _LOCKSTEP_PIECES + _ROLLOUT_PIECES,
                "rest (batch, timers)", "    ")
  commanded.close()
  joint.close()


if __name__ == "__main__":
  main()
