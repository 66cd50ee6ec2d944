"""The lower layer: a pretrained, frozen walker controller and its wrapper.

    from agents import lowlevel
    controller = lowlevel.load('position')          # shipped weights
    action = controller(observation_dict)            # [8] in [-1, 1]
    env = lowlevel.CommandWrapper(coop_suite.load('transport', 4),
                                  controller, command_period=0.5)

paradigms.py   PARADIGMS: position / velocity, their task and command key.
controller.py  Controller (deterministic, jit-compiled); FILES, files /
               from_files, read_files / load_from.
wrapper.py     CommandWrapper: per-agent commands instead of joint actions.
weights/       trained controllers, one folder per paradigm.

Only `paradigms` is imported with the package; the rest (JAX, MuJoCo) when
first used, so a CLI can check a paradigm without starting them.
"""
import os

from agents.lowlevel.paradigms import PARADIGMS

WEIGHTS_DIR = os.path.join(os.path.dirname(__file__), 'weights')


def load(paradigm: str = 'position', directory: str = None):
  """The controller shipped for `paradigm` ('position' or 'velocity').

  Args:
    paradigm: command paradigm.
    directory: read from here instead of `weights/<paradigm>/`.
  """
  if paradigm not in PARADIGMS:
    raise ValueError(f'Unknown paradigm {paradigm!r}; expected one of '
                     f'{sorted(PARADIGMS)}.')
  from agents.lowlevel.controller import load_from  # pylint: disable=g-import-not-at-top
  controller = load_from(directory or os.path.join(WEIGHTS_DIR, paradigm))
  if controller.paradigm != paradigm:
    raise ValueError(f'{directory} holds a {controller.paradigm!r} '
                     f'controller, not {paradigm!r}.')
  return controller


def __getattr__(name):
  # Imported when first used (see the module docstring).
  if name in ('Controller', 'FILES', 'files', 'from_files', 'load_from',
              'read_files'):
    from agents.lowlevel import controller  # pylint: disable=g-import-not-at-top
    return getattr(controller, name)
  if name == 'CommandWrapper':
    from agents.lowlevel.wrapper import CommandWrapper  # pylint: disable=g-import-not-at-top
    return CommandWrapper
  raise AttributeError(name)
