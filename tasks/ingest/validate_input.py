"""Input validation: everything wrong with an untrusted asset, at once, with stable codes.

:func:`validate_asset` reads an asset folder (or a URDF file) and returns every :class:`Finding`
(code, severity, file, line, link or joint, message, action, values); it never raises on bad input
and never writes. A :class:`ValidationPolicy` decides each finding's severity. The checks run in
order (files, XML, numbers, kinematic tree, inertials, mesh references and contents, extras), each
on what the earlier ones could read; what each checks and why: ``docs/design/validation.md``, the
codes: ``docs/guide/validation.md`` (from :data:`CODES`). The checks live in
:mod:`~asset2sim.tasks.ingest.urdf_checks`, :mod:`~asset2sim.tasks.ingest.tree_checks` and
:mod:`~asset2sim.tasks.ingest.mesh_checks`; this module runs them.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from asset2sim.tasks.ingest import partnet_mobility

from asset2sim.formats import read_asset_file, staging
from asset2sim.tasks.ingest.findings import (CODES, DEFAULT_POLICY, MAX_LINKS, MAX_TOTAL_FACES, SEMANTIC_KINDS, Finding,
                                             ValidationPolicy, ValidationResult, has_errors)
from asset2sim.tasks.ingest.mesh_checks import MeshChecks, zero_pose_bounds
from asset2sim.tasks.ingest.mesh_paths import inside, read_regular, resolve_mesh_reference
from asset2sim.tasks.ingest.mesh_scan import scan_mesh_file
from asset2sim.tasks.ingest.tree_checks import TreeChecks, check_inertia
from asset2sim.tasks.ingest.urdf_checks import UrdfChecks
from asset2sim.inert import did_you_mean
from asset2sim.urdf import NumberError, parse_number_list

__all__ = [
    "CODES", "DEFAULT_POLICY", "MAX_LINKS", "MAX_TOTAL_FACES", "Finding", "NumberError", "ValidationPolicy", "ValidationResult",
    "check_inertia", "has_errors", "parse_number_list", "resolve_mesh_reference", "run_validation", "scan_mesh_file",
    "validate_asset",
]


def _did_you_mean(path: Path) -> str:
    """``"; did you mean NAME, ...?"`` with up to three names in ``path``'s folder close to its name
    (:func:`asset2sim.inert.did_you_mean`; the folder's first 10,000 entries), else ``""``."""
    try:
        with os.scandir(path.parent) as it:
            names = [e.name for _, e in zip(range(10_000), it)]
    except OSError:
        return ""
    return did_you_mean(path.name, names, 3)


class _Validator(UrdfChecks, TreeChecks, MeshChecks):
    """One run: files, then the URDF checks, then meshes, then extras."""

    # -- files
    def locate(self) -> Path | None:
        asset = Path(os.path.abspath(str(self.asset)))
        try:
            st = os.stat(asset)
        except OSError:
            self.add("ASSET_NOT_FOUND", "no such file or folder" + _did_you_mean(asset), file=str(asset))
            return None
        if stat.S_ISDIR(st.st_mode):
            folder = asset
            try:
                cands = partnet_mobility.urdf_candidates(folder)
            except OSError as exc:
                self.add("URDF_UNREADABLE", f"cannot list {folder}: {exc}", file=str(folder))
                return None
            if not cands:
                self.add("URDF_NOT_FOUND", f"{folder}: no mobility.urdf or other *.urdf file", file=str(folder))
                return None
            if len(cands) > 1:
                self.add("URDF_AMBIGUOUS", f"several URDF files ({', '.join(p.name for p in cands)}); pass one", file=str(folder))
                return None
            urdf = cands[0]
        else:
            urdf = asset
            folder = asset.parent
        self.folder = self.result.folder = folder
        self.urdf_rel = self.rel(urdf)
        real = os.path.realpath(urdf)
        if not inside(real, os.path.realpath(folder)):
            self.add("URDF_OUTSIDE_ASSET", f"{urdf.name} is a symlink to {real}, outside the asset folder")
            return None
        try:
            st = os.stat(real)
        except OSError as exc:
            self.add("URDF_UNREADABLE", f"cannot stat {urdf}: {exc.strerror or exc}")
            return None
        if not stat.S_ISREG(st.st_mode):
            self.add("URDF_NOT_REGULAR_FILE", f"{urdf.name} is not a regular file (directory, FIFO, device or socket)")
            return None
        self.result.urdf = urdf
        return urdf

    # -- extras
    def extras(self, link_names: set[str]) -> None:
        assert self.folder is not None
        for ln in partnet_mobility.iter_semantics(self._read_extra(partnet_mobility.SEMANTICS_NAME) or ""):
            i, link, entry = ln.lineno, ln.link, ln.entry
            if link is None or entry is None:
                self.add("SEMANTICS_MALFORMED_LINE",
                         f"line {i}: expected 'link_name joint_kind semantic_label', got {ln.text[:80]!r}",
                         file="semantics.txt", line=i)
                continue
            self.result.semantics[link] = entry
            if link_names and link not in link_names:
                self.add("SEMANTICS_UNKNOWN_LINK", f"line {i}: no link {link!r} in the URDF", file="semantics.txt", line=i,
                         link=link)
            if entry.joint_kind not in SEMANTIC_KINDS:
                self.add("SEMANTICS_UNKNOWN_KIND",
                         f"line {i}: joint kind {entry.joint_kind!r} is not one of {', '.join(sorted(SEMANTIC_KINDS))}",
                         file="semantics.txt", line=i, link=link)
        text = self._read_extra(partnet_mobility.META_NAME)
        if text is None:
            return
        try:
            obj = json.loads(text)
        except ValueError as exc:
            self.add("META_UNREADABLE", f"not JSON: {exc}", file="meta.json")
            return
        if not isinstance(obj, dict):
            self.add("META_UNREADABLE", "not a JSON object", file="meta.json")
            return
        self.result.category = partnet_mobility.meta_category(obj)

    def _read_extra(self, name: str) -> str | None:
        """The text of the folder's ``semantics.txt`` or ``meta.json`` (``name``), recorded in ``result.extra_files``;
        None when absent, or after recording why it cannot be read (``ASSET_FILE_TOO_LARGE``, never opened, or
        ``ASSET_FILE_NOT_REGULAR``)."""
        assert self.folder is not None
        path = self.folder / name
        if not os.path.lexists(path):
            return None
        cap = self.policy.max_extra_bytes
        ref = resolve_mesh_reference(self.folder, path.name, extensions=(), max_bytes=cap)
        if ref.code == "MESH_TOO_LARGE":  # a regular file, only too big to read
            self.add("ASSET_FILE_TOO_LARGE", f"{path.name} has {ref.size} bytes, above the cap of {cap} bytes for "
                     f"{partnet_mobility.SEMANTICS_NAME} and {partnet_mobility.META_NAME} (ValidationPolicy.max_extra_bytes); "
                     "it is not read", file=path.name, size=ref.size, cap=cap)
            return None
        if ref.path is None:
            self.add("ASSET_FILE_NOT_REGULAR", f"{path.name}: {ref.message}", file=path.name)
            return None
        try:
            text = read_regular(ref.path, cap).decode("utf-8", "replace")
        except OSError as exc:
            self.add("ASSET_FILE_NOT_REGULAR", f"{path.name}: {exc}", file=path.name)
            return None
        self.result.extra_files.append(path)
        return text

    def run(self) -> ValidationResult:
        urdf = self.locate()
        if urdf is None:
            return self.result
        model = self.read(urdf)
        if model is None:
            return self.result
        moving, root = self.structure(model)
        links = model.link_elements
        # links, but none with a <visual> or <collision>
        if links and not any(ln.visuals or ln.collisions for ln in links):
            names = [ln.name for ln in links if ln.name]
            shown = ", ".join(repr(n) for n in names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
            self.add("ASSET_NO_GEOMETRY", f"none of the {len(links)} links of {self.urdf_rel} ({shown or 'unnamed'}) has a "
                     "<visual> or <collision> element: there is no geometry to size, weigh or collide, so the asset cannot be "
                     "refined (add the meshes or primitives of its parts)", links=len(links))
        self.inertials(model, moving)
        self.meshes(links)
        box = zero_pose_bounds(model, root, self.mesh_bounds)
        self.asset_size(box)
        self.joint_travel(model, box)
        self.joint_range_units(model)
        self.extras({ln.name for ln in links if ln.name})
        return self.result


def run_validation(asset: Path | str, policy: ValidationPolicy | None = None) -> ValidationResult:
    """Validate an asset and keep what was read (for the extraction stage).

    Args:
        asset: an asset folder (``mobility.urdf``, or the only ``*.urdf`` not named ``reference_*``)
            or a URDF file (its folder is the asset folder), or an MJCF or USD file (or a folder holding one
            and no URDF): the files it names checked first, then the file read and staged as a URDF folder,
            which is validated (:func:`_other_format`).
        policy: severities and caps; default :data:`DEFAULT_POLICY`.

    Returns:
        A :class:`ValidationResult`. Never raises for bad input: a failure of the validator itself
        becomes an ``INTERNAL_ERROR`` finding.
    """
    v = _Validator(Path(asset), policy or DEFAULT_POLICY)
    try:
        found = staging.other_format_file(asset)
        if found is not None:
            return _other_format(v, *found)
        return v.run()
    except Exception as exc:  # a bug must not crash a batch; it refuses the asset
        v.add("INTERNAL_ERROR", f"{type(exc).__name__}: {exc}")
        return v.result


def _other_format(v: _Validator, source: Path, fmt: str) -> ValidationResult:
    """An MJCF or USD file validated: the files it names under the reader policy (``MJCF_PATH_ESCAPES``,
    ``USD_LAYER_OUTSIDE_ASSET``, ``INPUT_*``: :mod:`~asset2sim.formats.mjcf.files`,
    :func:`~asset2sim.formats.usd.stage.open_layers`), then the file read and staged as a URDF folder,
    whose validation gives the rest of the findings (``FORMAT_UNREADABLE`` when the reader refuses it)."""
    try:
        staged_asset = staging.stage(read_asset_file(source, fmt), staging.staging_folder(source))
    except staging.StagingError as exc:
        v.add(exc.code or "FORMAT_UNREADABLE", str(exc), file=str(source))
        return v.result
    except ImportError as exc:
        v.add("FORMAT_UNREADABLE", f"{source}: {exc}", file=str(source))
        return v.result
    return _Validator(staged_asset.folder, v.policy).run()


def validate_asset(asset: Path | str, policy: ValidationPolicy | None = None) -> list[Finding]:
    """Every finding about an asset (as for :func:`run_validation`), in discovery order; the asset is
    acceptable iff none has severity ``error`` (:func:`has_errors`). Never raises for bad input."""
    return run_validation(asset, policy).findings

