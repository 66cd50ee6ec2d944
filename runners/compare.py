"""Compares evaluated models episode by episode: `coop-compare`.

    coop-compare --evaluations results/paper/transport_no_memory_n4_s1 \
        results/paper/transport_hrl_n4_s0 results/paper/transport_hrl_n4_s1
    coop-compare --evaluations results/paper/ravine_flat_crossers_n2_s0 \
        results/diagnostics/ravine_crossers_flat_n2_s0_sampled/eval_sampled.json

The same `coop-eval --seeds` and `--envs` start the same episodes
(`evaluate.copy_seeds`), so two models evaluated alike (every published
figure: `--seeds 1000 --envs 10`, 100 episodes) pair up episode by episode.
A pair's episodes that both models win or both lose say nothing about which
is better; those that only one wins do. The exact McNemar test asks how
likely so lopsided a split of those discordant episodes is when each one is
a fair coin's toss: p = min(1, 2 P(X <= min(b, c))), X ~ Binomial(b + c,
1/2), b and c the episodes only the one or only the other wins. It is more
sensitive than comparing two success rates with their standard errors,
because the episodes' shared difficulty cancels.

`--evaluations` takes `coop-eval --json` files, `coop-paper` eval JSONs
(`results/paper/<cell>/eval_n<N>.json`) or a cell's folder (its trained
population's file). A
file with several models (`coop-eval` with several `--checkpoint`s) gives
one model per run. The first model is the reference; every other one is
compared with it, on a 0 / 1 episode figure (`--metric`, default `success`).
The models must be of one evaluated task and population, with as many
episodes and, where the files record it, the same evaluation seed; where
the task records its starts (transport's `start_agent_cylinder`,
`start_cylinder_target`) the starts must agree episode by episode:
otherwise the pairing would be meaningless, and that is an error, not a
warning.
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
  """The 0 / 1 episode figure to compare (`success`, the ravine's
  `stone_in_place`, ...)."""


def mcnemar_p(only_a: int, only_b: int) -> float:
  """Exact two-sided McNemar p-value of `only_a` episodes won by one model
  alone against `only_b` won by the other alone (1.0 when there are none)."""
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
  `coop-paper` eval JSON), else None."""
  label: str
  task: str
  metrics: dict[str, list[float]]
  eval_seed: Optional[int] = None


def load(paths) -> list[Model]:
  """Every model in the evaluation files or folders `paths`, in order; a
  file with several models labels each with its run (`<file>
  [<task>/<algorithm>/<run>]`)."""
  models = []
  for path in paths:
    path, data = read_evaluation(path)
    try:
      runs = marl_eval.models(data)
    except ValueError as e:
      raise ValueError(f'{path}: {e}') from None
    for name, metrics in runs:
      models.append(Model(f'{path} [{name}]' if len(runs) > 1 else path,
                          name.split('/')[0], metrics, data.get('eval_seed')))
  return models


def _outcomes(model: Model, metric: str) -> list[bool]:
  """`model`'s episodes won (True) and lost on the 0 / 1 figure `metric`."""
  if metric not in model.metrics:
    raise ValueError(f'{model.label}: no episode figure {metric!r} (it has '
                     f'{sorted(model.metrics)})')
  values = model.metrics[metric]
  if any(v not in (0, 1) for v in values):
    raise ValueError(f'{model.label}: {metric!r} is not 0 / 1 per episode; '
                     'the McNemar test compares wins and losses')
  return [v == 1 for v in values]


def _check_paired(reference: Model, other: Model) -> None:
  """Raises ValueError unless `other` played the reference's episodes as
  far as the files tell: the same task and population, the same recorded
  evaluation seed, the same recorded starts."""
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
  if starts(other) != starts(reference):
    fail(f'records the starts {starts(other)}, the reference '
         f'{starts(reference)}')
  for key in starts(reference):
    pairs = zip(reference.metrics[key], other.metrics[key])
    for episode, (a, b) in enumerate(pairs):
      if not abs(a - b) <= START_TOLERANCE:  # NaN differs too
        fail(f"{key} of episode {episode} is {b:.3f}, the reference's "
             f'{a:.3f}')


def compare(args: CompareArgs) -> dict:
  """The reference model's wins and, for every other model, its wins and
  the discordant episodes with their exact McNemar p."""
  models = load(args.evaluations)
  if len(models) < 2:
    raise ValueError(f'--evaluations: {len(models)} model(s) '
                     f'{[m.label for m in models]}; name two or more')
  reference = models[0]
  ref = _outcomes(reference, args.metric)
  rows = []
  for other in models[1:]:
    wins = _outcomes(other, args.metric)
    if len(wins) != len(ref):
      raise ValueError(f'{other.label}: {len(wins)} episodes, the reference '
                       f'{len(ref)}: not the same episodes')
    _check_paired(reference, other)
    only_ref = sum(a and not b for a, b in zip(ref, wins))
    only_other = sum(b and not a for a, b in zip(ref, wins))
    rows.append({'model': other.label, 'wins': sum(wins),
                 'both': sum(a and b for a, b in zip(ref, wins)),
                 'reference_only': only_ref, 'model_only': only_other,
                 'p': mcnemar_p(only_ref, only_other)})
  return {'reference': reference.label, 'metric': args.metric,
          'episodes': len(ref), 'reference_wins': sum(ref), 'models': rows}


def table(out: dict) -> str:
  """`compare`'s result as aligned text."""
  n = out['episodes']
  head = ('model', out['metric'], 'both', 'reference only', 'model only',
          'exact McNemar p')
  lines = [(r['model'], f'{r["wins"]} of {n}', str(r['both']),
            str(r['reference_only']), str(r['model_only']), f'{r["p"]:.3g}')
           for r in out['models']]
  widths = [max(len(row[i]) for row in [head] + lines) for i in range(6)]

  def fmt(row):
    return '  '.join(c.ljust(w) if i == 0 else c.rjust(w)
                     for i, (c, w) in enumerate(zip(row, widths)))

  return '\n'.join(
      [f'reference: {out["reference"]}: {out["metric"]} '
       f'{out["reference_wins"]} of {n} episodes', fmt(head)]
      + [fmt(row) for row in lines])


def main(argv=None):
  _, out = cli.run(CompareArgs, compare, argv, 'coop-compare',
                   __doc__.splitlines()[0])
  print(table(out))


if __name__ == '__main__':
  main()
