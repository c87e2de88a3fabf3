"""How the C allocator of a refine process treats freed memory.

A refine allocates and frees large numpy arrays all the time (surface
samples, hull point sets, rendered images, simulation buffers). glibc's
``malloc`` serves a block above its mmap threshold with a fresh ``mmap`` and
returns it with ``munmap`` when freed, and gives the top of the heap back to
the system beyond its trim threshold; every such block is then faulted in
again, page by page, by the next array. With Dask's worker setting
``MALLOC_TRIM_THRESHOLD_=65536`` (``distributed.nanny.pre-spawn-environ``,
right for a long-lived worker that should hand memory back) a stage process
forked from a worker paid 0.5-1.2 s of system time per asset for 200-400
thousand page faults.

:func:`keep_freed_memory` sets the mmap threshold to 32 MiB (glibc's own
upper bound for its dynamic threshold, ``DEFAULT_MMAP_THRESHOLD_MAX`` on
64-bit) and the trim threshold to 256 MiB, so freed arrays are reused from
the heap. Measured on the stage server (docs/design/pipeline.md, "Throughput"): a
synthetic 1-drawer cabinet's refine with extras took 2.12 s of CPU with
Dask's setting, 2.01 s with glibc's defaults and 1.76 s with these (24
thousand page faults instead of 140-200 thousand). The cost is memory held
between frees, up to the trim threshold per heap: a refine process ends with
its asset (the stage children) or its command (the CLI).

Source of the parameters: glibc ``mallopt(3)`` (``M_MMAP_THRESHOLD`` = -3,
``M_TRIM_THRESHOLD`` = -1).
"""

from __future__ import annotations

import ctypes
import ctypes.util

#: ``mallopt`` parameter numbers (glibc ``malloc.h``).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3

#: Blocks at least this large (bytes) get their own ``mmap`` (glibc's largest dynamic threshold).
MMAP_THRESHOLD = 32 * 1024 * 1024
#: Free memory at the top of the heap (bytes) kept before it is given back.
TRIM_THRESHOLD = 256 * 1024 * 1024


def keep_freed_memory() -> bool:
    """Set this process's glibc ``malloc`` to keep freed memory for reuse
    (:data:`MMAP_THRESHOLD`, :data:`TRIM_THRESHOLD`). Returns True when both
    were set; False where the C library is not glibc (nothing changed).
    Never raises."""
    try:
        name = ctypes.util.find_library("c")
        libc = ctypes.CDLL(name) if name else None
        mallopt = getattr(libc, "mallopt", None) if libc is not None else None
        if mallopt is None:
            return False
        mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        mallopt.restype = ctypes.c_int
        return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    except (OSError, AttributeError, TypeError):
        return False
