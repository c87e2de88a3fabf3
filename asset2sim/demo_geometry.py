"""Box-built geometry of the demo objects (:mod:`asset2sim.demo_assets`) and
its OBJ / MTL text: :class:`DemoLink` s of :class:`Part` s (one OBJ each) made
of axis-aligned :class:`Box` pieces in the object frame (y up, +z front),
optionally moved by a rigid :class:`Pose`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from asset2sim.frames import axis_angle_matrix

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Box:
    """Axis-aligned box ``lo`` .. ``hi`` (3,) in object units."""

    lo: Vec3
    hi: Vec3

    def __post_init__(self) -> None:
        if not all(h > l for l, h in zip(self.lo, self.hi)):
            raise ValueError(f"degenerate box {self.lo} .. {self.hi}")

    def corners(self) -> np.ndarray:
        """(8, 3) corners; index = xbit + 2*ybit + 4*zbit."""
        return np.array([[self.hi[k] if i >> k & 1 else self.lo[k] for k in range(3)] for i in range(8)], dtype=float)


#: The quads of a box (corner indices; faces -x, +x, -y, +y, -z, +z), wound
#: counter-clockwise seen from outside, and their 12 triangles.
_QUADS = ((0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (2, 6, 7, 3), (0, 2, 3, 1), (4, 5, 7, 6))
_BOX_FACES = [tri for q in _QUADS for tri in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))]


@dataclass(frozen=True)
class Pose:
    """Rigid motion x -> R (x - pivot) + pivot (object frame, units)."""

    axis: Vec3
    angle: float
    pivot: Vec3

    def apply(self, pts: np.ndarray) -> np.ndarray:
        """Points (N, 3) moved by the pose (object units; ``angle`` in rad about
        the unit ``axis`` through ``pivot``, Rodrigues' formula in
        :func:`asset2sim.frames.axis_angle_matrix`)."""
        r = axis_angle_matrix(self.axis, self.angle)
        piv = np.asarray(self.pivot, float)
        return (pts - piv) @ r.T + piv


@dataclass
class Part:
    """One OBJ file: a named part made of one or more box pieces."""

    name: str
    """Visual name in the URDF (PartNet style ``label-N``)."""
    boxes: list[Box]
    color: Vec3
    pose: Pose | None = None
    """Applied to the vertices (a part modelled away from its closed pose)."""

    def vertices(self) -> list[np.ndarray]:
        """Corners (8, 3) of each box piece, after :attr:`pose`, object units."""
        return [b.corners() if self.pose is None else self.pose.apply(b.corners()) for b in self.boxes]


@dataclass
class DemoLink:
    """A link: its name, its ``semantics.txt`` joint kind and label, its parts."""

    name: str
    semantic_joint: str
    semantic_label: str
    parts: list[Part]


@dataclass
class DemoJoint:
    """A joint in the object frame: ``origin`` (3,) units, unit ``axis`` (3,),
    limits ``lower`` / ``upper`` (rad or units), ``rpy`` text of the fixed
    base joint (PartNet-Mobility's y-up to z-up turn)."""

    name: str
    type: str
    parent: str
    child: str
    origin: Vec3 = (0.0, 0.0, 0.0)
    axis: Vec3 | None = None
    lower: float | None = None
    upper: float | None = None
    rpy: str | None = None


@dataclass
class DemoArticulation:
    """An articulated object before serialisation."""

    asset_id: str
    category: str
    robot_name: str
    links: list[DemoLink]
    joints: list[DemoJoint]
    extra_meta: dict = field(default_factory=dict)


def fmt_number(x: float) -> str:
    """Deterministic short float text (9 significant digits, no ``-0``)."""
    v = round(float(x), 9) + 0.0
    return "0" if v == 0.0 else f"{v:.9g}"


def obj_text(part: Part, mtl_name: str) -> str:
    """OBJ text of ``part``: one ``o`` group of 8 vertices and 12 outward
    triangles per box piece (6 decimals, object units), all with material
    ``material_0`` of ``mtl_name``."""
    lines = ["# asset2sim demo asset (generated from geometry)", f"mtllib {mtl_name}"]
    base = 0
    for i, verts in enumerate(part.vertices()):
        lines += [f"o {part.name}/piece{i}", *("v " + " ".join(f"{c + 0.0:.6f}" for c in v) for v in verts), "usemtl material_0",
                  *("f " + " ".join(str(base + k + 1) for k in tri) for tri in _BOX_FACES)]
        base += 8
    return "\n".join(lines) + "\n"


def mtl_text(color: Vec3) -> str:
    """MTL text of one material ``material_0`` with diffuse ``color`` (RGB 0..1)."""
    return (
        "# asset2sim demo asset\n"
        "newmtl material_0\n"
        f"Kd {' '.join(fmt_number(c) for c in color)}\n"
        "Ka 0 0 0\n"
        "Ks 0.1 0.1 0.1\n"
        "Ns 10\n"
        "d 1\n"
        "illum 2\n"
    )


def box_xyz(x0, x1, y0, y1, z0, z1) -> Box:
    """The box x0..x1, y0..y1, z0..z1 (object units); ValueError when empty."""
    return Box((x0, y0, z0), (x1, y1, z1))


def open_box(x0, x1, y0, y1, z0, z1, t, prefix, color) -> list[Part]:
    """Bottom plate and four walls (parts 1 to 5) of an open-topped box (wall thickness t)."""
    return [
        Part(f"{prefix}_bottom-1", [box_xyz(x0, x1, y0, y0 + t, z0, z1)], color),
        Part(f"{prefix}_front-2", [box_xyz(x0, x1, y0 + t, y1, z1 - t, z1)], color),
        Part(f"{prefix}_back-3", [box_xyz(x0, x1, y0 + t, y1, z0, z0 + t)], color),
        Part(f"{prefix}_side-4", [box_xyz(x0, x0 + t, y0 + t, y1, z0 + t, z1 - t)], color),
        Part(f"{prefix}_side-5", [box_xyz(x1 - t, x1, y0 + t, y1, z0 + t, z1 - t)], color),
    ]
