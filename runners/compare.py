"""Compares evaluated models episode by episode: `coop-compare`.

    coop-compare --evaluations results/paper/transport_no_memory_n4_s1 \
        results/paper/transport_hrl_n4_s0 results/paper/transport_hrl_n4_s1
    coop-compare --evaluations results/paper/ravine_flat_crossers_n2_s0 \
        results/diagnostics/ravine_crossers_flat_n2_s0_sampled/eval_sampled.json
    coop-compare --evaluations results/paper/transport_hrl_n4_s{0,1,2,3,4} \
        --paired-with results/diagnostics/transport_hrl_n4_reset_memory/eval_reset_memory.json

The same `coop-eval --seeds` and `--envs` start the same episodes
(`evaluate.copy_seeds`), so two models evaluated alike (every published
figure: `--seeds 1000 --envs 10`, 100 episodes) pair up episode by episode.
A pair's episodes that both models win or both lose say nothing about which
is better; those that only one wins do. The exact McNemar test asks how
likely so lopsided a split of those discordant episodes is when each one is
a fair coin's toss: p = min(1, 2 P(X <= min(b, c))), X ~ Binomial(b + c,
1/2), b and c the episodes only the one or only the other wins. It is more
sensitive than comparing two success rates with their standard errors,
because the episodes' shared difficulty cancels. On a graded figure
(`--metric crossed`, the corridor's Ants through an episode; `return`)
the same test counts the episodes where each model scores higher and
leaves the ties out: the exact sign test, of which McNemar's is the 0 / 1
case.

`--evaluations` takes `coop-eval --json` files, `coop-paper` eval JSONs
(`results/paper/<cell>/eval_n<N>.json`), a cell's folder (its trained
population's file) or a difficulty reference played on coop-eval's
episodes (`python -m runners.baselines --envs 10 --json ...`). A
file with several models (`coop-eval` with several `--checkpoint`s) gives
one model per run. The first model is the reference; every other one is
compared with it, on an episode figure (`--metric`, default `success`):
0 / 1 figures print the wins, graded ones the means.
With `--paired-with`, each model is instead compared with the model of the
same evaluated task and run (`seed_<s>`) in those files, e.g. five trained
models against the same five played otherwise, and a last row pools the
pairs: their discordant episodes summed, one McNemar test over them all.
The models must be of one evaluated task and population, with as many
episodes and, where the files record it, the same evaluation seed; where
the task records its starts (transport's `start_agent_cylinder`,
`start_cylinder_target`, the corridor's `start_heading_error`, the
ravine's `start_stone_y`, `start_crossers_edge`) the starts must agree
episode by episode: otherwise the pairing would be meaningless, and that
is an error, not a warning. A file written before its task recorded
starts (the corridor's and the ravine's committed for the paper's plan)
has none: its pairs are checked on the rest alone, and the table says so
under its rows.
"""
import dataclasses
import glob
import json
import os
from typing import NamedTuple, Optional

from runners import cli
from runners import marl_eval

START_PREFIX = 'start_'
"""Episode figures that record an episode's start (equal for paired
episodes whatever the policy)."""
START_TOLERANCE = 1e-6


@dataclasses.dataclass(frozen=True)
class CompareArgs:
  """What to compare (every field is a `coop-compare` flag)."""

  evaluations: tuple[str, ...] = ()
  """Evaluation JSONs (`coop-eval --json`, `coop-paper`'s eval_n<N>.json)
  or `coop-paper` cell folders; the first model is the reference."""
  metric: str = 'success'
  """The episode figure to compare: 0 / 1 (`success`, the ravine's
  `stone_in_place`, ...: exact McNemar) or graded (the corridor's
  `crossed`, `return`, ...: the exact sign test on the episodes where one
  model scores higher)."""
  paired_with: tuple[str, ...] = ()
  """Evaluations of the same runs played otherwise (`coop-eval
  --reset-memory`, `--stochastic`, another variant's seeds): each model of
  `--evaluations` is compared with the one of the same evaluated task and
  run here (`seed_<s>`), not with a single reference, and a last row pools
  the pairs (their discordant episodes summed)."""


def mcnemar_p(only_a: int, only_b: int) -> float:
  """Exact two-sided McNemar p-value of `only_a` episodes won by one model
  alone against `only_b` won by the other alone (1.0 when there are none);
  with episodes where one model scores higher than the other, the exact
  sign test."""
  if only_a < 0 or only_b < 0:
    raise ValueError(f'discordant counts must be >= 0, got {only_a}, '
                     f'{only_b}')
  n = only_a + only_b
  term = tail = 1  # C(n, 0), then C(n, k) for k up to min(only_a, only_b)
  for k in range(1, min(only_a, only_b) + 1):
    term = term * (n - k + 1) // k
    tail += term
  return min(1.0, 2 * tail / 2 ** n)


def _read(path: str) -> dict:
  """The JSON object in the file `path`; anything else is an error that
  names the file."""
  with open(path) as f:
    try:
      data = json.load(f)
    except json.JSONDecodeError as e:
      raise ValueError(f'{path}: not JSON ({e})') from None
  if not isinstance(data, dict):
    raise ValueError(f'{path}: not an evaluation (a JSON object), got a '
                     f'{type(data).__name__}')
  return data


def _trained_population(data: dict) -> bool:
  """Whether an evaluation plays its model's training population (a
  `coop-paper` eval JSON says so; a file that does not say passes)."""
  n, trained = data.get('n_agents'), data.get('trained_n_agents')
  return n is None or trained is None or n == trained


def read_evaluation(path: str) -> tuple[str, dict]:
  """(file, its JSON) of the evaluation `path`: the file itself, or the
  eval_n<N>.json of a `coop-paper` cell folder `path` at the population it
  was trained with (its zero-shot ones are named by file)."""
  if not os.path.isdir(path):
    if not os.path.exists(path):
      raise FileNotFoundError(f'no evaluation at {path}')
    return path, _read(path)
  from runners import paper  # pylint: disable=g-import-not-at-top
  candidates = sorted(glob.glob(os.path.join(path,
                                             paper.EVAL_FILE.format('*'))))
  found = [(f, data) for f, data in ((f, _read(f)) for f in candidates)
           if _trained_population(data)]
  if len(found) != 1:
    names = [os.path.basename(f) for f in candidates]
    raise ValueError(f'{path}: {len(found)} of its evaluation files '
                     f'{names} play the trained population; name the file')
  return found[0]


class Model(NamedTuple):
  """One evaluated model: `label` names it, `task` is the evaluated task
  and population (`transport_n4`), `metrics` its per-episode figures,
  `eval_seed` the evaluation's first seed where the file records it (a
  `coop-paper` eval JSON), else None; `run` its marl-eval run
  (`seed_<s>`)."""
  label: str
  task: str
  metrics: dict[str, list[float]]
  eval_seed: Optional[int] = None
  run: str = ''


def load(paths) -> list[Model]:
  """Every model in the evaluation files or folders `paths`, in order; a
  file with several models labels each with its run (`<file>
  [<task>/<algorithm>/<run>]`)."""
  models = []
  from runners import baselines  # pylint: disable=g-import-not-at-top
  for path in paths:
    path, data = read_evaluation(path)
    if 'policy' in data and 'per_episode' in data:  # A difficulty reference.
      task, metrics = baselines.paired_figures(data, path)
      models.append(Model(path, task, metrics, data['eval_seed'],
                          data['policy']))
      continue
    try:
      runs = marl_eval.models(data)
    except ValueError as e:
      raise ValueError(f'{path}: {e}') from None
    for name, metrics in runs:
      models.append(Model(f'{path} [{name}]' if len(runs) > 1 else path,
                          name.split('/')[0], metrics, data.get('eval_seed'),
                          name.split('/')[-1]))
  return models


def _figures(model: Model, metric: str) -> list[float]:
  """`model`'s figure `metric`, one per episode (NaN is an error: the test
  needs every episode's)."""
  if metric not in model.metrics:
    raise ValueError(f'{model.label}: no episode figure {metric!r} (it has '
                     f'{sorted(model.metrics)})')
  values = model.metrics[metric]
  for episode, v in enumerate(values):
    if v != v:  # pylint: disable=comparison-with-itself
      raise ValueError(f'{model.label}: {metric!r} is NaN in episode '
                       f'{episode}; the paired test needs every episode\'s')
  return values


def _binary(models: list[Model], metric: str) -> bool:
  """Whether `metric` is 0 / 1 in every episode of every one of `models`
  (wins and losses: McNemar), else graded (the sign test). Decided by the
  figures, not by the figure's name: Ants through that never exceed 1 read
  as wins, with the same p (the sign test on 0 / 1 figures is McNemar's)."""
  return all(v in (0, 1) for m in models for v in _figures(m, metric))


def _check_paired(reference: Model, other: Model) -> list[str]:
  """Raises ValueError unless `other` played the reference's episodes as
  far as the files tell: the same task and population, the same recorded
  evaluation seed, the same recorded starts. Returns the start figures
  checked: none where a file records none (it predates its task's)."""
  def fail(why, hint=' (evaluate both with the same --seeds and --envs)'):
    raise ValueError(f'{other.label}: {why}: not the same episodes{hint}')

  def starts(model):
    return sorted(k for k in model.metrics if k.startswith(START_PREFIX))

  if other.task != reference.task:
    fail(f'evaluated on {other.task}, the reference on {reference.task}',
         hint='')
  if None not in (reference.eval_seed, other.eval_seed) and (
      other.eval_seed != reference.eval_seed):
    fail(f'evaluation seed {other.eval_seed}, the reference\'s '
         f'{reference.eval_seed}')
  checked, theirs = starts(reference), starts(other)
  if not (checked and theirs):
    return []  # One file predates its task's starts: nothing to check.
  if theirs != checked:
    fail(f'records the starts {theirs}, the reference {checked}')
  for key in checked:
    pairs = zip(reference.metrics[key], other.metrics[key])
    for episode, (a, b) in enumerate(pairs):
      if not abs(a - b) <= START_TOLERANCE:  # NaN differs too
        fail(f"{key} of episode {episode} is {b:.3f}, the reference's "
             f'{a:.3f}')
  return checked


BINARY_COUNTS = ('reference_wins', 'wins', 'both', 'reference_only',
                 'model_only')
"""A 0 / 1 figure's counts (summed when pairs are pooled); the last two
are the discordant ones."""
GRADED_COUNTS = ('ties', 'reference_higher', 'model_higher')
"""A graded figure's counts; the last two are the discordant ones."""


def _pair(reference: Model, other: Model, metric: str, binary: bool) -> dict:
  """`other` against `reference` on `metric`, episode by episode. 0 / 1
  (`binary`): the reference's wins, its wins, the episodes both win, those
  only one wins and their exact McNemar p. Graded: both means, the ties,
  the episodes where each scores higher and their exact sign test p."""
  ref, figures = _figures(reference, metric), _figures(other, metric)
  if len(figures) != len(ref):
    raise ValueError(f'{other.label}: {len(figures)} episodes, the '
                     f'reference {len(ref)}: not the same episodes')
  starts = _check_paired(reference, other)
  # The discordant episodes: on a 0 / 1 figure those only one model wins.
  higher_ref = sum(a > b for a, b in zip(ref, figures))
  higher_other = sum(b > a for a, b in zip(ref, figures))
  pair = {'episodes': len(ref), 'model': other.label,
          'p': mcnemar_p(higher_ref, higher_other), 'starts': starts}
  if binary:
    return {**pair, 'reference_wins': int(sum(ref)), 'wins': int(sum(figures)),
            'both': sum(a == b == 1 for a, b in zip(ref, figures)),
            'reference_only': higher_ref, 'model_only': higher_other}
  return {**pair, 'reference_mean': sum(ref) / len(ref),
          'mean': sum(figures) / len(figures),
          'ties': len(ref) - higher_ref - higher_other,
          'reference_higher': higher_ref, 'model_higher': higher_other}


def _pool(rows: list[dict], binary: bool) -> dict:
  """`rows`' counts summed (graded: their means over all their episodes)
  and the exact test of the summed discordant episodes."""
  episodes = sum(r['episodes'] for r in rows)
  counts = BINARY_COUNTS if binary else GRADED_COUNTS
  pooled = {'episodes': episodes,
            **{k: sum(r[k] for r in rows) for k in counts}}
  if not binary:
    for k in ('reference_mean', 'mean'):
      pooled[k] = sum(r[k] * r['episodes'] for r in rows) / episodes
  return {**pooled, 'p': mcnemar_p(*(pooled[k] for k in counts[-2:]))}


def _by_run(models: list[Model], flag: str) -> dict[tuple[str, str], Model]:
  """`models` by (evaluated task, run), in order; two models of one run
  in `flag`'s files are an error (which would it pair with?)."""
  runs = {}
  for model in models:
    key = (model.task, model.run)
    if key in runs:
      raise ValueError(f'{flag}: two models of {model.task} run {model.run} '
                       f'({runs[key].label}, {model.label})')
    runs[key] = model
  return runs


def compare(args: CompareArgs) -> dict:
  """The reference model's wins (graded `--metric`: its mean) and, for
  every other model, `_pair`'s row against it (with `--paired-with`:
  `compare_paired`)."""
  if args.paired_with:
    return compare_paired(args)
  models = load(args.evaluations)
  if len(models) < 2:
    raise ValueError(f'--evaluations: {len(models)} model(s) '
                     f'{[m.label for m in models]}; name two or more')
  reference = models[0]
  binary = _binary(models, args.metric)
  rows = [_pair(reference, other, args.metric, binary)
          for other in models[1:]]
  summary = 'reference_wins' if binary else 'reference_mean'
  return {'reference': reference.label, 'metric': args.metric,
          'binary': binary, 'episodes': rows[0]['episodes'],
          summary: rows[0][summary], 'models': rows}


def compare_paired(args: CompareArgs) -> dict:
  """Each model of `--evaluations` against its run in `--paired-with`
  (rows as `compare`'s, with the row's own 'reference'), and under
  'pooled' the rows' counts summed with the
  exact test of the summed discordant episodes (`_pool`)."""
  references = _by_run(load(args.evaluations), '--evaluations')
  others = _by_run(load(args.paired_with), '--paired-with')
  binary = _binary([*references.values(), *others.values()], args.metric)
  rows = []
  for key, reference in references.items():
    other = others.pop(key, None)
    if other is None:
      raise ValueError(f'--paired-with: no model of {reference.task} run '
                       f'{reference.run} to pair with {reference.label}')
    rows.append({'reference': reference.label,
                 **_pair(reference, other, args.metric, binary)})
  if others:
    raise ValueError('--paired-with: no model of --evaluations for '
                     f'{sorted(m.label for m in others.values())}')
  return {'metric': args.metric, 'binary': binary, 'pairs': rows,
          'pooled': _pool(rows, binary)}


def _aligned(rows: list[tuple[str, ...]], left: int) -> list[str]:
  """`rows` of cells as lines, the first `left` columns left-aligned and
  the others right-aligned to their widest cell."""
  widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
  return ['  '.join(c.ljust(w) if i < left else c.rjust(w)
                    for i, (c, w) in enumerate(zip(row, widths)))
          for row in rows]


def _mean(value: float) -> str:
  """A graded figure's mean: 4 significant digits, whole numbers from
  1,000 (returns)."""
  return f'{value:,.0f}' if abs(value) >= 1000 else f'{value:.4g}'


def table(out: dict) -> str:
  """`compare`'s result as aligned text."""
  metric, binary = out['metric'], out['binary']
  if binary:
    counts = ('both', 'reference only', 'model only', 'exact McNemar p')
    keys = ('both', 'reference_only', 'model_only')
  else:
    counts = ('ties', 'reference higher', 'model higher',
              'exact sign test p')
    keys = GRADED_COUNTS
    metric = f'{metric} mean'

  def tail(r):
    return (*(str(r[k]) for k in keys), f'{r["p"]:.3g}')

  def score(r, prefix=''):
    if binary:
      return f'{r[prefix + "wins"]} of {r["episodes"]}'
    return _mean(r[prefix + 'mean'])

  unchecked = [r['model'] for r in out.get('pairs', out.get('models'))
               if not r['starts']]
  note = [f'starts not checked (not recorded in both files: paired on the '
          f'task, the recorded seed and the episode count alone): '
          f'{", ".join(unchecked)}'] if unchecked else []
  if 'pairs' in out:
    pooled = out['pooled']
    return '\n'.join([f'pairs: each model of --evaluations (reference) '
                      f'against its run in --paired-with (model), {metric}']
                     + _aligned(
        [('reference', 'model', metric, metric, *counts)]
        + [(r['reference'], r['model'], score(r, 'reference_'), score(r),
            *tail(r)) for r in out['pairs']]
        + [(f'pooled ({len(out["pairs"])} pairs)', '',
            score(pooled, 'reference_'), score(pooled), *tail(pooled))],
        left=2) + note)
  n = out['episodes']
  reference = (f'{out["reference_wins"]} of {n} episodes' if binary else
               f'{_mean(out["reference_mean"])} over {n} episodes')
  return '\n'.join(
      [f'reference: {out["reference"]}: {metric} {reference}']
      + _aligned([('model', metric, *counts)]
                 + [(r['model'], score(r), *tail(r))
                    for r in out['models']], left=1) + note)


def main(argv=None):
  _, out = cli.run(CompareArgs, compare, argv, 'coop-compare',
                   __doc__.splitlines()[0])
  print(table(out))


if __name__ == '__main__':
  main()
