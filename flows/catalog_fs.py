"""Where the Parquet result catalog lives: a local folder, or a URI that
pyarrow (``s3://``, ``gs://``, ``hdfs://``: :func:`pyarrow.fs.FileSystem.from_uri`,
credentials from the usual ``AWS_*`` environment or the URI's query) or
fsspec (``memory://``, ``abfs://``, ...) opens. A write is atomic: a renamed
temporary file locally, one whole-object upload on an object store.
"""

from __future__ import annotations

import contextlib
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asset2sim import atomic

_URI_RE = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*://")


def is_uri(root: str | Path) -> bool:
    """True when ``root`` is a URI with a scheme (``s3://``, ``file://``, ...), not a plain path."""
    return isinstance(root, str) and bool(_URI_RE.match(root))


@dataclass(frozen=True)
class Location:
    """An opened catalog root: the pyarrow filesystem ``fs``, the root as a
    path inside it (``base``, no trailing slash), the root as the user wrote
    it (``uri``) and whether it is a local folder."""

    fs: Any
    base: str
    uri: str
    local: bool

    def join(self, *parts: str) -> str:
        """The filesystem path of ``parts`` under the root."""
        return "/".join([self.base.rstrip("/"), *parts]) if self.base else "/".join(parts)

    def display(self, path: str) -> str:
        """``path`` (inside the filesystem) as a user would address it: a
        local path, or the URI with the root's scheme."""
        if self.local:
            return path
        rel = path[len(self.base):].lstrip("/") if path.startswith(self.base) else path
        return self.uri.split("?", 1)[0].rstrip("/") + ("/" + rel if rel else "")


def open_location(root: str | Path) -> Location:
    """Open the catalog root ``root`` (a local path or a URI).

    Raises:
        ValueError: a URI whose scheme neither pyarrow nor fsspec can open
            (the message names the URI).
    """
    import pyarrow.fs as pafs

    uri = str(root)
    scheme = uri.split("://", 1)[0].lower() if is_uri(root) else None
    if scheme in (None, "file"):
        p = Path(uri.split("://", 1)[1] if scheme else root).expanduser().resolve()
        return Location(fs=pafs.LocalFileSystem(), base=str(p), uri=str(p), local=True)
    try:
        fs, path = pafs.FileSystem.from_uri(uri)
        return Location(fs=fs, base=path.rstrip("/"), uri=uri, local=False)
    except (ValueError, NotImplementedError, OSError) as arrow_exc:  # not one of pyarrow's own
        try:
            from fsspec.core import url_to_fs

            ffs, path = url_to_fs(uri)
        except (ImportError, ValueError, NotImplementedError) as exc:
            raise ValueError(f"catalog root {uri!r}: no filesystem for scheme {scheme!r} "
                             f"(pyarrow: {arrow_exc}; fsspec: {exc})") from exc
        fs = pafs.PyFileSystem(pafs.FSSpecHandler(ffs))
        return Location(fs=fs, base=str(path).rstrip("/"), uri=uri, local=False)


def write_bytes(loc: Location, path: str, data: bytes) -> None:
    """Write ``data`` as the file ``path`` of ``loc`` atomically, creating parent folders where the filesystem has them."""
    if loc.local:
        atomic.write_bytes(Path(path), data)
        return
    with open_output(loc, path) as fh:
        fh.write(data)


def open_output(loc: Location, path: str):
    """An output stream to file ``path`` of a store ``loc`` (not local), parent folders created where the filesystem
    has them."""
    if loc.fs.type_name not in ("s3", "gcs"):  # object stores have no folders to make (a marker object would be one more request)
        with contextlib.suppress(OSError):  # a filesystem without directories
            loc.fs.create_dir(path.rsplit("/", 1)[0], recursive=True)
    return loc.fs.open_output_stream(path)


def read_bytes(loc: Location, path: str) -> bytes | None:
    """The contents of file ``path``; None when it does not exist."""
    import pyarrow.fs as pafs

    if loc.fs.get_file_info(path).type != pafs.FileType.File:
        return None
    try:
        with loc.fs.open_input_stream(path) as fh:
            return fh.read()
    except (FileNotFoundError, OSError):
        return None


def list_files(loc: Location, path: str, recursive: bool = False) -> list[Any]:
    """:class:`pyarrow.fs.FileInfo` of the entries under folder ``path``
    (files and folders; all depths with ``recursive``); empty when it does not exist."""
    import pyarrow.fs as pafs

    try:
        return list(loc.fs.get_file_info(pafs.FileSelector(path, allow_not_found=True, recursive=recursive)))
    except FileNotFoundError:
        return []


def delete_file(loc: Location, path: str) -> bool:
    """Delete file ``path``; False when it was not there."""
    delete = os.unlink if loc.local else loc.fs.delete_file
    try:
        delete(path)
    except FileNotFoundError:
        return False
    return True
