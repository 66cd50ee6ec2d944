"""MuJoCo's C functions and mjData's memory, from compiled (numba) code.

The mujoco package ships its shared library beside its bindings; loading it
into LLVM's symbol table lets compiled code call its functions by name
(`function`), which (unlike a ctypes pointer) survives numba's on-disk
cache. Pointers (arrays, mjData's fields) are passed as integers
(`POINTER`), which the C ABI passes like pointers (`ndarray.ctypes.data`),
and `pointer` turns one back into memory that compiled code reads and
writes.
"""

import glob
import os

from llvmlite import binding as llvm
import mujoco
import numba
from numba.core import cgutils
import numba.extending

POINTER = numba.types.intp
"""The argument type of a pointer."""


def _load_library():
  folder = os.path.dirname(mujoco.__file__)
  paths = sorted(glob.glob(os.path.join(folder, "libmujoco.so*"))
                 + glob.glob(os.path.join(folder, "libmujoco*.dylib"))
                 + glob.glob(os.path.join(folder, "mujoco.dll")))
  if not paths:
    raise ImportError(f"MuJoCo's shared library was not found in {folder}.")
  llvm.load_library_permanently(paths[0])


_load_library()


def function(name, signature):
  """MuJoCo's C function `name` with numba `signature`, for compiled code."""
  return numba.types.ExternalFunction(name, signature)


@numba.extending.intrinsic
def pointer(typingctx, address):  # pylint: disable=unused-argument
  """`address` (an integer) as a `void*` in compiled code, for
  `numba.carray(pointer(address), shape, dtype)`: a view of memory that a
  Python object owns (the caller keeps that object alive)."""
  def codegen(context, builder, signature, args):
    del context, signature
    return builder.inttoptr(args[0], cgutils.voidptr_t)
  return numba.types.voidptr(POINTER), codegen
