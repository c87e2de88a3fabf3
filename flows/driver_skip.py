"""Skip decisions in the driver, before any worker starts, from a per-dataset *input index* in the catalog
(``dataset=<name>/_inputs.json``: per asset its folder's :func:`input_fingerprint` and what the input stage
found); any miss hands the asset to the workers. docs/design/pipeline.md, "Skips decided by the driver"."""

from __future__ import annotations

import hashlib
import json
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from asset2sim.flows import catalog_fs
from asset2sim.flows.catalog import ResultCatalog
from asset2sim.tasks.publish.contract import code_hash
from asset2sim.flows.job_records import Prepared
from asset2sim.flows.stages import reusable, worker_name

#: The input index of a dataset, beside its run partitions (not a partition:
#: the catalog's readers list only ``run=`` folders).
INDEX_NAME = "_inputs.json"
INDEX_VERSION = 1


@dataclass
class InputEntry:
    """What the input stage found for the asset folder with ``fingerprint``
    (``job_category``: the manifest's category then) and the ``code_hash`` of
    the code that read it."""

    fingerprint: str
    input_hash: str
    job_category: str | None
    category: str | None
    links: int | None
    movable_joints: int | None
    code_hash: str


def input_fingerprint(asset_dir: Path | str) -> str | None:
    """Fingerprint of an asset folder: SHA-256 (hex) over the sorted
    (resolved path, size in bytes, modification time in ns) of every regular
    file under it (symlinks followed; contents not read). None when the
    folder cannot be listed."""
    root = Path(asset_dir)
    items = []
    try:
        if not root.is_dir():
            return None
        for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
            dirnames.sort()
            for name in filenames:
                p = os.path.join(dirpath, name)
                try:
                    st = os.stat(p)  # follows a symlink: its target's size and time
                except OSError:
                    continue
                if not os.path.isfile(p):
                    continue
                items.append(f"{os.path.realpath(p)}\0{st.st_size}\0{st.st_mtime_ns}")
    except OSError:
        return None
    return hashlib.sha256((str(root.resolve()) + "".join("\n" + it for it in sorted(items))).encode()).hexdigest()


def _index_path(store: ResultCatalog, dataset: str) -> str:
    return store.location.join(f"dataset={dataset}", INDEX_NAME)


def read_index(store: ResultCatalog, dataset: str) -> dict[str, InputEntry]:
    """The dataset's input index, asset id -> entry; empty when absent,
    unreadable or of another version."""
    try:
        data = catalog_fs.read_bytes(store.location, _index_path(store, dataset))
        doc = json.loads(data) if data else {}
    except (OSError, ValueError):
        return {}
    if not isinstance(doc, dict) or doc.get("version") != INDEX_VERSION or not isinstance(doc.get("assets"), dict):
        return {}
    out = {}
    for aid, e in doc["assets"].items():
        try:
            out[str(aid)] = InputEntry(**e)
        except TypeError:
            continue
    return out


def write_index(store: ResultCatalog, dataset: str, entries: dict[str, InputEntry]) -> None:
    """Merge ``entries`` into the dataset's input index (written atomically).

    Raises:
        OSError: the catalog's filesystem refused the write.
    """
    if not entries:
        return
    merged = read_index(store, dataset)
    merged.update(entries)
    doc = {"version": INDEX_VERSION, "assets": {k: asdict(v) for k, v in sorted(merged.items())}}
    catalog_fs.write_bytes(store.location, _index_path(store, dataset), json.dumps(doc, separators=(",", ":")).encode())


def entry_for(job: Any, prepared: Prepared, fingerprint: str | None) -> InputEntry | None:
    """The index entry to record for ``job`` (an ``AssetJob``) after its input
    stage: None when the asset was not read or its folder had no fingerprint."""
    if fingerprint is None or not prepared.ok or not prepared.input_hash:
        return None
    return InputEntry(
        fingerprint=fingerprint,
        input_hash=prepared.input_hash,
        job_category=job.category,
        category=prepared.category,
        links=prepared.links,
        movable_joints=prepared.movable_joints,
        code_hash=code_hash(),
    )


def decide_skips(
    jobs: list[Any],
    index: dict[str, InputEntry],
    fingerprints: dict[str, str | None],
) -> dict[str, Prepared]:
    """The jobs the driver can skip: asset id -> the prepared record (with
    ``skip`` the earlier catalog row) the input stage would have returned.

    Args:
        jobs: ``AssetJob`` s of the run (``finished``: their earlier rows).
        index: :func:`read_index`; fingerprints: asset id -> :func:`input_fingerprint`.
    The skip rule: :func:`asset2sim.flows.stages.reusable`.
    """
    code = code_hash()
    todo = [j for j in jobs if j.finished and j.asset_id in index]
    if not todo:
        return {}

    def decide(job: Any) -> Prepared | None:
        t0, entry, fingerprint = time.perf_counter(), index[job.asset_id], fingerprints.get(job.asset_id)
        if (fingerprint is None or entry.fingerprint != fingerprint or entry.code_hash != code
                or entry.job_category != job.category):
            return None
        rec = reusable(Prepared(worker=f"{worker_name()} (driver)", category=entry.category,
                                links=entry.links, movable_joints=entry.movable_joints), job, entry.input_hash)
        if rec.skip is None:
            return None
        rec.seconds = time.perf_counter() - t0
        return rec

    with ThreadPoolExecutor(max_workers=min(8, len(todo))) as pool:
        return {job.asset_id: p for job, p in zip(todo, pool.map(decide, todo)) if p is not None}


def fingerprints(jobs: list[Any]) -> dict[str, str | None]:
    """:func:`input_fingerprint` of every job's asset folder (asset id -> fingerprint)."""
    if not jobs:
        return {}
    with ThreadPoolExecutor(max_workers=min(8, len(jobs))) as pool:
        return dict(zip((j.asset_id for j in jobs), pool.map(lambda j: input_fingerprint(j.asset_dir), jobs)))
