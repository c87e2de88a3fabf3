"""Simulator protocol and registry: an engine opens a :class:`SimSession` on a
URDF under the SPEC's measurement conventions ("How quality is measured";
``docs/design/simulators.md``) and registers with :func:`register_engine`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Protocol

import numpy as np

from asset2sim.schemas.config import SimConventions


@dataclass(frozen=True)
class Spring:
    """A joint spring, applied each step as :meth:`force`: torque/force -stiffness * (q - reference)
    (``stiffness`` N*m/rad or N/m, ``reference`` rad or m; SPEC, "How quality is measured"). Every output format
    carries it (MJCF ``stiffness`` / ``springref``, a UsdPhysics drive; the URDF through ``overlay.json``)."""

    stiffness: float
    reference: float

    def force(self, q: float) -> float:
        """Generalised force (N*m or N) at ``q`` (rad or m): -stiffness (q - reference)."""
        return -self.stiffness * (float(q) - self.reference)


@dataclass
class ContactPair:
    """Penetration between two links of the same body: ``depth`` m, the sum of
    max(0, -separation) over its points; ``max_depth`` m, the deepest point."""

    link_a: str
    link_b: str
    depth: float
    max_depth: float
    points: int


@dataclass
class SessionOptions:
    """How to open a session: ``initial_state`` joint -> rad or m; ``springs``
    joint -> :class:`Spring`; ``fixed_base`` pins the root; ``gravity`` False
    disables it; ``files_key``: a name for the exact contents of every file the session loads (a candidate's
    digest in its workspace, :meth:`asset2sim.tasks.assemble.candidate.Workspace.session`): sessions of one key
    may reuse what an engine kept of those files (PyBullet: an idle client that loaded them); None keeps nothing."""

    initial_state: dict[str, float] = field(default_factory=dict)
    springs: dict[str, Spring] = field(default_factory=dict)
    fixed_base: bool = False
    gravity: bool = True
    ground: bool = True
    conventions: SimConventions = field(default_factory=SimConventions)
    files_key: str | None = None
    press_efforts: dict[str, float] = field(default_factory=dict)
    """joint -> the most effort (N*m or N) a hand presses it with, the top of its operating range (an output folder's
    ``report.json``): what the MJCF's limit aid is judged on (:mod:`asset2sim.engines.mjcf.aids`)."""
    object_root_fixed: bool | None = None
    """The object's own root as its files declare it (True: mounted; False: it stands free), whatever ``fixed_base``
    the session asks: the MJCF's solver aids are judged on the object as its export writes it, this root with gravity
    on, so that a session that holds a free object's root carries the exported file's aids. None: judged on the
    session's own model."""


def session_root_options(fixed: bool) -> dict[str, bool]:
    """:class:`SessionOptions` keywords for a root as declared: mounted -> fixed base, no ground (the mount holds
    it where the file puts it); free -> ``{}`` (resting on the ground)."""
    return {"fixed_base": True, "ground": False} if fixed else {}


@dataclass
class HeldLink:
    """A rigid body as an engine holds it after loading: ``mass`` kg, ``com``
    (3,) m in the URDF link frame, ``principal`` (3,) kg*m^2 the principal
    moments of inertia about the COM, ascending."""

    mass: float
    com: np.ndarray
    principal: np.ndarray


@dataclass
class HeldJoint:
    """A movable joint as an engine holds it (SI, rad or m): limits (+-inf:
    unlimited), viscous ``damping``, Coulomb ``friction``, spring ``stiffness``
    and ``reference`` (None without a spring), initial ``position``."""

    lower: float
    upper: float
    damping: float
    friction: float
    stiffness: float
    reference: float | None
    position: float


@dataclass
class HeldPhysics:
    """What an engine holds after loading a file (URDF, MJCF, USD: ``source``),
    read back from the engine, by URDF link and joint name; ``how``: where each
    quantity was read, for the report."""

    engine: str
    source: str
    links: dict[str, HeldLink]
    joints: dict[str, HeldJoint]
    how: dict[str, str] = field(default_factory=dict)
    welded_to_world: list[str] = field(default_factory=list)
    """Links welded to the world (a fixed root): their mass may not be kept."""


def principal_moments(tensor: np.ndarray) -> np.ndarray:
    """Principal moments (3,) ascending of a symmetric inertia tensor (3, 3)
    (eigenvalues, ``numpy.linalg.eigvalsh``)."""
    t = np.asarray(tensor, float)
    return np.sort(np.linalg.eigvalsh(0.5 * (t + t.T)))


class EngineUnsupported(NotImplementedError):
    """The engine cannot answer this query (names the engine and the query)."""


@dataclass(frozen=True)
class EngineTraits:
    """What stage code needs to know of an engine beyond the protocol's queries, so that no stage keys a
    decision by engine name (each engine's session class declares its own; the defaults are the cautious ones).

    Attributes:
        reference: the SPEC's reference engine, on which its metrics are defined (PyBullet): the evaluation
            takes its extra measurements (extents, the sweep's extras) there.
        conservative_aabb: ``link_aabb`` encloses the link's collision shapes with the contact margin, so two
            links whose boxes are disjoint cannot be in contact (pairs are screened by box).
        springs_by_torque: joint springs are applied as a torque every step (PyBullet's torque control),
            which makes position holds of other joints drift: sweeps leave the others passive.
        incremental_penetration: ``self_penetration_fresh`` and per-pair closest points are cheap, so the
            state search re-queries only the pairs a moved joint touches
            (:class:`asset2sim.tasks.state.penetration.StatePenetration`).
    """

    reference: bool = False
    conservative_aabb: bool = False
    springs_by_torque: bool = False
    incremental_penetration: bool = False


class SimSession(Protocol):
    """One loaded asset in one engine; a query the engine cannot answer raises
    :class:`EngineUnsupported`. Positions m, angles rad, quaternions x, y, z,
    w, every pose in the world frame."""

    engine: str
    traits: EngineTraits
    """What the stages need to know of this engine (:class:`EngineTraits`)."""
    notes: list[str]
    """What the engine changed or could not load of the asset (a missing inertial, a shape not cooked)."""
    options: SessionOptions
    joint_names: list[str]
    """Movable (revolute, continuous, prismatic) joints, in file order."""
    joint_types: dict[str, str]
    joint_limits: dict[str, tuple[float, float]]
    joint_child: dict[str, str]
    """Movable joint -> its child link."""
    link_names: list[str]
    """Every link of the URDF, the root first (PyBullet: then in joint index order)."""

    # -------------------------------------------------------------- joints
    def set_joint_positions(self, q: dict[str, float]) -> None:
        """Teleport joints (rad or m) at zero velocity; unspecified joints keep their value."""

    def joint_positions(self) -> dict[str, float]:
        """Current joint positions (rad or m)."""

    def joint_velocities(self) -> dict[str, float]:
        """Current joint velocities (rad/s or m/s)."""

    def joint_state(self, joint: str) -> tuple[float, float]:
        """Position (rad or m) and velocity (rad/s or m/s) of one movable joint
        (KeyError: not a movable joint)."""

    def joint_axis(self, joint: str) -> np.ndarray:
        """Axis (3,) of a movable joint in its child link's frame (KeyError:
        not a movable joint)."""

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        """Generalized force (N*m or N) on a joint for the next step."""

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        """Drive a movable joint towards ``velocity`` (rad/s or m/s) with a
        motor of at most ``max_force`` (N*m or N, >= 0) on every step until
        :meth:`release_joint`; the joint's Coulomb friction stays a load.

        Raises:
            KeyError: not a movable joint.
            EngineUnsupported: the engine has no drives.
        """

    def release_joint(self, joint: str) -> None:
        """End :meth:`drive_joint` (KeyError: not a movable joint)."""

    # --------------------------------------------------------------- links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) m and rotation (3, 3) of the link's URDF frame
        (KeyError: unknown link)."""

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """The engine's world bounding box (lo (3,), hi (3,)) m of a link's
        collision shapes (KeyError: unknown link)."""

    def link_has_collision(self, link: str) -> bool:
        """Whether the link carries at least one collision shape."""

    def link_collision_vertices(self, link: str) -> np.ndarray:
        """Vertices (k, 3) of the link's collision meshes in the link frame, m
        (k = 0 when it has none or the engine keeps none)."""

    def link_masses(self) -> dict[str, float]:
        """Mass (kg) the engine uses for every link (defaults included)."""

    def link_distances(self, link_a: str, link_b: str, max_distance: float = 0.0) -> list[float]:
        """Signed closest-point distances (m, < 0: penetration) between two
        links' collision shapes within ``max_distance``, parent-child pairs
        included, independent of cached contacts (KeyError: unknown link)."""

    def apply_link_force(self, link: str, force: np.ndarray, point: np.ndarray) -> None:
        """External force (3,) N at a world point (3,) m on a link, for the
        next step only."""

    # ---------------------------------------------------------------- root
    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Root link position (3,) m and orientation quaternion (4,) x, y, z, w."""

    def set_root_pose(self, pos: np.ndarray, orn: np.ndarray) -> None:
        """Teleport the root to ``pos`` (3,) m, ``orn`` (4,) xyzw; zero its velocity."""

    def set_root_velocity(self, linear: np.ndarray, angular: np.ndarray) -> None:
        """Set the root's linear (3,) m/s and angular (3,) rad/s velocity,
        world frame (EngineUnsupported: fixed base, or no dynamics)."""

    def hold_root(self, max_force: float) -> None:
        """Hold the root at its current pose by a fixed constraint of at most
        ``max_force`` (N, and N*m on its torque rows) until :meth:`release_root`;
        a no-op on a fixed base (EngineUnsupported: no bounded constraints)."""

    def release_root(self) -> None:
        """End :meth:`hold_root` (no-op when the root is not held)."""

    # ------------------------------------------------------------- contact
    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        """Phi (m) = sum over self-contact points of max(0, -separation), and the
        pairs sorted by depth (deepest first). Contacts with the ground excluded."""

    def ground_penetration(self) -> float:
        """Deepest penetration of any link into the ground plane, m (>= 0)."""

    def place_on_ground(self) -> float:
        """Move a free root vertically so the lowest collision point of the object lies on the ground (z = 0);
        returns the height moved, m (EngineUnsupported where the engine has no exact lowest point)."""

    def step_ground_penetration(self) -> float:
        """Deepest ground penetration (m, >= 0) among the last step's contacts,
        without a new collision query."""

    # ------------------------------------------------------------ dynamics
    def step(self, n: int = 1) -> None:
        """Advance n timesteps, applying springs each step."""

    def save_state(self) -> int:
        """Snapshot the simulation state; returns a handle for :meth:`restore_state`."""

    def restore_state(self, handle: int) -> None:
        """Return to a snapshot of :meth:`save_state`."""

    def discard_state(self, handle: int) -> None:
        """Free a snapshot."""

    def held_physics(self) -> HeldPhysics:
        """Every link's and movable joint's physics as the engine holds them."""

    def close(self) -> None:
        """Release the engine's resources."""


class SessionDefaults:
    """Mixed into every session class: a context manager that closes it;
    ``step_ground_penetration`` = ``ground_penetration`` (no contact cache);
    snapshots kept in ``_states`` (:meth:`_keep_state`, ``discard_state``);
    ``hold_root`` / ``release_root`` of an engine without a bounded root
    constraint (a no-op on a fixed base, else :class:`EngineUnsupported`); ``place_on_ground`` of an
    engine without an exact lowest point (:class:`EngineUnsupported`); the cautious :class:`EngineTraits`
    and no notes."""

    engine: str
    options: SessionOptions
    traits: EngineTraits = EngineTraits()
    notes: tuple[str, ...] | list[str] = ()

    def step_ground_penetration(self) -> float:
        return self.ground_penetration()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def hold_root(self, max_force: float) -> None:
        if not self.options.fixed_base:
            raise EngineUnsupported(f"{self.engine}: no bounded root hold")

    def release_root(self) -> None:
        pass

    def place_on_ground(self) -> float:
        raise EngineUnsupported(f"{self.engine}: no exact lowest collision point to place on the ground")

    def _movable_root(self) -> None:
        """Raise :class:`EngineUnsupported` in a fixed-base session, whose root cannot be moved."""
        if self.options.fixed_base:
            raise EngineUnsupported(f"{self.engine}: the root of a fixed-base session cannot be moved")

    def _world_bounds(self, link: str, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World bounding box (lo (3,), hi (3,)) m of ``points`` (k, 3) in ``link``'s frame; the link origin when
        k = 0."""
        pos, rot = self.link_frame(link)
        if not len(points):
            return pos.copy(), pos.copy()
        w = np.asarray(points, float) @ rot.T + pos
        return w.min(axis=0), w.max(axis=0)

    def _keep_state(self, state) -> int:
        """Keep a snapshot in the session's ``_states`` (handle -> snapshot) of an engine without saved states of its
        own; its handle for :meth:`restore_state`."""
        handle = max(self._states, default=0) + 1
        self._states[handle] = state
        return handle

    def discard_state(self, handle: int) -> None:
        self._states.pop(handle, None)

    def _use_urdf(self, model) -> None:
        """``urdf`` = ``model`` (an :class:`~asset2sim.urdf.UrdfModel`) and ``joint_names``, ``joint_types``,
        ``joint_limits`` and ``joint_child`` of its movable joints, in file order."""
        self.urdf = model
        self.joint_names = [j.name for j in model.movable_joints]
        self.joint_types = {j.name: j.type for j in model.movable_joints}
        self.joint_limits = {j.name: (j.lower, j.upper) for j in model.movable_joints}
        self.joint_child = {j.name: j.child for j in model.movable_joints}


class ArrayJoints:
    """Mixed into a session whose engine holds joint positions and velocities in flat arrays: its joint queries.
    The session gives ``_qadr`` / ``_dadr`` (movable joint -> index of its position / velocity), ``_joint_q()`` /
    ``_joint_qd()`` (the arrays, writable: views or copies) and ``_put_joints(q, qd)`` (writes both back and updates
    the link poses)."""

    def set_joint_positions(self, q: dict[str, float]) -> None:
        jq, jd = self._joint_q(), self._joint_qd()
        for name, v in q.items():
            if name in self._qadr:
                jq[self._qadr[name]] = float(v)
                jd[self._dadr[name]] = 0.0
        self._put_joints(jq, jd)

    def joint_positions(self) -> dict[str, float]:
        jq = self._joint_q()
        return {n: float(jq[a]) for n, a in self._qadr.items()}

    def joint_velocities(self) -> dict[str, float]:
        jd = self._joint_qd()
        return {n: float(jd[a]) for n, a in self._dadr.items()}

    def joint_state(self, joint: str) -> tuple[float, float]:
        return float(self._joint_q()[self._qadr[joint]]), float(self._joint_qd()[self._dadr[joint]])


class ShapeWorld(Protocol):
    """Free static convex shapes in a private collision world: distance queries."""

    contact_margin: float
    """Distance (m) reported as penetration between two touching convex shapes
    (the engine's collision margins; PyBullet: 2 mm)."""

    def add_convex(self, vertices: np.ndarray, scale: np.ndarray, position: np.ndarray, orientation: np.ndarray) -> int:
        """Add the convex hull of ``vertices`` (k, 3), scaled per axis by
        ``scale`` (3,), at ``position`` (3,) m and ``orientation`` (4,) xyzw;
        returns its id."""

    def set_pose(self, shape: int, position, orientation) -> None:
        """Move a shape to ``position`` (3,) m, ``orientation`` (4,) xyzw."""

    def distances(self, shape_a: int, shape_b: int, max_distance: float = 0.0) -> list[float]:
        """Signed distances (m, negative = penetration) of the closest points
        between two shapes, within ``max_distance``."""

    def close(self) -> None:
        """Release the world."""


class Viewer(Protocol):
    """A URDF loaded for drawing (fixed base, visual shapes, MTL colours)."""

    joint_names: list[str]
    """Movable (revolute, prismatic) joints, in joint index order."""
    link_names: list[str]
    """Every link, the root first."""

    def visual_colors(self) -> list[tuple[str, int, tuple[float, float, float, float]]]:
        """(link, shape index within the link, rgba) of every visual shape."""

    def set_visual_color(self, link: str, shape: int, rgba) -> None:
        """Change the rgba (4,) of one visual shape."""

    def set_joint_positions(self, q: dict[str, float]) -> None:
        """Teleport joints (rad or m), zero velocity."""

    def set_root_pose(self, position, quat_xyzw) -> None:
        """Place the root link's URDF frame at ``position`` (3,) m with orientation ``quat_xyzw`` (4,)."""

    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) m and rotation (3, 3) of the link's URDF frame."""

    def draw(self, width: int, height: int, camera: dict, light: dict) -> tuple[np.ndarray, np.ndarray]:
        """RGBA (height, width, 4) uint8 and segmentation (height, width) int
        (< 0: no body) from ``camera`` (eye, target, up (3,) m; fov_deg, near,
        far) under ``light`` (direction, color, distance, shadow, ambient,
        diffuse, specular)."""

    def close(self) -> None:
        """Release the viewer."""


def penetration_sum(points: Iterable[tuple[str, str, float]]) -> tuple[float, list[ContactPair]]:
    """``(Phi, pairs)`` of ``(link_a, link_b, separation m)`` contact points
    (summed in the given order): Phi (m) = sum of max(0, -separation) (SPEC,
    "Refine the initial state"); one :class:`ContactPair` per penetrating
    unordered link pair, deepest total first."""
    pairs: dict[tuple[str, str], ContactPair] = {}
    total = 0.0
    for a, b, d in points:
        if d >= 0.0:
            continue
        key = (a, b) if a <= b else (b, a)
        if key not in pairs:
            pairs[key] = ContactPair(*key, 0.0, 0.0, 0)
        cp = pairs[key]
        cp.depth += -d
        cp.max_depth = max(cp.max_depth, -d)
        cp.points += 1
        total += -d
    return total, sorted(pairs.values(), key=lambda c: -c.depth)


EngineFactory = Callable[[Path, SessionOptions], SimSession]
#: ``reader(path, links, joints) -> HeldPhysics`` of an exported file (MJCF, USD).
FileReader = Callable[[Path, list[str], list[str]], HeldPhysics]

_ENGINES: dict[str, EngineFactory] = {}
_FILE_READERS: dict[tuple[str, str], FileReader] = {}
_SHAPE_WORLDS: dict[str, Callable[[], ShapeWorld]] = {}
_VIEWERS: dict[str, Callable[[Path], Viewer]] = {}


class EngineUnavailable(RuntimeError):
    """The engine's Python package is not installed (an optional extra)."""


def unsupported(message: str) -> Callable:
    """A session method for a query the engine does not answer: it raises :class:`EngineUnsupported` ``message``."""
    def method(self, *args, **kwargs):
        raise EngineUnsupported(message)
    return method


def register_engine(name: str, factory: EngineFactory) -> None:
    """Register ``factory(urdf_path, options) -> SimSession`` under ``name``."""
    _ENGINES[name] = factory


def register_shape_world(name: str, factory: Callable[[], ShapeWorld]) -> None:
    """Register ``factory() -> ShapeWorld`` under the engine name ``name``."""
    _SHAPE_WORLDS[name] = factory


def register_viewer(name: str, factory: Callable[[Path], Viewer]) -> None:
    """Register ``factory(urdf_path) -> Viewer`` under the engine name ``name``."""
    _VIEWERS[name] = factory


def register_file_reader(engine: str, fmt: str, reader: FileReader) -> None:
    """Register ``engine``'s :data:`FileReader` of format ``fmt`` (``"mjcf"``, ``"usd"``)."""
    _FILE_READERS[(engine, fmt)] = reader


