"""The order a flow starts its assets in. Assets whose folders hold the same files (a dataset that asks several
requests of one object keeps a copy of its folder per request) are started apart: the first of each such group
in manifest order, then the second of each, and so on. The refine's content-addressed caches (collision pieces,
decompositions, mesh reads) then serve a group's later assets from its first one's work, where two workers
starting copies side by side would both build everything. The order changes no result (a cache never changes one)."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TypeVar

J = TypeVar("J")


def files_key(asset_dir: Path | str) -> str | None:
    """SHA-256 (hex) over the sorted (path relative to ``asset_dir``, size in bytes) of every regular file under
    it (symlinks followed; contents not read): equal for copies of a folder. None when it cannot be listed."""
    root = Path(asset_dir)
    items = []
    try:
        for dirpath, _, filenames in os.walk(root):
            for name in filenames:
                p = os.path.join(dirpath, name)
                try:
                    if os.path.isfile(p):
                        items.append(f"{os.path.relpath(p, root)}\0{os.path.getsize(p)}")
                except OSError:
                    continue
    except OSError:
        return None
    if not items:
        return None
    return hashlib.sha256("\n".join(sorted(items)).encode()).hexdigest()


def spread_same_files(jobs: Sequence[J], folder_of=lambda j: j.asset_dir, threads: int = 8) -> list[J]:
    """``jobs`` reordered so that those whose folders (``folder_of(job)``) have the same :func:`files_key` run
    apart: round ``r`` holds the ``r``-th job of every group, groups in the order of their first job. Jobs whose
    folder cannot be listed form groups of their own; with no repeated folder the order is unchanged."""
    jobs = list(jobs)
    with ThreadPoolExecutor(max_workers=max(1, min(threads, len(jobs) or 1))) as pool:
        keys = list(pool.map(lambda j: files_key(folder_of(j)), jobs))
    groups: dict[object, list[J]] = {}
    for k, (job, key) in enumerate(zip(jobs, keys)):
        groups.setdefault(key if key is not None else ("unlisted", k), []).append(job)
    rounds = max((len(g) for g in groups.values()), default=0)
    return [g[r] for r in range(rounds) for g in groups.values() if r < len(g)]
