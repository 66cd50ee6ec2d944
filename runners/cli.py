"""Frozen dataclass of arguments <-> command line, with tyro (CleanRL style).

Each field becomes `--field-name` with its default, and the string literal
written under the field (its attribute docstring) becomes the help text.
Booleans take `--flag` / `--no-flag`; tuples take several values. A nested
dataclass (`TrainArgs.hierarchy`) adds its fields as flags of their own
names, without a prefix, so names must be unique across the nesting. A
value its field does not allow (`agents.fields`) is one line naming the
flag, exit status 2.
"""
import contextlib
import dataclasses
import os
import sys

import tyro

from agents import fields


class _Rejected(Exception):
  """A value that a config's `__post_init__` refused, to report as one line."""


def _reject(event):
  # tyro boxes a constructor's ValueError; this CLI says it in one line.
  if type(event).__name__ == 'InstantiationFailure':
    raise _Rejected(event.message)


def parse(cls, argv=None, description=None, prog=None):
  """Parses `argv` (default: sys.argv[1:]) into an instance of the
  dataclass `cls`; --help lists every flag with its docstring and default."""
  prog = prog or os.path.basename(sys.argv[0])
  # tyro's parse-error hook is private: without it, errors come in its box.
  hook = getattr(getattr(tyro, '_errors', None), 'on_parse_error', None)
  try:
    with hook(_reject) if hook else contextlib.nullcontext():
      return tyro.cli(cls, args=argv, prog=prog, description=description,
                      config=(tyro.conf.OmitArgPrefixes,))
  except _Rejected as e:
    fail(prog, e)


def run(cls, work, argv=None, prog=None, description=None):
  """The body of every CLI's `main`: parses `argv` into the dataclass `cls`
  and returns `(args, work(args))`; a user's error (`user_errors`) in either
  is one line naming `prog` (default: the command's own name), exit 2."""
  prog = prog or os.path.basename(sys.argv[0])
  args = parse(cls, argv, description=description, prog=prog)
  try:
    return args, work(args)
  except user_errors() as e:
    fail(prog, e)


def _flags(instance, skip):
  for field in dataclasses.fields(instance):
    value = getattr(instance, field.name)
    if dataclasses.is_dataclass(value):
      yield from _flags(value, skip)
      continue
    if field.name in skip or value == field.default:
      continue
    flag = fields.flag(field.name)
    if isinstance(value, bool):
      yield flag if value else '--no-' + flag[2:]
    elif isinstance(value, tuple):
      yield ' '.join([flag, *map(str, value)])
    else:
      yield f'{flag} {value}'


def command_line(instance, prog: str, skip=()) -> str:
  """The inverse of `parse`: `prog` with the flags of the fields of the
  dataclass `instance` (nested ones included) that differ from their
  defaults (`skip` names fields left out), e.g.
  'coop-train --task ravine --n-agents 2 --agent mappo'."""
  return ' '.join([prog, *_flags(instance, skip)])


def user_errors():
  """Exceptions that are the user's to fix (a flag, a path, a busy or
  damaged run directory, a Ray cluster it cannot join, a local Ray that a
  busy machine kept from starting): a CLI prints them as one line."""
  from runners import actor_pool  # pylint: disable=g-import-not-at-top
  from runners import checkpoints  # pylint: disable=g-import-not-at-top
  from runners import run_dir  # pylint: disable=g-import-not-at-top
  return (ValueError, FileExistsError, FileNotFoundError,
          run_dir.RunInUseError, checkpoints.CorruptCheckpoint,
          actor_pool.ClusterUnreachable, actor_pool.LocalRayTimeout)


def fail(prog: str, error: Exception):
  """Exits with status 2 and one line, or re-raises with the traceback
  when COOP_TRACEBACK is set (e.g. to report a bug)."""
  if os.environ.get('COOP_TRACEBACK'):
    raise error
  print(f'{prog}: error: {error}', file=sys.stderr, flush=True)
  sys.exit(2)
