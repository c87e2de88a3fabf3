"""MJCF objects built from box panels, with physics a real object of their kind has and, where asked, one planted
error each: mass x0.01, mass x100, the density of lead on a plastic part, an inertia tensor violating the triangle
inequality (MuJoCo loads it only with ``balanceinertia``), no damping on a spring-loaded lid.

Correct values are computed here, independently of asset2sim: each part's panels are boxes of a real material
(density from the material's datasheet range), and mass, center of mass and inertia tensor are trimesh's exact
integrals of the panels (``Trimesh.mass_properties``). Joint damping, friction and springs are values of real
hardware (a ~0.3 damping ratio on the spring lid).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

#: Densities kg/m^3 of the materials the objects are made of (mid-range of the datasheets asset2sim's
#: materials.yaml cites, so a correct value is a real one, not the product's own pick).
PLYWOOD = 600.0
PARTICLE_BOARD = 680.0
POLYPROPYLENE = 905.0
LEAD = 11340.0


@dataclass
class Panel:
    """A box panel: ``size`` (3,) full extents m, ``pos`` (3,) its center m in the body frame."""

    size: tuple[float, float, float]
    pos: tuple[float, float, float]


@dataclass
class Part:
    """A body of the object: panels of one material; ``inertial`` writes an explicit ``<inertial>`` (else MuJoCo
    infers it from the geoms at ``geom_density``); ``mass_factor`` plants a wrong mass; ``bad_inertia`` plants a
    tensor violating the triangle inequality."""

    name: str
    panels: list[Panel]
    density: float
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    joint: str = ""  # extra MJCF <joint .../> attributes text; "" for a part fixed to its parent
    inertial: bool = True
    geom_density: float | None = None
    mass_factor: float = 1.0
    bad_inertia: bool = False
    children: list["Part"] = field(default_factory=list)

    def mesh(self) -> trimesh.Trimesh:
        boxes = [trimesh.creation.box(extents=p.size, transform=trimesh.transformations.translation_matrix(p.pos)) for p in self.panels]
        return trimesh.util.concatenate(boxes)

    def physics(self) -> tuple[float, np.ndarray, np.ndarray]:
        """(mass kg, COM (3,) m, inertia (3, 3) kg*m^2 about the COM) of the panels at ``density``."""
        m = self.mesh()
        m.density = self.density
        return float(m.mass), np.asarray(m.center_mass, float), np.asarray(m.moment_inertia, float)


def _fmt(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in np.ravel(v))


def _body_xml(part: Part, depth: int) -> list[str]:
    pad = "  " * depth
    out = [f'{pad}<body name="{part.name}" pos="{_fmt(part.pos)}">']
    if depth == 2 and not part.joint:
        out.append(f"{pad}  <freejoint/>")
    if part.joint:
        out.append(f"{pad}  <joint {part.joint}/>")
    if part.inertial:
        mass, com, inertia = part.physics()
        if part.bad_inertia:
            out.append(f'{pad}  <inertial pos="{_fmt(com)}" mass="{mass:.9g}" diaginertia="{_fmt([inertia[0, 0] * 4, inertia[1, 1] * 0.5, inertia[2, 2] * 0.5])}"/>')
        else:
            mass2 = mass * part.mass_factor
            full = inertia * part.mass_factor
            out.append(f'{pad}  <inertial pos="{_fmt(com)}" mass="{mass2:.9g}" '
                       f'fullinertia="{_fmt([full[0, 0], full[1, 1], full[2, 2], full[0, 1], full[0, 2], full[1, 2]])}"/>')
    density = f' density="{part.geom_density:g}"' if part.geom_density is not None else f' density="{part.density:g}"'
    for p in part.panels:
        out.append(f'{pad}  <geom type="box" size="{_fmt(np.asarray(p.size) / 2)}" pos="{_fmt(p.pos)}"{density}/>')
    for child in part.children:
        out += _body_xml(child, depth + 1)
    out.append(f"{pad}</body>")
    return out


def write_mjcf(folder: Path, name: str, root: Part, compiler: str = "") -> Path:
    """``folder/<name>.xml`` holding the object ``root`` (free-standing on a floor plane); returns its path."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = [f'<mujoco model="{name}">', f'  <compiler angle="radian" {compiler}/>', "  <worldbody>",
             '    <geom name="floor" type="plane" size="2 2 0.1"/>', *_body_xml(root, 2), "  </worldbody>", "</mujoco>"]
    path = folder / f"{name}.xml"
    path.write_text("\n".join(lines) + "\n")
    return path


def open_box(w: float, d: float, h: float, t: float) -> list[Panel]:
    """Bottom and four walls of a box open at the top (outer size w x d x h, walls t thick), origin at the bottom center."""
    return [Panel((w, d, t), (0, 0, t / 2)),
            Panel((w, t, h - t), (0, d / 2 - t / 2, t + (h - t) / 2)), Panel((w, t, h - t), (0, -d / 2 + t / 2, t + (h - t) / 2)),
            Panel((t, d - 2 * t, h - t), (w / 2 - t / 2, 0, t + (h - t) / 2)), Panel((t, d - 2 * t, h - t), (-w / 2 + t / 2, 0, t + (h - t) / 2))]


def storage_box(*, lid_damping: float = 0.05, bad_inertia: bool = False) -> Part:
    """A plywood storage box 0.35 x 0.25 x 0.15 m (9 mm walls) with a spring-closed hinged lid."""
    w, d, h, t = 0.35, 0.25, 0.15, 0.009
    lid = Part("lid", [Panel((w, d, t), (0, -d / 2, t / 2))], PLYWOOD, pos=(0, d / 2, h), bad_inertia=bad_inertia,
               joint=f'name="lid_hinge" type="hinge" axis="-1 0 0" range="0 1.9" damping="{lid_damping:g}" frictionloss="0.05" '
                     'stiffness="0.6" springref="0"')
    return Part("base", open_box(w, d, h, t), PLYWOOD, children=[lid])


def cabinet(*, drawer_factor: float = 1.0, body_factor: float = 1.0) -> Part:
    """A particle-board cabinet 0.6 x 0.45 x 0.4 m (16 mm panels) with a drawer on a slide and a hinged door."""
    w, d, h, t = 0.6, 0.45, 0.4, 0.016
    carcass = [Panel((w, d, t), (0, 0, t / 2)), Panel((w, d, t), (0, 0, h - t / 2)),
               Panel((t, d, h - 2 * t), (w / 2 - t / 2, 0, h / 2)), Panel((t, d, h - 2 * t), (-w / 2 + t / 2, 0, h / 2)),
               Panel((t, d, h - 2 * t), (0, 0, h / 2)), Panel((w - 2 * t, t, h - 2 * t), (0, d / 2 - t / 2, h / 2))]
    dw = w / 2 - 1.5 * t - 0.004
    drawer_box = open_box(dw, d - 2 * t - 0.01, 0.12, 0.012)
    drawer = Part("drawer", [*drawer_box, Panel((dw + 0.004, t, 0.16), (0, -(d - 2 * t - 0.01) / 2 - t / 2, 0.06))], PARTICLE_BOARD,
                  pos=(-w / 4, -0.001, h / 2 - 0.02), mass_factor=drawer_factor,
                  joint='name="drawer_slide" type="slide" axis="0 -1 0" range="0 0.3" damping="8" frictionloss="4"')
    door = Part("door", [Panel((w / 2 - 1.5 * t - 0.004, t, h - 2 * t - 0.004), (-(w / 2 - 1.5 * t) / 2, -t / 2, 0))], PARTICLE_BOARD,
                pos=(w / 2 - t - 0.001, -d / 2 - 0.001, h / 2),
                joint='name="door_hinge" type="hinge" axis="0 0 1" range="0 1.6" damping="0.4" frictionloss="0.1"')
    return Part("body", carcass, PARTICLE_BOARD, mass_factor=body_factor, children=[drawer, door])


def trash_can(*, lid_density: float | None = None) -> Part:
    """A polypropylene trash can 0.3 x 0.26 x 0.4 m (3 mm walls) with a hinged lid (``lid_density``: the
    geom density MuJoCo infers the lid's mass from, no ``<inertial>``)."""
    w, d, h, t = 0.3, 0.26, 0.4, 0.003
    lid = Part("lid", [Panel((w, d, t), (0, -d / 2, t / 2)), Panel((w, t, 0.03), (0, -d + t / 2, -0.015))], POLYPROPYLENE,
               pos=(0, d / 2, h), inertial=lid_density is None, geom_density=lid_density,
               joint='name="lid_hinge" type="hinge" axis="-1 0 0" range="0 1.7" damping="0.02" frictionloss="0.02"')
    return Part("can", open_box(w, d, h, t), POLYPROPYLENE, children=[lid])


def write_planted_folder(folder: Path) -> dict[str, tuple[str, str, str]]:
    """A folder of MJCF objects, one per subfolder, each with one planted error and every other value correct.
    Returns object folder name -> (where, quantity, what was planted): the values the audit must flag."""
    write_mjcf(folder / "storage_box_spring_lid", "storage_box", storage_box(lid_damping=0.0))
    write_mjcf(folder / "cabinet_light_drawer", "cabinet", cabinet(drawer_factor=0.01))
    write_mjcf(folder / "cabinet_heavy_body", "cabinet", cabinet(body_factor=100.0))
    write_mjcf(folder / "trash_can_lead_lid", "trash_can", trash_can(lid_density=LEAD))
    write_mjcf(folder / "storage_box_bad_inertia", "storage_box", storage_box(bad_inertia=True), compiler='balanceinertia="true"')
    return {
        "storage_box_spring_lid": ("joint lid_hinge", "damping", "no damping on a spring-loaded lid"),
        "cabinet_light_drawer": ("link drawer", "mass", "mass x0.01"),
        "cabinet_heavy_body": ("link body", "mass", "mass x100"),
        "trash_can_lead_lid": ("link lid", "density", "density of lead on a plastic lid"),
        "storage_box_bad_inertia": ("link lid", "inertia", "inertia violating the triangle inequality"),
    }


def write_generated_urdf(folder: Path, unit: float = 1.0) -> Path:
    """A cabinet as generators ship URDFs: one GLB / PLY mesh per link, names like ``link_1_door``, no
    ``semantics.txt``, no inertials or dynamics; lengths times ``unit`` (100: centimetres written as metres).
    Returns the folder (``model.urdf`` + ``meshes/``)."""
    (folder / "meshes").mkdir(parents=True, exist_ok=True)

    def box(ext, pos):
        return trimesh.creation.box(extents=np.asarray(ext) * unit, transform=trimesh.transformations.translation_matrix(np.asarray(pos) * unit))

    w, d, h, t = 0.6, 0.45, 0.4, 0.016
    carcass = trimesh.util.concatenate([box((w, d, t), (0, 0, t / 2)), box((w, d, t), (0, 0, h - t / 2)),
                                        box((t, d, h - 2 * t), (w / 2 - t / 2, 0, h / 2)), box((t, d, h - 2 * t), (-w / 2 + t / 2, 0, h / 2)),
                                        box((w - 2 * t, t, h - 2 * t), (0, d / 2 - t / 2, h / 2))])
    carcass.export(folder / "meshes" / "base.glb")
    box((w - 2 * t - 0.004, t, h - 2 * t - 0.004), (-(w - 2 * t) / 2, -t / 2, 0)).export(folder / "meshes" / "door.ply")
    box((0.02, 0.03, 0.12), (-(w - 2 * t) + 0.05, -t - 0.015, 0)).export(folder / "meshes" / "handle.glb")
    o = np.array([w / 2 - t - 0.001, -d / 2 - 0.001, h / 2]) * unit
    link = '<link name="{0}"><visual><geometry><mesh filename="meshes/{1}"/></geometry></visual>' \
           '<collision><geometry><mesh filename="meshes/{1}"/></geometry></collision></link>'
    (folder / "model.urdf").write_text(f"""<robot name="generated_cabinet">
  {link.format("link_0_base", "base.glb")}
  {link.format("link_1_door", "door.ply")}
  {link.format("link_2_handle", "handle.glb")}
  <joint name="joint_0" type="revolute"><parent link="link_0_base"/><child link="link_1_door"/>
    <origin xyz="{_fmt(o)}"/><axis xyz="0 0 1"/><limit lower="0" upper="1.6" effort="10" velocity="1"/></joint>
  <joint name="joint_1" type="fixed"><parent link="link_1_door"/><child link="link_2_handle"/></joint>
</robot>
""")
    return folder
