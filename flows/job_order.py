"""The order a flow starts its assets in.

Assets whose folders hold the same files (a dataset that asks several requests of one object keeps a copy of its
folder per request) are started apart: the first of each such group, then the second of each, and so on. The
refine's content-addressed caches (collision pieces, decompositions, mesh reads) then serve a group's later
assets from its first one's work, where two workers starting copies side by side would both build everything.

Within each round the groups start largest first, by the bytes of their geometry files: the longest-processing-
time-first rule (R. L. Graham, "Bounds on multiprocessing timing anomalies", SIAM J. Appl. Math. 17(2), 1969:
greedy list scheduling of jobs sorted by decreasing time ends within 4/3 of the optimum) with the folder's size as
the estimate of its time. A refine's cost is its collision geometry (reading, decomposing and fitting the pieces
of its meshes), and on the 21 dev objects refined cold the rank correlation of mesh bytes and refine time is
0.5-0.6 (``benchmarks/bench_flow.py --requests 1``), so the slow objects start early and the last minutes of a
run are not one worker finishing a large object while the other waits. The order changes no result (a cache never
changes one)."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TypeVar

J = TypeVar("J")

#: File suffixes that carry no geometry to refine (textures, previews): not counted in :func:`folder_listing`'s size.
NO_GEOMETRY_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tga", ".tif", ".tiff", ".gif", ".webp"})


def folder_listing(asset_dir: Path | str) -> tuple[str | None, int]:
    """(key, geometry bytes) of ``asset_dir``: the key is the SHA-256 (hex) over the sorted (path relative to
    ``asset_dir``, size in bytes) of every regular file under it (symlinks followed; contents not read), equal
    for copies of a folder, None when it cannot be listed or holds no file; the bytes are the summed size of those
    files whose suffix is not in :data:`NO_GEOMETRY_SUFFIXES`. An asset given as one file (a URDF, MJCF or USD file)
    has no key and its own size (a USD file holds its meshes; a URDF or MJCF file is counted without the meshes it
    names)."""
    root = Path(asset_dir)
    if root.is_file():  # one file (a URDF, MJCF or USD file given as the asset): its own size, no key
        try:
            return None, int(root.stat().st_size)
        except OSError:
            return None, 0
    items = []
    size = 0
    try:
        for dirpath, _, filenames in os.walk(root):
            for name in filenames:
                p = os.path.join(dirpath, name)
                try:
                    if os.path.isfile(p):
                        n = os.path.getsize(p)
                        items.append(f"{os.path.relpath(p, root)}\0{n}")
                        if os.path.splitext(name)[1].lower() not in NO_GEOMETRY_SUFFIXES:
                            size += n
                except OSError:
                    continue
    except OSError:
        return None, 0
    if not items:
        return None, 0
    return hashlib.sha256("\n".join(sorted(items)).encode()).hexdigest(), size


def start_order(jobs: Sequence[J]) -> list[J]:
    """``jobs`` in the order a flow starts them (module docstring): jobs whose folders (``job.asset_dir``) have
    the same key (:func:`folder_listing`) form a group; round ``r`` holds the ``r``-th job of every group, the groups by
    decreasing geometry bytes (:func:`folder_listing`), equal sizes in the order of their first job. Jobs without a
    key (a folder that cannot be listed: size 0; an asset given as one file: its size) form groups of their own."""
    jobs = list(jobs)
    with ThreadPoolExecutor(max_workers=max(1, min(8, len(jobs) or 1))) as pool:
        listings = list(pool.map(lambda j: folder_listing(j.asset_dir), jobs))
    groups: dict[object, list[J]] = {}
    sizes: dict[object, int] = {}
    for k, (job, (key, size)) in enumerate(zip(jobs, listings)):
        gk = key if key is not None else ("unlisted", k)
        groups.setdefault(gk, []).append(job)
        sizes.setdefault(gk, size)
    order = sorted(groups, key=lambda g: -sizes[g])  # stable: equal sizes keep the order of their first job
    rounds = max((len(g) for g in groups.values()), default=0)
    return [groups[g][r] for r in range(rounds) for g in order if r < len(groups[g])]
