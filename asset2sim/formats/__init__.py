"""The input and output formats besides URDF, one folder each (:mod:`asset2sim.formats.mjcf`,
:mod:`asset2sim.formats.usd`: reader, staging conventions, export, physics writer), behind one table,
:data:`FORMATS`: format name (:func:`~asset2sim.formats.staging.input_format`) -> :class:`Format`. Extraction,
validation and the declared-physics reader read through :func:`read_asset_file`; the refine's extras export
through :attr:`Format.export` and the audit patches through :attr:`Format.patch`. Adding a format is its folder, one entry here, its suffixes in
:func:`~asset2sim.formats.staging.input_format` and its tests (``DEVELOPERS.md``, "Adding an input format")."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from asset2sim.formats import staging
from asset2sim.formats.mjcf import export as mjcf_export, physics as mjcf_physics, reader as mjcf_reader
from asset2sim.formats.mjcf.conventions import ReadOptions
from asset2sim.formats.staging import ReadAsset, StagingError
from asset2sim.formats.usd import export as usd_export, physics as usd_physics, reader as usd_reader

__all__ = ["FORMATS", "Format", "ReadOptions", "read_asset_file"]


@dataclass(frozen=True)
class Format:
    """One format's entries: ``label`` its name in messages (``MJCF``); ``read(path, options) -> ReadAsset`` one file
    into the asset model; ``export(out_dir, visuals=True, check=True) -> Path`` an output folder written in the
    format (``label`` + `` export`` in notes);
    ``patch(source, read, children, links, joints, folder, staged_urdf) -> Path`` the audit's patched input;
    ``aids(path) -> list[SolverAid]`` the solver aids an exported file carries (read back from it);
    ``suffixes`` its file names' suffixes (lower case);
    ``is_model(path)`` whether a file of the format is a whole model (not an include fragment); ``declares_root``
    whether the file declares how its root is held (no free joint: welded); ``real_units`` the sentence why its
    lengths are real sizes (``{name}``: the file's name)."""

    label: str
    read: Callable[[Path, ReadOptions | None], ReadAsset]
    export: Callable[..., Path]
    patch: Callable[..., Path]
    aids: Callable[[Path], list]
    suffixes: tuple[str, ...]
    is_model: Callable[[Path], bool]
    declares_root: bool
    real_units: str


#: Format name -> its entries.
FORMATS: dict[str, Format] = {
    "mjcf": Format(label="MJCF", read=mjcf_reader.read_mjcf_asset, export=mjcf_export.export_mjcf,
                   patch=mjcf_physics.write_patched_mjcf, aids=mjcf_export.solver_aids, suffixes=staging.MJCF_SUFFIXES,
                   is_model=lambda path: staging.root_element(path) == "mujoco", declares_root=True,
                   real_units="an MJCF file ({name}: MuJoCo's lengths are metres)"),
    # a USD stage carries its own units and up axis: the read options do not apply
    # export: the path of export_usd's file (out_dir: the folder, or the folder as a refine holds it, RefinedAsset.held)
    "usd": Format(label="USD", read=lambda path, options=None: usd_reader.read_usd_asset(path),
                  export=lambda out_dir, *, visuals=True, check=True: usd_export.export_usd(
                      out_dir, visuals=visuals, check=check).path,
                  patch=usd_physics.write_patched_usd, aids=lambda path: [], suffixes=staging.USD_SUFFIXES,
                  is_model=lambda path: True, declares_root=False,
                  real_units="a USD stage ({name}, read in metres through its metersPerUnit)"),
}


def read_asset_file(source: Path | str, fmt: str, options: ReadOptions | None = None) -> ReadAsset:
    """Read the ``fmt`` file ``source`` into the asset model with its registered reader (``options``: the body
    and angle unit of an MJCF file, :class:`~asset2sim.formats.mjcf.conventions.ReadOptions`).

    Raises:
        StagingError: no reader for ``fmt`` (the message lists the formats read), or the reader's own refusal.
        ImportError: the reader's optional library (MuJoCo, usd-core) is not installed.
    """
    entry = FORMATS.get(fmt)
    if entry is None:
        raise StagingError(f"{source}: no reader for the format {fmt!r} (formats read besides URDF: {', '.join(sorted(FORMATS))})")
    return entry.read(Path(source), options)
