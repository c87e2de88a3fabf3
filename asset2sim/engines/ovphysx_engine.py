"""ovphysx engine: the USD export as NVIDIA's USD runtime reads it (``ovphysx``, PhysX on an ``ovstage`` stage; the
CPU here), not a model rebuilt from the URDF.

The session opens ``usd/<urdf stem>.usd`` beside the URDF (written by ``asset2sim export OUT --format usd``) inside a
scene layer of its own: a ``PhysicsScene`` at the conventions' time step (``physxScene:timeStepsPerSecond``) and
gravity, a ground plane (``PhysicsCollisionAPI``; none for a mounted object), the object referenced under
``/World/object`` and lifted so its lowest collision point is :data:`GROUND_CLEARANCE` above z = 0; ``fixed_base`` adds a fixed joint from the
world to the root link. Everything else is the file's: masses, inertias, limits, joint friction as PhysX reads it
(``PhysxJointAxisAPI`` static and dynamic friction effort, N*m or N), damping and springs as drives, the initial
state. Joint positions, velocities and the root pose come from ovphysx's articulation bindings; a joint effort is
written as the DOF actuation force for one step.

Answered: joints, root pose, stepping, joint efforts, state snapshots (DOF positions and velocities, root pose and
velocity), ``held_physics`` of the joints' friction and limits. Not answered (``EngineUnsupported``): contacts and
penetration, link frames and boxes, drives, link forces. ``options.springs`` are the file's (the USD holds them).

Extra ``ovphysx``: ``pip install 'asset2sim[ovphysx]'`` (``ovphysx``, ``physx-usd-schemas``, ``usd-core``).
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from asset2sim.engines.base import ArrayJoints, EngineUnavailable, SessionDefaults, SessionOptions, register_engine, unsupported
from asset2sim.engines.loading import collision_pieces, read_urdf, transform_points
from asset2sim.engines.step_budget import spend
from asset2sim.extras import pxr_modules

#: Object prim of the session's scene layer.
OBJECT = "/World/object"
#: Gap (m) between a free object's lowest collision point and the ground at the start: placed exactly on it (float32
#: poses), the refined cabinet 19179 was thrown 2.3 m in PhysX's first quarter second; 0.1 mm above it, it settles still.
GROUND_CLEARANCE = 1e-4
_schemas_registered = False


def _ov():
    """(``ovphysx``, ``ovstage``, ``TensorType``), imported on first use; once per process, PhysX set to the CPU and
    the PhysX and Newton schemas registered with ovstage."""
    global _schemas_registered
    import ovphysx
    import ovstage
    from ovphysx.samples.python_samples.schema_support import physx_schema_paths
    from ovphysx.types import TensorType

    if not _schemas_registered:  # process-wide, before the first instance: the CPU, and the schemas ovstage reads
        ovphysx.PhysX.set_cpu_mode(True)
        ovstage.population.register_usd_schemas([*[str(p) for p in physx_schema_paths()], str(ovphysx.newton_schema_root())])
        _schemas_registered = True
    return ovphysx, ovstage, TensorType


def lowest_point(model, state: dict[str, float]) -> float:
    """Lowest z (m) of the URDF's collision pieces at joint positions ``state`` with the root at the world origin (as
    the USD export poses the links); 0 without pieces."""
    pieces, _ = collision_pieces(model)
    poses = model.link_poses(state)
    lows = [float(transform_points(poses[link] @ p.origin, p.points)[:, 2].min())
            for link, plist in pieces.items() for p in plist if p.points is not None]
    return min(lows, default=0.0)


def scene_layer(usd: Path, options: SessionOptions, lift: float, root_link_prim: str | None) -> str:
    """The session's scene (``.usda`` text): physics scene, ground (``options.ground``), the object referenced from
    ``usd`` lifted ``lift`` m, and with ``root_link_prim`` (the root link's prim under the object) a fixed joint to
    the world."""
    conv = options.conventions
    steps = round(1.0 / conv.timestep)
    gravity = abs(conv.gravity) if options.gravity else 0.0
    ground = ('    def Plane "ground" (prepend apiSchemas = ["PhysicsCollisionAPI"])\n    {\n        uniform token axis = "Z"\n'
              '        double length = 100\n        double width = 100\n    }\n') if options.ground else ""
    fixed = (f'    def PhysicsFixedJoint "root_fixed"\n    {{\n        rel physics:body1 = <{OBJECT}/{root_link_prim}>\n    }}\n'
             if root_link_prim else "")
    return f'''#usda 1.0
(
    defaultPrim = "World"
    upAxis = "Z"
    metersPerUnit = 1
    kilogramsPerUnit = 1
)
def Xform "World"
{{
    def PhysicsScene "physicsScene" (prepend apiSchemas = ["PhysxSceneAPI"])
    {{
        vector3f physics:gravityDirection = (0, 0, -1)
        float physics:gravityMagnitude = {gravity!r}
        uint physxScene:timeStepsPerSecond = {steps}
        bool physxScene:enableGPUDynamics = 0
        token physxScene:broadphaseType = "MBP"
    }}
{ground}{fixed}    def Xform "object" (prepend references = @{usd.resolve().as_posix()}@)
    {{
        double3 xformOp:translate = (0, 0, {lift!r})
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
}}
'''


class OvPhysxSession(ArrayJoints, SessionDefaults):
    """A :class:`~asset2sim.engines.base.SimSession` of the USD export in ovphysx (module docstring).

    Raises:
        EngineUnavailable: no USD export beside the URDF (parity reports the engine skipped with the reason).
        RuntimeError: ovphysx cannot load the stage, or it holds no articulation of the file's joints.
    """

    engine = "ovphysx"

    def __init__(self, urdf_path: Path, options: SessionOptions):
        ovphysx, ovstage, tt = _ov()
        _, _, Tf, Usd, _, _ = pxr_modules()
        self.options = options
        urdf_path = Path(urdf_path)
        self.usd = urdf_path.parent / "usd" / f"{urdf_path.stem}.usd"
        if not self.usd.is_file():  # a refine's candidate, or an output not exported: this engine has nothing to run
            raise EngineUnavailable(f"engine 'ovphysx' runs the USD export, and {self.usd} does not exist "
                                    "(asset2sim export OUT --format usd)")
        self._use_urdf(read_urdf(urdf_path))
        self.link_names = self.urdf.tree_order()
        usd_stage = Usd.Stage.Open(str(self.usd))
        prim_of_joint = {prim.GetName(): str(name.Get()) for prim in usd_stage.Traverse()
                         if (name := prim.GetAttribute("asset2sim:name")) and name.HasAuthoredValue()}
        links = {Tf.MakeValidIdentifier(n): n for n in self.link_names}
        root_prim = next((k for k, v in links.items() if v == self.urdf.root), self.urdf.root)
        state = {**{j: 0.0 for j in self.joint_names}, **options.initial_state}
        lift = 0.0 if options.fixed_base or not options.ground else -lowest_point(self.urdf, state) + GROUND_CLEARANCE
        self._dir = tempfile.TemporaryDirectory(prefix="asset2sim-ovphysx-")
        scene = Path(self._dir.name) / "scene.usda"
        scene.write_text(scene_layer(self.usd, options, lift, root_prim if options.fixed_base else None))
        note = (f"ovphysx {getattr(ovphysx, '__version__', '?')} on the CPU: {self.usd.name} as written, in a scene "
                f"with a ground plane and the object lifted {lift:.4g} m; springs, damping and friction as the file holds them")
        self.notes = [note]
        self._physx = ovphysx.PhysX()
        self._stage = ovstage.Stage(f"asset2sim-{id(self)}")
        try:
            ovstage.population.open_usd(self._stage, str(scene), ordinal=1, domains=ovstage.PopulationDomain.ALL)
            self._stage.advance_write_floor(ordinal=1).wait()
            self._physx.wait_task(self._physx.attach_ovstage(self._stage, read_ordinal=1))
            self._physx.wait_all()
            bind = lambda t: self._physx.create_tensor_binding(pattern=OBJECT, tensor_type=t)
            self._q = bind(tt.ARTICULATION_DOF_POSITION)
            self._qd = bind(tt.ARTICULATION_DOF_VELOCITY)
            self._f = bind(tt.ARTICULATION_DOF_ACTUATION_FORCE)
            self._root = bind(tt.ARTICULATION_ROOT_POSE)
            self._root_v = bind(tt.ARTICULATION_ROOT_VELOCITY)
            self._friction = bind(tt.ARTICULATION_DOF_FRICTION_PROPERTIES)
            self._limits = bind(tt.ARTICULATION_DOF_LIMIT)
        except Exception as exc:
            self.close()
            raise RuntimeError(f"ovphysx cannot load {self.usd}: {exc}") from exc
        if self._q.count != 1:
            self.close()
            raise RuntimeError(f"ovphysx found {self._q.count} articulations in {self.usd}, expected 1")
        prims = (str(n).rsplit("/", 1)[-1] for n in self._q.dof_names)
        self._dof = {prim_of_joint.get(p, p): i for i, p in enumerate(prims)}
        missing = [j for j in self.joint_names if j not in self._dof]
        if missing:
            self.close()
            raise RuntimeError(f"ovphysx holds no DOF for joints {missing} of {self.usd}")
        self._qadr = self._dadr = {j: i for j, i in self._dof.items() if j in self.joint_types}
        self._signs = np.ones(self._q.shape[1], np.float32)  # per DOF: PhysX's coordinate along the URDF axis
        for j, i in self._qadr.items():
            self._signs[i] = self._axis_sign(j)
        self._effort = np.zeros(self._f.shape, np.float32)
        self._applied = False
        self._states: dict[int, tuple] = {}
        held = self.joint_positions()  # the file's state; a different one asked is written (teleports the parts)
        if any(abs(held[j] - float(v)) > 1e-6 for j, v in options.initial_state.items() if j in held):
            self.set_joint_positions(options.initial_state)

    def _axis_sign(self, joint: str) -> float:
        """+1 or -1: PhysX's DOF coordinate along the URDF joint's (the export turns each joint frame so its axis is
        x; the sign is read from the lower limit PhysX holds against the file's; +1 for limits symmetric about 0 or
        none, which the export's frames give on every dev row: each initial state reads back as written)."""
        lo = float(self._read(self._limits)[0, self._dof[joint], 0])
        want_lo, want_hi = self.joint_limits[joint]
        if not (math.isfinite(want_lo) and math.isfinite(want_hi)) or abs(want_lo + want_hi) < 1e-6:
            return 1.0
        return 1.0 if abs(lo - want_lo) <= abs(lo + want_hi) else -1.0

    # ------------------------------------------------------------------ state
    def _read(self, binding) -> np.ndarray:
        out = np.zeros(binding.shape, np.float32)
        binding.read(out)
        return out

    def _joint_q(self) -> np.ndarray:
        """The first articulation's DOF positions (n,) along the URDF axes (a copy)."""
        return self._read(self._q)[0] * self._signs

    def _joint_qd(self) -> np.ndarray:
        return self._read(self._qd)[0] * self._signs

    def _put_joints(self, q: np.ndarray, qd: np.ndarray) -> None:
        self._q.write((q * self._signs)[None])
        self._qd.write((qd * self._signs)[None])

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Position (3,) m and quaternion (x, y, z, w) of the articulation root (ovphysx: px py pz qx qy qz qw)."""
        r = self._read(self._root)[0].astype(float)
        return r[:3].copy(), r[3:7].copy()

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        i = self._qadr[joint]
        self._effort[0, i] += self._signs[i] * float(effort)
        self._applied = True

    def save_state(self) -> int:
        return self._keep_state(tuple(self._read(b) for b in self._saved()))

    def restore_state(self, handle: int) -> None:
        for binding, values in zip(self._saved(), self._states[handle]):
            binding.write(values)

    def _saved(self) -> tuple:
        """The bindings a snapshot holds: DOF positions and velocities, root pose and velocity."""
        return self._q, self._qd, self._root, self._root_v

    def step(self, n: int = 1) -> None:
        spend(n)  # the refine's one budget of steps (asset2sim.engines.step_budget)
        dt = self.options.conventions.timestep
        for _ in range(int(n)):
            if self._applied:
                self._f.write(self._effort)
            self._physx.step(dt)
            self._physx.wait_all()
            if self._applied:  # efforts act for one step
                self._effort[:] = 0.0
                self._f.write(self._effort)
                self._applied = False

    def held_friction(self) -> dict[str, tuple[float, float, float]]:
        """joint -> (static, dynamic, viscous) friction as PhysX holds it (N*m or N; viscous per its unit)."""
        fr = self._read(self._friction)[0]
        return {j: tuple(float(x) for x in fr[i]) for j, i in self._qadr.items()}

    def close(self) -> None:
        physx, stage = getattr(self, "_physx", None), getattr(self, "_stage", None)
        try:
            if physx is not None and stage is not None and physx.is_stage_attached(stage):
                physx.wait_task(physx.detach_ovstage())
            if physx is not None:
                physx.destroy()
            if stage is not None:
                stage.destroy()
        finally:
            self._physx = self._stage = None
            if getattr(self, "_dir", None) is not None:
                self._dir.cleanup()
                self._dir = None


for _query, _what in (("self_penetration", "contacts (penetration)"), ("ground_penetration", "ground penetration"),
                      ("link_frame", "link frames"), ("link_aabb", "link boxes"), ("drive_joint", "joint drives"),
                      ("release_joint", "joint drives"), ("apply_link_force", "link forces")):
    setattr(OvPhysxSession, _query, unsupported(f"ovphysx: {_what} is not read from the USD runtime here"))
register_engine("ovphysx", OvPhysxSession)
