"""Orbax's chunk shape against an array's length: why checkpoints pad.

One packed float32 array of each length, saved with the run writer's
settings (`SaveArgs(chunk_byte_size=1 MiB)`, OCDBT data files of 2 MiB),
then restored; prints the chunk shape orbax chose and the times. 271,553 is
a ravine policy's packed length (prime), 271,552 one less, 327,680 the
prime length padded to a multiple of 2^16 (checkpoint format 5).

    python results/benchmarks/chunking_2026-11-27/chunk_shape.py
"""
import os
import tempfile
import time

import numpy as np
import orbax.checkpoint as ocp
from orbax.checkpoint._src.arrays import subchunking

MIB = 2 ** 20
for length in (271_553, 271_552, 327_680):
  chunk = subchunking.choose_chunk_shape((length,), (length,),
                                         np.dtype(np.float32), MIB)
  path = os.path.join(tempfile.mkdtemp(), 'x')
  array = np.random.default_rng(0).random(length, np.float32)
  wall, cpu = time.perf_counter(), time.process_time()
  with ocp.Checkpointer(ocp.PyTreeCheckpointHandler()) as checkpointer:
    checkpointer.save(path, args=ocp.args.PyTreeSave(
        {'a': array}, save_args={'a': ocp.SaveArgs(chunk_byte_size=MIB)},
        ocdbt_target_data_file_size=2 * MIB))
  saved = time.perf_counter() - wall, time.process_time() - cpu
  wall, cpu = time.perf_counter(), time.process_time()
  with ocp.Checkpointer(ocp.PyTreeCheckpointHandler()) as checkpointer:
    back = checkpointer.restore(path)['a']
  read = time.perf_counter() - wall, time.process_time() - cpu
  assert np.array_equal(back, array)
  print(f'{length:>8,} floats: chunk {chunk[0]:>7,} ({length // chunk[0]:,} '
        f'chunks); save {saved[0]:.2f} s ({saved[1]:.2f} s CPU), restore '
        f'{read[0]:.2f} s ({read[1]:.2f} s CPU)', flush=True)
