"""`coop-compare`: two models on the same episodes, paired (exact McNemar)."""
import json
import math

import pytest

from runners import compare
from runners import marl_eval


def _model(success, agent='hrl', seed=0, task='transport', n_agents=4,
           starts=None, **figures):
  episodes = []
  for i, s in enumerate(success):
    episode = {'success': float(s), 'return': 100.0 * s + i}
    if starts is not None:
      episode['start_agent_cylinder'] = starts[i]
    episode.update({k: v[i] for k, v in figures.items()})
    episodes.append(episode)
  return {'task': task, 'n_agents': n_agents, 'stage': '', 'agent': agent,
          'seed': seed, 'update': 7, 'env_steps': 700, 'episodes': episodes}


def _write(path, *models, paper=None):
  data = marl_eval.layout(models)
  if paper is not None:  # a `coop-paper` eval JSON wraps the layout
    data = dict(paper, marl_eval=data)
  path.write_text(json.dumps(data))
  return str(path)


def _binomial_p(b, c):
  """Two-sided exact binomial p at 1/2 by its definition: the probability
  of every split no more likely than the one seen."""
  n = b + c
  probs = [math.comb(n, k) / 2 ** n for k in range(n + 1)]
  return min(1.0, sum(p for p in probs if p <= probs[b] * (1 + 1e-12)))


@pytest.mark.parametrize('b,c', [(30, 18), (41, 12), (0, 5), (3, 3), (1, 0),
                                 (13, 26), (0, 0)])
def test_mcnemar_p_is_the_exact_two_sided_binomial_test(b, c):
  expected = 1.0 if b + c == 0 else _binomial_p(b, c)
  assert compare.mcnemar_p(b, c) == pytest.approx(expected, rel=1e-9)
  assert compare.mcnemar_p(b, c) == compare.mcnemar_p(c, b)


def test_mcnemar_p_known_values():
  assert compare.mcnemar_p(5, 0) == pytest.approx(0.0625)
  assert compare.mcnemar_p(30, 18) == pytest.approx(0.11140289106101878)
  with pytest.raises(ValueError):
    compare.mcnemar_p(-1, 3)


def test_counts_the_discordant_episodes(tmp_path, capsys):
  starts = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
  ref = _write(tmp_path / 'a.json', _model([1, 1, 1, 0, 0, 1], starts=starts))
  other = _write(tmp_path / 'b.json',
                 _model([1, 0, 0, 0, 1, 0], agent='flat', starts=starts),
                 _model([1, 1, 1, 0, 0, 1], agent='flat', seed=1,
                        starts=starts))
  compare.main(['--evaluations', ref, other])
  out = capsys.readouterr().out
  assert f'reference: {ref}: success 4 of 6 episodes' in out
  rows = [line.split() for line in out.splitlines()[2:]]
  # success, both, reference only, model only: 2 of 6, 1 / 3 / 1; then the
  # second model wins exactly the reference's episodes.
  assert rows[0][-7:-1] == ['2', 'of', '6', '1', '3', '1']
  assert float(rows[0][-1]) == pytest.approx(compare.mcnemar_p(3, 1),
                                             rel=1e-3)
  assert rows[1][-4:] == ['4', '0', '0', '1']
  assert 'transport_n4/flat/seed_1' in out.splitlines()[3]


def test_paired_with_compares_each_run_with_its_own_and_pools(tmp_path,
                                                              capsys):
  starts = [1.0, 2.0, 3.0, 4.0]
  # Two runs, two files each way: seed 0 played both ways, seed 1 too.
  refs = [_write(tmp_path / f'ref{s}.json',
                 _model(wins, seed=s, starts=starts))
          for s, wins in ((0, [1, 1, 1, 0]), (1, [1, 0, 0, 0]))]
  probe = _write(tmp_path / 'probe.json',
                 _model([0, 1, 0, 1], seed=1, starts=starts),
                 _model([0, 0, 1, 0], seed=0, starts=starts))
  out = compare.compare(compare.CompareArgs(evaluations=tuple(refs),
                                            paired_with=(probe,)))
  first, second = out['pairs']
  # Seed 0: 3 of 4 against 1 of 4 (both 1, reference only 2, model only 0);
  # seed 1 against its own run, not the file's first model.
  assert (first['reference'], first['reference_wins'], first['wins'],
          first['both'], first['reference_only'], first['model_only']) == (
              refs[0], 3, 1, 1, 2, 0)
  assert first['model'].endswith('[transport_n4/hrl/seed_0]')
  assert (second['reference_wins'], second['wins'], second['both'],
          second['reference_only'], second['model_only']) == (1, 2, 0, 1, 2)
  assert out['pooled'] == {
      'episodes': 8, 'reference_wins': 4, 'wins': 3, 'both': 1,
      'reference_only': 3, 'model_only': 2, 'p': compare.mcnemar_p(3, 2)}
  compare.main(['--evaluations', *refs, '--paired-with', probe])
  lines = capsys.readouterr().out.splitlines()
  assert lines[-1].split()[:6] == ['pooled', '(2', 'pairs)', '4', 'of', '8']
  # A run without its pair, a pair without its run, a run twice: errors.
  for evaluations, paired, message in (
      (refs + [_write(tmp_path / 'ref2.json', _model([1, 0, 0, 0], seed=2,
                                                      starts=starts))],
       (probe,), 'no model of transport_n4 run seed_2'),
      (refs[:1], (probe,), r'no model of --evaluations for .*seed_1'),
      (refs, (probe, probe), 'two models of transport_n4 run seed_1'),
      (refs + refs[:1], (probe,), '--evaluations: two models of transport_n4 '
                                  'run seed_0')):
    with pytest.raises(ValueError, match=message):
      compare.compare(compare.CompareArgs(evaluations=tuple(evaluations),
                                          paired_with=paired))
  # The pairs are checked as any: other starts are not the same episodes.
  moved = _write(tmp_path / 'moved.json',
                 _model([0, 0, 1, 0], seed=0, starts=[1.0, 2.0, 3.0, 9.0]))
  with pytest.raises(ValueError, match='start_agent_cylinder of episode 3'):
    compare.compare(compare.CompareArgs(evaluations=tuple(refs[:1]),
                                        paired_with=(moved,)))


def test_a_graded_figure_is_the_sign_test_over_the_untied_episodes(
    tmp_path, capsys):
  starts = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
  ref = _write(tmp_path / 'a.json',
               _model([0] * 6, starts=starts, crossed=[3, 2, 4, 0, 5, 1]))
  # Against the reference it is higher in episodes 1 and 3, lower in 0, 2
  # and 4, tied in 5.
  other = _write(tmp_path / 'b.json',
                 _model([0] * 6, agent='mappo', starts=starts,
                        crossed=[1, 3, 0, 1, 4, 1]))
  out = compare.compare(compare.CompareArgs(evaluations=(ref, other),
                                            metric='crossed'))
  assert not out['binary'] and out['reference_mean'] == pytest.approx(2.5)
  row, = out['models']
  assert (row['mean'], row['ties'], row['reference_higher'],
          row['model_higher']) == (pytest.approx(10 / 6), 1, 3, 2)
  assert row['p'] == compare.mcnemar_p(3, 2)
  compare.main(['--evaluations', ref, other, '--metric', 'crossed'])
  lines = capsys.readouterr().out.splitlines()
  assert lines[0] == f'reference: {ref}: crossed mean 2.5 over 6 episodes'
  assert lines[1].endswith('model higher  exact sign test p')
  assert lines[2].split()[-5:-1] == ['1.667', '1', '3', '2']
  # Paired runs pool their untied episodes and their means over all their
  # episodes: seed 0 (6 episodes, means 2.5 and 3) and seed 1 (2 episodes,
  # 0 / 1 in the reference, means 0.5 and 4).
  twins = (_write(tmp_path / 'c.json', _model([0] * 6, seed=0, starts=starts,
                                              crossed=[3] * 6)),
           _write(tmp_path / 'd.json', _model([0] * 2, seed=1,
                                              starts=starts[:2],
                                              crossed=[5, 3])))
  short = _write(tmp_path / 'e.json', _model([0] * 2, seed=1,
                                             starts=starts[:2],
                                             crossed=[1, 0]))
  out = compare.compare(compare.CompareArgs(
      evaluations=(ref, short), paired_with=twins, metric='crossed'))
  assert out['pooled'] == {
      'episodes': 8, 'ties': 1, 'reference_higher': 2, 'model_higher': 5,
      'reference_mean': pytest.approx((15 + 1) / 8),
      'mean': pytest.approx((18 + 8) / 8), 'p': compare.mcnemar_p(2, 5)}
  # A figure that is 0 / 1 in one model and graded in the other is graded
  # for both; `success`, 0 / 1 everywhere, stays McNemar's wins.
  assert not compare.compare(compare.CompareArgs(
      evaluations=(short, twins[1]), metric='crossed'))['binary']
  assert compare.compare(compare.CompareArgs(
      evaluations=(ref, other)))['binary']
  # Means from 1,000 up in whole numbers (returns).
  assert compare._mean(1641.72) == '1,642'  # pylint: disable=protected-access
  assert compare._mean(3.0149) == '3.015'  # pylint: disable=protected-access


def test_a_coop_paper_cell_folder_reads_its_trained_population(tmp_path):
  cell = tmp_path / 'transport_hrl_n4_s0'
  cell.mkdir()
  for n in (2, 4, 5):
    _write(cell / f'eval_n{n}.json',
           _model([1, 0, 1] if n == 4 else [0, 0, 0], n_agents=n),
           paper={'n_agents': n, 'trained_n_agents': 4})
  other = _write(tmp_path / 'b.json', _model([0, 0, 1], agent='flat'))
  out = compare.compare(compare.CompareArgs(evaluations=(str(cell), other)))
  assert out['reference'].endswith('eval_n4.json')
  assert out['reference_wins'] == 2
  assert out['models'][0]['reference_only'] == 1


def test_a_cell_folder_without_its_trained_population_is_an_error(tmp_path):
  cell = tmp_path / 'transport_hrl_n4_s0'
  cell.mkdir()
  _write(cell / 'eval_n5.json', _model([1, 0, 1], n_agents=5),
         paper={'n_agents': 5, 'trained_n_agents': 4})
  with pytest.raises(ValueError, match=r"0 of its evaluation files "
                     r"\['eval_n5.json'\] play the trained population"):
    compare.read_evaluation(str(cell))
  (cell / 'eval_n4.json').write_text('[1, 2]')
  with pytest.raises(ValueError, match='eval_n4.json: not an evaluation'):
    compare.read_evaluation(str(cell))
  (cell / 'eval_n4.json').write_text('{"n_agents": 4,')
  with pytest.raises(ValueError, match='eval_n4.json: not JSON'):
    compare.read_evaluation(str(cell))


@pytest.mark.parametrize('case,message', [
    ('episodes', 'not the same episodes'),
    ('starts', 'start_agent_cylinder of episode 1'),
    ('nan_start', 'start_agent_cylinder of episode 2 is nan'),
    ('other_starts', "records the starts ['start_stone_y'], the reference "
                     "['start_agent_cylinder']"),
    ('eval_seed', "evaluation seed 7, the reference's 1000"),
    ('task', 'evaluated on transport_n5'),
    ('nan_figure', "'return' is NaN in episode 1"),
    ('missing', "no episode figure 'reached'"),
    ('one', 'name two or more'),
])
def test_unpairable_evaluations_are_errors(tmp_path, capsys, case, message):
  starts = [1., 2., 3.]
  ref = _write(tmp_path / 'a.json', _model([1, 0, 1], starts=starts),
               paper={'eval_seed': 1000})
  other = {
      'episodes': _model([1, 0, 1, 1], starts=starts + [4.]),
      'starts': _model([1, 0, 1], starts=[1., 2.5, 3.]),
      'nan_start': _model([1, 0, 1], starts=[1., 2., float('nan')]),
      'other_starts': _model([1, 0, 1], start_stone_y=starts),
      'eval_seed': _model([1, 0, 1], starts=starts),
      'task': _model([1, 0, 1], n_agents=5, starts=starts),
      'nan_figure': _model([1, 0, 1], starts=starts,
                           **{'return': [3.0, float('nan'), 1.0]}),
      'missing': _model([1, 0, 1], starts=starts),
      'one': None,
  }[case]
  paths = [ref] if other is None else [
      ref, _write(tmp_path / 'b.json', other,
                  paper={'eval_seed': 7 if case == 'eval_seed' else 1000})]
  metric = {'nan_figure': ['--metric', 'return'],
            'missing': ['--metric', 'reached']}.get(case, [])
  with pytest.raises(SystemExit) as exit_info:
    compare.main(['--evaluations', *paths, *metric])
  assert exit_info.value.code == 2
  err = capsys.readouterr().err
  assert err.startswith('coop-compare: error:') and message in err


def test_a_file_without_starts_pairs_on_the_rest_and_says_so(tmp_path,
                                                             capsys):
  """A file written before its task recorded starts (the corridor's and
  the ravine's committed for the paper's plan) pairs with one that
  records them; the table names the pairs whose starts went unchecked."""
  starts = [1., 2., 3.]
  ref = _write(tmp_path / 'a.json', _model([1, 0, 1], starts=starts))
  old = _write(tmp_path / 'old.json', _model([1, 1, 0], agent='flat'))
  same = _write(tmp_path / 'same.json', _model([1, 0, 0], agent='mappo',
                                               starts=starts))
  out = compare.compare(compare.CompareArgs(evaluations=(ref, old, same)))
  assert [r['starts'] for r in out['models']] == [[],
                                                  ['start_agent_cylinder']]
  assert (out['models'][0]['reference_only'],
          out['models'][0]['model_only']) == (1, 1)
  compare.main(['--evaluations', ref, old, same])
  last = capsys.readouterr().out.splitlines()[-1]
  assert last.startswith('starts not checked') and last.endswith(old)
  compare.main(['--evaluations', ref, same])
  assert 'starts not checked' not in capsys.readouterr().out


def test_missing_and_broken_files_are_errors(tmp_path):
  with pytest.raises(FileNotFoundError):
    compare.load([str(tmp_path / 'none.json')])
  broken = tmp_path / 'broken.json'
  broken.write_text('{"coop_suite": {"transport_n4": {}}}')
  with pytest.raises(ValueError, match='broken.json: marl-eval layout'):
    compare.load([str(broken)])
