"""The input readers, registered once: each input format other than URDF -> the function that reads one file
of it into the asset model (:class:`~asset2sim.tasks.ingest.staged.ReadAsset`), which
:func:`~asset2sim.tasks.ingest.staged.stage` then writes as a URDF folder. Extraction, validation and the
declared-physics reader all read through :func:`read_asset_file`; adding a format is one entry in
:data:`READERS`, its reader module, its suffixes in :func:`~asset2sim.tasks.ingest.staged.input_format` and
its tests (``DEVELOPERS.md``, "Adding an input format")."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from asset2sim.tasks.ingest import mjcf_reader, usd_reader
from asset2sim.tasks.ingest.host_conventions import ReadOptions
from asset2sim.tasks.ingest.staged import ReadAsset, StagingError


def _read_usd(path: Path, options: ReadOptions | None = None) -> ReadAsset:
    """:func:`~asset2sim.tasks.ingest.usd_reader.read_usd_asset` (a USD stage carries its own units and up
    axis: ``options`` do not apply)."""
    return usd_reader.read_usd_asset(path)


#: Format (``staged.input_format``) -> reader of one file of it: ``read(path, options) -> ReadAsset``.
READERS: dict[str, Callable[[Path, ReadOptions | None], ReadAsset]] = {
    "mjcf": mjcf_reader.read_mjcf_asset,
    "usd": _read_usd,
}


def read_asset_file(source: Path | str, fmt: str, options: ReadOptions | None = None) -> ReadAsset:
    """Read the ``fmt`` file ``source`` into the asset model with its registered reader (``options``: the body
    and angle unit of an MJCF file, :class:`~asset2sim.tasks.ingest.host_conventions.ReadOptions`).

    Raises:
        StagingError: no reader for ``fmt`` (the message lists the formats read), or the reader's own refusal.
        ImportError: the reader's optional library (MuJoCo, usd-core) is not installed.
    """
    read = READERS.get(fmt)
    if read is None:
        raise StagingError(f"{source}: no reader for the format {fmt!r} (formats read besides URDF: {', '.join(sorted(READERS))})")
    return read(Path(source), options)
