"""Refined outputs on object storage (``output_store``, ``asset2sim flow --out URI``), any filesystem
:func:`asset2sim.flows.catalog_fs.open_location` opens: workers refine into :func:`local_work_root` and
upload, the completion marker last (docs/design/pipeline.md, "Outputs on object storage").
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

from asset2sim import __version__
from asset2sim.flows.catalog_fs import is_uri, list_files, open_location, open_output
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
    loc = open_location(uri)
    files = sorted(p for p in local_dir.rglob("*") if p.is_file() and not p.name.endswith(".tmp"))
    files.sort(key=lambda p: p.name == MARKER_NAME and p.parent == local_dir)  # the marker last
    total = 0
    for p in files:
        dest = f"{loc.base}/{p.relative_to(local_dir).as_posix()}"
        if loc.local:
            Path(dest).parent.mkdir(parents=True, exist_ok=True)
            tmp = Path(dest + ".tmp")
            shutil.copyfile(p, tmp)
            tmp.replace(dest)
        else:
            with open(p, "rb") as src, open_output(loc, dest) as out:
                while chunk := src.read(CHUNK_BYTES):
                    out.write(chunk)
        total += p.stat().st_size
    return {"files": len(files), "bytes": total, "seconds": time.perf_counter() - t0}


def store_complete(uri: str, input_hash: str, config_hash: str) -> bool:
    """True when the store folder ``uri`` holds a completion marker for
    exactly this input, refine configuration and code version, and every
    file the marker lists is present (one listing; object writes are whole,
    and the marker is written last by :func:`upload_folder`)."""
    import pyarrow.fs as pafs

    try:
        loc = open_location(uri)
        base = loc.base
        with loc.fs.open_input_stream(f"{base}/{MARKER_NAME}") as fh:
            data = json.loads(fh.read(16 * 1024 * 1024))
        infos = list_files(loc, base, recursive=True)
    except (OSError, ValueError):
        return False
    if not isinstance(data, dict) or not isinstance(data.get("files", {}), dict):
        return False
    if data.get("input_hash") != input_hash or data.get("config_hash") != config_hash or data.get("version") != __version__:
        return False
    present = {i.path[len(base):].lstrip("/") for i in infos if i.type == pafs.FileType.File}
    return all(rel in present for rel in data.get("files", {}))
