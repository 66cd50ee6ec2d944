"""The command paradigms of the lower layer, and what each one means.

A paradigm names how the middle layer commands the lower layer (the
paper's position and velocity commands): the locomotion task a controller
of that paradigm is pretrained on and the command key it reads. This module
imports nothing heavy, so the CLIs can check `--paradigm` without starting
JAX or MuJoCo.
"""
from typing import NamedTuple


class Paradigm(NamedTuple):
  task: str
  """The locomotion task (coop_suite) its controller is pretrained on."""
  command_key: str
  """The observation key that carries the command."""


PARADIGMS = {
    'position': Paradigm('walk_to_target', 'command/target'),
    'velocity': Paradigm('walk_velocity', 'command/velocity'),
}
"""Paradigm name -> `Paradigm`."""
