"""A small asset that satisfies the SPEC's output contract, for tests of
engines, export and parity (:func:`write_contract_asset`). Units SI, radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import atomic
from asset2sim.frames import translation_matrix
from asset2sim.urdf import UrdfDynamics, UrdfGeometry, UrdfInertial, UrdfJoint, UrdfLimit, UrdfLink, UrdfModel, write_urdf
from asset2sim.output_folder import OVERLAY_NAME, STATE_NAME, URDF_NAME

#: The box (m): length along x, width along y, height, wall (and lid) thickness.
_L, _W, _H, _T = 0.30, 0.20, 0.12, 0.01

Box = tuple[tuple[float, float, float], tuple[float, float, float]]
#: Mass kg, COM (3,) m, inertia (3, 3) kg*m^2 about the COM, in the link frame.
Inertial = tuple[float, np.ndarray, np.ndarray]


def _box_obj(boxes: list[Box]) -> str:
    """OBJ text of axis-aligned boxes given as (min corner, max corner), one ``o`` group each."""
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    lines, off = [], 1
    for k, (lo, hi) in enumerate(boxes):
        lines.append(f"o piece_{k}")
        for i in range(8):
            x, y, z = (hi[a] if i & bit else lo[a] for a, bit in ((0, 4), (1, 2), (2, 1)))
            lines.append(f"v {x!r} {y!r} {z!r}")
        lines.extend(f"f {a + off} {b + off} {c + off}" for a, b, c in faces)
        off += 8
    return "\n".join(lines) + "\n"


def _box_inertia(mass: float, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """COM (3,) m and inertia (3, 3) kg*m^2 about it of a solid box of ``mass`` kg."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    d = hi - lo
    return (lo + hi) / 2, mass / 12.0 * np.diag([d[1] ** 2 + d[2] ** 2, d[0] ** 2 + d[2] ** 2, d[0] ** 2 + d[1] ** 2])


def _combine(parts: list[Inertial]) -> Inertial:
    """Mass, COM (3,), inertia about the COM (3, 3) of point-mass-shifted parts."""
    m = sum(p[0] for p in parts)
    com = sum(p[0] * p[1] for p in parts) / m
    inertia = np.zeros((3, 3))
    for mi, ci, ii in parts:
        d = ci - com
        inertia += ii + mi * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return m, com, inertia


@dataclass
class ContractAsset:
    """Paths and facts of an asset written by :func:`write_contract_asset`."""

    root: Path
    urdf: Path
    initial_state: dict[str, float]
    masses: dict[str, float]
    lid_mass: float
    lid_com_radius: float
    """distance (m) of the lid's COM from the hinge axis, in the lid plane"""
    post_overlap_at: float
    """post position (m) above which the post's top pokes into the closed lid"""


def write_contract_asset(out_dir: Path, *, lid_angle: float = 0.0, post_height: float = 0.0, lid_damping: float = 0.02,
                         lid_friction: float = 0.02, lid_stiffness: float = 0.0, lid_spring_reference: float | None = None,
                         post_damping: float = 1.0, post_friction: float = 2.0, base_inertial: bool = True, body_mass: float = 1.5,
                         lid_mass: float = 0.2, latch: bool = False) -> ContractAsset:
    """Write a small box-with-lid asset that satisfies the SPEC output contract.

    Links: ``base`` (root, fixed to ``body``; an ``<inertial>`` only when
    ``base_inertial``), ``body`` (an open 0.30 x 0.20 x 0.12 m box, five walls
    as five ``o`` groups of one OBJ), ``lid`` (a 0.01 m plate hinged along -x
    at the top back edge, ``lid_angle`` rad opens it, limits [0, 2.0]) and
    ``post`` (0.02 x 0.02 x 0.10 m, prismatic along +z, limits [0, 0.05] m;
    above ``post_overlap_at`` it pokes into the closed lid). ``latch``: a
    0.30 x 0.03 x 0.01 m bar of 0.02 kg fixed to the body 1 mm above the
    closed lid, holding it shut.

    Masses kg, damping N*m*s/rad / N*s/m, friction N*m / N, stiffness N*m/rad.
    Files: ``mobility.urdf``, ``textured_objs/*.obj``, ``initial_state.json``,
    ``overlay.json``. Returns a :class:`ContractAsset`.
    """
    out = Path(out_dir)
    boxes = _boxes(latch)
    for name, parts in boxes.items():
        atomic.write_text(out / "textured_objs" / f"{name}.obj", _box_obj(parts))
    inertials = {name: part for name, part in _inertials(boxes, body_mass, lid_mass).items() if name != "base" or base_inertial}
    model = _model(inertials, (lid_damping, lid_friction), (post_damping, post_friction))
    urdf_path = atomic.write_bytes(out / URDF_NAME, write_urdf(model, comment=" initial joint positions: initial_state.json "))
    state = {"lid_hinge": float(lid_angle), "post_slide": float(post_height)}
    atomic.write_json(out / STATE_NAME, {"initial_joint_positions": state})
    joints = {"lid_hinge": _joint_entry(lid_damping, lid_friction, lid_stiffness, lid_spring_reference),
              "post_slide": _joint_entry(post_damping, post_friction, 0.0, None)}
    atomic.write_json(out / OVERLAY_NAME, _overlay(inertials, joints, state))
    post_top = boxes["post"][0][1][2]
    return ContractAsset(root=out, urdf=urdf_path, initial_state=state, masses={name: float(part[0]) for name, part in inertials.items()},
                         lid_mass=lid_mass, lid_com_radius=_W / 2, post_overlap_at=float(_H + 0.0005 - post_top))


def _boxes(latch: bool) -> dict[str, list[Box]]:
    """Each meshed link's boxes (min corner, max corner) m in its link frame."""
    L, W, H, t = _L, _W, _H, _T
    walls = [
        ((-L / 2, -W / 2, 0.0), (L / 2, W / 2, t)),
        ((-L / 2, -W / 2, t), (-L / 2 + t, W / 2, H)),
        ((L / 2 - t, -W / 2, t), (L / 2, W / 2, H)),
        ((-L / 2 + t, -W / 2, t), (L / 2 - t, -W / 2 + t, H)),
        ((-L / 2 + t, W / 2 - t, t), (L / 2 - t, W / 2, H)),
    ]
    # the lid frame is on the hinge (y = +W/2, z = H); the plate extends to -y, 0.5 mm above the walls
    boxes = {"body": walls, "lid": [((-L / 2, -W, 0.0005), (L / 2, 0.0, 0.0005 + t))], "post": [((-0.01, -0.01, t), (0.01, 0.01, t + 0.10))]}
    if latch:
        boxes["latch"] = [((-L / 2, -W / 2, H + 0.0015 + t), (L / 2, -W / 2 + 0.03, H + 0.0115 + t))]
    return boxes


def _inertials(boxes: dict[str, list[Box]], body_mass: float, lid_mass: float) -> dict[str, Inertial]:
    """Link -> (mass kg, COM (3,) m, inertia (3, 3) kg*m^2) of solid boxes (the base: 10 g), in overlay order."""
    walls = boxes["body"]
    vol = [np.prod(np.subtract(hi, lo)) for lo, hi in walls]
    out = {
        "body": _combine([(body_mass * v / sum(vol), *_box_inertia(body_mass * v / sum(vol), lo, hi)) for v, (lo, hi) in zip(vol, walls)]),
        "lid": (lid_mass, *_box_inertia(lid_mass, *boxes["lid"][0])),
        "post": (0.05, *_box_inertia(0.05, *boxes["post"][0])),
    }
    if "latch" in boxes:
        out["latch"] = (0.02, *_box_inertia(0.02, *boxes["latch"][0]))
    out["base"] = (0.01, np.zeros(3), np.diag([1e-5, 1e-5, 1e-5]))
    return out


def _link(name: str, parts: Inertial | None, with_mesh: bool = True) -> UrdfLink:
    """A link with an ``<inertial>`` (unless ``parts`` is None) and its box mesh as visual and collision."""
    ln = UrdfLink(name=name)
    if parts is not None:
        m, com, inertia = parts
        ln.inertial = UrdfInertial(mass=float(m), origin=translation_matrix(com), inertia=np.asarray(inertia, float))
    if with_mesh:
        mesh = dict(kind="mesh", filename=f"textured_objs/{name}.obj", mesh_scale=np.ones(3))
        ln.visuals.append(UrdfGeometry(**mesh))
        ln.collisions.append(UrdfGeometry(**mesh))
    return ln


def _moving(name, jtype, child, origin, axis, upper, damping, friction) -> UrdfJoint:
    """A movable joint from ``body`` to ``child``, limits [0, ``upper``] (rad or m)."""
    return UrdfJoint(name=name, type=jtype, parent="body", child=child, origin=translation_matrix(origin), axis_xyz=np.asarray(axis, float),
                     limit=UrdfLimit(lower=0.0, upper=upper, effort=1000.0, velocity=1000.0),
                     dynamics=UrdfDynamics(damping=float(damping), friction=float(friction)))


def _model(inertials: dict[str, Inertial], lid: tuple[float, float], post: tuple[float, float]) -> UrdfModel:
    """The URDF model (a latch and a base inertial when ``inertials`` has them); ``lid``, ``post``: (damping, friction)."""
    links = {"base": _link("base", inertials.get("base"), with_mesh=False)}
    links.update({n: _link(n, inertials[n]) for n in ("body", "lid", "post")})
    model = UrdfModel(name="contract_box", links=links, joints=[
        UrdfJoint(name="root_fixed", type="fixed", parent="base", child="body"),
        _moving("lid_hinge", "revolute", "lid", (0.0, _W / 2, _H), (-1.0, 0.0, 0.0), 2.0, *lid),
        _moving("post_slide", "prismatic", "post", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.05, *post),
    ])
    if "latch" in inertials:
        model.links["latch"] = _link("latch", inertials["latch"])
        model.joints.append(UrdfJoint(name="latch_fixed", type="fixed", parent="body", child="latch"))
    return model


def _joint_entry(damping: float, friction: float, stiffness: float, reference: float | None) -> dict:
    """A joint of ``overlay.json``: damping, friction, spring stiffness and reference (None: no spring)."""
    return {"damping": float(damping), "friction": float(friction), "stiffness": float(stiffness),
            "spring_reference": None if reference is None else float(reference)}


def _overlay(inertials: dict[str, Inertial], joints: dict[str, dict], state: dict[str, float]) -> dict:
    """``overlay.json`` of the asset: every link with an ``<inertial>``, the joints' dynamics, the initial state."""
    keys = {"ixx": (0, 0), "ixy": (0, 1), "ixz": (0, 2), "iyy": (1, 1), "iyz": (1, 2), "izz": (2, 2)}
    links = {name: {"mass": float(m), "inertia": {k: float(inertia[i, j]) for k, (i, j) in keys.items()}, "com": [float(c) for c in com],
                    "source": "geometry"} for name, (m, com, inertia) in inertials.items()}
    return {"schema_version": "1.0", "estimator": {"name": "test-fixture", "queries": 0}, "scale": 1.0, "links": links,
            "joints": joints, "initial_joint_positions": state}
