"""MJCF (MuJoCo) articulated objects read into the project's one asset model.

The file and every file it names are checked and read first
(:mod:`asset2sim.formats.mjcf.files`); the checked copy is parsed and compiled by
MuJoCo itself (``mujoco.MjSpec.from_file``, then ``spec.compile()``): default classes, ``<compiler angle>`` (degrees are
MJCF's default), ``meshdir``, mesh scale and recentring, ``fromto`` and
alternative orientations all come resolved from the compiled ``MjModel``; the
spec says which bodies declare an ``<inertial>``. Nothing here walks XML.

Conventions (MJCF -> URDF):

- The object is the world body's child whose subtree carries the joints
  (:mod:`asset2sim.formats.mjcf.scene`: the static bodies around it, a
  table or a wall, are noted and left out); its body is the root link. Angles
  are read in the unit the file's host package compiles it with
  (:mod:`asset2sim.formats.mjcf.conventions`). A ``<freejoint>`` on it
  means a free-standing object; none means the root is welded to the world
  (a mounted object). Geoms on the world body (a ground plane) are scenery
  and are left out, with a note.
- A body with one hinge or slide joint is a link whose URDF frame is the body
  frame moved to the joint's ``pos``; the joint origin is the URDF frame at
  joint value 0 (MuJoCo's ``ref`` is undone), so joint values, ``range``,
  ``springref`` read the same in both. A body without joints is a fixed
  joint. Ball joints, several joints on one body and a slide without a range
  are refused.
- ``damping`` and ``frictionloss`` become ``<dynamics damping friction>``;
  ``stiffness`` about ``springref`` is a declared spring; the largest force of
  the joint's ``actuatorfrcrange`` or of an actuator driving it is the limit's
  effort. ``armature``, tendons and equality constraints have no URDF element
  and are noted, and so is each solver aid an asset2sim export names (:mod:`asset2sim.engines.mjcf.aids`).
- A geom with ``contype`` and ``conaffinity`` 0 is a visual; any other is a
  collision, and a body without visual geoms shows its collision geoms. Boxes,
  spheres and cylinders stay primitives; capsules, ellipsoids and meshes are
  written as meshes (MuJoCo's compiled vertices, in the geom frame).
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

from asset2sim.engines.mjcf.aids import read_aids
from asset2sim.engines.mjcf.base import load_mujoco
from asset2sim.frames import axis_angle_matrix, quat_wxyz_matrix, rigid_inverse, rigid_matrix, translation_matrix
from asset2sim.formats.mjcf import conventions
from asset2sim.formats.mjcf import scene
from asset2sim.formats.mjcf.conventions import ReadOptions
from asset2sim.formats.mjcf.files import MjcfSources, compile_mjcf, gather_mjcf
from asset2sim.formats.staging import DeclaredSpring, ReadAsset, StagingError, collisions_as_visuals, mesh_name, rgba_material
from asset2sim.urdf import UrdfDynamics, UrdfGeometry, UrdfInertial, UrdfJoint, UrdfLimit, UrdfLink, UrdfModel

#: Primitive geoms written as a mesh of their surface: triangles per full turn of the tessellation.
PRIMITIVE_SEGMENTS = 16


def _pose(pos, quat_wxyz) -> np.ndarray:
    """The (4, 4) pose of a position (3,) m and a unit quaternion (w, x, y, z)."""
    return rigid_matrix(quat_wxyz_matrix(np.asarray(quat_wxyz, float)), pos)


def read_mjcf_asset(path: Path | str, options: ReadOptions | None = None) -> ReadAsset:
    """Read one articulated object from an MJCF file (or from a scene holding it).

    Args:
        path: the ``<mujoco>`` XML file (its meshes resolved as MuJoCo resolves them). The file and every file it
            names are checked and read first (:func:`~asset2sim.formats.mjcf.files.gather_mjcf`: regular
            files inside the file's folder, or inside its package's asset folder for a file of a known package
            (:func:`~asset2sim.formats.mjcf.conventions.package_tree`), under the size cap); MuJoCo reads
            only a private copy of those.
        options: ``body`` picks the object in a scene with several jointed subtrees
            (:func:`~asset2sim.formats.mjcf.scene.pick_object`); ``mjcf_angle`` overrides the angle unit
            the file's place implies (:func:`~asset2sim.formats.mjcf.conventions.mjcf_angle`). The notes
            say which convention was used and why, and which bodies around the object were left out.

    Returns:
        A :class:`~asset2sim.formats.staging.ReadAsset` (format ``"mjcf"``): lengths in m, angles in
        rad, masses in kg, inertia tensors (3, 3) in kg*m^2 about the center of mass in the link axes.

    Raises:
        MissingExtra (an ImportError): MuJoCo is not installed (the message names the extra, ``[mujoco]``).
        StagingError: a named file refused by the reader policy (``code`` set: ``MJCF_PATH_ESCAPES``,
            ``INPUT_NOT_REGULAR_FILE``, ``INPUT_TOO_LARGE`` ...); MuJoCo cannot compile the file, or the file holds
            something the asset model cannot take (names the body or joint): no object or several under the world
            body and no ``body`` naming one, a ball joint, several joints on one body, a free joint below the root,
            a slide joint without a range.
    """
    path = Path(path)
    options = options or ReadOptions()
    sources = gather_mjcf(path)  # first: every file it names checked before anything reads it
    tree = conventions.package_tree(path)
    convention = conventions.mjcf_angle(path, options.mjcf_angle, files=sources.files)  # the bytes read, not the disk
    spec, m, warned = compile_mjcf(sources, degree=convention.unit == "degree")
    mujoco = load_mujoco()
    pick = scene.pick_object(m, path, options.body)
    reader = _Reader(path, spec, m, mujoco, sources)
    reader.notes.append(convention.note)
    if tree is not None:
        reader.notes.append(f"files it names read within its package's asset folder {tree}")
    reader.notes.extend(pick.notes)
    reader.notes.extend(warned)
    return replace(reader.read(pick.root, pick.bodies), sources=sources, angle_unit=convention.unit)  # the bytes, for later stages


class _Reader:
    """State of one :func:`read_mjcf_asset` call."""

    def __init__(self, path: Path, spec, m, mujoco, sources: MjcfSources):
        self.path, self.spec, self.m, self.mj, self.sources = path, spec, m, mujoco, sources
        self.notes: list[str] = []
        self.meshes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.mesh_files: dict[tuple, str] = {}
        self.used: set[str] = set()
        self.springs: dict[str, DeclaredSpring] = {}
        self.inferred: list[str] = []
        self.simulated: dict[str, UrdfInertial] = {}
        self.densities: dict[str, float] = {}
        self.written_moments: dict[str, tuple[float, float, float]] = {}
        self.root_fixed = False
        self.explicit = {b.name: bool(b.explicitinertial) for b in spec.bodies if b.name}

    def body_name(self, b: int) -> str:
        """Body ``b``'s name (MuJoCo refuses repeated names), ``body_<b>`` for an unnamed one."""
        return scene.label(self.m, b)

    def read(self, root: int, bodies: tuple[int, ...]) -> ReadAsset:
        """The object whose root body is ``root`` and whose bodies are ``bodies`` (depth first, ``root`` first)."""
        m = self.m
        if world_geoms := int(m.body_geomnum[0]):
            self.notes.append(f"{world_geoms} geom(s) on the world body (scenery, e.g. a ground plane) left out")
        links: dict[str, UrdfLink] = {}
        joints: list[UrdfJoint] = []
        frames: dict[int, np.ndarray] = {}  # body -> its URDF link frame in the body frame (the joint's pos)
        for b in bodies:  # depth first: MuJoCo numbers a parent before its children
            parent = int(m.body_parentid[b])
            joint, frame = self._joint(b, is_root=b == root)
            frames[b] = frame
            if b != root:
                origin = rigid_inverse(frames[parent]) @ _pose(m.body_pos[b], m.body_quat[b]) @ frame
                joints.append(self._urdf_joint(b, joint, origin))
            links[self.body_name(b)] = self._link(b, rigid_inverse(frame))
        self.notes += [f"{n} {what} not carried (URDF has no element for them)"
                       for n, what in ((m.ntendon, "tendon(s)"), (m.neq, "equality constraint(s)")) if n]
        self.notes += [f"solver aid {a.kind} on {a.element!r} {a.written} ({a.criterion}; {a.effect}): not carried, an aid of "
                       "the MJCF solver only" for a in read_aids(m)]
        model = UrdfModel(name=self.spec.modelname or self.path.stem, links=links, joints=joints, root=self.body_name(root))
        files = tuple(sorted({self.path.resolve(), *self.sources.real.values()}))
        # joint -> position (rad or m) in the keyframe named initial, else the first keyframe (noted when used); MuJoCo's
        # joint values are the URDF joint's: ref moved the URDF origin, not the values
        initial = {}
        names = [m.key(k).name for k in range(m.nkey)]
        k = names.index("initial") if "initial" in names else 0
        for j in joints if m.nkey else []:
            jid = self.mj.mj_name2id(m, self.mj.mjtObj.mjOBJ_JOINT, j.name)
            if j.type == "fixed" or jid < 0:
                continue
            value = float(m.key_qpos[k, int(m.jnt_qposadr[jid])])  # as MuJoCo reads it (a joint's ref moves its frame)
            if np.isfinite(value):
                initial[j.name] = value
            else:  # a NaN or infinity in the keyframe is no position: the joint's default kept
                self.notes.append(f"keyframe {names[k] or f'#{k}'!r}: joint {j.name!r} at {value}, not a number: not used")
        if initial:
            self.notes.append(f"initial joint positions from keyframe {names[k] or f'#{k}'!r}")
        return ReadAsset(source=self.path, format="mjcf", model=model, meshes=self.meshes, springs=self.springs, initial_state=initial,
                         inferred=tuple(self.inferred), notes=tuple(self.notes), files=files, root_fixed=self.root_fixed,
                         simulated=self.simulated, densities=self.densities, written_moments=self.written_moments)

    # ------------------------------------------------------------------ joints
    def _joint(self, b: int, is_root: bool) -> tuple[int | None, np.ndarray]:
        """(the body's joint id or None, the URDF link frame (4, 4) in the body frame)."""
        m = self.m
        ids = scene.body_joints(m, b)
        n = len(ids)
        free = scene.body_joints(m, b, (scene.JNT_FREE,))
        if free and not is_root:
            raise StagingError(f"{self.path}: body {self.body_name(b)!r} has a free joint below the root")
        if is_root:
            if not free:
                self.root_fixed = True
                self.notes.append(f"root body {self.body_name(b)!r} has no free joint: welded to the world (mounted)")
            others = [j for j in ids if j not in free]
            if others:
                raise StagingError(f"{self.path}: the root body {self.body_name(b)!r} has joint(s) "
                                   f"{[m.joint(j).name for j in others]}; the root may only have a free joint")
            return None, np.eye(4)
        if n == 0:
            return None, np.eye(4)
        if n > 1:
            raise StagingError(f"{self.path}: body {self.body_name(b)!r} has {n} joints "
                               f"{[m.joint(j).name for j in ids]}; a link takes one joint to its parent")
        j = ids[0]
        if m.jnt_type[j] == scene.JNT_BALL:
            raise StagingError(f"{self.path}: joint {m.joint(j).name!r} of body {self.body_name(b)!r} is a ball joint; "
                               "only hinge and slide joints are read")
        return j, translation_matrix(m.jnt_pos[j])

    def _urdf_joint(self, b: int, j: int | None, origin: np.ndarray) -> UrdfJoint:
        """The URDF joint carrying body ``b`` (fixed when ``j`` is None); ``origin`` at MuJoCo's ``ref``."""
        m = self.m
        parent, child = self.body_name(int(m.body_parentid[b])), self.body_name(b)
        if j is None:
            return UrdfJoint(name=f"{child}_fixed", type="fixed", parent=parent, child=child, origin=origin)
        name = m.joint(j).name or f"{child}_joint"
        axis = np.asarray(m.jnt_axis[j], float)
        hinge = m.jnt_type[j] == scene.JNT_HINGE
        ref = float(m.qpos0[m.jnt_qposadr[j]])
        if ref != 0.0:  # the body frame is drawn at q = ref; URDF's origin is q = 0
            undo = np.eye(4)
            if hinge:
                undo[:3, :3] = axis_angle_matrix(axis, -ref)
            else:
                undo[:3, 3] = -ref * axis
            origin = origin @ undo
            self.notes.append(f"joint {name!r}: ref {ref:g} undone (the URDF origin is the joint at 0)")
        limited = bool(m.jnt_limited[j])
        if not hinge and not limited:
            raise StagingError(f"{self.path}: slide joint {name!r} of body {child!r} has no range; give it one")
        kind = ("revolute" if limited else "continuous") if hinge else "prismatic"
        lo, hi = (float(v) for v in m.jnt_range[j]) if limited else (None, None)
        dof = int(m.jnt_dofadr[j])
        # the largest force (N or N*m) its actuator force range or an actuator on it allows; None when unbounded
        forces = [float(np.abs(m.jnt_actfrcrange[j]).max())] if bool(m.jnt_actfrclimited[j]) else []
        forces += [float(np.abs(m.actuator_forcerange[a]).max() * abs(float(m.actuator_gear[a, 0]))) for a in range(m.nu)
                   if m.actuator_trntype[a] == self.mj.mjtTrn.mjTRN_JOINT and int(m.actuator_trnid[a, 0]) == j
                   and bool(m.actuator_forcelimited[a])]
        effort = max(forces, default=None)
        limit = UrdfLimit(lower=lo, upper=hi, effort=effort) if limited or effort is not None else None
        dyn = UrdfDynamics(damping=float(m.dof_damping[dof]), friction=float(m.dof_frictionloss[dof]))
        k = float(m.jnt_stiffness[j])
        if k > 0:
            self.springs[name] = DeclaredSpring(stiffness=k, reference=float(m.qpos_spring[m.jnt_qposadr[j]]))
        if float(m.dof_armature[dof]) > 0:
            self.notes.append(f"joint {name!r}: armature {float(m.dof_armature[dof]):g} not carried (URDF has no element for it)")
        return UrdfJoint(name=name, type=kind, parent=parent, child=child, origin=origin, axis_xyz=axis,
                         limit=limit, dynamics=dyn)

    # ------------------------------------------------------------------- links
    def _link(self, b: int, to_link: np.ndarray) -> UrdfLink:
        """The link of body ``b``; ``to_link`` (4, 4) maps the body frame to the link frame."""
        m = self.m
        name = self.body_name(b)
        inertial = None
        if float(m.body_mass[b]) > 0:
            r = quat_wxyz_matrix(m.body_iquat[b])
            tensor = r @ np.diag(m.body_inertia[b]) @ r.T
            rot = to_link[:3, :3]
            com = rot @ m.body_ipos[b] + to_link[:3, 3]
            compiled = UrdfInertial(mass=float(m.body_mass[b]), origin=translation_matrix(com), inertia=rot @ tensor @ rot.T)
            if self.explicit.get(name, False):
                inertial = compiled
                # the principal moments as written, when MuJoCo's balanceinertia changed them on loading (noted)
                body = self.spec.bodies[b]
                full = np.asarray(body.fullinertia, float)
                declared = (np.array([[full[0], full[3], full[4]], [full[3], full[1], full[5]], [full[4], full[5], full[2]]])
                            if not np.isnan(full).any() else np.diag(np.asarray(body.inertia, float)))
                written = np.sort(np.linalg.eigvalsh(declared))
                loaded = np.sort(np.asarray(m.body_inertia[b], float))
                if not np.allclose(written, loaded, rtol=1e-6, atol=1e-12):
                    self.written_moments[name] = tuple(float(v) for v in written)
                    self.notes.append(f"body {name!r}: principal moments written {np.round(written, 9).tolist()} kg*m^2, "
                                      f"loaded as {np.round(loaded, 9).tolist()} (MuJoCo's balanceinertia)")
            else:
                self.inferred.append(name)
                self.simulated[name] = compiled
                density = self._density(b)
                if density is not None:
                    self.densities[name] = density
        visuals, collisions, friction = [], [], set()
        for g in range(int(m.body_geomadr[b]), int(m.body_geomadr[b]) + int(m.body_geomnum[b])):
            geom = self._geometry(g, to_link @ _pose(m.geom_pos[g], m.geom_quat[g]))
            if geom is None:
                continue
            if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0:
                visuals.append(geom)
            else:
                collisions.append(geom)
                friction.add(float(m.geom_friction[g, 0]))
        contact = {"lateral_friction": friction.pop()} if len(friction) == 1 else {}
        link = UrdfLink(name=name, inertial=inertial, visuals=visuals, collisions=collisions, contact=contact)
        collisions_as_visuals(link)
        return link

    def _density(self, b: int) -> float | None:
        """The density (kg/m^3) MuJoCo infers body ``b``'s mass from: the one ``density`` of the geoms that
        count for inertia (``compiler inertiagrouprange``), none of them given a ``mass``; else None."""
        m = self.m
        lo, hi = (int(x) for x in self.spec.compiler.inertiagrouprange)
        body = self.spec.body(m.body(b).name) if m.body(b).name else None
        if body is None:
            return None
        geoms = [g for g in body.geoms if lo <= int(g.group) <= hi]
        if not geoms or any(float(g.mass) > 0 for g in geoms if not np.isnan(float(g.mass))):
            return None
        values = {float(g.density) for g in geoms}
        return values.pop() if len(values) == 1 else None

    def _geometry(self, g: int, origin: np.ndarray) -> UrdfGeometry | None:
        """The URDF geometry of geom ``g`` at ``origin`` (4, 4, link frame); None (noted) for a kind URDF cannot take."""
        m, T = self.m, self.mj.mjtGeom
        kind, size = int(m.geom_type[g]), np.asarray(m.geom_size[g], float)
        name = m.geom(g).name or None
        rgba = np.asarray(m.mat_rgba[m.geom_matid[g]] if m.geom_matid[g] >= 0 else m.geom_rgba[g], float)
        shape = partial(UrdfGeometry, origin=origin, name=name, material=rgba_material(rgba))
        if kind == T.mjGEOM_BOX:
            return shape(kind="box", size=2.0 * size)
        if kind == T.mjGEOM_SPHERE:
            return shape(kind="sphere", radius=float(size[0]))
        if kind == T.mjGEOM_CYLINDER:
            return shape(kind="cylinder", radius=float(size[0]), length=2.0 * float(size[1]))
        if kind in (T.mjGEOM_MESH, T.mjGEOM_CAPSULE, T.mjGEOM_ELLIPSOID):
            return shape(kind="mesh", filename=self._mesh_file(g, kind, size))
        self.notes.append(f"geom {name or g} of body {self.body_name(int(m.geom_bodyid[g]))!r}: type "
                          f"{T(kind).name.removeprefix('mjGEOM_').lower()} has no URDF geometry; left out")
        return None

    def _mesh_file(self, g: int, kind: int, size: np.ndarray) -> str:
        """``meshes/<name>.obj`` holding the surface of geom ``g`` in its own frame (one file per mesh asset)."""
        import trimesh

        m, T = self.m, self.mj.mjtGeom
        if kind == T.mjGEOM_MESH:
            mid = int(m.geom_dataid[g])
            key: tuple = ("mesh", mid)
            if key not in self.mesh_files:
                va, vn, fa, fn = (int(x) for x in (m.mesh_vertadr[mid], m.mesh_vertnum[mid], m.mesh_faceadr[mid], m.mesh_facenum[mid]))
                fname = mesh_name(m.mesh(mid).name or f"mesh_{mid}", self.used)
                self.meshes[fname] = (np.array(m.mesh_vert[va:va + vn], float), np.array(m.mesh_face[fa:fa + fn], np.int64))
                self.mesh_files[key] = fname
            return self.mesh_files[key]
        key = ("primitive", kind, *np.round(size, 12))
        if key not in self.mesh_files:
            if kind == T.mjGEOM_CAPSULE:
                shape = trimesh.creation.capsule(height=2.0 * float(size[1]), radius=float(size[0]), count=[PRIMITIVE_SEGMENTS, PRIMITIVE_SEGMENTS])
                label = "capsule"
            else:
                shape = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
                shape.apply_scale(size)
                label = "ellipsoid"
            fname = mesh_name(f"{label}_{len(self.mesh_files)}", self.used)
            self.meshes[fname] = (np.asarray(shape.vertices, float), np.asarray(shape.faces, np.int64))
            self.mesh_files[key] = fname
            self.notes.append(f"{label} geom(s) written as a mesh of {len(shape.faces)} triangles ({fname})")
        return self.mesh_files[key]
