"""The stage processes and the CLI keep freed memory for reuse: a numpy
array allocated and freed again is not faulted in page by page each time."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

_LOOP = """
import resource, sys
import numpy as np
from asset2sim import allocator
applied = allocator.keep_freed_memory() if sys.argv[1] == "keep" else None
np.ones(1 << 20)  # 8 MiB once before counting
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(40):
    a = np.ones(1 << 20)  # 8 MiB, written: every page touched
    del a
print(applied, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> tuple[str, int]:
    env = {**os.environ, "MALLOC_TRIM_THRESHOLD_": "65536"}  # what Dask's nanny gives its workers
    out = subprocess.run([sys.executable, "-c", _LOOP, mode], env=env, capture_output=True, text=True, check=True)
    applied, faults = out.stdout.split()
    return applied, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc settings")
def test_freed_arrays_are_reused_instead_of_faulted_in_again():
    _, plain = _faults("plain")
    applied, kept = _faults("keep")
    assert applied == "True"
    pages = (8 << 20) // os.sysconf("SC_PAGE_SIZE")
    assert plain > 40 * 100  # each 8 MiB array mapped afresh and faulted in again (20,640 faults here)
    assert kept < pages // 4  # reused from the heap (none here)
