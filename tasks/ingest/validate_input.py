"""Input validation: everything wrong with an untrusted asset, at once, with stable codes.

:func:`validate_asset` reads an asset folder (or a URDF file) and returns a list
of :class:`Finding` (code, severity, file, line, link or joint, message,
action, values). It never raises on bad input and never writes. A
:class:`ValidationPolicy` decides each finding's severity (what is an error);
:func:`errors` picks the findings that refuse the asset. The codes and what
each checks are tabulated in ``docs/guide/validation.md`` (generated from
:data:`CODES`).

What is checked, in order (later checks run on what the earlier ones could
read; nothing stops at the first problem):

1. Files: the URDF is a regular file inside the asset folder, below the size
   cap, in UTF-8 (``URDF_*``).
2. XML: hardened parsing by :mod:`asset2sim.safexml` (``XML_*``), through
   the one URDF reader, :func:`asset2sim.urdf.parse_urdf_bytes` in mode
   ``"collect"``; every later check runs on its :class:`asset2sim.urdf.UrdfModel`.
3. Numbers: every numeric attribute the URDF format defines is parsed
   strictly (decimal literal, finite as a float64: NaN, inf, ``1e400``, empty,
   hex, ``1_0``, ``1,2`` rejected) with the right count (``NUMBER_*``).
4. Kinematic structure: unique names, joint parent and child exist, no self
   loop, no link with two parents, no cycles, no orphans, exactly one root,
   known joint types, non-zero axis, limits present on revolute/prismatic,
   lower <= upper (warning when equal), non-negative effort, velocity,
   damping and friction, at most 128 links, no ``<mimic>`` (not modelled:
   refused, never dropped), revolute limits within +-4 pi and prismatic
   travel within the object's size (``LINK_*``, ``JOINT_*``, ``TREE_*``).
5. Given inertials: mass > 0 on moving links, inertia symmetric positive
   definite with the triangle inequality of principal moments. An invalid
   one is reported with its eigenvalues and ``action="replace_with_estimate"``
   (the extraction stage drops it so the estimator replaces it); it is never
   balanced or clipped (``INERTIAL_*``, ``INERTIA_*``).
6. Mesh references: resolved real path inside the asset folder, a regular
   file with a mesh extension, below the size cap; absolute paths, ``..``
   escapes, URIs (``file://``, ``http://``, ``package://``), symlinks leaving
   the folder, NUL and control characters, directories, FIFOs, devices and
   sockets are refused, and the path must open as written. Every missing
   mesh is listed. Formats refine's simulator cannot load (PLY, OFF, GLB,
   GLTF) are refused. MTL files and textures that are FIFOs, devices or
   sockets are refused (``MESH_*``, ``MATERIAL_*``).
7. Mesh contents (OBJ by :func:`asset2sim.mesh_io.read_obj`, the reader of
   every later stage, with strict checks on top; STL by a strict reader; DAE
   via trimesh): parse errors, no faces, the face caps (1,000,000 triangles
   per asset: refine's time and memory bound), non-finite vertices, bad
   face indices, zero area. These are errors where the mesh is used for
   collision or for mass (a link's collision geometry, or its visual geometry
   when it has no collision), warnings where it is only drawn. A mesh with
   zero volume (all vertices in one plane) is ``info``; a link whose whole
   mass geometry has zero volume is a warning with
   ``action="mass_from_area"`` (PartNet-Mobility has such links, e.g. the
   single-quad door of object 8877), because a volume-based mass would be 0.
8. PartNet-Mobility extras: ``semantics.txt`` lines, ``meta.json`` (regular
   files of at most ``max_extra_bytes``: ``ASSET_FILE_NOT_REGULAR``,
   ``ASSET_FILE_TOO_LARGE``).

A URDF whose links have no ``<visual>`` or ``<collision>`` at all is refused
(``ASSET_NO_GEOMETRY``): there is nothing to size, weigh or collide.

Whatever is accepted, ``asset2sim refine`` can read without a traceback or a
hang (``docs/design/validation.md``, "Agreement with refine"). The checks live in
:mod:`~asset2sim.tasks.ingest.findings` (codes, policy, result),
:mod:`~asset2sim.tasks.ingest.urdf_checks`,
:mod:`~asset2sim.tasks.ingest.tree_checks`,
:mod:`~asset2sim.tasks.ingest.mesh_paths` and
:mod:`~asset2sim.tasks.ingest.mesh_checks`; this module runs them in order.

Units: lengths in the file's units (metres nominally), angles rad, mass kg,
inertia kg*m^2, sizes of files in bytes.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.finding_codes import CodeInfo, codes_markdown_table
from asset2sim.tasks.ingest.findings import (
    CODES,
    DEFAULT_POLICY,
    IMAGE_EXTENSIONS,
    JOINT_TYPES,
    MAX_LINKS,
    MAX_REVOLUTE_LIMIT,
    MAX_TOTAL_FACES,
    MESH_EXTENSIONS,
    MESH_USE_DEPENDENT,
    MOVABLE_TYPES,
    SEMANTIC_KINDS,
    SIMULATOR_MESH_EXTENSIONS,
    Action,
    Finding,
    MeshUse,
    Severity,
    ValidationPolicy,
    ValidationResult,
    errors,
    has_errors,
)
from asset2sim.tasks.ingest.mesh_checks import MeshChecks
from asset2sim.tasks.ingest.mesh_paths import MeshReference, inside, read_regular, resolve_mesh_reference
from asset2sim.tasks.ingest.mesh_scan import MeshScan, scan_mesh_file
from asset2sim.tasks.ingest.tree_checks import TreeChecks, check_inertia
from asset2sim.tasks.ingest.urdf_checks import UrdfChecks
from asset2sim.urdf import NumberError, parse_number_list

__all__ = [
    "Action",
    "DEFAULT_POLICY",
    "IMAGE_EXTENSIONS",
    "JOINT_TYPES",
    "MAX_LINKS",
    "MAX_REVOLUTE_LIMIT",
    "MAX_TOTAL_FACES",
    "MESH_EXTENSIONS",
    "MESH_USE_DEPENDENT",
    "MOVABLE_TYPES",
    "MeshUse",
    "SEMANTIC_KINDS",
    "SIMULATOR_MESH_EXTENSIONS",
    "Severity",
    "CODES",
    "CodeInfo",
    "Finding",
    "ValidationPolicy",
    "ValidationResult",
    "MeshReference",
    "MeshScan",
    "validate_asset",
    "run_validation",
    "errors",
    "has_errors",
    "resolve_mesh_reference",
    "scan_mesh_file",
    "check_inertia",
    "parse_number_list",
    "NumberError",
    "codes_markdown_table",
]



class _Validator(UrdfChecks, TreeChecks, MeshChecks):
    """One run: files, then the URDF checks, then meshes, then extras."""

    # -- files
    def locate(self) -> Path | None:
        asset = Path(os.path.abspath(str(self.asset)))
        try:
            st = os.stat(asset)
        except OSError:
            self.add("ASSET_NOT_FOUND", f"{asset}: no such file or folder", file=str(asset))
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
        self.folder = folder
        self.result.folder = folder
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
        sem = self.folder / partnet_mobility.SEMANTICS_NAME
        if os.path.lexists(sem):
            text = self._read_extra(sem)
            if text is not None:
                self.result.extra_files.append(sem)
                for ln in partnet_mobility.iter_semantics(text):
                    i, link, entry = ln.lineno, ln.link, ln.entry
                    if link is None or entry is None:
                        self.add("SEMANTICS_MALFORMED_LINE", f"line {i}: expected 'link_name joint_kind semantic_label', got {ln.text[:80]!r}",
                                 file="semantics.txt", line=i)
                        continue
                    self.result.semantics[link] = entry
                    if link_names and link not in link_names:
                        self.add("SEMANTICS_UNKNOWN_LINK", f"line {i}: no link {link!r} in the URDF", file="semantics.txt", line=i, link=link)
                    if entry.joint_kind not in SEMANTIC_KINDS:
                        self.add("SEMANTICS_UNKNOWN_KIND", f"line {i}: joint kind {entry.joint_kind!r} is not one of {', '.join(sorted(SEMANTIC_KINDS))}",
                                 file="semantics.txt", line=i, link=link)
        meta = self.folder / partnet_mobility.META_NAME
        if os.path.lexists(meta):
            text = self._read_extra(meta)
            if text is not None:
                self.result.extra_files.append(meta)
                try:
                    obj = json.loads(text)
                except ValueError as exc:
                    self.add("META_UNREADABLE", f"not JSON: {exc}", file="meta.json")
                    return
                if not isinstance(obj, dict):
                    self.add("META_UNREADABLE", "not a JSON object", file="meta.json")
                    return
                self.result.category = partnet_mobility.meta_category(obj)

    def _read_extra(self, path: Path) -> str | None:
        """The text of ``semantics.txt`` or ``meta.json`` (``path``), or None
        after recording why it cannot be read: ``ASSET_FILE_TOO_LARGE`` (a
        regular file above ``policy.max_extra_bytes``, never opened) or
        ``ASSET_FILE_NOT_REGULAR`` (a FIFO, device, folder, a symlink leaving
        the folder ...)."""
        assert self.folder is not None
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
            return read_regular(ref.path, self.policy.max_extra_bytes).decode("utf-8", "replace")
        except OSError as exc:
            self.add("ASSET_FILE_NOT_REGULAR", f"{path.name}: {exc}", file=path.name)
            return None

    def geometry_present(self, links: list) -> None:
        """``ASSET_NO_GEOMETRY`` when the URDF has links but none of them has
        a ``<visual>`` or ``<collision>`` element: refine takes the object's
        size (hence its scale), masses and contacts from its geometry, so
        such an asset would otherwise fail later with a misleading code
        (an overlay scale out of range, blaming the request). Links without
        geometry beside others with it are fine (PartNet-Mobility's
        ``base``)."""
        if not links or any(ln.visuals or ln.collisions for ln in links):
            return
        names = [ln.name for ln in links if ln.name]
        shown = ", ".join(repr(n) for n in names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        self.add("ASSET_NO_GEOMETRY", f"none of the {len(links)} links of {self.urdf_rel} ({shown or 'unnamed'}) has a <visual> or "
                 "<collision> element: there is no geometry to size, weigh or collide, so the asset cannot be refined "
                 "(add the meshes or primitives of its parts)", links=len(links))

    def run(self) -> ValidationResult:
        urdf = self.locate()
        if urdf is None:
            return self.result
        model = self.read(urdf)
        if model is None:
            return self.result
        moving, root = self.structure(model)
        self.geometry_present(model.link_elements)
        self.inertials(model, moving)
        self.meshes(model.link_elements)
        self.asset_size(model, root)
        self.joint_travel(model, root)
        self.extras({ln.name for ln in model.link_elements if ln.name})
        return self.result


def run_validation(asset: Path | str, policy: ValidationPolicy | None = None) -> ValidationResult:
    """Validate an asset and keep what was read (for the extraction stage).

    Args:
        asset: an asset folder (``mobility.urdf``, or the only ``*.urdf``
            not named ``reference_*``) or a URDF file (its folder is the asset
            folder).
        policy: severities and caps; default :data:`DEFAULT_POLICY`.

    Returns:
        A :class:`ValidationResult`. Never raises for bad input: an
        unexpected failure of the validator itself becomes an
        ``INTERNAL_ERROR`` finding.
    """
    v = _Validator(Path(asset), policy or DEFAULT_POLICY)
    try:
        return v.run()
    except Exception as exc:  # a bug must not crash a batch; it refuses the asset
        v.add("INTERNAL_ERROR", f"{type(exc).__name__}: {exc}")
        return v.result


def validate_asset(asset: Path | str, policy: ValidationPolicy | None = None) -> list[Finding]:
    """Every finding about an asset (folder or URDF file), in discovery order.

    Args:
        asset: as for :func:`run_validation`.
        policy: severities and caps; default :data:`DEFAULT_POLICY`.

    Returns:
        The findings; the asset is acceptable iff none has severity
        ``error`` (:func:`has_errors`). Never raises for bad input; never
        writes anything.
    """
    return run_validation(asset, policy).findings

