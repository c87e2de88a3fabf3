"""Refined outputs on object storage: the output store of a flow run.

With ``output_store`` in ``catalog.yaml`` (or ``asset2sim flow --out URI``)
a run's outputs go to ``<store>/<dataset>/<run>/<asset id>/`` (and the
metrics stage's ``evaluation.json`` to ``<store>/<dataset>/<run>/_metrics/<asset id>/``)
on any filesystem pyarrow or fsspec opens (``s3://bucket/prefix``,
``gs://...``, ``memory://...``, or a plain path), the same way the result
catalog is opened (:func:`asset2sim.flows.catalog_fs.open_location`; S3
credentials and endpoint from the usual ``AWS_*`` environment or the URI's
query). Workers need no shared disk: each refines into a local temporary
folder (:func:`local_work_root`), and the publish stage uploads it.

Atomicity (upload, then manifest): every file of the folder is uploaded
first (one ``PUT`` each: a reader never sees part of an object), the
completion marker (:data:`asset2sim.output_folder.MARKER_NAME`,
which lists every file of the folder with its SHA-256) last. A folder in the
store is complete only when its marker is there and every file the marker
lists exists (:func:`store_complete`): an upload cut off by a killed worker
leaves a folder without a marker, which the skip rule never takes, and the
asset's next attempt uploads it again over the same keys.

The skip rule reads the store: a catalog row whose ``out_dir`` is a store
URI is a finished result when :func:`store_complete` holds for its input
and refine configuration (file presence from one listing, not a download:
a rerun of finished assets stays a listing per asset).
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

from asset2sim import __version__
from asset2sim.flows.catalog_fs import Location, is_uri, open_location
from asset2sim.output_folder import MARKER_NAME

#: Bytes per read when uploading (files are streamed, not held whole in memory).
CHUNK_BYTES = 8 * 1024 * 1024


def join_uri(root: str, *parts: str) -> str:
    """``root`` (a URI, possibly with a ``?query``, or a path) with ``parts``
    appended to its path; the query stays at the end."""
    base, _, query = str(root).partition("?")
    joined = "/".join([base.rstrip("/"), *[p.strip("/") for p in parts if p]])
    return joined + (f"?{query}" if query else "")


def is_store_uri(path: str | None) -> bool:
    """True when ``path`` names a folder in a remote store (a URI other than ``file://``)."""
    return bool(path) and is_uri(str(path)) and not str(path).lower().startswith("file://")


def local_work_root() -> Path:
    """The local folder under which a worker refines before uploading
    (``<system temp>/asset2sim-work``; ``TMPDIR`` moves it)."""
    return Path(tempfile.gettempdir()) / "asset2sim-work"


def _open(uri: str) -> tuple[Location, str]:
    loc = open_location(uri)
    return loc, loc.base


def upload_folder(local_dir: Path | str, uri: str) -> dict[str, float | int]:
    """Upload the folder ``local_dir`` to ``uri``: every file under it, the
    completion marker (when there is one) last.

    Returns:
        ``{"files": count, "bytes": total, "seconds": s}``.

    Raises:
        FileNotFoundError: ``local_dir`` is not a folder.
        OSError: the store refused a write (the folder stays without its marker).
    """
    t0 = time.perf_counter()
    local_dir = Path(local_dir)
    if not local_dir.is_dir():
        raise FileNotFoundError(f"{local_dir}: no folder to upload")
    loc, base = _open(uri)
    files = sorted(p for p in local_dir.rglob("*") if p.is_file() and not p.name.endswith(".tmp"))
    files.sort(key=lambda p: p.name == MARKER_NAME and p.parent == local_dir)  # the marker last
    total = 0
    for p in files:
        rel = p.relative_to(local_dir).as_posix()
        dest = f"{base}/{rel}"
        if loc.local:
            Path(dest).parent.mkdir(parents=True, exist_ok=True)
            tmp = Path(dest + ".tmp")
            shutil.copyfile(p, tmp)
            tmp.replace(dest)
        else:
            if loc.fs.type_name not in ("s3", "gcs"):
                try:
                    loc.fs.create_dir(dest.rsplit("/", 1)[0], recursive=True)
                except OSError:
                    pass
            with open(p, "rb") as src, loc.fs.open_output_stream(dest) as out:
                while chunk := src.read(CHUNK_BYTES):
                    out.write(chunk)
        total += p.stat().st_size
    return {"files": len(files), "bytes": total, "seconds": time.perf_counter() - t0}


def download_folder(uri: str, local_dir: Path | str) -> Path:
    """Download the folder ``uri`` into ``local_dir`` (created); returns it.

    Raises:
        FileNotFoundError: nothing under ``uri``.
    """
    import pyarrow.fs as pafs

    loc, base = _open(uri)
    infos = [i for i in loc.fs.get_file_info(pafs.FileSelector(base, allow_not_found=True, recursive=True))
             if i.type == pafs.FileType.File]
    if not infos:
        raise FileNotFoundError(f"{uri}: no files")
    local_dir = Path(local_dir)
    for info in infos:
        rel = info.path[len(base):].lstrip("/")
        dest = local_dir / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        with loc.fs.open_input_stream(info.path) as src, open(dest, "wb") as out:
            while chunk := src.read(CHUNK_BYTES):
                out.write(chunk)
    return local_dir


def store_complete(uri: str, input_hash: str, config_hash: str) -> bool:
    """True when the store folder ``uri`` holds a completion marker for
    exactly this input, refine configuration and code version, and every
    file the marker lists is present (one listing; object writes are whole,
    and the marker is written last by :func:`upload_folder`)."""
    import pyarrow.fs as pafs

    try:
        loc, base = _open(uri)
        with loc.fs.open_input_stream(f"{base}/{MARKER_NAME}") as fh:
            data = json.loads(fh.read(16 * 1024 * 1024))
        infos = loc.fs.get_file_info(pafs.FileSelector(base, allow_not_found=True, recursive=True))
    except (OSError, ValueError):
        return False
    if not isinstance(data, dict) or not isinstance(data.get("files", {}), dict):
        return False
    if data.get("input_hash") != input_hash or data.get("config_hash") != config_hash or data.get("version") != __version__:
        return False
    present = {i.path[len(base):].lstrip("/") for i in infos if i.type == pafs.FileType.File}
    return all(rel in present for rel in data.get("files", {}))


def remove_local(path: Path | str) -> None:
    """Delete a worker's local folder after its upload (missing is fine)."""
    shutil.rmtree(path, ignore_errors=True)
