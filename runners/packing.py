"""A learner's saved state packed into one flat array per dtype.

`runners.checkpoints` writes each species' saved state (`Learner.save()`:
a nested dict of host arrays, ~127 of them for a hierarchy learner) packed,
because orbax's cost is Python per array written (metadata, TensorStore
specs): ~0.5 ms an array, so a ravine checkpoint of two learners costs
~120-140 ms of CPU as orbax's own tree and ~30-35 ms packed
(docs/performance.md, "Checkpoints packed"). The layout that unpacks it is
JSON (it goes into the checkpoint's state item): one [path, dtype name,
shape] per array in packing order, [path, '{}', None] for an empty dict and
[path, 'None', None] for None (what format-3 checkpoints hold for an array
without elements, `agents.checkpointing.from_state_dict` puts it back).
"""
from typing import Any, Mapping

import numpy as np

Layout = list[list[Any]]
_EMPTY, _NONE = '{}', 'None'  # The layout's names for {} and None.


def pack(state_dict: Mapping[str, Any]
         ) -> tuple[dict[str, np.ndarray], Layout]:
  """({dtype name: 1-D array}, layout) of a saved state dict. A dtype whose
  arrays have no elements at all gets no array (orbax stores none).

  Raises:
    ValueError: a leaf is neither an array of numbers nor None.
  """
  from flax import traverse_util  # pylint: disable=g-import-not-at-top
  flat = traverse_util.flatten_dict(dict(state_dict), keep_empty_nodes=True)
  parts, layout = {}, []
  for path, leaf in flat.items():
    if leaf is traverse_util.empty_node or leaf is None:
      layout.append([list(path), _EMPTY if leaf is not None else _NONE, None])
      continue
    leaf = np.asarray(leaf)
    if leaf.dtype.kind in 'OSUa':
      raise ValueError(f'Cannot pack {"/".join(map(str, path))}: '
                       f'{type(flat[path]).__name__} is not an array of '
                       'numbers.')
    parts.setdefault(leaf.dtype.name, []).append(leaf.reshape(-1))
    layout.append([list(path), leaf.dtype.name, list(leaf.shape)])
  arrays = {dtype: np.concatenate(p) for dtype, p in parts.items()}
  return {dtype: a for dtype, a in arrays.items() if a.size}, layout


Padding = tuple[int, int]
"""(multiple, above) of `pad`."""


def pad(arrays: Mapping[str, np.ndarray], padding: Padding
        ) -> dict[str, np.ndarray]:
  """`arrays` (`pack`'s) with each one of more than `above` bytes
  zero-padded to a multiple of `multiple` elements, `padding` = (multiple,
  above); `unpack` with the same `padding` takes them back."""
  return {dtype: np.pad(a, (0, _padded_size(a.size, a.itemsize, padding)
                            - a.size))
          for dtype, a in arrays.items()}


def _padded_size(size: int, itemsize: int, padding: Padding) -> int:
  multiple, above = padding
  return size + (-size % multiple) if size * itemsize > above else size


def unpack(arrays: Mapping[str, np.ndarray], layout: Layout,
           padding: Padding = (1, 0)) -> dict[str, Any]:
  """The saved state dict that `pack` packed into `arrays` with `layout`
  (and `pad` padded with `padding`); its arrays are views of `arrays`.

  Raises:
    ValueError: `arrays` and `layout` do not match, or either is malformed.
  """
  from flax import traverse_util  # pylint: disable=g-import-not-at-top
  try:
    flat, used = {}, {}
    for path, dtype, shape in layout:
      if dtype in (_EMPTY, _NONE):
        flat[tuple(path)] = (traverse_util.empty_node if dtype == _EMPTY
                             else None)
        continue
      packed = arrays.get(dtype)
      if packed is None:
        packed = np.zeros(0, dtype)
      start = used.get(dtype, 0)
      used[dtype] = start + int(np.prod(shape, dtype=np.int64))
      if (np.ndim(packed) != 1 or np.dtype(packed.dtype) != dtype
          or used[dtype] > np.size(packed)):
        raise ValueError(f'no {dtype} values for {path}')
      flat[tuple(path)] = packed[start:used[dtype]].reshape(shape)
    extra = [d for d, a in arrays.items()
             if not _only_padding(a, used.get(d, 0), padding)]
    if extra:
      raise ValueError(f'{extra} values that the layout does not place')
    return traverse_util.unflatten_dict(flat)
  except (AttributeError, IndexError, KeyError, TypeError, ValueError) as e:
    raise ValueError(f'the packed arrays do not match their layout ({e})'
                     ) from None


def _only_padding(packed: np.ndarray, used: int, padding: Padding) -> bool:
  """Whether a 1-D `packed` holds `used` values and then exactly the zeros
  that `pad` adds to as many."""
  size = _padded_size(used, np.dtype(packed.dtype).itemsize, padding)
  return (np.ndim(packed) == 1 and np.size(packed) == size
          and not np.any(packed[used:]))
