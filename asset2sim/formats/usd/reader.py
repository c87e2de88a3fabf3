"""OpenUSD (UsdPhysics) articulated objects read into the project's asset model.

:func:`read_usd_asset` opens a stage with pxr (``usd-core``; the file is never parsed here) and gives a
:class:`~asset2sim.formats.staging.ReadAsset` (``format="usd"``) whose :class:`~asset2sim.urdf.UrdfModel`
is in SI units (m, kg, rad) and Z up. Rigid bodies are the links, revolute / prismatic / fixed joints the joints
(``body0`` the parent, ``body1`` the child). The stage is re-expressed in metres, Z up: every transform ``X``
becomes ``L X L^-1`` (:mod:`asset2sim.formats.usd.stage`, which also reads the geometry). A child's link frame has its body's axes and its origin at the joint (``localPos1``), so a
USD written by :mod:`asset2sim.formats.usd.export` reads back in the source URDF's link frames. The root
link keeps the world's axes: the object stands as it stands on the stage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim.frames import quat_wxyz_matrix, rigid_inverse, rigid_matrix
from asset2sim.extras import pxr_modules
from asset2sim.formats.staging import DeclaredSpring, ReadAsset, collisions_as_visuals, numbered
from asset2sim.formats.usd.stage import StageReading, authored, link_geometry, open_stage, used_files, value_or
from asset2sim.urdf import UrdfDynamics, UrdfInertial, UrdfJoint, UrdfLimit, UrdfLink, UrdfModel

#: Degrees per radian (UsdPhysics angles, angular limits and angular gains are per degree).
DEG = 180.0 / math.pi
#: A limit or force of this magnitude or more (or not finite) means "none".
UNLIMITED = 1e30
#: Attributes read as Coulomb joint friction (N*m or N in stage units), first authored wins.
FRICTION_ATTRS = ("asset2sim:friction", "newton:friction")
#: Token -> unit vector (3,) along that axis.
_AXES = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]), "Z": np.array([0.0, 0.0, 1.0])}


def quat_matrix(q) -> np.ndarray:
    """Rotation (3, 3) of a Gf quaternion (identity when zero or None)."""
    v = np.zeros(4) if q is None else np.array([q.GetReal(), *q.GetImaginary()], float)
    n = float(np.linalg.norm(v))
    return np.eye(3) if n == 0.0 else quat_wxyz_matrix(v / n)


def _name(prim) -> str:
    """``asset2sim:name`` when authored, else the prim name."""
    value = authored(prim, "asset2sim:name")
    return str(value) if value else prim.GetName()


def _unique(names: list[str]) -> list[str]:
    """``names`` with repeats numbered (``name_1``, ...)."""
    used: set[str] = set()
    return [numbered(n, used) for n in names]


@dataclass
class _Joint:
    """A UsdPhysics joint: ``kind`` revolute / prismatic / fixed (None: another type), its bodies (None: the
    world), the prims its local frames are given in (the ``body0`` / ``body1`` targets), and what is wrong with
    it (raised only when it belongs to the object read)."""

    prim: object
    name: str
    kind: str | None
    body0: object = None
    body1: object = None
    target0: object = None
    target1: object = None
    problem: str | None = None

    @property
    def what(self) -> str:
        return f"joint {self.name!r} ({self.prim.GetPath()})"


def read_usd_asset(path: Path | str) -> ReadAsset:
    """Read the USD articulated object at ``path`` (``.usd``, ``.usda``, ``.usdc``, ``.usdz``), format ``"usd"``.

    Read: the rigid bodies (``PhysicsRigidBodyAPI``) under the one ``PhysicsArticulationRootAPI`` prim and those
    jointed to them (the whole stage without one, noted), named by ``asset2sim:name`` or the prim name. Units:
    lengths times ``metersPerUnit`` (mesh points, joint positions, prismatic limits, COM), masses times
    ``kilogramsPerUnit``, inertia times kg * m^2, degrees -> rad; a Y-up stage is turned to Z up (noted).

    * Frames: the root link's has the root body's origin and the world's axes (Z up), so the object stands in
      the URDF as on the stage, under gravity along -z; a child's has its body's axes (scale stripped: scale
      goes into the geometry) and its origin at the joint (``localPos1`` on ``body1``'s side). Joint origin (4, 4):
      parent link frame^-1 * (``localPos0``, ``localRot0`` on ``body0``'s side) * the turn from the joint frame to
      the child's axes; axis: the ``physics:axis`` token's unit vector in the child link frame.
    * Joints: revolute (limits in degrees; none or infinite -> continuous), prismatic (both limits needed),
      fixed; a fixed joint without ``body0`` is the root fixed to the world: no URDF joint, noted
      ``root fixed to the world (fixed_root)``. ``PhysicsDriveAPI:angular`` / ``:linear``: damping -> URDF damping
      N*m*s/rad or N*s/m (angular gains per degree times 180/pi), stiffness > 0 with ``targetPosition`` ->
      ``springs``, ``maxForce`` -> limit effort; ``physxJoint:maxJointVelocity`` -> limit velocity. Coulomb
      friction N*m or N from ``asset2sim:friction``, else ``newton:friction`` (:data:`FRICTION_ATTRS`);
      ``physxJoint:jointFriction`` (PhysX's unitless coefficient) is noted, not taken.
    * Inertial: ``physics:mass`` > 0, ``physics:centerOfMass`` and ``physics:diagonalInertia`` /
      ``physics:principalAxes`` -> mass kg, origin (4, 4) at the COM in the link frame (identity rotation),
      inertia (3, 3) kg*m^2 ``R diag(d) R^T`` in the link axes. A link with any of them left to the simulator
      (not authored, <= 0, a ``physics:density``) has ``inertial`` None and is listed in ``inferred``.
    * Geometry: the body's ``UsdGeom.Gprim`` descendants (not a nested body's). ``PhysicsCollisionAPI`` ->
      collision; other visible prims of purpose default / render -> visual (a body with collisions only uses
      them as visuals too). Mesh: polygons fan-triangulated, vertices (n, 3) m in the link frame and triangles
      (m, 3) in ``meshes`` under ``meshes/<stem>.obj``. Cube / Sphere / Cylinder -> box / sphere / cylinder
      (origin turned to the cylinder's axis) unless a scale deforms them; those, Capsule and Cone -> a mesh
      of the surface (noted). First ``displayColor`` / ``displayOpacity`` -> the visual's rgba.

    Raises:
        ImportError: ``usd-core`` is not installed.
        StagingError: naming the file and the prim or joint: no file, not a stage, bad stage units; several
            articulation roots; no rigid body; a joint of another type (spherical, distance, D6 / generic), with
            several targets or no body, a movable joint to the world, revolute limits on one side only,
            prismatic limits not on both sides, lower > upper; a body that is ``body1`` of two joints (a loop),
            not exactly one root body, bodies not connected to it, a body other than the root fixed to the
            world; an authored inertia on a scaled body; faceVertexCounts not matching faceVertexIndices.
    """
    ctx = open_stage(Path(path))
    bodies, joints = _collect(ctx)
    parent_of, order = _tree(ctx, bodies, joints)
    key = {b.GetPath(): n for b, n in zip(order, _unique([_name(b) for b in order]))}
    root = key[order[0].GetPath()]
    # link -> its frame; the world's axes at the root
    frames = {root: rigid_matrix(np.eye(3), ctx.world(order[0])[:3, 3])}
    tree_joints = [parent_of[b.GetPath()] for b in order[1:]]
    for j, name in zip(tree_joints, _unique([j.name for j in tree_joints])):
        j.name = name
    out_joints, springs = [], {}
    for j in tree_joints:
        frame, uj, spring = _joint(ctx, j, frames[key[j.body0.GetPath()]], key)
        frames[uj.child] = frame
        out_joints.append(uj)
        if spring is not None:
            springs[uj.name] = spring
    links = {n: _link(ctx, b, n, frames[n]) for b, n in zip(order, key.values())}
    default = ctx.stage.GetDefaultPrim()
    model = UrdfModel(name=_name(default) if default else ctx.path.stem, links=links, joints=out_joints, root=root)
    return ReadAsset(source=ctx.path, format="usd", model=model, meshes=ctx.meshes, springs=springs,
                     inferred=tuple(n for n, lk in links.items() if lk.inertial is None), notes=tuple(ctx.notes),
                     files=used_files(ctx), root_fixed=any("(fixed_root)" in n for n in ctx.notes),
                     prims={**{n: str(p) for p, n in key.items()}, **{j.name: str(j.prim.GetPath()) for j in tree_joints}},
                     frames=frames)


def _collect(ctx: StageReading) -> tuple[list, list[_Joint]]:
    """The rigid bodies to read (under the articulation root, or all, and those jointed to them) and the joints
    touching them."""
    _, _, _, Usd, _, UsdPhysics = pxr_modules()
    prims = list(ctx.stage.Traverse(Usd.TraverseInstanceProxies()))
    roots = [p for p in prims if p.HasAPI(UsdPhysics.ArticulationRootAPI)]
    if len(roots) > 1:
        raise ctx.error("articulation roots", f"{len(roots)} of them ({', '.join(str(p.GetPath()) for p in roots)}); "
                        "one articulated object per file")
    if not roots:
        ctx.notes.append("no articulation root: the whole stage is read")
    all_bodies = [p for p in prims if p.HasAPI(UsdPhysics.RigidBodyAPI)]
    scope = roots[0].GetPath() if roots else None
    chosen = {p.GetPath() for p in all_bodies if scope is None or p.GetPath().HasPrefix(scope)}
    joints = [j for j in (_read_joint(ctx, p) for p in prims if p.IsA(UsdPhysics.Joint)) if j is not None]
    grown = True
    while grown:  # bodies jointed to the chosen ones are part of the articulation
        grown = False
        for j in joints:
            ends = {b.GetPath() for b in (j.body0, j.body1) if b is not None}
            if ends & chosen and not ends <= chosen:
                chosen, grown = chosen | ends, True
    bodies = [p for p in all_bodies if p.GetPath() in chosen]
    if not bodies:
        raise ctx.error("rigid bodies", "no prim with PhysicsRigidBodyAPI" + (f" under {scope}" if scope else ""))
    return bodies, [j for j in joints if any(b is not None and b.GetPath() in chosen for b in (j.body0, j.body1))
                    or scope is None or j.prim.GetPath().HasPrefix(scope)]


def _read_joint(ctx: StageReading, prim) -> _Joint | None:
    """A joint prim's kind, bodies and frame prims (None for a disabled joint, noted)."""
    UsdPhysics = pxr_modules()[5]
    api = UsdPhysics.Joint(prim)
    kinds = ((UsdPhysics.RevoluteJoint, "revolute"), (UsdPhysics.PrismaticJoint, "prismatic"), (UsdPhysics.FixedJoint, "fixed"))
    j = _Joint(prim, _name(prim), next((k for t, k in kinds if prim.IsA(t)), None))
    if not api.GetJointEnabledAttr().Get():
        ctx.notes.append(f"{j.what} is disabled: left out")
        return None
    ends = []
    for rel in (api.GetBody0Rel(), api.GetBody1Rel()):
        targets = rel.GetForwardedTargets()
        target = ctx.stage.GetPrimAtPath(targets[0]) if len(targets) == 1 else None
        if targets and not target:
            j.problem = f"{rel.GetName()} targets {', '.join(map(str, targets))}: not one prim of the stage"
        body = target
        while body and not body.IsPseudoRoot() and not body.HasAPI(UsdPhysics.RigidBodyAPI):
            body = body.GetParent()
        ends.append((target, body if body and not body.IsPseudoRoot() else None))
    (j.target0, j.body0), (j.target1, j.body1) = ends
    if j.body0 is None and j.body1 is None:
        j.problem = j.problem or "neither body0 nor body1 is (in) a rigid body"
    elif j.body0 is not None and j.body1 is not None and j.body0.GetPath() == j.body1.GetPath():
        j.problem = f"body0 and body1 are the same body {j.body0.GetPath()}"
    return j


def _tree(ctx: StageReading, bodies: list, joints: list[_Joint]) -> tuple[dict, list]:
    """Body path -> its parent joint, and the bodies depth first from the root (the root first)."""
    parent_of, world = {}, []
    for j in joints:
        if j.problem is not None:
            raise ctx.error(j.what, j.problem)
        if j.kind is None:
            raise ctx.error(j.what, f"a {j.prim.GetTypeName() or 'generic'} joint has no URDF counterpart "
                            "(revolute, prismatic and fixed joints are read)")
        if j.body0 is None or j.body1 is None:
            if j.kind != "fixed":
                raise ctx.error(j.what, f"a {j.kind} joint to the world has no URDF counterpart "
                                "(only a fixed joint from the world to the root body is read)")
            world.append(j.body1 if j.body1 is not None else j.body0)
            continue
        other = parent_of.get(j.body1.GetPath())
        if other is not None:
            raise ctx.error(f"body {j.body1.GetPath()}", f"body1 of joints {other.name!r} and {j.name!r}: a loop, "
                            "which a URDF tree cannot hold")
        parent_of[j.body1.GetPath()] = j
    roots = [b for b in bodies if b.GetPath() not in parent_of]
    if len(roots) != 1:
        raise ctx.error("joint tree", f"{len(bodies)} bodies and {len(roots)} root bodies "
                        f"({', '.join(str(b.GetPath()) for b in roots) or 'none'}); exactly one body must be no joint's body1")
    order, stack = [], [roots[0]]
    while stack:
        body = stack.pop()
        order.append(body)
        stack.extend(j.body1 for j in reversed(joints) if j.body0 is not None and j.body1 is not None
                     and j.body0.GetPath() == body.GetPath())
    reached = {b.GetPath() for b in order}
    missed = [str(b.GetPath()) for b in bodies if b.GetPath() not in reached]
    if missed:
        raise ctx.error("joint tree", f"bodies {', '.join(missed)} are not connected to the root {roots[0].GetPath()}")
    for b in world:
        if b.GetPath() != roots[0].GetPath():
            raise ctx.error(f"body {b.GetPath()}", "fixed to the world but not the root body (a loop)")
    if world:
        ctx.notes.append(f"root fixed to the world (fixed_root): {roots[0].GetPath()}")
    return parent_of, order


def _joint_frame(ctx: StageReading, j: _Joint, side: int) -> np.ndarray:
    """The joint frame (4, 4) in the world (m, Z up) of ``localPos<side>`` / ``localRot<side>``."""
    pos = np.array(value_or(j.prim, f"physics:localPos{side}", None), float)
    rot = ctx.u @ quat_matrix(value_or(j.prim, f"physics:localRot{side}", None)) @ ctx.u.T
    target = j.target1 if side else j.target0
    return rigid_matrix(ctx.frame(target)[:3, :3] @ rot, (ctx.world(target) @ np.append(pos, 1.0))[:3])


def _joint(ctx: StageReading, j: _Joint, parent_frame: np.ndarray, key: dict) -> tuple[np.ndarray, UrdfJoint, DeclaredSpring | None]:
    """The child's link frame (4, 4, world), the URDF joint (origin in the parent link frame ``parent_frame``,
    axis in the child's) and the declared spring."""
    j0, j1 = _joint_frame(ctx, j, 0), _joint_frame(ctx, j, 1)
    child = rigid_matrix(ctx.frame(j.body1)[:3, :3], j1[:3, 3])
    turn = j1[:3, :3].T @ child[:3, :3]  # joint frame -> child link axes
    origin = rigid_inverse(parent_frame) @ rigid_matrix(j0[:3, :3] @ turn, j0[:3, 3])
    uj = UrdfJoint(name=j.name, type=j.kind, parent=key[j.body0.GetPath()], child=key[j.body1.GetPath()], origin=origin)
    spring = None
    if j.kind != "fixed":
        token = str(value_or(j.prim, "physics:axis", None))
        if token not in _AXES:
            raise ctx.error(j.what, f"axis {token!r} is not X, Y or Z")
        uj.axis_xyz = turn.T @ ctx.u @ _AXES[token]  # the joint frame's axis in the child link axes
        uj.type, uj.limit = _limits(ctx, j)
        # damping and friction, the spring (stiffness > 0) and the effort limit (N*m or N), in SI
        UsdPhysics = pxr_modules()[5]
        rot = j.kind == "revolute"
        dof = "angular" if rot else "linear"
        force = ctx.kg * ctx.m * (ctx.m if rot else 1.0)  # stage unit of torque or force -> N*m or N
        gain = ctx.kg * ctx.m ** 2 * DEG if rot else ctx.kg  # per degree or per stage length -> per rad or per m
        damping = None
        if j.prim.HasAPI(UsdPhysics.DriveAPI, dof):
            drive = UsdPhysics.DriveAPI.Get(j.prim, dof)
            damping = float(drive.GetDampingAttr().Get() or 0.0) * gain
            stiffness = float(drive.GetStiffnessAttr().Get() or 0.0) * gain
            if stiffness > 0:
                target = float(drive.GetTargetPositionAttr().Get() or 0.0) * (1.0 / DEG if rot else ctx.m)
                spring = DeclaredSpring(stiffness=stiffness, reference=target)
            max_force = float(drive.GetMaxForceAttr().Get())
            if math.isfinite(max_force) and 0 <= max_force < UNLIMITED:
                uj.limit = uj.limit or UrdfLimit()
                uj.limit.effort = max_force * force
            if str(drive.GetTypeAttr().Get()) == "acceleration":
                ctx.notes.append(f"{j.what}: acceleration drive, its gains read as force gains")
        friction = next((float(v) * force for a in FRICTION_ATTRS if (v := authored(j.prim, a)) is not None), None)
        physx = authored(j.prim, "physxJoint:jointFriction")
        if physx is not None and friction is None:
            ctx.notes.append(f"{j.what}: physxJoint:jointFriction {physx} is PhysX's unitless coefficient, not a "
                             "friction torque or force: not taken")
        if damping is not None or friction is not None:
            uj.dynamics = UrdfDynamics(damping=damping, friction=friction)
    return child, uj, spring


def _limits(ctx: StageReading, j: _Joint) -> tuple[str, UrdfLimit | None]:
    """URDF type (revolute / continuous / prismatic) and limits (rad or m; velocity rad/s or m/s)."""
    rot = j.kind == "revolute"
    unit = 1.0 / DEG if rot else ctx.m
    lo, hi = (float(value_or(j.prim, f"physics:{end}Limit", None)) for end in ("lower", "upper"))  # fallbacks -inf, inf
    limited = [math.isfinite(v) and abs(v) < UNLIMITED for v in (lo, hi)]
    vel = authored(j.prim, "physxJoint:maxJointVelocity")
    vel = float(vel) * unit if vel is not None and math.isfinite(vel) and abs(vel) < UNLIMITED else None
    if rot and not any(limited):
        return "continuous", (UrdfLimit(velocity=vel) if vel is not None else None)
    if not all(limited):
        raise ctx.error(j.what, f"{j.kind} limits ({lo}, {hi}) are not finite on both sides, as a URDF {j.kind} joint needs")
    if lo > hi:
        raise ctx.error(j.what, f"lower limit {lo} > upper limit {hi}")
    return j.kind, UrdfLimit(lower=lo * unit, upper=hi * unit, velocity=vel)


def _link(ctx: StageReading, body, name: str, frame: np.ndarray) -> UrdfLink:
    """The link of ``body`` in its link ``frame`` (4, 4, world): inertial and geometry."""
    link = UrdfLink(name=name, inertial=_inertial(ctx, body, name, frame))
    link_geometry(ctx, body, link, rigid_inverse(frame))
    collisions_as_visuals(link)
    return link


def _inertial(ctx: StageReading, body, name: str, frame: np.ndarray) -> UrdfInertial | None:
    """Mass kg, COM (origin (4, 4), identity rotation) and inertia (3, 3) kg*m^2 in the link frame ``frame``;
    None (noted) when any of them is left to the simulator."""
    mass, com, diag = (authored(body, f"physics:{a}") for a in ("mass", "centerOfMass", "diagonalInertia"))
    missing = [w for w, ok in (("mass", mass is not None and mass > 0),
                               ("center of mass", com is not None and np.isfinite(np.array(com, float)).all()),
                               ("inertia", diag is not None and max(diag) > 0)) if not ok]
    if missing:
        density = authored(body, "physics:density")
        how = f" (physics:density {density} per stage unit^3 authored)" if density else ""
        ctx.notes.append(f"link {name!r}: {', '.join(missing)} left to the simulator{how}: inertial not declared")
        return None
    to_link = rigid_inverse(frame) @ ctx.world(body)
    a = to_link[:3, :3] / ctx.m  # body axes -> link axes (identity when the link frame is the body frame)
    if not np.allclose(a.T @ a, np.eye(3), atol=1e-6):
        raise ctx.error(f"body {body.GetPath()}", "scaled, with an authored inertia (its units are ambiguous)")
    q = a @ quat_matrix(value_or(body, "physics:principalAxes", None))
    inertia = ctx.kg * ctx.m ** 2 * (q @ np.diag(np.array(diag, float)) @ q.T)
    origin = rigid_matrix(np.eye(3), (to_link @ np.append(np.array(com, float), 1.0))[:3])
    return UrdfInertial(mass=float(mass) * ctx.kg, origin=origin, inertia=(inertia + inertia.T) / 2)


