"""Frozen dataclass of arguments -> argparse CLI (CleanRL style, no tyro).

Each field becomes `--field-name` with its default, and the string literal
written under the field (its attribute docstring) becomes the help text.
Booleans take `--flag` / `--no-flag`; tuples take several values.
"""
import argparse
import ast
import dataclasses
import inspect
import os
import sys
import textwrap
import typing


def field_docs(cls) -> dict[str, str]:
  """Attribute docstrings of a dataclass: {field name: docstring}."""
  docs = {}
  for klass in reversed(cls.__mro__):
    try:
      source = textwrap.dedent(inspect.getsource(klass))
    except (OSError, TypeError):
      continue
    body = ast.parse(source).body
    if not body or not isinstance(body[0], ast.ClassDef):
      continue
    statements = body[0].body
    for node, after in zip(statements, statements[1:]):
      if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
          and isinstance(after, ast.Expr)
          and isinstance(after.value, ast.Constant)
          and isinstance(after.value.value, str)):
        docs[node.target.id] = ' '.join(after.value.value.split())
  return docs


def parse(cls, argv=None, description=None):
  """Parses `argv` into an instance of the dataclass `cls`."""
  parser = argparse.ArgumentParser(
      description=description,
      formatter_class=argparse.ArgumentDefaultsHelpFormatter)
  docs = field_docs(cls)
  hints = typing.get_type_hints(cls)
  for field in dataclasses.fields(cls):
    flag = '--' + field.name.replace('_', '-')
    kind = hints[field.name]
    help_text = docs.get(field.name, ' ')
    if kind is bool:
      parser.add_argument(flag, action=argparse.BooleanOptionalAction,
                          default=field.default, help=help_text)
    elif typing.get_origin(kind) is tuple:
      element = typing.get_args(kind)[0]
      parser.add_argument(flag, type=element, nargs='+',
                          default=field.default, help=help_text)
    else:
      parser.add_argument(flag, type=kind, default=field.default,
                          help=help_text)
  values = vars(parser.parse_args(argv))
  values = {k: tuple(v) if isinstance(v, list) else v
            for k, v in values.items()}
  try:
    return cls(**values)
  except (ValueError, TypeError) as e:
    parser.error(str(e))  # Usage and one line naming the flag; exit 2.


def command_line(instance, prog: str, skip=()) -> str:
  """The inverse of `parse`: `prog` with the flags of the fields of the
  dataclass `instance` that differ from their defaults (`skip` names fields
  left out), e.g. 'coop-train --task ravine --n-agents 2'."""
  words = [prog]
  for field in dataclasses.fields(instance):
    value = getattr(instance, field.name)
    if field.name in skip or value == field.default:
      continue
    flag = '--' + field.name.replace('_', '-')
    if isinstance(value, bool):
      words.append(flag if value else '--no-' + flag[2:])
    elif isinstance(value, tuple):
      words += [flag, *map(str, value)]
    else:
      words += [flag, str(value)]
  return ' '.join(words)


def user_errors():
  """Exceptions that are the user's to fix (a flag, a path, a busy or
  damaged run directory, a Ray cluster it cannot join): a CLI prints them
  as one line."""
  from runners import actor_pool  # pylint: disable=g-import-not-at-top
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  from runners import run_dir  # pylint: disable=g-import-not-at-top
  return (ValueError, FileExistsError, FileNotFoundError,
          run_dir.RunInUseError, checkpoints.CorruptCheckpoint,
          actor_pool.ClusterUnreachable)


def fail(prog: str, error: Exception):
  """Exits with status 2 and one line, or re-raises with the traceback
  when COOP_TRACEBACK is set (e.g. to report a bug)."""
  if os.environ.get('COOP_TRACEBACK'):
    raise error
  print(f'{prog}: error: {error}', file=sys.stderr, flush=True)
  sys.exit(2)
