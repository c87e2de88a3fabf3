"""How the C allocator of a refine process treats freed memory.

:func:`keep_freed_memory` raises glibc's mmap and trim thresholds so freed
numpy arrays are reused from the heap instead of being unmapped and faulted
in again page by page. Parameters: glibc ``mallopt(3)``.
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
        mallopt = getattr(ctypes.CDLL(name), "mallopt", None) if name else None
        if mallopt is None:
            return False
        mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        mallopt.restype = ctypes.c_int
        return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    except (OSError, AttributeError, TypeError):
        return False
