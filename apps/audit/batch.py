"""Many assets to audit: the assets a set of paths holds (one asset, a folder of many, or a package's whole asset
tree) and one asset audited into its own folder, a failure recorded in its row instead of raised."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

from asset2sim import file_names
from asset2sim.schemas.audit import AuditRow
from asset2sim.schemas.config import RefineConfig
from asset2sim.apps.audit.audit import AuditError, audit_asset
from asset2sim.formats import FORMATS, staging

__all__ = ["AuditTarget", "audit_one", "find_assets"]


@dataclass(frozen=True)
class AuditTarget:
    """One asset to audit: ``asset_id`` (unique in the run) and ``path`` (a URDF folder or file, an MJCF or USD file)."""

    asset_id: str
    path: Path


def _is_asset(path: Path) -> bool:
    """A path that is one asset by itself: a file, a folder with a URDF, or a folder holding one MJCF or USD file."""
    return path.is_file() or any(path.glob("*.urdf")) or staging.other_format_file(path) is not None


def _model_files(folder: Path) -> list[Path]:
    """The MJCF and USD files directly in ``folder``; MJCF files whose root element is not ``<mujoco>`` (include
    fragments such as ``<mujocoinclude>``) are parts of other files, not assets."""
    return [f for f in sorted(folder.iterdir())
            if f.is_file() and f.suffix.lower() in (*staging.MJCF_SUFFIXES, *staging.USD_SUFFIXES)
            and (fmt := FORMATS.get(staging.input_format(f))) is not None and fmt.is_model(f)]


def find_assets(paths: list[Path | str]) -> list[AuditTarget]:
    """The assets ``paths`` hold, in a stable order.

    A path that is one asset (:func:`_is_asset`) is one target, named after the folder or the file's stem. Any
    other folder is walked (sorted, symlinked folders not followed): a folder with a ``*.urdf`` is one URDF asset
    (not walked further); every MJCF file with a ``<mujoco>`` root (:func:`_model_files`) or USD file is one asset, named after its folder when it is the only one
    there, else after its stem; names are the path below the given folder, ``/`` written ``__``.

    Raises:
        FileNotFoundError: a path does not exist.
    """
    out: list[AuditTarget] = []
    for given in paths:
        root = Path(given)
        if not root.exists():
            raise FileNotFoundError(f"{root}: no such file or folder")
        if _is_asset(root):
            out.append(AuditTarget(root.stem if root.is_file() else root.resolve().name, root))
            continue
        for folder, dirs, _ in os.walk(root):
            here = Path(folder)
            dirs.sort()
            if here != root and any(here.glob("*.urdf")):
                out.append(AuditTarget(_name(here.relative_to(root)), here))
                dirs.clear()
                continue
            models = _model_files(here)
            for f in models:
                rel = f.relative_to(root)
                name = rel.parent if len(models) == 1 and here != root else rel.with_suffix("")
                out.append(AuditTarget(_name(name), f))
    seen: dict[str, int] = {}
    unique = []
    for t in out:  # the same name from two given paths: numbered
        n = seen.get(t.asset_id, 0)
        seen[t.asset_id] = n + 1
        unique.append(t if n == 0 else AuditTarget(f"{t.asset_id}_{n}", t.path))
    return unique


def _name(rel: Path) -> str:
    return "__".join(rel.parts) or "asset"


def audit_one(target: AuditTarget, out_root: Path | str | None, *, category: str | None = None, simulate: bool = True,
              config: RefineConfig | None = None) -> AuditRow:
    """Audit ``target`` into ``out_root/<asset_id>`` (a safe folder name; None: nothing written), with ``config``
    (:func:`~asset2sim.apps.audit.audit.audit_asset`). Never raises for a bad asset, nor for a patch that cannot be
    written: the row's ``failure_mode`` is ``audit_failed`` and ``error`` says why."""
    start = time.perf_counter()
    out = None if out_root is None else file_names.join_inside(out_root, file_names.file_stem(target.asset_id))
    try:
        result = audit_asset(target.path, out, category=category, asset_id=target.asset_id, simulate=simulate, config=config)
    except Exception as exc:  # noqa: BLE001 - a failed asset never stops a batch; its row says why
        error = str(exc) if isinstance(exc, AuditError) else f"{target.path}: {type(exc).__name__}: {exc}"
        return AuditRow(asset_id=target.asset_id, source=str(target.path), failure_mode="audit_failed", error=error,
                        seconds=time.perf_counter() - start)
    return AuditRow.of(result.report, None if out is None else str(out), time.perf_counter() - start)
