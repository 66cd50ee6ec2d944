"""Evaluations in marl-eval's JSON layout (the one BenchMARL writes).

marl-eval (instadeepai/marl-eval, README "Data Structure for Raw Experiment
data") aggregates raw results of this form:

    {env_name: {task_name: {algorithm_name: {run_name: {
        'step_<k>': {'step_count': <int>, <metric>: [one value per episode]},
        ...,
        'absolute_metrics': {<metric>: [one value per episode]}}}}}}

What we fill (`layout`): env_name `coop_suite`; task_name the evaluation
task and population, `<task>_n<N>` (ravine: N crossers; a curriculum
stage other than joint adds it, `ravine_pushers_n2`, `transport_push_n4`); algorithm_name the variant
(`hrl`, `no_memory`, `flat`, `mappo`), with how `coop-eval` played it
where that is not the protocol's (`algorithm_name`:
`hrl+reset_memory=crosser`, `flat+stochastic`,
`hrl+time_limit=60`, `hrl+stone_in_path_probability=1`); run_name `seed_<training seed>` (as
BenchMARL names runs); one logging step per model, `step_<update>` of
the evaluated checkpoint, with `step_count` its environment steps (0.05 s
control steps of one environment copy) and every numeric episode figure
(`success` 0 / 1, `return`, each `reward/<term>`, the task's progress
figures) as a list over the evaluation episodes; `absolute_metrics` repeats
that checkpoint's lists, because the protocol evaluates the final
checkpoint, declared before evaluation (marl-eval's absolute metric, the
best checkpoint evaluated on 10x the episodes, is not what we report).
"""
import json
import os
from typing import Any, Iterable

ENV_NAME = 'coop_suite'
ABSOLUTE = 'absolute_metrics'


def task_name(task: str, n_agents: int, stage: str = '') -> str:
  """`<task>_n<N>`, with a stage other than joint: `ravine_pushers_n2`."""
  stage = f'_{stage}' if stage and stage != 'joint' else ''
  return f'{task}{stage}_n{n_agents}'


def algorithm_name(model: dict[str, Any]) -> str:
  """The model's variant (`agent`), then a `+<tag>` for each way its
  evaluation left the protocol's (the final checkpoint's mean commands,
  with its own lower layer, on its training task), in this order:
  `stochastic` (sampled commands), `reset_memory=<species,...>`,
  `policy_from=<species,...>`, `controller=<folder name>` (another lower
  layer), the task's `time_limit=<s>` and `n_pushers=<N>` when given, and
  the task options by name, `<key>=<value>` (text as is, other values as
  JSON). A probe's runs thus stay apart from the protocol's in marl-eval's
  tables, while `coop-compare` still pairs them by task and run."""
  tags = ['stochastic'] if model.get('stochastic') else []
  for key in ('reset_memory', 'policy_from'):
    if model.get(key):
      tags.append(f'{key}={",".join(model[key])}')
  if model.get('controller'):
    tags.append('controller='
                + os.path.basename(os.path.normpath(model['controller'])))
  for key in ('time_limit', 'n_pushers'):
    if model.get(key):
      tags.append(f'{key}={model[key]:g}')
  options = model.get('options') or {}
  tags += [f'{key}={value}' if isinstance(value, str) else
           f'{key}={json.dumps(value, separators=(",", ":"))}'
           for key, value in sorted(options.items())]
  return '+'.join([model['agent'], *tags])


def layout(models: Iterable[dict[str, Any]]) -> dict[str, Any]:
  """The marl-eval dict of evaluated models.

  Args:
    models: one dict per model with 'task', 'n_agents', 'stage', 'agent',
      'seed' (the training seed), 'update', 'env_steps' and 'episodes'
      (one `metrics.episode_figures` dict per evaluation episode), and
      how it was played where it records it (`algorithm_name`), as
      `runners.evaluate.evaluate` returns them under 'models'.

  Returns:
    {env: {task: {algorithm: {run: {step_k, 'absolute_metrics'}}}}}; two
    models of one training seed get runs `seed_<s>` and `seed_<s>_2`.
  """
  data = {}
  for model in models:
    runs = data.setdefault(ENV_NAME, {}).setdefault(
        task_name(model['task'], model['n_agents'], model.get('stage', '')),
        {}).setdefault(algorithm_name(model), {})
    run = f'seed_{model["seed"]}'
    copy = 2
    while run in runs:
      run, copy = f'seed_{model["seed"]}_{copy}', copy + 1
    names = list(dict.fromkeys(k for e in model['episodes'] for k in e))
    metrics = {k: [float(e[k]) for e in model['episodes']] for k in names}
    runs[run] = {f'step_{model["update"]}': {
        'step_count': int(model['env_steps']), **metrics},
                 ABSOLUTE: {k: list(v) for k, v in metrics.items()}}
  return data


def merge(datas: Iterable[dict[str, Any]]) -> dict[str, Any]:
  """One marl-eval dict holding the runs of all `datas` (a run present in
  two of them is an error)."""
  merged = {}
  for data in datas:
    for env, tasks in data.items():
      for (task, algorithm, run), steps in _runs(tasks):
        runs = merged.setdefault(env, {}).setdefault(task, {}).setdefault(
            algorithm, {})
        if run in runs:
          raise ValueError(f'marl-eval: {env}/{task}/{algorithm}/{run} '
                           'twice.')
        runs[run] = steps
  return merged


def check(data: Any) -> None:
  """Raises ValueError naming the first place where `data` leaves
  marl-eval's layout (its README and `DiagnoseData`): four levels of dicts
  keyed by strings; every run a dict of logging steps, each with an int
  `step_count` and metric lists of numbers, `absolute_metrics` last and
  without `step_count`; within a run every step has the same metrics, and
  every run of an environment the same number of steps."""
  def fail(where, what):
    raise ValueError(f'marl-eval layout: {"/".join(where)}: {what}')

  def numbers(where, values):
    if not isinstance(values, list) or not values or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool)
        for v in values):
      fail(where, f'expected a non-empty list of numbers, got {values!r:.60}')

  if not isinstance(data, dict) or not data:
    fail(['.'], 'expected a non-empty dict of environments')
  for env, tasks in data.items():
    steps_per_run = set()
    for level, where, value in _levels(env, tasks):
      if not isinstance(value, dict) or not value or not all(
          isinstance(k, str) for k in value):
        fail(where, f'expected a non-empty dict keyed by {level} names')
    for (task, algorithm, run), steps in _runs(tasks):
      where = [env, task, algorithm, run]
      names = list(steps)
      if names[-1] != ABSOLUTE or names.count(ABSOLUTE) != 1:
        fail(where, f'the last entry must be {ABSOLUTE!r}, got {names}')
      if len(names) < 2:
        fail(where, 'no logging step before absolute_metrics')
      steps_per_run.add(len(names) - 1)
      metrics = None
      for step in names[:-1]:
        entry = steps[step]
        if not isinstance(entry.get('step_count'), int) or isinstance(
            entry.get('step_count'), bool):
          fail(where + [step], 'step_count must be an int')
        keys = sorted(k for k in entry if k != 'step_count')
        if metrics is not None and keys != metrics:
          fail(where + [step], f'metrics {keys} differ from {metrics}')
        metrics = keys
        for key in keys:
          numbers(where + [step, key], entry[key])
      absolute = steps[ABSOLUTE]
      if 'step_count' in absolute:
        fail(where + [ABSOLUTE], 'holds no step_count')
      for key, values in absolute.items():
        numbers(where + [ABSOLUTE, key], values)
    if len(steps_per_run) > 1:
      fail([env], f'runs have different numbers of steps: {steps_per_run}')


def models(data: dict[str, Any]) -> list[tuple[str, dict[str, list[float]]]]:
  """Each run of the marl-eval dict `data` as `(label, metrics)`, in the
  file's order: the label `<task>/<algorithm>/<run>` (`transport_n4/hrl/
  seed_0`), the metrics its `absolute_metrics` lists, one value per
  episode. `data` may also be a `coop-paper` eval JSON, which holds the
  marl-eval dict under 'marl_eval'."""
  data = data.get('marl_eval', data) if isinstance(data, dict) else data
  check(data)
  return [('/'.join(name), steps[ABSOLUTE])
          for tasks in data.values() for name, steps in _runs(tasks)]


def _levels(env, tasks):
  yield 'task', [env], tasks
  for task, algorithms in (tasks.items() if isinstance(tasks, dict) else ()):
    yield 'algorithm', [env, task], algorithms
    for algorithm, runs in (algorithms.items()
                            if isinstance(algorithms, dict) else ()):
      yield 'run', [env, task, algorithm], runs
      for run, steps in (runs.items() if isinstance(runs, dict) else ()):
        yield 'step', [env, task, algorithm, run], steps
        for step, entry in (steps.items() if isinstance(steps, dict) else ()):
          yield 'metric', [env, task, algorithm, run, step], entry


def _runs(tasks):
  for task, algorithms in tasks.items():
    for algorithm, runs in algorithms.items():
      for run, steps in runs.items():
        yield (task, algorithm, run), steps
