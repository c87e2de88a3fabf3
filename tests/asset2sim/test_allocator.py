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
    # what Dask's nanny gives its workers; numpy's huge-page advice off, so the
    # count does not depend on whether the kernel had huge pages free
    env = {**os.environ, "MALLOC_TRIM_THRESHOLD_": "65536", "NUMPY_MADVISE_HUGEPAGE": "0"}
    out = subprocess.run([sys.executable, "-c", _LOOP, mode], env=env, capture_output=True, text=True, check=True)
    applied, faults = out.stdout.split()
    return applied, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc settings")
def test_freed_arrays_are_reused_instead_of_faulted_in_again():
    _, plain = _faults("plain")
    applied, kept = _faults("keep")
    assert applied == "True"
    # each 8 MiB array mapped afresh faults in at least once per allocation, page by
    # page (81,960 faults here; 4 per array where the kernel backs it with 2 MiB pages)
    assert plain >= 40
    assert kept < 40  # reused from the heap: fewer faults than allocations (none here)
    assert kept < plain
