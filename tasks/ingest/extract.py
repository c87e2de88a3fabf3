"""Extraction stage: an asset folder (or URDF file) in, an :class:`AssetDescription` out.

Validation runs first (:mod:`asset2sim.tasks.ingest.validate_input`); an asset with any error
finding is refused with an :class:`AssetError` carrying every finding. The validated URDF bytes
are then read by :mod:`asset2sim.urdf`, with ``semantics.txt`` and ``meta.json`` when present.
Given inertials that validation marks ``replace_with_estimate`` are left out
(``given_inertial=None``). ``input_hash`` covers every file the asset references.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from asset2sim import atomic, file_memo, input_files
from asset2sim.atomic import sha256_files
from asset2sim.frames import matrix_rpy
from asset2sim.schemas.asset import AssetDescription, GeometryRef, GivenInertial, JointDesc, LinkDesc, Origin
from asset2sim.tasks.ingest import partnet_mobility, urdf_meshes, validate_input
from asset2sim.formats import ReadOptions, read_asset_file, staging
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.partnet_mobility import URDF_NAMES
from asset2sim.urdf import UrdfError, UrdfGeometry, UrdfJoint, UrdfLink, UrdfModel, parse_urdf_bytes

if TYPE_CHECKING:  # pragma: no cover
    from asset2sim.tasks.ingest.validate_input import Finding, ValidationPolicy


#: How many error findings the AssetError message lists (all are in ``.findings``).
MESSAGE_FINDINGS = 20


def _origin(matrix) -> Origin:
    if matrix is None:
        return Origin()
    m = np.asarray(matrix, float)
    return Origin(xyz=tuple(map(float, m[:3, 3])), rpy=tuple(map(float, matrix_rpy(m))))


def _geometry(g: UrdfGeometry, role: str, mesh_paths: dict[str, Path], where: str) -> GeometryRef | None:
    """The description of one ``<visual>`` / ``<collision>`` of the model."""
    ref = dict(role=role, kind=g.kind, name=g.name, origin=_origin(g.origin))
    if g.kind == "mesh":
        fname = g.filename
        path = mesh_paths.get(fname or "")
        if path is None:  # validation refuses every unresolved reference; defensive
            raise AssetError(f"{where}: mesh {fname!r} was not validated")
        return GeometryRef(**ref, filename=fname, path=path, scale=tuple(map(float, g.scale)))
    if g.kind == "box" and g.size is not None:
        return GeometryRef(**ref, size=tuple(map(float, g.size)))
    if g.kind == "cylinder":
        return GeometryRef(**ref, radius=float(g.radius), length=float(g.length))
    if g.kind == "sphere":
        return GeometryRef(**ref, radius=float(g.radius))
    return None


def extract_asset_checked(asset: Path | str, *, asset_id: str | None = None, category: str | None = None,
                          policy: "ValidationPolicy | None" = None,
                          reading: ReadOptions | None = None) -> tuple[AssetDescription, list["Finding"]]:
    """Validate, then read an asset; also return every validation finding.

    Args:
        asset: folder with ``mobility.urdf`` (or one ``*.urdf``), a URDF file, or an MJCF (``.xml``) or
            OpenUSD (``.usd``, ``.usda``, ``.usdc``, ``.usdz``) file, read and staged as a URDF folder
            (:func:`_stage_other_format`; the description's ``staged_from`` names the file), or a folder
            without a URDF holding one such file.
        asset_id: identifier to record; default the folder name (an MJCF or USD file given alone: its stem).
        category: overrides ``meta.json``'s ``model_cat`` when given.
        policy: validation policy; default ``validate_input.DEFAULT_POLICY`` (then the result is
            memoized while the files are unchanged, :data:`_EXTRACT_MEMO`).
        reading: how an MJCF file is read (:class:`~asset2sim.formats.mjcf.conventions.ReadOptions`: the
            object's body in a scene, the angle unit); default: as its package compiles it.

    Returns:
        ``(description, findings)``: lengths in the file's units, angles in radians; findings of every
        severity, for ``report.json``.

    Raises:
        AssetError: validation found errors (``.findings`` has them all; the message lists them), or
            the URDF reader cannot read the validated bytes.
    """
    reading = reading or ReadOptions()
    key = (os.path.realpath(asset), asset_id, category, reading, input_files.allowed_folders()) if policy is None else None
    if key is not None and (hit := _EXTRACT_MEMO.get(key)) is not None:
        return hit
    given = Path(asset)
    staged_asset = _stage_other_format(asset, reading)
    if staged_asset is not None:
        asset = staged_asset.folder
    result = validate_input.run_validation(asset, policy)
    errs = result.errors
    if errs:
        more = f"\n  ... and {len(errs) - MESSAGE_FINDINGS} more" if len(errs) > MESSAGE_FINDINGS else ""
        lines = "\n  ".join(f.describe() for f in errs[:MESSAGE_FINDINGS])
        raise AssetError(f"{asset}: {len(errs)} validation error(s):\n  {lines}{more}", errs)
    assert result.urdf is not None and result.folder is not None and result.urdf_bytes is not None
    urdf = Path(os.path.realpath(result.urdf))
    folder = Path(os.path.realpath(result.folder))
    try:  # the validated bytes, never the file a second time
        robot = parse_urdf_bytes(result.urdf_bytes, source=str(urdf), mode="lenient")
    except UrdfError as exc:
        raise AssetError(f"{urdf}: the validated URDF could not be read: {exc}") from exc
    assert robot is not None
    links = [_link(ln, result.mesh_paths, result.semantics, result.replace_inertials, urdf) for ln in robot.links.values()]
    held = partnet_mobility.held_bodies(robot.joints, {ln.name: ln.semantic_joint for ln in links})  # the part kinds as meant
    joints = [_joint(jt, held=jt.name in held) for jt in robot.joints]
    root = _root(urdf, links, joints)  # validation refuses none or several; defensive
    # every file the asset references, for the input hash: the URDF, its meshes, semantics.txt, meta.json, the MTL
    # libraries and texture maps
    files = [urdf, *sorted({g.path for ln in links for g in ln.visuals + ln.collisions if g.path}),
             *(Path(os.path.realpath(p)) for p in [*result.extra_files, *result.material_files])]
    if staged_asset is not None:  # the file read and what it names, then the staged URDF and meshes made of them
        files = [*staged_asset.read.files, *files]
        read = file_memo.identities(list(staged_asset.read.files))
        default_id = given.name if given.is_dir() else staged_asset.read.source.stem
        # path -> sha256 of the files whose bytes the reader kept (an MJCF input's sources): never read a second time
        src = staged_asset.read.sources
        known = ({str(src.real[k]): hashlib.sha256(data).hexdigest() for k, data in src.files.items()}
                 if hasattr(src, "real") else {})
    else:
        # the files' identities before they are hashed (asset2sim.file_memo): the folder too, whose listing found the URDF
        read = file_memo.identities(([folder] if Path(asset).is_dir() else []) + files)
        default_id = folder.name if urdf.name in URDF_NAMES else urdf.stem
        known = {}
    desc = AssetDescription(
        asset_id=asset_id or default_id, source_dir=folder, urdf_path=urdf,
        robot_name=robot.name or urdf.stem, links=links, joints=joints, root_link=root,
        category=category or result.category,
        input_hash=sha256_files(files, known=known, named=_staged_names(staged_asset, folder)),
        staged_from=None if staged_asset is None else Path(os.path.realpath(staged_asset.read.source)),
        staging_notes=([] if staged_asset is None else list(staged_asset.read.notes)) + list(held.values()))
    if key is not None:
        _EXTRACT_MEMO.put(key, read, (desc, list(result.findings)))
    return desc, list(result.findings)


def _staged_names(staged_asset: "staging.StagedAsset | None", folder: Path):
    """The name each file is hashed under: a file of the staging ``folder`` (a new temporary folder every run) by
    its place in it (``<staged>/model.urdf``), every other file by its path; None for an input not staged. The same
    input then has the same hash in every process (a rerun is skipped, two outputs of it are the same bytes)."""
    if staged_asset is None:
        return None

    def named(p: Path) -> str:
        try:
            return f"<staged>/{Path(os.path.realpath(p)).relative_to(folder).as_posix()}"
        except ValueError:
            return str(p)

    return named


def _stage_other_format(asset: Path | str, reading: ReadOptions | None) -> "staging.StagedAsset | None":
    """An MJCF or USD file (:func:`~asset2sim.formats.staging.other_format_file` of ``asset``) read (:mod:`~asset2sim.formats.mjcf.reader`, :mod:`~asset2sim.formats.usd.reader`)
    and staged as a URDF folder (:func:`~asset2sim.formats.staging.stage`), or a URDF naming GLB / glTF / PLY
    meshes staged with OBJ copies (:mod:`~asset2sim.tasks.ingest.urdf_meshes`, its ``semantics.txt`` and
    ``meta.json`` beside it); None for any other URDF input.

    Raises:
        AssetError: the file cannot be read into the asset model (the reader's message, naming the body, prim
            or joint), or its reader is not installed.
    """
    found = staging.other_format_file(asset)
    if found is None:
        urdf = urdf_meshes.urdf_needing_conversion(asset)
        if urdf is None:
            return None
        try:
            out = staging.stage(urdf_meshes.read_urdf_converting(urdf), staging.staging_folder(urdf))
        except (staging.StagingError, OSError) as exc:
            raise AssetError(f"{urdf}: cannot convert its meshes: {exc}") from exc
        for side in ("semantics.txt", "meta.json"):  # the dataset's side files go with the URDF
            if (urdf.parent / side).is_file():
                atomic.copy_file(urdf.parent / side, out.folder / side)
        return out
    source, fmt = found
    try:
        return staging.stage(read_asset_file(source, fmt, reading), staging.staging_folder(source))
    except (staging.StagingError, ImportError, OSError) as exc:
        code = exc.code if isinstance(exc, staging.StagingError) else None  # a file the reader policy refused: its finding
        found = [validate_input.Finding(code=code, severity="error", message=str(exc), file=str(source),
                                        action="refuse")] if code else []
        raise AssetError(f"{source}: cannot read this {fmt.upper()} file: {f'{code}: ' if code else ''}{exc}", found) from exc


def validate_any(asset: Path | str, policy: "ValidationPolicy | None" = None,
                 reading: ReadOptions | None = None) -> tuple[list["Finding"], tuple[str, ...]]:
    """(every validation finding, the reader's notes) of any input: a URDF asset as
    :func:`~asset2sim.tasks.ingest.validate_input.validate_asset` checks it; an MJCF or USD file read as ``reading``
    says (the object in a scene, the angle unit), staged and checked as a URDF folder, with the notes saying what
    was read and which conventions applied.

    Raises:
        AssetError: an MJCF or USD file that cannot be read into the asset model (names the body, prim or joint).
    """
    staged_asset = None
    if os.path.exists(asset):  # else ASSET_NOT_FOUND, as for any input
        try:
            staged_asset = _stage_other_format(asset, reading)
        except AssetError as exc:
            if exc.findings:  # a file the reader policy refused: its finding, as validate_asset reports it
                return list(exc.findings), ()
            raise
    if staged_asset is None:
        return validate_input.validate_asset(asset, policy), ()
    return validate_input.validate_asset(staged_asset.folder, policy), staged_asset.read.notes


def _link(ln: UrdfLink, mesh_paths: dict[str, Path], semantics: dict, replace: set[str], urdf: Path) -> LinkDesc:
    """The description of one link: geometry (mesh filename -> ``mesh_paths``), semantics (link -> (joint
    kind, label)) and the given inertial (None for the links in ``replace``)."""
    where = f"{urdf.name}: link {ln.name!r}"
    visuals = [g for v in ln.visuals if (g := _geometry(v, "visual", mesh_paths, where))]
    collisions = [g for c in ln.collisions if (g := _geometry(c, "collision", mesh_paths, where))]
    given = None
    if ln.inertial is not None and ln.inertial.mass is not None and ln.name not in replace:
        I = np.asarray(ln.inertial.inertia if ln.inertial.inertia is not None else np.zeros((3, 3)), float)
        given = GivenInertial(mass=float(ln.inertial.mass), origin=_origin(ln.inertial.origin),
                              inertia=tuple(tuple(map(float, row)) for row in I))  # type: ignore[arg-type]
    kind, label = semantics.get(ln.name, (None, None))
    return LinkDesc(name=ln.name, visuals=visuals, collisions=collisions, semantic_label=label, semantic_joint=kind,
                    given_inertial=given)


def describe_model(model: UrdfModel) -> AssetDescription:
    """The description of a URDF model held in memory (a refine's candidate, its
    ``path`` the scratch file engines load), as :func:`extract_asset` gives it for
    that file: geometry and joints of ``model`` (mesh paths as the model resolved
    them, lengths in its units, angles in radians); no semantic labels, category
    or input hash (a file's own come from its folder, which a model has not).

    Raises:
        AssetError: a mesh the model did not resolve, or not exactly one root link.
    """
    urdf = Path(model.path or f"{model.name}.urdf")
    meshes = {str(g.filename): Path(g.path) for ln in model.links.values() for g in (*ln.visuals, *ln.collisions)
              if g.kind == "mesh" and g.path is not None}
    links = [_link(ln, meshes, {}, set(), urdf) for ln in model.links.values()]
    return AssetDescription(asset_id=urdf.parent.name, source_dir=urdf.parent, urdf_path=urdf, robot_name=model.name or urdf.stem,
                            links=links, joints=[_joint(j) for j in model.joints], root_link=_root(urdf, links, model.joints))


def _root(urdf: Path, links: list[LinkDesc], joints: list) -> str:
    """The one link of ``links`` no joint of ``joints`` moves.

    Raises:
        AssetError: none or several (naming ``urdf``).
    """
    children = {j.child for j in joints}
    roots = [ln.name for ln in links if ln.name not in children]
    if len(roots) != 1:
        raise AssetError(f"{urdf}: expected exactly one root link, found {roots or 'none'}")
    return roots[0]


def _float_or_none(obj, attr: str) -> float | None:
    """``float(obj.attr)``; None when ``obj`` or the value is None."""
    value = None if obj is None else getattr(obj, attr)
    return None if value is None else float(value)


def _joint(jt: UrdfJoint, held: bool = False) -> JointDesc:
    """The description of one joint (limits on revolute and prismatic joints only; axis default (1, 0, 0)); ``held``:
    a movable joint the asset's part kinds hold where it was modelled (:func:`partnet_mobility.held_bodies`), described
    as the fixed joint the output writes."""
    axis = tuple(map(float, jt.axis_xyz if jt.axis_xyz is not None else (1.0, 0.0, 0.0)))
    frame = dict(name=jt.name, parent=jt.parent, child=jt.child, origin=_origin(jt.origin), axis=axis)
    if held:
        return JointDesc(**frame, type="fixed")
    lim, dyn = jt.limit, jt.dynamics
    stops = lim if jt.type in ("revolute", "prismatic") else None
    return JointDesc(**frame, type=jt.type, lower=_float_or_none(stops, "lower"), upper=_float_or_none(stops, "upper"),
                     effort=_float_or_none(lim, "effort"), velocity=_float_or_none(lim, "velocity"),
                     damping=_float_or_none(dyn, "damping"), friction=_float_or_none(dyn, "friction"))


def _copy_extracted(value: tuple[AssetDescription, list["Finding"]]) -> tuple[AssetDescription, list["Finding"]]:
    desc, findings = value
    return desc.model_copy(deep=True), [f.model_copy(deep=True) for f in findings]


#: What :func:`extract_asset_checked` returned with the default policy, by (real path, asset id, category, folders
#: allowed outside the input (:func:`asset2sim.input_files.allow_outside`)), while the folder and the files it references are unchanged (each caller gets a copy).
_EXTRACT_MEMO = file_memo.FileMemo(_copy_extracted, max_entries=16)


def extract_asset(asset: Path | str, *, asset_id: str | None = None, category: str | None = None) -> AssetDescription:
    """The description of :func:`extract_asset_checked` (lengths in the file's units, angles in radians).

    Raises:
        AssetError: any validation error; ``.findings`` lists them all, the message names the file,
            line and link or joint of each.
    """
    return extract_asset_checked(asset, asset_id=asset_id, category=category)[0]
