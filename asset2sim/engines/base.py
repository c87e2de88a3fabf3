"""Simulator protocol and registry.

An *engine* opens a :class:`SimSession` on a URDF under the SPEC's measurement
conventions ("How quality is measured"):

- timestep 1/240 s, gravity -9.81 m/s^2 along z, a ground plane at z = 0;
- self-collision on except between a link and its parent;
- inertia taken from the file;
- the root free (not fixed), placed so its lowest collision point touches the
  ground, joints at the initial state;
- passive joints: Coulomb friction as a zero-target-velocity motor whose maximum
  force is ``<dynamics friction>``, viscous damping ``<dynamics damping>``, and a
  spring torque -k (q - q_s) applied each step where the overlay has one.

Metrics (``asset2sim.tasks.check.metrics``) only use this protocol, so the same
definitions run in every engine. Engines register with :func:`register_engine`;
heavy engines are imported lazily by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Protocol

import numpy as np

from asset2sim.schemas.config import SimConventions


@dataclass(frozen=True)
class Spring:
    """A joint spring: torque/force -stiffness * (q - reference) each step.

    ``stiffness`` N*m/rad or N/m, ``reference`` rad or m.
    """

    stiffness: float
    reference: float


@dataclass
class ContactPair:
    """Penetration between two links of the same body.

    ``depth`` m: sum over the pair's contact points of max(0, -separation);
    ``max_depth`` m: the deepest point.
    """

    link_a: str
    link_b: str
    depth: float
    max_depth: float
    points: int


@dataclass
class SessionOptions:
    """How to open a session.

    ``initial_state``: joint name -> position (rad or m). ``springs``: joint name
    -> :class:`Spring`. ``fixed_base``: pin the root (used only by state
    refinement, never by the SPEC's metrics). ``gravity``: False disables it
    (contact queries only).
    """

    initial_state: dict[str, float] = field(default_factory=dict)
    springs: dict[str, Spring] = field(default_factory=dict)
    fixed_base: bool = False
    gravity: bool = True
    ground: bool = True
    conventions: SimConventions = field(default_factory=SimConventions)


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
    """A movable joint as an engine holds it (SI: rad or m): ``lower`` /
    ``upper`` limits (+-inf when unlimited), viscous ``damping`` (N*m*s/rad or
    N*s/m), Coulomb ``friction`` (N*m or N), spring ``stiffness`` (N*m/rad or
    N/m) and ``reference`` (rad or m; None without a spring), ``position`` the
    initial joint position."""

    lower: float
    upper: float
    damping: float
    friction: float
    stiffness: float
    reference: float | None
    position: float


@dataclass
class HeldPhysics:
    """What an engine holds after loading a file, read back from the engine's
    own data structures (not from the file), by URDF link and joint name.

    ``source``: the file the engine loaded (URDF, MJCF, USD); ``how``: where
    each quantity was read (engine API / attribute names), for the report.
    """

    engine: str
    source: str
    links: dict[str, HeldLink]
    joints: dict[str, HeldJoint]
    how: dict[str, str] = field(default_factory=dict)
    welded_to_world: list[str] = field(default_factory=list)
    """Links the engine welds to the world (a fixed root): their mass and
    inertia take no part in the simulation and some engines do not keep them
    (PyBullet stores 0 kg for a fixed base)."""


def principal_moments(tensor: np.ndarray) -> np.ndarray:
    """Principal moments (3,) ascending of a symmetric inertia tensor (3, 3)
    (eigenvalues, ``numpy.linalg.eigvalsh``)."""
    t = np.asarray(tensor, float)
    return np.sort(np.linalg.eigvalsh(0.5 * (t + t.T)))


class EngineUnsupported(NotImplementedError):
    """The engine cannot answer this query (names the engine and the query)."""


class SimSession(Protocol):
    """One loaded asset in one engine.

    Stages talk to a simulator only through these attributes and methods
    (as dm_control's tasks talk to ``Physics``); an engine that cannot answer
    a query raises :class:`EngineUnsupported`. Positions m, angles rad,
    quaternions x, y, z, w, every pose in the world frame.
    """

    engine: str
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
    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        """Teleport joints (rad or m); unspecified joints keep their value."""

    def joint_positions(self) -> dict[str, float]:
        """Current joint positions (rad or m)."""

    def joint_velocities(self) -> dict[str, float]:
        """Current joint velocities (rad/s or m/s)."""

    def joint_state(self, joint: str) -> tuple[float, float]:
        """Position (rad or m) and velocity (rad/s or m/s) of one movable joint.

        Raises:
            KeyError: not a movable joint.
        """

    def joint_axis(self, joint: str) -> np.ndarray:
        """Axis (3,) of a movable joint in its child link's frame, as the
        engine holds it (world axis: ``link_frame(joint_child[joint])[1] @ axis``).

        Raises:
            KeyError: not a movable joint.
        """

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        """Generalized force (N*m or N) on a joint for the next step."""

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        """Drive a movable joint towards ``velocity`` (rad/s or m/s) with a
        motor whose effort is at most ``max_force`` (N*m or N, >= 0), as a
        robot's force-limited velocity controller; the drive acts on every
        following step until :meth:`release_joint`. The joint's own Coulomb
        friction stays a load the drive must overcome (PyBullet and PhysX: the
        passive friction motor's limit becomes ``max_force + friction``;
        MuJoCo: ``frictionloss`` stays and the drive adds a clipped force).
        Position control is this drive with ``velocity`` recomputed each step
        from the position error (:mod:`asset2sim.tasks.check.sweep`).

        Raises:
            KeyError: not a movable joint.
            EngineUnsupported: the engine has no drives.
        """

    def release_joint(self, joint: str) -> None:
        """End :meth:`drive_joint`: the joint is passive again (Coulomb
        friction, damping, spring). Raises KeyError: not a movable joint."""

    # --------------------------------------------------------------- links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) m and rotation matrix (3, 3) of the link's URDF
        frame (the child frame of its parent joint) at the current state.

        Raises:
            KeyError: unknown link.
        """

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """The engine's axis-aligned bounding box of a link's collision
        shapes, world, (lo (3,), hi (3,)) m. PyBullet: its broadphase AABB
        (loose for rotated hulls); PhysX: bounds of the cooked hull points.

        Raises:
            KeyError: unknown link.
        """

    def link_has_collision(self, link: str) -> bool:
        """Whether the link carries at least one collision shape."""

    def link_collision_vertices(self, link: str) -> np.ndarray:
        """Vertices (k, 3) of the link's collision meshes in the link frame, m
        (k = 0 when it has none or the engine keeps none)."""

    def link_masses(self) -> dict[str, float]:
        """Mass (kg) the engine uses for every link (defaults included)."""

    def link_distances(self, link_a: str, link_b: str, max_distance: float = 0.0) -> list[float]:
        """Signed distances (m, negative = penetration) of the closest points
        between the collision shapes of two links of the body, every pair
        within ``max_distance``, parent-child pairs included. Independent of
        cached contacts.

        Raises:
            KeyError: unknown link.
        """

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
        world frame (a nudge); joint velocities are kept.

        Raises:
            EngineUnsupported: fixed base, or an engine without dynamics.
        """

    def hold_root(self, max_force: float) -> None:
        """Hold the root at its current pose as a hand grips a body: a fixed
        constraint to the world whose force is at most ``max_force`` (N; the
        engine applies the same bound, as N*m, to its torque rows), acting on
        every following step until :meth:`release_root`. A no-op on a
        fixed-base session (its root is already held).

        Raises:
            EngineUnsupported: the engine has no bounded constraints.
        """

    def release_root(self) -> None:
        """End :meth:`hold_root` (no-op when the root is not held)."""

    # ------------------------------------------------------------- contact
    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        """Phi (m) = sum over self-contact points of max(0, -separation), and the
        pairs sorted by depth (deepest first). Contacts with the ground excluded."""

    def ground_penetration(self) -> float:
        """Deepest penetration of any link into the ground plane, m (>= 0)."""

    def step_ground_penetration(self) -> float:
        """Deepest ground penetration (m, >= 0) among the contacts the last
        step generated, without a new collision query (PyBullet: a query
        would refresh its contact manifolds and change the next steps);
        engines without step contacts answer :meth:`ground_penetration`."""

    # ------------------------------------------------------------ dynamics
    def step(self, n: int = 1) -> None:
        """Advance n timesteps, applying springs each step."""

    def save_state(self) -> int:
        """Snapshot the simulation state (poses, velocities, contacts the
        engine caches); returns a handle for :meth:`restore_state`."""

    def restore_state(self, handle: int) -> None:
        """Return to a snapshot of :meth:`save_state`."""

    def discard_state(self, handle: int) -> None:
        """Free a snapshot."""

    def held_physics(self) -> HeldPhysics:
        """Every link's mass, COM and principal moments and every movable
        joint's limits, damping, friction, spring and position as the engine
        holds them (read from the engine, for the authored-equals-simulated
        check, ``asset2sim.tasks.check.authored``)."""

    def close(self) -> None:
        """Release the engine's resources."""


class NoRootHold:
    """:meth:`SimSession.hold_root` / :meth:`SimSession.release_root` of an
    engine without a bounded root constraint (every engine but PyBullet; the
    probes, which hold the root, run in PyBullet): a no-op on a fixed base,
    else :class:`EngineUnsupported`. Mixed into the engine's session class,
    which has ``engine`` and ``options``."""

    engine: str
    options: SessionOptions

    def hold_root(self, max_force: float) -> None:
        """Raises :class:`EngineUnsupported` unless the base is fixed (then a no-op)."""
        if self.options.fixed_base:
            return
        raise EngineUnsupported(f"{self.engine}: no bounded root hold")

    def release_root(self) -> None:
        """Nothing to release: :meth:`hold_root` holds nothing here."""


class ShapeWorld(Protocol):
    """Free static convex shapes in a private collision world (no articulation,
    no dynamics): distance queries between pieces of geometry."""

    contact_margin: float
    """Distance (m) the world reports between two convex shapes whose
    surfaces touch, as a penetration: the engine's collision margins of
    both shapes (PyBullet: 1 mm each, -2 mm reported for touching hulls)."""

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

    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) m and rotation (3, 3) of the link's URDF frame."""

    def draw(self, width: int, height: int, camera: dict, light: dict) -> tuple[np.ndarray, np.ndarray]:
        """RGBA (height, width, 4) uint8 and segmentation (height, width) int
        (< 0 where no body) of the scene from ``camera`` (eye, target, up (3,)
        m; fov_deg, near, far) under ``light`` (direction (3,), color (3,),
        distance m, shadow bool, ambient, diffuse, specular coefficients)."""

    def close(self) -> None:
        """Release the viewer."""


def penetration_sum(points: Iterable[tuple[str, str, float]]) -> tuple[float, list[ContactPair]]:
    """Phi and its per-pair parts from signed contact distances.

    Args:
        points: ``(link_a, link_b, separation)`` per contact point, separation
            in m (< 0: penetration), in the engine's order (the sum is taken
            in that order).

    Returns:
        ``(Phi, pairs)``: Phi (m) = sum of max(0, -separation) (SPEC,
        "Refine the initial state"); one :class:`ContactPair` per unordered
        link pair with a penetrating point, deepest total first.
    """
    pairs: dict[tuple[str, str], ContactPair] = {}
    total = 0.0
    for a, b, d in points:
        if d >= 0.0:
            continue
        key = (a, b) if a <= b else (b, a)
        cp = pairs.get(key)
        if cp is None:
            cp = pairs[key] = ContactPair(key[0], key[1], 0.0, 0.0, 0)
        cp.depth += -d
        cp.max_depth = max(cp.max_depth, -d)
        cp.points += 1
        total += -d
    return total, sorted(pairs.values(), key=lambda c: -c.depth)


EngineFactory = Callable[[Path, SessionOptions], SimSession]

ShapeWorldFactory = Callable[[], ShapeWorld]
ViewerFactory = Callable[[Path], Viewer]

#: ``reader(path, links, joints) -> HeldPhysics``: load an exported file
#: (MJCF, USD) with the engine's own importer and read back what it holds.
FileReader = Callable[[Path, list[str], list[str]], HeldPhysics]

_ENGINES: dict[str, EngineFactory] = {}
_FILE_READERS: dict[tuple[str, str], FileReader] = {}
_SHAPE_WORLDS: dict[str, ShapeWorldFactory] = {}
_VIEWERS: dict[str, ViewerFactory] = {}
class EngineUnavailable(RuntimeError):
    """The engine's Python package is not installed (an optional extra)."""


def register_engine(name: str, factory: EngineFactory) -> None:
    """Register ``factory(urdf_path, options) -> SimSession`` under ``name``."""
    _ENGINES[name] = factory


def register_shape_world(name: str, factory: ShapeWorldFactory) -> None:
    """Register ``factory() -> ShapeWorld`` under the engine name ``name``."""
    _SHAPE_WORLDS[name] = factory


def register_viewer(name: str, factory: ViewerFactory) -> None:
    """Register ``factory(urdf_path) -> Viewer`` under the engine name ``name``."""
    _VIEWERS[name] = factory


def register_file_reader(engine: str, fmt: str, reader: FileReader) -> None:
    """Register how ``engine`` loads an exported file of format ``fmt``
    (``"mjcf"``, ``"usd"``) and reads back what it holds."""
    _FILE_READERS[(engine, fmt)] = reader


