"""What every engine loads from a URDF, so that all see the same inertials,
frames and collision hulls (PyBullet's: one per OBJ group), Bullet's
defaults the other engines copy, and an overlay's joint springs. An output
folder is read by :class:`asset2sim.refined_asset.RefinedAsset`. Pure numpy; units SI, radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import file_memo, urdf
from asset2sim.engines.base import Spring
from asset2sim.mesh_io import MeshReadError, hull_point_sets
from asset2sim.urdf import SIMULATED_JOINT_TYPES, UrdfError, UrdfModel
from asset2sim.schemas.overlay import Overlay

#: What PyBullet 3.2.7 gives a link without ``<inertial>``: 1 kg, identity
#: inertia (kg*m^2) at the link origin (Bullet's ``UrdfParser``).
BULLET_DEFAULT_MASS = 1.0
BULLET_DEFAULT_INERTIA = (1.0, 1.0, 1.0)
#: PyBullet's default lateral friction of a link and of its ground plane (contact friction: the product).
BULLET_DEFAULT_FRICTION = 0.5
BULLET_PLANE_FRICTION = 0.5
#: Contact friction of a link without ``<contact>`` on the ground (PyBullet's 0.5 x 0.5).
CONTACT_FRICTION = BULLET_DEFAULT_FRICTION * BULLET_PLANE_FRICTION
#: The eight corners (8, 3) of the box [-1, 1]^3.
BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` (k, 3) m moved by ``pose`` (4, 4): rotated, then translated."""
    return np.asarray(points, float) @ pose[:3, :3].T + pose[:3, 3]


def read_urdf(path: Path | str) -> UrdfModel:
    """:func:`asset2sim.urdf.read_urdf` (strict) limited to the joint types the
    engines build (UrdfError naming the file, line and link or joint)."""
    return urdf.read_urdf(path, joint_types=SIMULATED_JOINT_TYPES)


def link_friction(model: UrdfModel, link: str) -> float:
    """PyBullet's contact friction of a link on the ground plane: its lateral friction x the plane's."""
    lat = model.links[link].lateral_friction
    return (BULLET_DEFAULT_FRICTION if lat is None else lat) * BULLET_PLANE_FRICTION


def principal_axes(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments (3,) kg*m^2 and axes (3, 3) (columns, a proper
    rotation, det = +1) of a symmetric inertia tensor (3, 3):
    ``tensor = axes @ diag(moments) @ axes.T`` (numpy ``eigh``)."""
    t = np.asarray(tensor, float)
    w, v = np.linalg.eigh(0.5 * (t + t.T))
    if np.linalg.det(v) < 0:
        v[:, 2] = -v[:, 2]
    return w, v


#: Unscaled point sets of the collision meshes by path, while the file is unchanged (shared, never modified).
_HULLS: file_memo.FileMemo[list[np.ndarray]] = file_memo.FileMemo(list, max_entries=4096)


def mesh_hulls(path: Path, scale=(1.0, 1.0, 1.0)) -> list[np.ndarray]:
    """Point sets (k, 3) m whose convex hulls PyBullet uses for collision mesh
    ``path`` scaled by ``scale`` (3,): one per OBJ group (other formats: one),
    degenerate ones kept (UrdfError: the mesh cannot be read)."""
    path = Path(path)
    groups = _HULLS.get(str(path))
    if groups is None:
        files = file_memo.identities([path])  # before reading
        if files[0][1] is None:
            raise UrdfError(f"collision mesh {path} does not exist")
        try:
            groups = hull_point_sets(path)
        except MeshReadError as exc:
            raise UrdfError(str(exc)) from exc
        _HULLS.put(str(path), files, groups)
    s = np.asarray(scale, float).reshape(3)
    return [g * s for g in groups]


def hull_is_solid(points: np.ndarray) -> bool:
    """True when the points (k, 3) span a volume (not all on one plane/line, to 1e-9 of their spread)."""
    p = np.asarray(points, float)
    if len(p) < 4:
        return False
    c = p - p.mean(axis=0)
    sv = np.linalg.svd(c, compute_uv=False)
    return bool(sv[-1] > 1e-9 * max(1.0, sv[0]))


#: Thickness (m) of the slab made of a coplanar hull (PyBullet inflates one by its 1 mm margin per side).
FLAT_HULL_THICKNESS = 0.002


@dataclass
class CollisionPiece:
    """One convex collision shape of a link, as PyBullet builds it: ``kind``
    ``hull`` (``points`` (k, 3) m, scaled), ``box`` (``size`` (3,) m),
    ``sphere`` (``radius``) or ``cylinder`` (``radius``, ``length`` along z);
    ``origin`` (4, 4) in the link frame; ``collision`` / ``group`` the
    ``<collision>`` and OBJ group indices; ``whole_file``: the hull is the
    single-group file ``source`` unchanged; ``thickened``: a coplanar group made a slab.
    """

    link: str
    collision: int
    group: int
    kind: str
    origin: np.ndarray
    points: np.ndarray | None = None
    size: np.ndarray | None = None
    radius: float | None = None
    length: float | None = None
    source: Path | None = None
    scale: np.ndarray | None = None
    whole_file: bool = False
    thickened: bool = False


def _thicken(points: np.ndarray, thickness: float) -> np.ndarray | None:
    p = np.asarray(points, float)
    c = p.mean(axis=0)
    _, sv, vt = np.linalg.svd(p - c, full_matrices=False)
    if len(sv) < 2 or sv[1] <= 1e-12 * max(1.0, sv[0]):
        return None  # a point or a segment: nothing to collide with
    n = vt[-1] if len(vt) == 3 else np.cross(vt[0], vt[1])
    n = n / np.linalg.norm(n)
    h = 0.5 * thickness
    return np.vstack([p + h * n, p - h * n])


def collision_pieces(model: UrdfModel) -> tuple[dict[str, list[CollisionPiece]], list[str]]:
    """Every link's convex collision pieces (one hull per OBJ group) and notes:
    coplanar groups become slabs :data:`FLAT_HULL_THICKNESS` m thick, groups spanning
    no area are dropped (UrdfError: a mesh cannot be read)."""
    out: dict[str, list[CollisionPiece]] = {}
    notes: list[str] = []
    for name, link in model.links.items():
        pieces: list[CollisionPiece] = []
        for k, c in enumerate(link.collisions):
            if c.kind != "mesh":
                pieces.append(CollisionPiece(name, k, 0, c.kind, c.origin, size=c.size, radius=c.radius, length=c.length))
                continue
            groups = mesh_hulls(c.path, c.scale)
            for g, pts in enumerate(groups):
                thick = False
                if not hull_is_solid(pts):
                    slab = _thicken(pts, FLAT_HULL_THICKNESS)
                    if slab is None:
                        notes.append(f"link {name!r} collision {k} group {g} ({c.filename}) spans no area: dropped")
                        continue
                    notes.append(f"link {name!r} collision {k} group {g} ({c.filename}) is flat: made a {FLAT_HULL_THICKNESS * 1000:g} mm slab")
                    pts, thick = slab, True
                pieces.append(CollisionPiece(name, k, g, "hull", c.origin, points=pts, source=c.path, scale=c.scale,
                                             whole_file=len(groups) == 1 and not thick, thickened=thick))
        out[name] = pieces
    return out, notes


def overlay_springs(overlay: Overlay, initial_state: dict[str, float] | None = None) -> dict[str, Spring]:
    """Joint springs of ``overlay``: every joint with stiffness > 0 (N*m/rad or N/m), about ``spring_reference``
    (rad or m), else about ``initial_state`` (else 0)."""
    state = initial_state or {}
    return {name: Spring(stiffness=float(dyn.stiffness),
                         reference=float(state.get(name, 0.0) if dyn.spring_reference is None else dyn.spring_reference))
            for name, dyn in overlay.joints.items() if dyn.stiffness > 0}
