"""The paper's tables from committed results alone: `coop-paper --report`.

Reads `--results`/<cell>/eval_n<N>.json of the plan's cells (no training,
no simulation) and `--baselines` (the difficulty references), and writes
markdown: per table, our success rate +- standard error over all models x
episodes, the spread between models (standard error of the per-model
rates), how many of the declared models are in, the paper's figure and the
greedy and oracle references beside (IPPO against MAPPO: the Ants
through an episode too); the curriculum stages' own
evaluations in a table of their own; with `--figures`, the learning
curves of the committed cells (their metrics.csv) as PNGs, linked; then
each cell's command.
"""
import json
import os
from typing import Any, Optional

from runners import baselines
from runners import evaluate
from runners import marl_eval
from runners import paper
from runners import paper_plan
from runners import run_dir

INTRODUCTION = ('The plan of docs/paper.md, regenerated from the committed '
                '`results/paper/` with `coop-paper --report --docs '
                'docs/results.md`.')
SCALING_SEEDS = 3
"""Fig. 4a's models per population."""
FIGURE_COLUMNS = ('success', 'return')
"""What the learning-curve figures show (training windows of metrics.csv)."""
THROUGH = 'crossed'
"""The corridor's Ants through the slit in an episode: the IPPO-MAPPO
table's figure beside success, which with 6 and 7 Ants is near 0 for the
learners and the references alike."""
BEGIN, END = '<!-- paper:begin -->', '<!-- paper:end -->'


def read_evaluation(cell: paper_plan.Cell, n_agents: int,
                    args: paper.PaperArgs) -> Optional[dict[str, Any]]:
  """The eval JSON of `cell` at population `n_agents`, or None."""
  return _evaluation_in(paper.results_directory(cell, args), n_agents)


def _evaluation_in(folder: str, n_agents: int) -> Optional[dict[str, Any]]:
  """The eval JSON at population `n_agents` in a cell's results `folder`,
  or None."""
  path = os.path.join(folder, paper.EVAL_FILE.format(n_agents))
  if not os.path.exists(path):
    return None
  with open(path) as f:
    return json.load(f)


def _episodes(evaluation: dict[str, Any], metric: str) -> list[float]:
  """Per-episode values of `metric` from an eval JSON's marl-eval runs."""
  return [value for _, metrics in marl_eval.models(evaluation)
          for value in metrics[metric]]


def summarize(cells, n_agents: int, args: paper.PaperArgs,
              metrics=('success', 'return')) -> dict[str, Any]:
  """Each of `metrics` over the models of `cells` evaluated at
  `n_agents`: pooled over all episodes, with the spread between models
  (`evaluate.mean_and_error`, as coop-eval does), and how many of the
  declared models are in ('models', 'declared')."""
  evaluated = [(c, e) for c, e in ((c, read_evaluation(c, n_agents, args))
                                    for c in cells) if e is not None]
  evaluations = [e for _, e in evaluated]
  out = {'models': len(evaluations), 'declared': len(cells),
         'env_steps': sorted({_model_steps(c, e, args)
                              for c, e in evaluated})}
  if not evaluations:
    return out
  for metric in metrics:
    try:
      per_model = [_episodes(e, metric) for e in evaluations]
    except KeyError:  # An evaluation without it (older files): left out.
      continue
    out[metric], out[f'{metric}_se'] = evaluate.mean_and_error(
        [v for values in per_model for v in values])
    out[f'{metric}_spread'] = evaluate.mean_and_error(
        [sum(v) / len(v) for v in per_model])[1]
  return out


def _model_steps(cell, evaluation, args) -> tuple[int, ...]:
  """A model's environment steps: its run's, then those of the stage cells
  it started from (the curriculum; -1 where a stage has no evaluation)."""
  steps = [evaluation['env_steps']]
  for _, folder in paper.stage_directories(cell, args):
    stage = _evaluation_in(folder, cell.n_agents)
    steps.append(-1 if stage is None else stage['env_steps'])
  return tuple(steps)


def _rate(value, error) -> str:
  return f'{value:.1f}% +- {error:.1f}'


def _ours(summary, metric='success') -> list[str]:
  """[figure +- SE, spread, models, env steps] cells of a table row."""
  if not summary['models']:
    return ['not run' if metric == 'success' else '', '',
            f'0/{summary["declared"]}', '']
  scale = 100 if metric == 'success' else 1
  spread = summary[f'{metric}_spread'] * scale
  # Each distinct figure once: runs end a few steps past their budget.
  steps = '/'.join(dict.fromkeys(
      ' + '.join(_steps(s) if s >= 0 else '?' for s in model)
      for model in summary['env_steps']))
  return [_rate(summary[metric] * scale, summary[f'{metric}_se'] * scale)
          if metric == 'success' else
          f'{summary[metric]:.0f} +- {summary[f"{metric}_se"]:.0f}',
          f'+- {spread:.1f}' if summary['models'] > 1 else '',
          f'{summary["models"]}/{summary["declared"]}', steps]


def _steps(count: int) -> str:
  """Environment steps as 20M, 5.12k or 16."""
  for scale, unit in ((1e6, 'M'), (1e3, 'k')):
    if count >= scale:
      return f'{count / scale:.3g}{unit}'
  return str(count)


def _reference(references, task, n_agents, policy) -> str:
  out = references.get(task, {}).get((n_agents, policy))
  return '' if out is None else baselines.success_cell(out)


def _through(summary) -> str:
  """Our models' Ants through an episode +- standard error, or '' (no
  model, or one whose evaluation lacks the figure)."""
  if THROUGH not in summary:
    return ''
  return f'{summary[THROUGH]:.2f} +- {summary[f"{THROUGH}_se"]:.2f}'


def _reference_through(references, n_agents) -> str:
  """The corridor's greedy and oracle references' Ants through an episode
  (their per-episode figures), 'greedy / oracle': '' without either
  reference, '?' for one whose episodes do not all record it."""
  def mean(out):
    episodes = out.get('per_episode', ())
    if not episodes or any(THROUGH not in e for e in episodes):
      return '?'
    return f'{evaluate.mean_and_error([e[THROUGH] for e in episodes])[0]:.2f}'
  found = [references.get('corridor', {}).get((n_agents, p))
           for p in ('greedy', 'oracle')]
  return '' if None in found else ' / '.join(mean(out) for out in found)


def _row(cells) -> str:
  return '| ' + ' | '.join(cells) + ' |'


def _header(names) -> list[str]:
  return [_row(names), '|' + '---|' * len(names)]


def _models(plan, experiment, task, agent, n_agents):
  """The joint (final) cells of one trained configuration, all seeds."""
  return [c for c in plan if (c.experiment, c.task, c.agent, c.n_agents) ==
          (experiment, task, agent, n_agents) and not c.stage]


def _scaling_models(plan) -> dict[int, list[paper_plan.Cell]]:
  """Fig. 4a's cells per training population (4 Ants: Table 1's first
  `SCALING_SEEDS` models), populations without cells left out."""
  scaling = {n: _models(plan, 'scaling', 'transport', 'hrl', n) or [
      c for c in _models(plan, 'table1', 'transport', 'hrl', n)
      if c.seed < SCALING_SEEDS] for n in paper_plan.POPULATIONS}
  return {n: cells for n, cells in scaling.items() if cells}


def figures(args: paper.PaperArgs, plan, directory: str
            ) -> list[tuple[str, str]]:
  """Draws the learning curves of the committed cells into `directory`;
  returns (caption, path) of each figure drawn (none without results).

  Table 1, per task: each variant's models; Fig. 4a: transport by training
  population; Fig. 4b, c: IPPO against MAPPO on the corridor with 6 and 7
  Ants. Each line is the mean of a configuration's models in a band of +-
  one standard error (`plot.plot_groups`); a transport model's line begins
  with its push stage.
  """
  from runners import plot  # pylint: disable=g-import-not-at-top (matplotlib)

  def curve(cell):
    """A model's run, after its stage's where it has one (transport's push
    stage: one curve over the model's steps; the ravine's two stages train
    side by side, so its joint run alone)."""
    path = paper.results_directory(cell, args)
    stages = paper.stage_directories(cell, args)
    if len(stages) == 1 and run_dir.has_metrics(stages[0][1]):
      return plot.STAGES.join([stages[0][1], path])
    return path
  done = lambda cells: [curve(c) for c in cells if paper.is_done(c, args)]
  specs = []
  for task, n in paper_plan.TABLE1_TASKS:
    specs.append((f'table1_{task}.png', f'Table 1, {task} with {n} '
                  f'{baselines.population_unit(task)}: training windows',
                  {paper_plan.VARIANT_NAMES[a]: done(_models(
                      plan, 'table1', task, a, n))
                   for a in ('hrl', 'no_memory', 'flat')}))
  specs.append(('fig4a_transport_populations.png',
                'Fig. 4a, transport by training population',
                {f'{n} Ants': done(cells)
                 for n, cells in _scaling_models(plan).items()}))
  for n in (6, 7):
    specs.append((f'fig4_corridor_n{n}.png',
                  f'Fig. 4b, c, corridor with {n} Ants: IPPO against MAPPO',
                  {name: done(_models(plan, 'mappo', 'corridor', a, n))
                   for a, name in (('hrl', 'IPPO (hrl)'),
                                   ('mappo', 'MAPPO'))}))
  drawn = []
  for name, caption, groups in specs:
    groups = {label: runs for label, runs in groups.items() if runs}
    if groups:
      path = os.path.join(directory, name)
      plot.plot_groups(groups, FIGURE_COLUMNS, path, caption)
      drawn.append((caption, path))
  starts = _starts(plan, args)
  if starts:
    caption = ('Fig. 5, transport with 4 Ants: success by start position, '
               'final checkpoints')
    path = os.path.join(directory, 'fig5_transport_starts.png')
    plot.success_by_start(starts, "the Ants' mean start distance from the "
                          'cylinder (m)', 'target distance from the '
                          'cylinder (m)', path, caption)
    drawn.append((caption, path))
  return drawn


def _starts(plan, args) -> dict[str, tuple[list, list, list]]:
  """{variant: (Ants' mean start distance, target distance, success)} over
  the evaluation episodes of Table 1's transport models that record their
  start (`start_agent_cylinder`, `start_cylinder_target`)."""
  out = {}
  for agent in ('hrl', 'no_memory', 'flat'):
    x, y, success = [], [], []
    for cell in _models(plan, 'table1', 'transport', agent, 4):
      evaluation = read_evaluation(cell, 4, args)
      if evaluation is None:
        continue
      try:
        starts = [_episodes(evaluation, 'start_agent_cylinder'),
                  _episodes(evaluation, 'start_cylinder_target')]
      except KeyError:  # Evaluated before the start was recorded.
        continue
      x += starts[0]
      y += starts[1]
      success += _episodes(evaluation, 'success')
    if x:
      out[paper_plan.VARIANT_NAMES[agent]] = (x, y, success)
  return out


def report(args: paper.PaperArgs, plan=None) -> str:
  """The markdown tables (and commands) of the plan's committed results."""
  plan = paper.selected(args, plan)
  references = (baselines.read_results(args.baselines)
                if os.path.isdir(args.baselines) else {})
  refs = lambda task, n: [_reference(references, task, n, p)  # pylint: disable=g-long-lambda
                          for p in ('greedy', 'oracle')]
  columns = ['success +- SE', 'between models', 'models', 'env steps']
  lines = [
      f'Generated by `coop-paper --report` from `{args.results}` (do not '
      'edit by hand). Success rate +- standard error over all models x '
      f'episodes ({args.episodes} episodes per model from seed '
      f'{args.eval_seed}, final checkpoints); "between models": standard '
      'error of the per-model rates; "env steps": the run\'s, + its '
      'curriculum stages\' (transport\'s push stage; the ravine\'s pushers '
      'and crossers stages); references: docs/baselines.md.', '']
  table1 = [(t, a, n) for t, n in paper_plan.TABLE1_TASKS
            for a in ('hrl', 'no_memory', 'flat')
            if _models(plan, 'table1', t, a, n)]
  if table1:
    lines += ['### Table 1: success rate, HRL against the ablations', '',
              *_header(['task', 'variant', *columns, 'paper', 'greedy',
                        'oracle'])]
    for task, agent, n in table1:
      summary = summarize(_models(plan, 'table1', task, agent, n), n, args)
      lines.append(_row([f'{task} ({n} {baselines.population_unit(task)})',
                         paper_plan.VARIANT_NAMES[agent], *_ours(summary),
                         _rate(*paper_plan.PAPER_TABLE1[(task, agent)]),
                         *refs(task, n)]))
    lines.append('')
  table2 = [(t, n) for t, n in paper_plan.TABLE1_TASKS
            if _models(plan, 'table1', t, 'hrl', n)]
  if table2:
    lines += ['### Table 2: zero-shot transfer of the HRL models', '',
              *_header(['task', 'population', *columns, 'paper', 'greedy',
                        'oracle'])]
    for task, trained in table2:
      cells = _models(plan, 'table1', task, 'hrl', trained)
      for n in paper_plan.POPULATIONS:
        note = ' (trained)' if n == trained else ''
        lines.append(_row([task, f'{n} {baselines.population_unit(task)}{note}',
                           *_ours(summarize(cells, n, args)),
                           _rate(*paper_plan.PAPER_TABLE2[task][n]),
                           *refs(task, n)]))
    lines.append('')
  lines += _curves_tables(plan, args, columns, refs, references)
  stages = {}  # (experiment, task, agent, stage, n_agents) -> its cells.
  for c in plan:
    if c.stage:
      stages.setdefault((c.experiment, c.task, c.agent, c.stage,
                         c.n_agents), []).append(c)
  stages = [(key, cells) for key, cells in stages.items()
            if any(paper.is_done(c, args) for c in cells)]
  if stages:
    lines += ['### Curriculum stages', '',
              'Each stage model on its own stage\'s task (transport\'s push '
              'stage: the task without the agent-target term; the '
              'ravine\'s pushers stage: the stone in front of the crossers\' '
              'markers; its crossers stage: no pushers, the stone across '
              'a crosser\'s path in half of the episodes, that crosser '
              'starting in front of the stone, on it or past it in 70% of '
              'those, the '
              'crossers paid for nearing the finish line and penalised '
              'for falling in: docs/tasks.md), '
              'final checkpoints. '
              'The joint runs above start from them; the paper reports no '
              'stage figures.', '',
              *_header(['task', 'variant', 'stage', 'population',
                        *columns])]
    for (_, task, agent, stage, n), cells in stages:
      population = f'{n} {baselines.population_unit(task)}'
      if (task, stage) == ('ravine', 'pushers'):  # No crossers: markers.
        pushers = paper.train_args(cells[0], args).n_pushers
        population = f'{pushers} pushers ({n} markers)'
      lines.append(_row([task, paper_plan.VARIANT_NAMES[agent], stage,
                         population, *_ours(summarize(cells, n, args))]))
    lines.append('')
  drawn = figures(args, plan, args.figures) if args.figures else []
  if drawn:
    # Links relative to the page the tables go into.
    base = os.path.dirname(os.path.abspath(args.docs)) if args.docs else '.'
    lines += ['### Learning curves', '',
              'Training success and return (windows of 100 episodes in each '
              "model's metrics.csv) against environment steps: the mean of "
              "a configuration's models in a band of +- one standard error; "
              'the legend gives how many models. A transport model\'s line '
              'begins with its push stage, whose return leaves out the '
              'agent-target term (hence its step when the joint run '
              'starts). Fig. 5: each start layout of the evaluation '
              "episodes, coloured by the share of the variant's final "
              'checkpoints that succeeded from it (the models share the '
              'starts).', '']
    for caption, path in drawn:
      lines += [f'![{caption}]({os.path.relpath(path, base)})', '']
  lines += ['### Commands', '',
            f'Each cell: `coop-paper --only <path>` runs the command below, '
            f'then `coop-eval --checkpoint {args.results}/<cell> '
            f'{paper.eval_flags(args)}` (`--n-agents N` for '
            'the zero-shot populations) on its final checkpoint.', '',
            f'<details><summary>The {len(plan)} cells\' commands</summary>',
            '', '```']
  for cell in plan:
    lines.append(f'# {cell.path} ({_plan_state(cell, args)})')
    lines.append(paper.command(cell, args))
  lines += ['```', '', '</details>', '']
  return '\n'.join(lines)


def _plan_state(cell, args) -> str:
  """'done', 'stashed at 8.04M/15M' (an unfinished run committed in
  `--partial`, which the next `coop-paper` resumes) or 'not run'."""
  if paper.is_done(cell, args):
    return 'done'
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  folder = paper.partial_directory(cell, args)
  if not checkpoints.list_checkpoints(folder):
    return 'not run'
  steps = checkpoints.read_state(checkpoints.resolve(folder))['env_steps']
  return f'stashed at {paper.progress(steps, paper.budget(cell, args))}'


def _curves_tables(plan, args, columns, refs, references) -> list[str]:
  """IPPO vs MAPPO (Fig. 4b, c) and training population (Fig. 4a): the
  paper shows curves only, so its column is a note."""
  lines = []
  mappo = [(n, a) for n in (6, 7) for a in ('hrl', 'mappo')
           if _models(plan, 'mappo', 'corridor', a, n)]
  if mappo:
    lines += ['### IPPO against MAPPO on the corridor (Fig. 4b, c)', '',
              f'Paper: {paper_plan.PAPER_FIGURE4["mappo"]}.', '',
              *_header(['Ants', 'variant', *columns, 'return +- SE',
                        'Ants through +- SE', 'greedy', 'oracle',
                        'Ants through: greedy / oracle'])]
    for n, agent in mappo:
      summary = summarize(_models(plan, 'mappo', 'corridor', agent, n), n,
                          args, metrics=('success', 'return', THROUGH))
      name = 'IPPO (`hrl`)' if agent == 'hrl' else paper_plan.VARIANT_NAMES[
          agent]
      lines.append(_row([str(n), name, *_ours(summary),
                         _ours(summary, 'return')[0], _through(summary),
                         *refs('corridor', n),
                         _reference_through(references, n)]))
    lines.append('')
  scaling = _scaling_models(plan)
  if scaling:
    lines += ['### Transport trained with 2-5 Ants (Fig. 4a)', '',
              f'Paper: {paper_plan.PAPER_FIGURE4["scaling"]}. 4 Ants: '
              f'Table 1\'s first {SCALING_SEEDS} models.', '',
              *_header(['Ants', *columns, 'return +- SE',
                        'training return (last window)', 'greedy',
                        'oracle'])]
    for n, cells in scaling.items():
      summary = summarize(cells, n, args)
      lines.append(_row([str(n), *_ours(summary),
                         _ours(summary, 'return')[0],
                         _training_return(cells, args),
                         *refs('transport', n)]))
    lines.append('')
  return lines


def _training_return(cells, args) -> str:
  """Mean over the models of the last metrics.csv row's window return."""
  values = []
  for cell in cells:
    folder = paper.results_directory(cell, args)
    if run_dir.has_metrics(folder):
      rows = [r for r in run_dir.read_metrics(folder) if 'return' in r]
      if rows:
        values.append(rows[-1]['return'])
  return f'{sum(values) / len(values):.0f}' if values else ''


def marl_eval_data(args: paper.PaperArgs, plan=None) -> dict[str, Any]:
  """Every committed evaluation of the plan in one marl-eval dict."""
  from runners import marl_eval  # pylint: disable=g-import-not-at-top
  evaluations = [read_evaluation(c, n, args) for c in paper.selected(
      args, plan) for n in c.populations]
  return marl_eval.merge(e['marl_eval'] for e in evaluations if e)


def write_block(path: str, text: str) -> None:
  """Puts `text` between the BEGIN and END markers of the markdown file
  `path` (a section with them is appended when absent), whole."""
  with open(path) as f:
    document = f.read()
  block = f'{BEGIN}\n{text.rstrip()}\n{END}'
  if BEGIN in document and END in document:
    head, _, rest = document.partition(BEGIN)
    document = head + block + rest.partition(END)[2]
  else:
    document = (document.rstrip('\n') + '\n\n## The paper\'s experiments\n\n'
                + INTRODUCTION + '\n\n' + block + '\n')
  run_dir.write_file(path, document)
