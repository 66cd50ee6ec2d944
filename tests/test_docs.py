"""The documentation lists every observation with its true shape."""

import os
import re

import pytest

import coop_suite

_DOC = os.path.join(os.path.dirname(__file__), "..", "docs", "observations.md")


def _documented():
  """(task or None, key) -> shape string, from the doc's tables."""
  rows = {}
  for line in open(_DOC, encoding="utf-8"):
    cells = [c.strip() for c in line.strip().strip("|").split("|")]
    keys = [i for i, c in enumerate(cells) if re.fullmatch(r"`\w+/\w+`", c)]
    if not keys:
      continue
    i = keys[0]
    task = cells[i - 1].strip("`") if i > 0 else None
    rows[(task, cells[i].strip("`"))] = cells[i + 1]
  return rows


@pytest.mark.parametrize("task", sorted(coop_suite.TASKS))
def test_every_observation_is_documented_with_its_shape(task):
  documented = _documented()
  env = coop_suite.load(task, 1)
  for key, spec in env.observation_spec()[0].items():
    shape = documented.get((task, key), documented.get((None, key)))
    assert shape is not None, f"{task}: {key} is missing from {_DOC}"
    expected = {"(2k,)": "(2,)", "(k,)": "(1,)", "(g²,)": "(9,)"}.get(
        shape, shape)
    assert expected == str(spec.shape), (task, key, shape, spec.shape)
