"""One OpenUSD stage being read (:mod:`asset2sim.formats.usd.reader`): its basis change to metres and
Z up, the files it uses, and the geometry of a rigid body's Gprims in its link frame.

A stage's lengths are ``metersPerUnit`` m and its up axis Y or Z: every transform ``X`` becomes ``L X L^-1``,
``L = metersPerUnit * U`` (``U`` +90 deg about x for a Y-up stage), local coordinates ``v`` become ``L v``.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim.frames import rigid_matrix, rigid_part
from asset2sim.input_files import InputFileError, check_file
from asset2sim.extras import pxr_modules
from asset2sim.formats.staging import MAX_BUILT_FACES, StagingError, input_tree, mesh_name, rgba_material
from asset2sim.urdf import UrdfGeometry, UrdfLink, UrdfMaterial


def authored(prim, name: str):
    """The authored value of attribute ``name`` of ``prim``; None when the attribute is absent or not authored."""
    a = prim.GetAttribute(name)
    return a.Get() if a and a.HasAuthoredValue() else None


def value_or(prim, name: str, default):
    """Attribute ``name``'s value (its schema fallback included); ``default`` when it has none."""
    a = prim.GetAttribute(name)
    value = a.Get() if a else None
    return default if value is None else value

#: Rotation (3, 3) taking +z to the axis of a Cylinder / Capsule / Cone.
_AXIS_TURN = {"X": np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]), "Y": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
              "Z": np.eye(3)}
#: Y up -> Z up: +90 deg about x.
_Y_TO_Z = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])


@dataclass
class StageReading:
    """One stage being read: the stage, the basis change ``L`` (4, 4; stage units and up axis -> m, Z up) with its
    rotation ``u`` (3, 3), metres ``m`` and kilograms ``kg`` per stage unit, and what is gathered."""

    path: Path
    stage: object
    cache: object
    L: np.ndarray
    u: np.ndarray
    m: float
    kg: float
    notes: list[str] = field(default_factory=list)
    meshes: dict = field(default_factory=dict)
    used: set = field(default_factory=set)
    #: triangles built so far, every Gprim counted (a mesh referenced or instanced many times is built as often)
    faces: int = 0

    def error(self, what: str, message: str) -> StagingError:
        return StagingError(f"{self.path}: {what}: {message}")

    def world(self, prim) -> np.ndarray:
        """Prim-local coordinates (stage units) -> world (m, Z up), (4, 4)."""
        return self.L @ np.array(self.cache.GetLocalToWorldTransform(prim), float).T

    def frame(self, prim) -> np.ndarray:
        """The prim's rigid frame (4, 4) in the world (m, Z up), its scale stripped."""
        return rigid_part(self.world(prim) @ np.linalg.inv(self.L))


#: Layers per stage (sublayers, references and payloads, each counted once).
MAX_LAYERS = 1024


def open_layers(path: Path | str) -> list:
    """Open the root layer at ``path`` and every layer it composes (sublayers, references, payloads, in variants
    too: ``Sdf.Layer.GetCompositionAssetDependencies``), each checked before pxr opens it: a regular file inside
    the file's folder (:func:`~asset2sim.formats.staging.input_tree`; symlinks resolved) under
    :data:`~asset2sim.input_files.DEFAULT_MAX_BYTES`. A stage opened on the first layer returned finds the others
    open and opens no other file.

    Returns:
        The open ``Sdf.Layer`` objects, the root first (keep them alive while the stage is open).

    Raises:
        StagingError: with ``code``: ``USD_LAYER_OUTSIDE_ASSET`` (a layer outside the tree: an absolute path,
            ``../``, a symlink out, a URI), ``INPUT_NOT_FOUND``, ``INPUT_NOT_REGULAR_FILE`` (a FIFO, device or
            socket), ``INPUT_TOO_LARGE``, ``INPUT_OUTSIDE_TREE`` (the file given a symlink out of its folder),
            ``INPUT_UNREADABLE``; without a code when pxr cannot read a layer.
    """
    Sdf = pxr_modules()[1]
    path = Path(os.path.abspath(str(path)))
    root = str(input_tree(path))

    def check(file: str, what: str) -> None:
        try:
            check_file(file, tree=root, what=what)
        except InputFileError as exc:
            code = "USD_LAYER_OUTSIDE_ASSET" if exc.code == "INPUT_OUTSIDE_TREE" and what != "USD file" else exc.code
            raise StagingError(str(exc), code=code) from None

    def layer(identifier: str, what: str):
        try:
            opened = Sdf.Layer.FindOrOpen(identifier)
        except Exception as exc:  # Tf.ErrorException
            raise StagingError(f"{path}: {what} {identifier}: not a readable USD layer: {str(exc).strip()[:300]}") from None
        if opened is None:
            raise StagingError(f"{path}: {what} {identifier}: not a readable USD layer")
        return opened

    check(str(path), "USD file")
    layers = [layer(str(path), "USD file")]
    seen = {layers[0].identifier}
    todo = list(layers)
    while todo:
        current = todo.pop()
        for dep in current.GetCompositionAssetDependencies():
            if not dep:
                continue
            resolved = current.ComputeAbsolutePath(dep)
            # a layer inside a package: pkg.usdz[inner.usd]
            packaged = resolved.endswith("]") and "[" in resolved
            file = resolved[:resolved.index("[")] if packaged else resolved
            what = f"USD layer {dep!r} named by {current.identifier}"
            if "://" in file or not os.path.isabs(file):
                raise StagingError(f"{what}: resolves to {resolved!r}, not a file inside {root}", code="USD_LAYER_OUTSIDE_ASSET")
            check(file, what)
            if resolved in seen:
                continue
            seen.add(resolved)
            if len(seen) > MAX_LAYERS:
                raise StagingError(f"{path}: more than {MAX_LAYERS} layers", code="INPUT_TOO_LARGE")
            opened = layer(resolved, what)
            layers.append(opened)
            if not packaged:
                todo.append(opened)
    return layers


def open_stage(path: Path) -> StageReading:
    """The stage at ``path`` and its basis change (the conversions noted).

    Raises:
        ImportError: ``usd-core`` is not installed.
        StagingError: a layer refused by :func:`open_layers` (``code`` set), not a readable stage, or stage units
            that are not positive numbers.
    """
    _, _, _, Usd, UsdGeom, UsdPhysics = pxr_modules()
    try:
        layers = open_layers(path)
        stage = Usd.Stage.Open(layers[0])
    except StagingError:
        raise
    except Exception as exc:  # pxr raises Tf.ErrorException for an unreadable layer
        raise StagingError(f"{path}: not a readable USD stage: {str(exc).strip()[:300]}") from None
    if stage is None:
        raise StagingError(f"{path}: not a readable USD stage")
    m, kg = float(UsdGeom.GetStageMetersPerUnit(stage)), float(UsdPhysics.GetStageKilogramsPerUnit(stage))
    if not (math.isfinite(m) and m > 0 and math.isfinite(kg) and kg > 0):
        raise StagingError(f"{path}: metersPerUnit {m} / kilogramsPerUnit {kg}: not positive numbers")
    notes = [] if UsdGeom.StageHasAuthoredMetersPerUnit(stage) else [f"metersPerUnit not authored: USD's fallback {m} used"]
    if m != 1.0 or kg != 1.0:
        notes.append(f"stage units converted to SI: {m} m and {kg} kg per unit")
    u = np.eye(3)
    if str(UsdGeom.GetStageUpAxis(stage)) == "Y":
        u = _Y_TO_Z
        notes.append("stage is Y up: the object is turned +90 deg about x to Z up")
    L = rigid_matrix(m * u)
    return StageReading(path=path, stage=stage, cache=UsdGeom.XformCache(Usd.TimeCode.Default()), L=L, u=u, m=m, kg=kg, notes=notes)


def used_files(ctx: StageReading) -> tuple[Path, ...]:
    """The file read and every other layer file the stage uses (existing on disk)."""
    out = [ctx.path]
    for layer in ctx.stage.GetUsedLayers():
        real = layer.realPath
        if real and Path(real).is_file() and Path(real).resolve() != ctx.path.resolve():
            out.append(Path(real))
    return tuple(dict.fromkeys(out))


def link_geometry(ctx: StageReading, body, link: UrdfLink, inverse: np.ndarray) -> None:
    """Collisions and visuals of ``body`` (its Gprims, not those of nested bodies) into ``link``; ``inverse``
    (4, 4) world -> link frame."""
    _, _, _, Usd, UsdGeom, UsdPhysics = pxr_modules()
    it, approx = iter(Usd.PrimRange(body, Usd.TraverseInstanceProxies())), Counter()
    for prim in it:
        if prim != body and prim.HasAPI(UsdPhysics.RigidBodyAPI):
            it.PruneChildren()
            continue
        if not prim.IsA(UsdGeom.Gprim):
            continue
        img = UsdGeom.Imageable(prim)
        collision = prim.HasAPI(UsdPhysics.CollisionAPI) and bool(UsdPhysics.CollisionAPI(prim).GetCollisionEnabledAttr().Get())
        visual = (not collision and img.ComputePurpose() in (UsdGeom.Tokens.default_, UsdGeom.Tokens.render)
                  and img.ComputeVisibility() != UsdGeom.Tokens.invisible)
        g = _shape(ctx, prim, link.name, inverse @ ctx.world(prim)) if collision or visual else None
        if g is None:
            continue
        if collision:
            approx[str(authored(prim, "physics:approximation") or "none")] += 1
            link.collisions.append(g)
        else:
            g.material = _color(prim)
            link.visuals.append(g)
    for how, n in sorted(approx.items()):
        if how != "none":
            ctx.notes.append(f"link {link.name!r}: {n} collision mesh(es) with physics:approximation {how} (kept as authored)")


def _color(prim) -> UrdfMaterial | None:
    """rgba (4,) of the first displayColor / displayOpacity values, None when no colour is authored."""
    color = authored(prim, "primvars:displayColor")
    if not color:
        return None
    opacity = authored(prim, "primvars:displayOpacity")
    return rgba_material([*color[0], opacity[0] if opacity else 1.0])


def _shape(ctx: StageReading, prim, link: str, to_link: np.ndarray) -> UrdfGeometry | None:
    """The geometry of a Gprim whose local coordinates (stage units) ``to_link`` (4, 4) maps to the link frame (m)."""
    UsdGeom = pxr_modules()[4]
    import trimesh

    if prim.IsA(UsdGeom.Mesh):
        return _mesh(ctx, prim, link, to_link)
    turn = rigid_matrix(_AXIS_TURN.get(str(value_or(prim, "axis", "Z")), np.eye(3)))
    r, h = float(value_or(prim, "radius", 1.0)), float(value_or(prim, "height", 2.0))
    if prim.IsA(UsdGeom.Cube):
        size = float(value_or(prim, "size", 2.0))
        g, surface = _exact(to_link, "box", np.full(3, size)), trimesh.creation.box(extents=np.full(3, size))
    elif prim.IsA(UsdGeom.Sphere):
        g, surface = _exact(to_link, "sphere", np.full(3, 2 * r)), trimesh.creation.icosphere(subdivisions=3, radius=r)
    elif prim.IsA(UsdGeom.Cylinder):
        g = _exact(to_link @ turn, "cylinder", np.array([2 * r, 2 * r, h]))
        surface = trimesh.creation.cylinder(radius=r, height=h, sections=48).apply_transform(turn)
    elif prim.IsA(UsdGeom.Capsule) or prim.IsA(UsdGeom.Cone):
        surface = (trimesh.creation.capsule(height=h, radius=r) if prim.IsA(UsdGeom.Capsule)
                   else trimesh.creation.cone(radius=r, height=h).apply_translation([0, 0, -h / 2])).apply_transform(turn)
        g = None
    else:
        ctx.notes.append(f"link {link!r}: {prim.GetTypeName()} {prim.GetPath()} has no URDF geometry: left out")
        return None
    if g is not None:
        g.name = prim.GetName()
        return g
    ctx.notes.append(f"link {link!r}: {prim.GetTypeName()} {prim.GetPath()} written as a mesh of its surface")
    verts = np.asarray(surface.vertices) @ to_link[:3, :3].T + to_link[:3, 3]
    return _store(ctx, prim, link, verts, np.asarray(surface.faces))


def _exact(m: np.ndarray, kind: str, size: np.ndarray) -> UrdfGeometry | None:
    """A URDF primitive of local ``size`` (3,) (box edges; sphere or cylinder diameters and length) placed by
    ``m`` (4, 4, local -> link frame), or None when ``m``'s scale or shear makes it another shape."""
    scale = np.linalg.norm(m[:3, :3], axis=0)
    if (scale <= 0).any():
        return None
    rot = m[:3, :3] / scale  # orthonormal up to binary32 rounding unless sheared
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        return None
    s, origin = size * scale, rigid_part(rigid_matrix(rot, m[:3, 3]))
    if kind == "box":
        return UrdfGeometry(kind="box", origin=origin, size=s)
    if kind == "sphere" and np.allclose(s, s[0], rtol=1e-6):
        return UrdfGeometry(kind="sphere", origin=origin, radius=float(s[0] / 2))
    if kind == "cylinder" and math.isclose(s[0], s[1], rel_tol=1e-6):
        return UrdfGeometry(kind="cylinder", origin=origin, radius=float(s[0] / 2), length=float(s[2]))
    return None


def _mesh(ctx: StageReading, prim, link: str, to_link: np.ndarray) -> UrdfGeometry | None:
    """A UsdGeom.Mesh, fan-triangulated, its points mapped to the link frame (m) by ``to_link`` (4, 4)."""
    UsdGeom = pxr_modules()[4]
    mesh = UsdGeom.Mesh(prim)
    attrs = (mesh.GetPointsAttr(), mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr())
    points, counts, idx = (a.Get() for a in attrs)
    if counts is not None and idx is not None:  # counted before any array is built from them
        ctx.faces += max(0, len(idx) - 2 * len(counts))  # a fan of c - 2 triangles per polygon of c corners
        if ctx.faces > MAX_BUILT_FACES:
            raise StagingError(f"{ctx.path}: the stage's meshes come to more than {MAX_BUILT_FACES} triangles as they are built "
                               f"(every mesh prim counted, a referenced or instanced mesh as often as it appears; at "
                               f"{prim.GetPath()}); not read", code="INPUT_TOO_LARGE")
    pts = np.array(points or [], float).reshape(-1, 3)
    counts, idx = np.array(counts or [], np.int64), np.array(idx or [], np.int64)
    if counts.sum() != len(idx) or (counts < 0).any():
        raise ctx.error(f"mesh {prim.GetPath()}", f"faceVertexCounts sum to {counts.sum()}, not the {len(idx)} faceVertexIndices")
    ntri = np.clip(counts - 2, 0, None)  # a fan of c - 2 triangles per polygon of c corners
    first = np.repeat(np.cumsum(counts) - counts, ntri)
    k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    tris = np.stack([idx[first], idx[first + k], idx[first + k + 1]], axis=1).reshape(-1, 3)
    tris = tris[((tris >= 0) & (tris < len(pts))).all(axis=1)]
    if not len(tris):
        ctx.notes.append(f"link {link!r}: mesh {prim.GetPath()} has no triangles: left out")
        return None
    if (str(mesh.GetOrientationAttr().Get()) == "leftHanded") != (np.linalg.det(to_link[:3, :3]) < 0):
        tris = tris[:, ::-1]  # counter-clockwise in the link frame
    return _store(ctx, prim, link, pts @ to_link[:3, :3].T + to_link[:3, 3], tris)


def _store(ctx: StageReading, prim, link: str, vertices: np.ndarray, triangles: np.ndarray) -> UrdfGeometry:
    """Keep a mesh (vertices (n, 3) m in the link frame, triangles (m, 3)); its geometry has an identity origin."""
    name = mesh_name(f"{link}_{prim.GetName()}", ctx.used)
    ctx.meshes[name] = (np.ascontiguousarray(vertices, float), np.ascontiguousarray(triangles, np.int64))
    return UrdfGeometry(kind="mesh", filename=name, name=prim.GetName())
