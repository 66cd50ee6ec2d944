"""Config fields that carry their allowed values, and the one check of them.

Every config is a frozen dataclass whose fields are CLI flags of the same
name (`runners.cli`: `learning_rate` is `--learning-rate`, nested configs
included). A field declared with `field(default, allowed)` keeps in its
metadata the values it may take, e.g. `POSITIVE`, `between(0, 1)`,
`one_of('hrl', 'flat')` or `equal(0, 'the default') | above(0)`; `check`,
called from the config's `__post_init__`, raises one ValueError naming the
flag and what it allows:

    --learning-rate must be > 0, got -0.001.

`field(..., resumable=True)` marks an argument of a run that may change when
the run is resumed (`runners.config.check_resumable`). A field of KEY=VALUE
strings (`--init-from pusher=DIR`) reads as a dict with `pairs`, whose
errors name the flag alike.
"""
import dataclasses
import math
from typing import Any, Callable, NamedTuple


class Range(NamedTuple):
  """The values a field allows: a test and how to say it."""
  test: Callable[[Any], bool]
  text: str

  def __contains__(self, value) -> bool:
    return bool(self.test(value))

  def __or__(self, other: 'Range') -> 'Range':
    return Range(lambda v: v in self or v in other,
                 f'{self.text}, or {other.text}')


def _finite(value) -> bool:
  return isinstance(value, (int, float)) and math.isfinite(value)


def at_least(low) -> Range:
  return Range(lambda v: _finite(v) and v >= low, f'>= {low}')


def above(low) -> Range:
  return Range(lambda v: _finite(v) and v > low, f'> {low}')


def between(low, high, high_text: str = '') -> Range:
  """[low, high]; with `high_text`, [low, high) written that way."""
  if high_text:
    return Range(lambda v: _finite(v) and low <= v < high,
                 f'in [{low}, {high_text})')
  return Range(lambda v: _finite(v) and low <= v <= high,
               f'in [{low}, {high}]')


def one_of(*choices) -> Range:
  return Range(lambda v: v in choices, f'one of {choices}')


def equal(value, meaning: str) -> Range:
  return Range(lambda v: v == value, f'{value} ({meaning})')


POSITIVE = above(0)
NON_NEGATIVE = at_least(0)
COUNT = at_least(1)
UNIT = between(0, 1)
SEED = between(0, 2**32, '2**32')


def field(default, allowed: Range | None = None, *, resumable: bool = False):
  """A dataclass field with its allowed values (for a tuple: of each
  element) and whether it may change when a run is resumed."""
  return dataclasses.field(
      default=default, metadata={'allowed': allowed, 'resumable': resumable})


def flag(name: str) -> str:
  """The CLI flag of field `name`: 'n_agents' -> '--n-agents'."""
  return '--' + name.replace('_', '-')


def check(config) -> None:
  """Raises ValueError naming the flag of the first field of `config` whose
  value it does not allow."""
  for f in dataclasses.fields(config):
    allowed = f.metadata.get('allowed')
    value = getattr(config, f.name)
    values = value if isinstance(value, (tuple, list)) else (value,)
    if allowed is not None and not all(v in allowed for v in values):
      shown = list(value) if isinstance(value, (tuple, list)) else value
      raise ValueError(f'{flag(f.name)} must be {allowed.text}, got '
                       f'{shown!r}.')


def pairs(items, name: str, form: str) -> dict[str, str]:
  """{KEY: VALUE} of the KEY=VALUE strings `items` of field `name` (a flag
  taking several pairs, e.g. `--init-from pusher=DIR`); ValueError naming
  the flag, with `form` (e.g. 'SPECIES=PATH pairs (e.g. pusher=runs/a)'),
  for a malformed pair or a key given twice."""
  out = {}
  for item in items:
    key, equals, value = str(item).partition('=')
    key = key.strip()
    if not equals or not key or not value:
      raise ValueError(f'{flag(name)} takes {form}, got {item!r}.')
    if key in out:
      raise ValueError(f'{flag(name)} names {key!r} twice.')
    out[key] = value
  return out
