"""Generated assets of categories the dev set lacks, in PartNet-Mobility's
layout (a y-up body under a z-up ``base``, ``link_N`` / ``joint_N`` with the
body listed last, ``semantics.txt``, ``meta.json``), built from boxes with
the demo generator (:mod:`asset2sim.demo_geometry`). Nothing is copied from a
dataset; dimensions are in object units, as PartNet-Mobility's are.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from asset2sim import atomic, mesh_io, urdf
from asset2sim.demo_assets import _serialise, _write_folder
from asset2sim.demo_geometry import DemoArticulation, DemoJoint, DemoLink, Part, Pose, box_xyz

_BASE_RPY = "1.570796326794897 0 -1.570796326794897"
_WHITE, _GREY, _DARK = (0.92, 0.92, 0.9), (0.6, 0.62, 0.65), (0.15, 0.15, 0.17)


class _Builder:
    """Links and joints of one object; joints placed at object-frame pivots."""

    def __init__(self, asset_id: str, category: str):
        self.asset_id, self.category = asset_id, category
        self.links: list[DemoLink] = []
        self.joints: list[DemoJoint] = []
        self.frame: dict[str, tuple[float, float, float]] = {}
        self.n = 0

    def part(self, label: str, boxes, color, pose: Pose | None = None) -> Part:
        self.n += 1
        return Part(f"{label}-{self.n}", boxes if isinstance(boxes, list) else [boxes], color, *([pose] if pose else []))

    def body(self, name: str, label: str, parts: list[Part]) -> None:
        self.links.append(DemoLink(name, "static", label, parts))
        self.joints.append(DemoJoint(name.replace("link", "joint"), "fixed", "base", name, rpy=_BASE_RPY))
        self.frame[name] = (0.0, 0.0, 0.0)

    def moving(self, name: str, kind: str, label: str, parts: list[Part], jtype: str, parent: str, pivot, axis,
               lo: float | None = None, hi: float | None = None) -> None:
        self.links.append(DemoLink(name, kind, label, parts))
        origin = tuple(p - q for p, q in zip(pivot, self.frame[parent]))
        self.frame[name] = tuple(pivot)
        self.joints.append(DemoJoint(name.replace("link", "joint"), jtype, parent, name, origin=origin, axis=axis, lower=lo, upper=hi))

    def write(self, folder: Path) -> Path:
        links = self.links[1:] + self.links[:1]  # moving links first, the body last
        obj = DemoArticulation(asset_id=self.asset_id, category=self.category, robot_name=f"partnet_{self.asset_id}",
                               links=links, joints=self.joints)
        return _write_folder(Path(folder), _serialise(obj))


def build_toggle_switch(folder: Path) -> Path:
    """A wall light switch: a plate and a toggle (``toggle_button``) on a
    revolute joint of +-0.35 rad about the plate's horizontal axis."""
    b = _Builder("u_switch", "Switch")
    b.body("link_1", "switch_frame", [b.part("switch_frame", box_xyz(-0.3, 0.3, -0.5, 0.5, -0.08, 0.0), _WHITE)])
    b.moving("link_0", "hinge", "toggle_button", [b.part("toggle_button", box_xyz(-0.06, 0.06, -0.03, 0.03, 0.03, 0.3), _WHITE)],
             "revolute", "link_1", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), -0.35, 0.35)
    return b.write(folder)


def _wheel(b: _Builder, cx: float, cy: float, cz: float, radius: float, half_width: float, sticks: int = 8) -> list[Part]:
    """A roughly round wheel in the y-z plane (axis x): ``sticks`` bars of
    half-length ``radius`` through the centre, turned in steps of pi / sticks."""
    return [b.part("wheel", box_xyz(cx - half_width, cx + half_width, cy - radius, cy + radius, cz - 0.012, cz + 0.012), _DARK,
                   Pose(axis=(1.0, 0.0, 0.0), angle=math.pi * k / sticks, pivot=(cx, cy, cz))) for k in range(sticks)]


def build_cart(folder: Path) -> Path:
    """A hand cart: a tray with a push handle on four wheels (continuous
    joints, label ``wheel``) that stand on the ground."""
    b = _Builder("u_cart", "Cart")
    body = [b.part("cart_body", box_xyz(-0.5, 0.5, -0.2, -0.16, -0.3, 0.3), _GREY),
            b.part("cart_body", [box_xyz(-0.5, 0.5, -0.16, 0.05, -0.3, -0.28), box_xyz(-0.5, 0.5, -0.16, 0.05, 0.28, 0.3),
                                 box_xyz(-0.5, -0.48, -0.16, 0.05, -0.28, 0.28), box_xyz(0.48, 0.5, -0.16, 0.05, -0.28, 0.28)], _GREY),
            b.part("handle", [box_xyz(-0.52, -0.5, -0.16, 0.45, -0.25, -0.22), box_xyz(-0.52, -0.5, -0.16, 0.45, 0.22, 0.25),
                              box_xyz(-0.52, -0.5, 0.42, 0.45, -0.22, 0.22)], _DARK)]
    for x in (-0.42, 0.42):
        for z in (-0.22, 0.22):
            body.append(b.part("cart_body", box_xyz(x - 0.06, x - 0.045, -0.35, -0.2, z - 0.015, z + 0.015), _DARK))
    b.body("link_4", "cart_body", body)
    i = 0
    for x in (-0.42, 0.42):
        for z in (-0.22, 0.22):
            b.moving(f"link_{i}", "hinge", "wheel", _wheel(b, x, -0.38, z, 0.1, 0.03), "continuous", "link_4", (x, -0.38, z), (1.0, 0.0, 0.0))
            i += 1
    return b.write(folder)


_GLASS = (0.6, 0.8, 0.9)


def build_sliding_window(folder: Path) -> Path:
    """A window frame (``window_frame``) with two sashes (``window``) that
    slide past each other in two tracks (prismatic, 0-0.5 units): modelled
    closed, each sash over its half of the opening. Sliding one open moves
    it over the other inside the frame: the object is equally compact at
    every opening."""
    b = _Builder("u_window_slide", "Window")
    x, y, z, f = 0.6, 0.45, 0.05, 0.06
    b.body("link_2", "window_frame", [
        b.part("window_frame", box_xyz(-x, x, -y, -y + f, -z, z), _WHITE),
        b.part("window_frame", box_xyz(-x, x, y - f, y, -z, z), _WHITE),
        b.part("window_frame", box_xyz(-x, -x + f, -y + f, y - f, -z, z), _WHITE),
        b.part("window_frame", box_xyz(x - f, x, -y + f, y - f, -z, z), _WHITE)])
    xi, yi = x - f - 0.005, y - f - 0.005
    b.moving("link_0", "slider", "window", [b.part("window", box_xyz(-xi, 0.02, -yi, yi, 0.005, 0.035), _GLASS)],
             "prismatic", "link_2", (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.0, 0.5)
    b.moving("link_1", "slider", "window", [b.part("window", box_xyz(-0.02, xi, -yi, yi, -0.035, -0.005), _GLASS)],
             "prismatic", "link_2", (0.0, 0.0, 0.0), (-1.0, 0.0, 0.0), 0.0, 0.5)
    return b.write(folder)


_STEEL, _RED = (0.75, 0.76, 0.78), (0.8, 0.15, 0.1)


def build_pliers(folder: Path) -> Path:
    """A pair of pliers lying flat (0.04 units thick): two coplanar halves
    (jaw + handle, label ``leg`` / ``handle``) on one revolute joint about
    the vertical through the pivot (0-0.5 rad), each half one layer at the
    pivot, out beyond the other layer's swept radius."""
    b = _Builder("u_pliers", "Pliers")
    up, down, full = (0.0025, 0.02), (-0.02, -0.0025), (-0.02, 0.02)
    b.body("link_1", "leg", [
        b.part("leg", [box_xyz(-0.06, 0.06, *up, -0.06, 0.06), box_xyz(0.06, 0.1, *up, 0.0025, 0.04),
                       box_xyz(-0.1, -0.06, *up, -0.06, -0.03), box_xyz(0.1, 0.32, *full, 0.0025, 0.04)], _STEEL),
        b.part("handle", [box_xyz(-0.7, -0.1, *full, -0.1, -0.03)], _RED)])
    b.moving("link_0", "hinge", "leg", [
        b.part("leg", [box_xyz(-0.06, 0.06, *down, -0.06, 0.06), box_xyz(0.06, 0.1, *down, -0.04, -0.0025),
                       box_xyz(-0.1, -0.06, *down, 0.03, 0.06), box_xyz(0.1, 0.32, *full, -0.04, -0.0025)], _STEEL),
        b.part("handle", [box_xyz(-0.7, -0.1, *full, 0.03, 0.1)], _RED)],
        "revolute", "link_1", (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 0.0, 0.5)
    return b.write(folder)


def build_double_door_cabinet(folder: Path) -> Path:
    """A wardrobe-like cabinet (0.8 x 1.0 x 0.5 units, open-front carcass of
    0.03 boards) with two doors (``door``, revolute 0-1.57 rad about vertical
    axes at the outer edges) that meet at the middle with no gap, as
    PartNet-Mobility's double doors are modelled: closing one door slides its
    edge past the other's."""
    b = _Builder("u_double_door", "StorageFurniture")
    w, h, d, t = 0.4, 0.5, 0.25, 0.03
    b.body("link_2", "furniture_body", [
        b.part("board", box_xyz(-w, -w + t, -h, h, -d, d), _WHITE), b.part("board", box_xyz(w - t, w, -h, h, -d, d), _WHITE),
        b.part("board", box_xyz(-w + t, w - t, h - t, h, -d, d), _WHITE), b.part("board", box_xyz(-w + t, w - t, -h, -h + t, -d, d), _WHITE),
        b.part("board", box_xyz(-w + t, w - t, -h + t, h - t, -d, -d + t), _WHITE)])
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, 0.0, -h, h, d, d + 0.02), _GREY)],
             "revolute", "link_2", (-w, 0.0, d), (0.0, -1.0, 0.0), 0.0, 1.57)
    b.moving("link_1", "hinge", "door", [b.part("door", box_xyz(0.0, w, -h, h, d, d + 0.02), _GREY)],
             "revolute", "link_2", (w, 0.0, d), (0.0, 1.0, 0.0), 0.0, 1.57)
    return b.write(folder)


def _carcass(b: _Builder, label: str, w: float, h: float, d: float, t: float, color) -> list[Part]:
    """An open-front box (x in [-w, w], y in [-h, h], z in [-d, d], front at
    +z) of boards ``t`` thick."""
    return [b.part(label, box_xyz(-w, -w + t, -h, h, -d, d), color), b.part(label, box_xyz(w - t, w, -h, h, -d, d), color),
            b.part(label, box_xyz(-w + t, w - t, h - t, h, -d, d), color), b.part(label, box_xyz(-w + t, w - t, -h, -h + t, -d, d), color),
            b.part(label, box_xyz(-w + t, w - t, -h + t, h - t, -d, -d + t), color)]


def _drawer(b: _Builder, x0: float, x1: float, y0: float, y1: float, back: float, front: float, t: float) -> Part:
    """A drawer box of boards ``t`` thick: its front flush at z = ``front``, its bottom just above y0."""
    return b.part("drawer", [box_xyz(x0, x1, y0, y1, front - t, front),
                             box_xyz(x0 + t, x1 - t, y0 + 0.01, y0 + 0.01 + t, back, front - t),
                             box_xyz(x0 + t, x0 + 2 * t, y0 + 0.01 + t, y1 - 0.03, back, front - t),
                             box_xyz(x1 - 2 * t, x1 - t, y0 + 0.01 + t, y1 - 0.03, back, front - t),
                             box_xyz(x0 + 2 * t, x1 - 2 * t, y0 + 0.01 + t, y1 - 0.03, back, back + t)], _GREY)


def build_wardrobe(folder: Path) -> Path:
    """A wardrobe (1.0 x 2.0 x 0.6 units, open-front carcass of 0.02 boards and a shelf) with two doors over the
    upper three quarters (``door``, revolute 0-1.57 rad about vertical axes at the outer edges, meeting at the
    middle with no gap) and two drawers below (``drawer``, prismatic 0-0.45 units), as PartNet-Mobility's
    wardrobes are modelled."""
    b = _Builder("u_wardrobe", "StorageFurniture")
    w, h, d, t = 0.5, 1.0, 0.3, 0.02
    b.body("link_4", "furniture_body", _carcass(b, "furniture_body", w, h, d, t, _WHITE)
           + [b.part("shelf", box_xyz(-w + t, w - t, -0.5, -0.5 + t, -d + t, d), _WHITE)])
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, 0.0, -0.5 + t, h, d, d + t), _GREY)],
             "revolute", "link_4", (-w, 0.0, d), (0.0, -1.0, 0.0), 0.0, 1.57)
    b.moving("link_1", "hinge", "door", [b.part("door", box_xyz(0.0, w, -0.5 + t, h, d, d + t), _GREY)],
             "revolute", "link_4", (w, 0.0, d), (0.0, 1.0, 0.0), 0.0, 1.57)
    for i, (y0, y1) in enumerate([(-h + t, -0.75), (-0.75, -0.5)]):
        b.moving(f"link_{i + 2}", "slider", "drawer", [_drawer(b, -w + t, w - t, y0, y1, -d + t + 0.01, d + t, t)],
                 "prismatic", "link_4", (0.0, y0, d), (0.0, 0.0, 1.0), 0.0, 0.45)
    return b.write(folder)


def build_safe(folder: Path) -> Path:
    """A home safe: a thick-walled steel box (0.8 x 0.9 x 0.8 units) whose
    door (``door``, revolute 0-1.75 rad about the vertical axis at its left
    edge) closes the front, with a dial (``knob``, continuous about the
    door's normal) on the door."""
    b = _Builder("u_safe", "Safe")
    w, h, d, t = 0.4, 0.45, 0.4, 0.06
    b.body("link_2", "safe_body", _carcass(b, "safe_body", w, h, d, t, _GREY))
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, w, -h, h, d, d + 0.06), _GREY)],
             "revolute", "link_2", (-w, 0.0, d + 0.03), (0.0, -1.0, 0.0), 0.0, 1.75)
    b.moving("link_1", "hinge", "knob", [b.part("knob", [box_xyz(0.12, 0.24, 0.04, 0.16, d + 0.06, d + 0.1),
                                                         box_xyz(0.17, 0.19, 0.16, 0.19, d + 0.06, d + 0.1)], _DARK)],
             "continuous", "link_0", (0.18, 0.1, d + 0.08), (0.0, 0.0, 1.0))
    return b.write(folder)


#: How far (units) the parts of :func:`build_french_door_oven` and :func:`build_safe_with_panels` overlap as modelled.
MODELLED_OVERLAP = 0.006


def build_french_door_oven(folder: Path, overlap: float = MODELLED_OVERLAP) -> Path:
    """A French-door wall oven (0.8 x 0.8 x 0.6 units carcass) whose two doors (``door``, revolute 0-1.57 rad about
    vertical axes at the outer edges) meet at the middle overlapping ``overlap`` units, as PartNet-Mobility's meshes
    often overlap where parts meet: no state of the closed band separates them (closing one door slides its edge
    along the other's)."""
    b = _Builder("u_french_oven", "Oven")
    w, h, d, t, o = 0.4, 0.4, 0.3, 0.04, overlap / 2
    b.body("link_2", "oven_body", _carcass(b, "oven_body", w, h, d, t, _DARK))
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, o, -h, h, d, d + 0.04), _STEEL)],
             "revolute", "link_2", (-w, 0.0, d), (0.0, -1.0, 0.0), 0.0, 1.57)
    b.moving("link_1", "hinge", "door", [b.part("door", box_xyz(-o, w, -h, h, d, d + 0.04), _STEEL)],
             "revolute", "link_2", (w, 0.0, d), (0.0, 1.0, 0.0), 0.0, 1.57)
    return b.write(folder)


def build_safe_with_panels(folder: Path) -> Path:
    """A variant of :func:`build_safe` whose top rail (``frame``, 0.1 units tall across the front above the door) and
    the lock panel on it (``panel``) are links of their own, each fixed to the body, the panel sunk
    :data:`MODELLED_OVERLAP` units into the rail: no joint moves the two apart, so no state separates them."""
    b = _Builder("u_safe_panels", "Safe")
    w, h, d, t, o = 0.4, 0.45, 0.4, 0.06, MODELLED_OVERLAP
    b.body("link_3", "safe_body", _carcass(b, "safe_body", w, h, d, t, _GREY))
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, w, -h, h - 0.1, d, d + 0.06), _GREY)],
             "revolute", "link_3", (-w, 0.0, d + 0.03), (0.0, -1.0, 0.0), 0.0, 1.75)
    b.moving("link_1", "static", "frame", [b.part("frame", box_xyz(-w, w, h - 0.1, h, d, d + 0.06), _DARK)],
             "fixed", "link_3", (0.0, 0.0, 0.0), None)
    b.moving("link_2", "static", "panel", [b.part("panel", box_xyz(-0.1, 0.1, h - 0.08, h - 0.02, d + 0.06 - o, d + 0.08), _STEEL)],
             "fixed", "link_3", (0.0, 0.0, 0.0), None)
    return b.write(folder)


def build_barred_safe(folder: Path) -> Path:
    """A variant of :func:`build_safe` built to fail: a bar of the body
    (0.1 x 0.06 units in section, on two posts) runs across the front 2 cm
    before the door, so the door (revolute 0-1.75 rad) cannot open past a
    few hundredths of a radian. The door is the body's child, and simulators
    do not collide a link with its parent: any state asked open lies through
    the bar."""
    b = _Builder("u_safe_barred", "Safe")
    w, h, d, t = 0.4, 0.45, 0.4, 0.06
    body = _carcass(b, "safe_body", w, h, d, t, _GREY)
    body.append(b.part("safe_body", box_xyz(-w - 0.1, w + 0.1, -0.05, 0.05, d + 0.08, d + 0.14), _DARK))  # the bar
    body.append(b.part("safe_body", box_xyz(w, w + 0.1, -0.05, 0.05, d, d + 0.14), _DARK))  # its posts
    body.append(b.part("safe_body", box_xyz(-w - 0.1, -w, -0.05, 0.05, d, d + 0.14), _DARK))
    b.body("link_1", "safe_body", body)
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, w, -h, h, d, d + 0.06), _GREY)],
             "revolute", "link_1", (-w, 0.0, d + 0.03), (0.0, -1.0, 0.0), 0.0, 1.75)
    return b.write(folder)


def build_dispenser(folder: Path) -> Path:
    """A pump soap dispenser (0.3 x 1.06 x 0.3 units): a bottle with a hollow neck (a square tube), and a pump head
    on a stem (``pump_lid``, PartNet-Mobility's label of pressed pump heads; prismatic 0-0.05 units down into the
    neck) with a spout."""
    b = _Builder("u_dispenser", "Dispenser")
    neck = [box_xyz(-0.05, -0.035, 0.3, 0.4, -0.05, 0.05), box_xyz(0.035, 0.05, 0.3, 0.4, -0.05, 0.05),
            box_xyz(-0.035, 0.035, 0.3, 0.4, -0.05, -0.035), box_xyz(-0.035, 0.035, 0.3, 0.4, 0.035, 0.05)]
    b.body("link_1", "dispenser_body", [b.part("bottle", box_xyz(-0.15, 0.15, -0.5, 0.3, -0.15, 0.15), _WHITE),
                                        b.part("neck", neck, _WHITE)])
    b.moving("link_0", "slider", "pump_lid", [b.part("pump_lid", [box_xyz(-0.03, 0.03, 0.4, 0.5, -0.03, 0.03),
                                                                  box_xyz(-0.06, 0.06, 0.5, 0.56, -0.06, 0.2)], _GREY)],
             "prismatic", "link_1", (0.0, 0.5, 0.0), (0.0, -1.0, 0.0), 0.0, 0.05)
    return b.write(folder)


def build_toaster(folder: Path) -> Path:
    """A two-slot toaster (0.6 x 0.45 x 0.3 units) with a push-down lever
    (``slider``, prismatic 0-0.2 units down the front face, in a slot) and a
    browning dial (``knob``, continuous about the front face's normal)."""
    b = _Builder("u_toaster", "Toaster")
    w, h, d = 0.3, 0.22, 0.15
    body = [b.part("toaster_body", box_xyz(-w, w, -h, -h + 0.03, -d, d), _STEEL),  # base plate
            b.part("toaster_body", box_xyz(-w, w, -h + 0.03, h, -d, -0.05), _STEEL),  # back half, up to the slots
            b.part("toaster_body", box_xyz(-w, w, -h + 0.03, h, 0.05, d), _STEEL),  # front half
            b.part("toaster_body", box_xyz(-w, -0.2, -h + 0.03, h, -0.05, 0.05), _STEEL),  # ends and middle wall between the slots
            b.part("toaster_body", box_xyz(0.2, w, -h + 0.03, h, -0.05, 0.05), _STEEL),
            b.part("toaster_body", box_xyz(-0.02, 0.02, -h + 0.03, h, -0.05, 0.05), _STEEL)]
    b.body("link_2", "toaster_body", body)
    b.moving("link_0", "slider", "slider", [b.part("slider", box_xyz(0.2, 0.27, 0.1, 0.14, d, d + 0.06), _DARK)],
             "prismatic", "link_2", (0.235, 0.12, d), (0.0, -1.0, 0.0), 0.0, 0.2)
    b.moving("link_1", "hinge", "knob", [b.part("knob", [box_xyz(-0.2, -0.12, -0.08, 0.0, d, d + 0.04),
                                                         box_xyz(-0.17, -0.15, 0.0, 0.02, d, d + 0.04)], _DARK)],
             "continuous", "link_2", (-0.16, -0.04, d + 0.02), (0.0, 0.0, 1.0))
    return b.write(folder)


def build_bottle(folder: Path) -> Path:
    """A bottle (body 0.3 x 0.8 x 0.3 units and a neck) with a cap
    (``lid``, prismatic 0-0.25 units up along the neck) over the neck."""
    b = _Builder("u_bottle", "Bottle")
    b.body("link_1", "bottle_body", [b.part("bottle_body", box_xyz(-0.15, 0.15, -0.5, 0.3, -0.15, 0.15), _GLASS),
                                      b.part("bottle_body", box_xyz(-0.06, 0.06, 0.3, 0.45, -0.06, 0.06), _GLASS)])
    c, t = 0.08, 0.02
    cap = [box_xyz(-c, c, 0.45, 0.47, -c, c), box_xyz(-c, -c + t, 0.37, 0.45, -c, c), box_xyz(c - t, c, 0.37, 0.45, -c, c),
           box_xyz(-c + t, c - t, 0.37, 0.45, -c, -c + t), box_xyz(-c + t, c - t, 0.37, 0.45, c - t, c)]
    b.moving("link_0", "slider", "lid", [b.part("lid", cap, _RED)], "prismatic", "link_1", (0.0, 0.45, 0.0), (0.0, 1.0, 0.0), 0.0, 0.25)
    return b.write(folder)


def build_table_with_drawer(folder: Path) -> Path:
    """A desk (top 1.2 x 0.8 units on four legs, 0.8 high) with a drawer
    (``drawer``, prismatic 0-0.5 units out of the front) in a housing under
    the top."""
    b = _Builder("u_table", "Table")
    top, leg = 0.4, 0.05
    body = [b.part("tabletop", box_xyz(-0.6, 0.6, top - 0.04, top, -0.4, 0.4), _WHITE)]
    for x in (-0.6, 0.6 - leg):
        for z in (-0.4, 0.4 - leg):
            body.append(b.part("leg", box_xyz(x, x + leg, -0.4, top - 0.04, z, z + leg), _GREY))
    body += [b.part("drawer_housing", box_xyz(-0.3, -0.28, 0.16, top - 0.04, -0.35, 0.38), _WHITE),
             b.part("drawer_housing", box_xyz(0.28, 0.3, 0.16, top - 0.04, -0.35, 0.38), _WHITE),
             b.part("drawer_housing", box_xyz(-0.28, 0.28, 0.16, 0.18, -0.35, 0.38), _WHITE)]
    b.body("link_1", "table_body", body)
    drawer = [box_xyz(-0.3, 0.3, 0.17, 0.35, 0.38, 0.4),  # front
              box_xyz(-0.27, 0.27, 0.185, 0.2, -0.33, 0.38),  # bottom
              box_xyz(-0.27, -0.255, 0.2, 0.33, -0.33, 0.38), box_xyz(0.255, 0.27, 0.2, 0.33, -0.33, 0.38),
              box_xyz(-0.255, 0.255, 0.2, 0.33, -0.33, -0.315)]
    b.moving("link_0", "slider", "drawer", [b.part("drawer", drawer, _GREY)], "prismatic", "link_1", (0.0, 0.25, 0.39), (0.0, 0.0, 1.0), 0.0, 0.5)
    return b.write(folder)


def build_oven(folder: Path) -> Path:
    """A range oven (0.9 x 0.8 x 0.7 units carcass on a 0.12 plinth) with a
    bottom-hinged door (``door``, revolute 0-1.57 rad about the horizontal
    axis at its lower edge) and a temperature dial (``knob``, continuous) on
    the top rail."""
    b = _Builder("u_oven", "Oven")
    w, h, d, t = 0.45, 0.4, 0.35, 0.04
    body = _carcass(b, "oven_body", w, h, d, t, _DARK) + [b.part("oven_body", box_xyz(-w, w, h, h + 0.12, -d, d + 0.02), _STEEL),
                                                          b.part("oven_body", box_xyz(-w, w, -h - 0.12, -h, -d, d), _DARK)]  # plinth
    b.body("link_2", "oven_body", body)
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, w, -h, h, d, d + 0.05), _STEEL),
                                        b.part("handle", box_xyz(-0.3, 0.3, h - 0.08, h - 0.05, d + 0.05, d + 0.1), _DARK)],
             "revolute", "link_2", (0.0, -h, d + 0.025), (1.0, 0.0, 0.0), 0.0, 1.57)
    b.moving("link_1", "hinge", "knob", [b.part("knob", box_xyz(0.2, 0.28, h + 0.02, h + 0.1, d + 0.02, d + 0.06), _DARK)],
             "continuous", "link_2", (0.24, h + 0.06, d + 0.04), (0.0, 0.0, 1.0))
    return b.write(folder)


def _open_box(b: _Builder, label: str, w: float, h: float, d: float, t: float, color) -> list[Part]:
    """A box open at the top (x in [-w, w], y in [-h, h], z in [-d, d]) of
    walls ``t`` thick."""
    return [b.part(label, box_xyz(-w, w, -h, -h + t, -d, d), color),
            b.part(label, box_xyz(-w, -w + t, -h + t, h, -d, d), color), b.part(label, box_xyz(w - t, w, -h + t, h, -d, d), color),
            b.part(label, box_xyz(-w + t, w - t, -h + t, h, -d, -d + t), color), b.part(label, box_xyz(-w + t, w - t, -h + t, h, d - t, d), color)]


def build_kitchen_pot(folder: Path) -> Path:
    """A cooking pot (1.0 x 0.6 x 1.0 units, open at the top, two side
    handles) with a lid (``lid``, prismatic 0-0.4 units straight up) resting
    on its rim."""
    b = _Builder("u_pot", "KitchenPot")
    w, h = 0.5, 0.3
    body = _open_box(b, "pot_body", w, h, w, 0.04, _STEEL)
    body += [b.part("handle", box_xyz(-w - 0.15, -w, h - 0.1, h - 0.05, -0.1, 0.1), _DARK),
             b.part("handle", box_xyz(w, w + 0.15, h - 0.1, h - 0.05, -0.1, 0.1), _DARK)]
    b.body("link_1", "pot_body", body)
    b.moving("link_0", "slider", "lid", [b.part("lid", [box_xyz(-w - 0.02, w + 0.02, h, h + 0.03, -w - 0.02, w + 0.02),
                                                       box_xyz(-0.08, 0.08, h + 0.03, h + 0.1, -0.05, 0.05)], _STEEL)],
             "prismatic", "link_1", (0.0, h, 0.0), (0.0, 1.0, 0.0), 0.0, 0.4)
    return b.write(folder)


def build_bucket(folder: Path) -> Path:
    """A bucket (1.0 x 1.1 x 1.0 units, open at the top) with a wire bail handle (``handle``, revolute
    -1.3..1.3 rad about the axis through its two pivots on the side walls, upright at 0): it falls either
    way onto the rim, as a real bail does."""
    b = _Builder("u_bucket", "Bucket")
    w, h, t, py = 0.5, 0.55, 0.03, 0.45
    b.body("link_1", "bucket_body", _open_box(b, "bucket_body", w, h, w, t, _WHITE))
    arms = [box_xyz(sx * (w + 0.01) - (0.02 if sx > 0 else 0.0), sx * (w + 0.01) + (0.0 if sx > 0 else 0.02), py - 0.03,
                    h + 0.37, -0.015, 0.015) for sx in (1.0, -1.0)]
    grip = box_xyz(-w - 0.03, w + 0.03, h + 0.33, h + 0.37, -0.015, 0.015)
    b.moving("link_0", "hinge", "handle", [b.part("handle", [*arms, grip], _GREY)], "revolute", "link_1", (0.0, py, 0.0),
             (1.0, 0.0, 0.0), -1.3, 1.3)
    return b.write(folder)


def build_washing_machine(folder: Path) -> Path:
    """A front-loading washing machine (0.6 x 0.85 x 0.6 units carcass with
    an open front) with a door (``door``, revolute 0-1.9 rad about the
    vertical axis at its left edge) and a programme dial (``knob``,
    continuous) on the top panel's front."""
    b = _Builder("u_washer", "WashingMachine")
    w, h, d, t = 0.3, 0.425, 0.3, 0.03
    b.body("link_2", "washing_machine_body", _carcass(b, "washing_machine_body", w, h, d, t, _WHITE))
    b.moving("link_0", "hinge", "door", [b.part("door", box_xyz(-w, w, -h, h - 0.15, d, d + 0.04), _GLASS)],
             "revolute", "link_2", (-w, 0.0, d + 0.02), (0.0, -1.0, 0.0), 0.0, 1.9)
    b.moving("link_1", "hinge", "knob", [b.part("knob", box_xyz(0.12, 0.2, h - 0.11, h - 0.03, d, d + 0.04), _DARK)],
             "continuous", "link_2", (0.16, h - 0.07, d + 0.02), (0.0, 0.0, 1.0))
    return b.write(folder)


def build_eyeglasses(folder: Path) -> Path:
    """A pair of glasses standing open (frame 1.0 x 0.35 units, 0.04 thick)
    with two temples (``leg``, 0.45 long, revolute 0-1.5 rad about vertical
    axes on hinge blocks behind the frame's ends, folding inwards behind the
    frame); the right hinge block is deeper, so the folded temples lie one
    behind the other and each folds clear of the other."""
    b = _Builder("u_glasses", "Eyeglasses")
    w, h, q = 0.5, 0.175, 0.03
    frame = [box_xyz(-w, w, h - 0.05, h, -0.02, 0.02), box_xyz(-w, -0.05, -h, h - 0.05, -0.02, 0.02),
             box_xyz(0.05, w, -h, h - 0.05, -0.02, 0.02),
             box_xyz(-w, -w + q, h - 0.06, h, -0.05, -0.02), box_xyz(w - q, w, h - 0.06, h, -0.1, -0.02)]  # hinge blocks
    b.body("link_2", "eyeglasses_body", [b.part("eyeglasses_body", frame, _DARK)])
    b.moving("link_0", "hinge", "leg", [b.part("leg", box_xyz(-w, -w + q, h - 0.06, h, -0.5, -0.05), _DARK)],
             "revolute", "link_2", (-w, 0.0, -0.05), (0.0, -1.0, 0.0), 0.0, 1.5)
    b.moving("link_1", "hinge", "leg", [b.part("leg", box_xyz(w - q, w, h - 0.06, h, -0.55, -0.1), _DARK)],
             "revolute", "link_2", (w, 0.0, -0.1), (0.0, 1.0, 0.0), 0.0, 1.5)
    return b.write(folder)


def build_usb_swivel(folder: Path) -> Path:
    """A swivel USB stick lying flat (body 1.0 x 0.16 x 0.35 units with its
    plug) whose U-shaped cover (``rotor``, revolute 0-3.14 rad about the
    vertical axis through the body's rear) covers the plug closed and swings
    around the body to open it."""
    b = _Builder("u_usb", "USB")
    t = 0.08
    b.body("link_1", "usb_body", [b.part("usb_body", box_xyz(-0.5, 0.5, -t, t, -0.175, 0.175), _DARK),
                                  b.part("usb_body", box_xyz(0.5, 0.75, -0.03, 0.03, -0.12, 0.12), _STEEL)])
    cover = [box_xyz(-0.45, 0.8, t + 0.01, t + 0.04, -0.19, 0.19), box_xyz(-0.45, 0.8, -t - 0.04, -t - 0.01, -0.19, 0.19),
             box_xyz(0.78, 0.8, -t - 0.01, t + 0.01, -0.19, 0.19)]
    b.moving("link_0", "hinge", "rotor", [b.part("rotor", cover, _STEEL)], "revolute", "link_1", (-0.35, 0.0, 0.0),
             (0.0, 1.0, 0.0), 0.0, 3.14)
    return b.write(folder)


def build_kettle(folder: Path) -> Path:
    """An electric kettle (body 0.8 x 1.0 x 0.7 units, open at the top, a
    handle at the back) with a lid (``lid``, revolute 0-1.4 rad about the
    horizontal axis at its rear edge) resting on the rim."""
    b = _Builder("u_kettle", "Kettle")
    w, h, d = 0.4, 0.5, 0.35
    body = _open_box(b, "kettle_body", w, h, d, 0.04, _STEEL)
    body += [b.part("handle", [box_xyz(-0.08, 0.08, -0.3, 0.4, -d - 0.2, -d - 0.12), box_xyz(-0.08, 0.08, 0.32, 0.4, -d - 0.12, -d),
                               box_xyz(-0.08, 0.08, -0.3, -0.22, -d - 0.12, -d)], _DARK)]
    b.body("link_1", "kettle_body", body)
    b.moving("link_0", "hinge", "lid", [b.part("lid", box_xyz(-w, w, h, h + 0.04, -d, d), _STEEL)],
             "revolute", "link_1", (0.0, h + 0.02, -d), (-1.0, 0.0, 0.0), 0.0, 1.4)
    return b.write(folder)


def build_desk_lamp(folder: Path) -> Path:
    """A desk lamp (1.0 units tall): a base plate, a lower and an upper arm (``leg``, revolute about the
    horizontal x axis, +-0.6 and +-1.2 rad) and a shade (``head``, revolute +-0.8 rad) at the upper arm's end, held
    out in front of it: the arms carry the shade's weight."""
    b = _Builder("u_lamp", "Lamp")
    b.body("link_3", "lamp_base", [b.part("lamp_base", box_xyz(-0.3, 0.3, -0.5, -0.44, -0.25, 0.25), _DARK)])
    b.moving("link_0", "hinge", "leg", [b.part("leg", box_xyz(-0.03, 0.03, -0.42, 0.08, -0.03, 0.03), _GREY)],
             "revolute", "link_3", (0.0, -0.44, 0.0), (1.0, 0.0, 0.0), -0.6, 0.6)
    b.moving("link_1", "hinge", "leg", [b.part("leg", box_xyz(-0.03, 0.03, 0.12, 0.48, -0.03, 0.03), _GREY)],
             "revolute", "link_0", (0.0, 0.1, 0.0), (1.0, 0.0, 0.0), -1.2, 1.2)
    b.moving("link_2", "hinge", "head", [b.part("head", box_xyz(-0.1, 0.1, 0.36, 0.5, 0.04, 0.3), _WHITE)],
             "revolute", "link_1", (0.0, 0.5, 0.0), (1.0, 0.0, 0.0), -0.8, 0.8)
    return b.write(folder)


def build_desk_fan(folder: Path, front: float = 0.15) -> Path:
    """A desk fan (1.0 units tall): a base and a post, a head (``head``) tilting +-0.3 rad about the horizontal
    x axis on top of the post, and three blades (``rotor``, continuous about the head's forward z axis) turning
    ``front`` units in front of the post's axis: clear of the post at every tilt at the default, grazing it at 0.07."""
    b = _Builder("u_fan", "Fan")
    b.body("link_2", "fan_body", [b.part("fan_body", box_xyz(-0.3, 0.3, -0.5, -0.44, -0.25, 0.25), _WHITE),
                                  b.part("fan_body", box_xyz(-0.04, 0.04, -0.44, 0.0, -0.04, 0.04), _WHITE)])
    b.moving("link_0", "hinge", "head", [b.part("head", box_xyz(-0.1, 0.1, 0.0, 0.2, -0.15, front - 0.02), _WHITE)],
             "revolute", "link_2", (0.0, 0.02, 0.0), (1.0, 0.0, 0.0), -0.3, 0.3)
    blades = [b.part("rotor", box_xyz(-0.3, 0.3, 0.07, 0.13, front - 0.01, front + 0.01), _GREY,
                     Pose(axis=(0.0, 0.0, 1.0), angle=math.pi * k / 3, pivot=(0.0, 0.1, front))) for k in range(3)]
    b.moving("link_1", "hinge", "rotor", blades, "continuous", "link_0", (0.0, 0.1, front), (0.0, 0.0, 1.0))
    return b.write(folder)


def build_keyboard(folder: Path, rows: int = 3, cols: int = 8) -> Path:
    """A keyboard (1.0 x 0.05 x 0.34 units): a base and ``rows`` x ``cols`` keys (``key``, PartNet-Mobility's word for
    a keyboard's buttons), each on its own slider pressed 0.009 units down into the base's top, a fifth of the pitch
    apart."""
    b = _Builder("u_keyboard", "Keyboard")
    body = f"link_{rows * cols}"
    b.body(body, "keyboard_base", [b.part("keyboard_base", box_xyz(-0.5, 0.5, -0.05, 0.0, -0.17, 0.17), _DARK)])
    px, pz = 1.0 / cols, 0.32 / rows
    for k in range(rows * cols):
        x, z = -0.5 + px * (k % cols + 0.5), -0.16 + pz * (k // cols + 0.5)
        b.moving(f"link_{k}", "slider", "key", [b.part("key", box_xyz(x - 0.4 * px, x + 0.4 * px, 0.001, 0.025, z - 0.4 * pz, z + 0.4 * pz), _GREY)],
                 "prismatic", body, (x, 0.001, z), (0.0, -1.0, 0.0), 0.0, 0.009)
    return b.write(folder)


def build_printer(folder: Path) -> Path:
    """An inkjet printer (1.0 x 0.4 x 0.8 units, open at the top) with a lid (``lid``, revolute 0-1.3 rad about
    its rear edge) and a paper tray (``drawer``, prismatic 0-0.35 units out of the front) low inside it."""
    b = _Builder("u_printer", "Printer")
    w, h, d = 0.5, 0.2, 0.4
    b.body("link_2", "printer_body", _open_box(b, "printer_body", w, h, d, 0.03, _GREY))
    b.moving("link_0", "hinge", "lid", [b.part("lid", box_xyz(-w, w, h, h + 0.03, -d, d), _GREY)],
             "revolute", "link_2", (0.0, h + 0.015, -d), (-1.0, 0.0, 0.0), 0.0, 1.3)
    b.moving("link_1", "slider", "drawer", [b.part("drawer", [box_xyz(-0.35, 0.35, -0.15, -0.13, -0.3, d + 0.02),
                                                            box_xyz(-0.35, 0.35, -0.15, -0.08, d + 0.02, d + 0.04)], _DARK)],
             "prismatic", "link_2", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.0, 0.35)
    return b.write(folder)


def build_office_chair(folder: Path) -> Path:
    """An office chair (1.2 units tall): a three-armed base on a gas column, a caster's wheel (``wheel``, continuous
    about its horizontal axle, the three turned alike) under each arm standing on the ground, a seat with its backrest
    (``seat``, continuous about the column's vertical axis) and a height lever under the seat (``lever``, revolute 0-0.3
    rad on the seat)."""
    b = _Builder("u_chair", "Chair")
    arms = [b.part("chair_base", box_xyz(-0.03, 0.03, -0.50, -0.45, 0.0, 0.36), _DARK,
                   Pose(axis=(0.0, 1.0, 0.0), angle=2 * math.pi * k / 3, pivot=(0.0, 0.0, 0.0))) for k in range(3)]
    b.body("link_5", "chair_base", [*arms, b.part("chair_base", box_xyz(-0.04, 0.04, -0.45, -0.02, -0.04, 0.04), _GREY)])
    for k in range(3):
        a = 2 * math.pi * k / 3
        x, z = 0.32 * math.sin(a), 0.32 * math.cos(a)
        b.moving(f"link_{k}", "hinge", "wheel", _wheel(b, x, -0.54, z, 0.04, 0.012), "continuous", "link_5", (x, -0.54, z),
                 (1.0, 0.0, 0.0))  # the casters turned alike, their axles along x
    b.moving("link_3", "hinge", "seat", [b.part("seat", box_xyz(-0.3, 0.3, 0.0, 0.08, -0.3, 0.3), _DARK),
                                         b.part("seat", box_xyz(-0.28, 0.28, 0.08, 0.66, -0.3, -0.24), _DARK)],
             "continuous", "link_5", (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    b.moving("link_4", "hinge", "lever", [b.part("lever", box_xyz(0.2, 0.38, -0.03, -0.01, 0.1, 0.13), _GREY)],
             "revolute", "link_3", (0.2, -0.02, 0.115), (0.0, 0.0, 1.0), 0.0, 0.3)
    return b.write(folder)


def build_desk_globe(folder: Path) -> Path:
    """A desk globe (1.0 units tall): a round foot, a post and a half meridian over the top, and a sphere (``sphere``,
    continuous about its vertical axis) of radius 0.3 held between the post's top and the meridian, 1 cm clear of
    each."""
    b = _Builder("u_globe", "Globe")
    stand = [b.part("globe_base", box_xyz(-0.2, 0.2, -0.5, -0.46, -0.2, 0.2), _DARK),
             b.part("globe_base", box_xyz(-0.02, 0.02, -0.46, -0.26, -0.02, 0.02), _GREY),
             b.part("globe_base", box_xyz(-0.02, 0.02, -0.3, 0.42, -0.37, -0.33), _GREY),
             b.part("globe_base", box_xyz(-0.02, 0.02, 0.38, 0.42, -0.33, 0.02), _GREY)]
    b.body("link_1", "globe_base", stand)
    ball = [b.part("sphere", box_xyz(-0.3, 0.3, -0.2, 0.3, -0.3, 0.3), _GLASS,
                   Pose(axis=(0.0, 1.0, 0.0), angle=math.pi * k / 6, pivot=(0.0, 0.05, 0.0))) for k in range(3)]
    ball.append(b.part("sphere", box_xyz(-0.2, 0.2, -0.25, 0.37, -0.2, 0.2), _GLASS))
    b.moving("link_0", "hinge", "sphere", ball, "continuous", "link_1", (0.0, 0.05, 0.0), (0.0, 1.0, 0.0))
    return b.write(folder)


def build_scissors(folder: Path) -> Path:
    """Office scissors lying flat (0.9 units long): a blade with its handle loop (``blade``) and the other blade
    (``leg``) above it, turning 0-0.8 rad about the vertical screw at the pivot (closed: the blades over each
    other)."""
    b = _Builder("u_scissors", "Scissors")
    b.body("link_1", "blade", [b.part("blade", box_xyz(0.0, 0.5, 0.0, 0.01, -0.03, 0.0), _STEEL),
                               b.part("blade", box_xyz(-0.4, 0.0, 0.0, 0.01, -0.12, -0.02), _DARK)])
    b.moving("link_0", "hinge", "leg", [b.part("leg", box_xyz(0.0, 0.5, 0.01, 0.02, 0.0, 0.03), _STEEL),
                                        b.part("leg", box_xyz(-0.4, 0.0, 0.01, 0.02, 0.02, 0.12), _DARK)],
             "revolute", "link_1", (0.0, 0.01, 0.0), (0.0, 1.0, 0.0), 0.0, 0.8)
    return b.write(folder)


def build_wall_clock(folder: Path) -> Path:
    """A desk clock (0.8 x 0.8 x 0.2 units) standing on its edge, its face toward +z, with an hour and a minute
    hand (``hand``, continuous about the face's normal at its centre) in front of the face, 1 cm apart."""
    b = _Builder("u_clock", "Clock")
    b.body("link_2", "clock_body", [b.part("clock_body", box_xyz(-0.4, 0.4, -0.4, 0.4, -0.1, 0.1), _WHITE),
                                    b.part("clock_body", box_xyz(-0.03, 0.03, -0.03, 0.03, 0.1, 0.14), _DARK)])
    b.moving("link_0", "hinge", "hand", [b.part("hand", box_xyz(-0.02, 0.02, -0.03, 0.22, 0.105, 0.115), _DARK)],
             "continuous", "link_2", (0.0, 0.0, 0.11), (0.0, 0.0, 1.0))
    b.moving("link_1", "hinge", "hand", [b.part("hand", box_xyz(-0.015, 0.015, -0.04, 0.33, 0.125, 0.135), _DARK)],
             "continuous", "link_2", (0.0, 0.0, 0.13), (0.0, 0.0, 1.0))
    return b.write(folder)


def build_coffee_machine(folder: Path) -> Path:
    """A drip coffee machine (0.6 x 1.0 x 0.7 units, its water tank open at the top) with a lid over the tank
    (``lid``, revolute 0-1.6 rad about its rear edge), a power button on the front (``button``, prismatic 0-0.02 units
    in) and a carafe on the hot plate (``container``, prismatic 0-0.35 units out of the front)."""
    b = _Builder("u_coffee", "CoffeeMachine")
    w, h, d = 0.3, 0.5, 0.35
    body = [b.part("coffee_machine_body", box_xyz(-w, w, -h, -h + 0.08, -d, d), _DARK),
            b.part("coffee_machine_body", box_xyz(-w, w, -h + 0.08, h, -d, -0.05), _DARK),
            b.part("coffee_machine_body", box_xyz(-w, w, 0.15, h, -0.05, d), _DARK)]
    b.body("link_3", "coffee_machine_body", body)
    b.moving("link_0", "hinge", "lid", [b.part("lid", box_xyz(-w, w, h, h + 0.03, -d, d), _DARK)],
             "revolute", "link_3", (0.0, h + 0.015, -d), (-1.0, 0.0, 0.0), 0.0, 1.6)
    b.moving("link_1", "slider", "button", [b.part("button", box_xyz(-0.05, 0.05, 0.25, 0.3, d, d + 0.03), _RED)],
             "prismatic", "link_3", (0.0, 0.27, d), (0.0, 0.0, -1.0), 0.0, 0.02)
    b.moving("link_2", "slider", "container", [b.part("container", box_xyz(-0.2, 0.2, -h + 0.085, 0.1, -0.02, 0.3), _GLASS)],
             "prismatic", "link_3", (0.0, -h + 0.085, 0.0), (0.0, 0.0, 1.0), 0.0, 0.35)
    return b.write(folder)


def build_monitor(folder: Path) -> Path:
    """A computer display (0.9 units wide): a base plate and a post (``display_base``) and a screen (``screen``,
    revolute -0.1-0.35 rad about the horizontal axis at the post's top, tilting back) held in front of the post:
    its weight leans it forward, the tilt hinge's friction holds it."""
    b = _Builder("u_display", "Display")
    b.body("link_1", "display_base", [b.part("display_base", box_xyz(-0.2, 0.2, -0.5, -0.47, -0.15, 0.15), _DARK),
                                      b.part("display_base", box_xyz(-0.04, 0.04, -0.47, 0.05, -0.06, -0.02), _DARK)])
    b.moving("link_0", "hinge", "screen", [b.part("screen", box_xyz(-0.45, 0.45, -0.22, 0.32, -0.015, 0.03), _DARK)],
             "revolute", "link_1", (0.0, 0.05, -0.02), (-1.0, 0.0, 0.0), -0.1, 0.35)
    return b.write(folder)


def build_folding_chair(folder: Path) -> Path:
    """A folding chair (0.9 units tall): four legs and a backrest (``chair_frame``) and a seat (``seat``, revolute
    0-1.5 rad about the horizontal axis at its rear edge, folding up against the backrest)."""
    b = _Builder("u_folding_chair", "FoldingChair")
    legs = [b.part("chair_frame", box_xyz(x - 0.02, x + 0.02, -0.45, -0.02, z - 0.02, z + 0.02), _STEEL) for x in (-0.2, 0.2)
            for z in (-0.2, 0.2)]
    legs += [b.part("chair_frame", box_xyz(-0.22, 0.22, -0.02, 0.45, -0.24, -0.2), _STEEL)]
    b.body("link_1", "chair_frame", legs)
    b.moving("link_0", "hinge", "seat", [b.part("seat", box_xyz(-0.18, 0.18, -0.02, 0.01, -0.19, 0.2), _DARK)],
             "revolute", "link_1", (0.0, 0.0, -0.19), (1.0, 0.0, 0.0), 0.0, 1.5)
    return b.write(folder)


def build_folding_knife(folder: Path) -> Path:
    """A folding pocket knife lying flat (0.5 units long closed, 0.03 thick): a handle of two scales with a slot between
    them (``knife_body``) and a blade a fifth of the handle's thickness (``blade``, revolute 0-3.1 rad about the vertical pivot at the handle's end) folded
    into the slot."""
    b = _Builder("u_knife", "Knife")
    b.body("link_1", "knife_body", [b.part("knife_body", box_xyz(-0.25, 0.25, 0.0, 0.01, -0.04, 0.04), _DARK),
                                    b.part("knife_body", box_xyz(-0.25, 0.25, 0.02, 0.03, -0.04, 0.04), _DARK),
                                    b.part("knife_body", box_xyz(-0.25, -0.2, 0.01, 0.02, -0.04, 0.04), _DARK)])
    b.moving("link_0", "hinge", "blade", [b.part("blade", box_xyz(-0.19, 0.23, 0.012, 0.018, -0.03, 0.025), _STEEL)],
             "revolute", "link_1", (0.22, 0.015, 0.0), (0.0, 1.0, 0.0), 0.0, 3.1)
    return b.write(folder)


def build_pocket_lighter(folder: Path) -> Path:
    """A windproof lighter (0.4 x 0.6 x 0.15 units): a case (``lighter_body``) with a flint wheel on top (``wheel``,
    continuous about its horizontal axle) under a lid open at the bottom (``lid``, revolute 0-1.9 rad about the hinge on
    one side)."""
    b = _Builder("u_lighter", "Lighter")
    b.body("link_2", "lighter_body", [b.part("lighter_body", box_xyz(-0.2, 0.2, -0.3, 0.1, -0.075, 0.075), _STEEL),
                                      b.part("lighter_body", box_xyz(-0.1, 0.1, 0.1, 0.12, -0.05, 0.05), _STEEL)])
    b.moving("link_0", "hinge", "wheel", _wheel(b, 0.0, 0.17, 0.0, 0.04, 0.02, 4), "continuous", "link_2", (0.0, 0.17, 0.0),
             (1.0, 0.0, 0.0))
    lid = [box_xyz(-0.2, 0.2, 0.29, 0.3, -0.075, 0.075), box_xyz(-0.2, -0.19, 0.105, 0.29, -0.075, 0.075),
           box_xyz(0.19, 0.2, 0.105, 0.29, -0.075, 0.075), box_xyz(-0.19, 0.19, 0.105, 0.29, -0.075, -0.065),
           box_xyz(-0.19, 0.19, 0.105, 0.29, 0.065, 0.075)]
    b.moving("link_1", "hinge", "lid", [b.part("lid", lid, _STEEL)], "revolute", "link_2", (0.2, 0.1, 0.0), (0.0, 0.0, -1.0),
             0.0, 1.9)
    return b.write(folder)


def build_computer_mouse(folder: Path) -> Path:
    """A computer mouse (0.6 x 0.35 units, 0.12 tall): a body, a left and a right button (``button``, revolute
    0-0.04 rad about the horizontal axis at their rear, pressed down) and a scroll wheel between them (``wheel``,
    continuous)."""
    b = _Builder("u_mouse", "Mouse")
    b.body("link_3", "mouse_body", [b.part("mouse_body", box_xyz(-0.17, 0.17, 0.0, 0.09, -0.3, 0.3), _DARK)])
    for i, (x0, x1) in enumerate(((-0.17, -0.025), (0.025, 0.17))):
        b.moving(f"link_{i}", "hinge", "button", [b.part("button", box_xyz(x0, x1, 0.092, 0.12, 0.0, 0.3), _GREY)],
                 "revolute", "link_3", (0.0, 0.092, 0.0), (1.0, 0.0, 0.0), 0.0, 0.04)
    b.moving("link_2", "hinge", "wheel", _wheel(b, 0.0, 0.1, 0.15, 0.03, 0.012, 4), "continuous", "link_3", (0.0, 0.1, 0.15),
             (1.0, 0.0, 0.0))
    return b.write(folder)


def build_click_pen(folder: Path) -> Path:
    """A click pen lying on the table (1.0 units long): a barrel (``pen_body``) and a button at its end (``button``,
    prismatic 0-0.06 units into the barrel along its length)."""
    b = _Builder("u_pen", "Pen")
    b.body("link_1", "pen_body", [b.part("pen_body", box_xyz(-0.45, 0.42, 0.0, 0.07, -0.035, 0.035), _WHITE),
                                  b.part("pen_body", box_xyz(-0.5, -0.45, 0.02, 0.05, -0.015, 0.015), _DARK)])
    b.moving("link_0", "slider", "button", [b.part("button", box_xyz(0.422, 0.5, 0.015, 0.055, -0.02, 0.02), _DARK)],
             "prismatic", "link_1", (0.422, 0.035, 0.0), (-1.0, 0.0, 0.0), 0.0, 0.06)
    return b.write(folder)


def build_remote(folder: Path) -> Path:
    """A TV remote lying flat (0.2 x 0.03 x 0.8 units) with four buttons (``button``, prismatic 0-0.008 units
    down into its top)."""
    b = _Builder("u_remote", "Remote")
    b.body("link_4", "remote_base", [b.part("remote_base", box_xyz(-0.1, 0.1, 0.0, 0.03, -0.4, 0.4), _DARK)])
    for i, (x, z) in enumerate(((-0.05, 0.25), (0.05, 0.25), (-0.05, 0.1), (0.05, 0.1))):
        b.moving(f"link_{i}", "slider", "button", [b.part("button", box_xyz(x - 0.03, x + 0.03, 0.031, 0.045, z - 0.03, z + 0.03), _GREY)],
                 "prismatic", "link_4", (x, 0.031, z), (0.0, -1.0, 0.0), 0.0, 0.008)
    return b.write(folder)


def build_compact_camera(folder: Path) -> Path:
    """A compact camera (0.8 x 0.5 x 0.3 units): a body, a lens (``lens``, prismatic 0-0.15 units out of the front),
    a shutter button on top (``button``, prismatic 0-0.015 units down) and a mode dial (``knob``, revolute 0-4.7 rad
    about the vertical)."""
    b = _Builder("u_camera", "Camera")
    b.body("link_3", "camera_body", [b.part("camera_body", box_xyz(-0.4, 0.4, -0.25, 0.25, -0.15, 0.15), _DARK)])
    b.moving("link_0", "slider", "lens", [b.part("lens", box_xyz(-0.12, 0.12, -0.15, 0.09, 0.15, 0.22), _GREY)],
             "prismatic", "link_3", (0.0, -0.03, 0.15), (0.0, 0.0, 1.0), 0.0, 0.15)
    b.moving("link_1", "slider", "button", [b.part("button", box_xyz(0.22, 0.3, 0.251, 0.28, -0.04, 0.04), _GREY)],
             "prismatic", "link_3", (0.26, 0.251, 0.0), (0.0, -1.0, 0.0), 0.0, 0.015)
    b.moving("link_2", "hinge", "knob", [b.part("knob", box_xyz(-0.3, -0.16, 0.251, 0.3, -0.07, 0.07), _GREY)],
             "revolute", "link_3", (-0.23, 0.251, 0.0), (0.0, 1.0, 0.0), 0.0, 4.7)
    return b.write(folder)


def build_flip_phone(folder: Path) -> Path:
    """A flip phone lying on its back (0.5 x 1.0 units closed): a keypad half (``phone_base``) and a screen half
    (``screen``, revolute 0-2.8 rad about the horizontal hinge at their shared end) folded over it."""
    b = _Builder("u_phone", "Phone")
    b.body("link_1", "phone_base", [b.part("phone_base", box_xyz(-0.25, 0.25, 0.0, 0.08, -0.5, 0.5), _DARK)])
    b.moving("link_0", "hinge", "screen", [b.part("screen", box_xyz(-0.25, 0.25, 0.085, 0.15, -0.5, 0.5), _GREY)],
             "revolute", "link_1", (0.0, 0.085, -0.5), (-1.0, 0.0, 0.0), 0.0, 2.8)
    return b.write(folder)


def one_mesh_per_link(folder: Path) -> Path:
    """Rewrite the generated asset in ``folder`` in place so that each link draws and collides with one OBJ of one
    group holding all its parts (``textured_objs/merged-<link>.obj``), as PartNet-Mobility's files are: one group per
    file, a part concave as modelled, so that no convex piece comes for free from the generator's boxes. The per-part
    files stay on disk, unreferenced. Returns ``folder``.

    Raises:
        ValueError: a link whose meshes differ in origin or scale (the builders of this module give all the parts of
            a link the same).
    """
    folder = Path(folder)
    model = urdf.read_urdf(folder / "mobility.urdf")
    merged: dict[tuple[str, ...], str] = {}  # the part files -> their merged file (visuals and collisions share them)
    for name, link in model.links.items():
        for role in ("visuals", "collisions"):
            meshes = [g for g in getattr(link, role) if g.kind == "mesh"]
            if not meshes:
                continue
            first = meshes[0]
            if any(not np.array_equal(g.origin, first.origin) or not np.array_equal(g.scale, first.scale) for g in meshes):
                raise ValueError(f"{folder}: link {name!r}: its meshes differ in origin or scale")
            files = tuple(g.filename for g in meshes)
            rel = merged.get(files)
            if rel is None:
                rel = merged[files] = f"textured_objs/merged-{name}{'' if role == 'visuals' else '-collision'}.obj"
                _write_merged_obj(folder, files, folder / rel, name)
            setattr(link, role, [dataclasses.replace(first, filename=rel, path=None)]
                    + [g for g in getattr(link, role) if g.kind != "mesh"])
    atomic.write_bytes(folder / "mobility.urdf", urdf.write_urdf(model, style=urdf.PARTNET_STYLE))
    return folder


def _write_merged_obj(folder: Path, files: tuple[str, ...], dst: Path, group: str) -> None:
    """Write ``dst``: the OBJ ``files`` (paths relative to ``folder``) as one group ``group``, with the first file's
    material library and material ``material_0`` (the generator's)."""
    verts, faces, n = [], [], 0
    for rel in files:
        mesh = mesh_io.read_mesh(folder / rel)
        v, f = mesh.vertices, mesh.faces
        verts.append(v)
        faces.append(f + n)
        n += len(v)
    lines = [f"mtllib {Path(files[0]).with_suffix('.mtl').name}", f"o {group}",
             *(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in np.vstack(verts)),
             "usemtl material_0", *(f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.vstack(faces))]
    atomic.write_text(dst, "\n".join(lines) + "\n")

#: Every builder of this module: (asset name, builder, category).
UNSEEN_BUILDERS = (
    ("u_switch", build_toggle_switch, "Switch"),
    ("u_cart", build_cart, "Cart"),
    ("u_window_slide", build_sliding_window, "Window"),
    ("u_pliers", build_pliers, "Pliers"),
    ("u_double_door", build_double_door_cabinet, "StorageFurniture"),
    ("u_wardrobe", build_wardrobe, "StorageFurniture"),
    ("u_safe", build_safe, "Safe"),
    ("u_toaster", build_toaster, "Toaster"),
    ("u_bottle", build_bottle, "Bottle"),
    ("u_table", build_table_with_drawer, "Table"),
    ("u_oven", build_oven, "Oven"),
    ("u_pot", build_kitchen_pot, "KitchenPot"),
    ("u_washer", build_washing_machine, "WashingMachine"),
    ("u_glasses", build_eyeglasses, "Eyeglasses"),
    ("u_usb", build_usb_swivel, "USB"),
    ("u_kettle", build_kettle, "Kettle"),
    ("u_bucket", build_bucket, "Bucket"),
    ("u_dispenser", build_dispenser, "Dispenser"),
    ("u_lamp", build_desk_lamp, "Lamp"),
    ("u_fan", build_desk_fan, "Fan"),
    ("u_printer", build_printer, "Printer"),
    ("u_keyboard", build_keyboard, "Keyboard"),
    ("u_chair", build_office_chair, "Chair"),
    ("u_globe", build_desk_globe, "Globe"),
    ("u_scissors", build_scissors, "Scissors"),
    ("u_clock", build_wall_clock, "Clock"),
    ("u_coffee", build_coffee_machine, "CoffeeMachine"),
    ("u_display", build_monitor, "Display"),
    ("u_folding_chair", build_folding_chair, "FoldingChair"),
    ("u_knife", build_folding_knife, "Knife"),
    ("u_lighter", build_pocket_lighter, "Lighter"),
    ("u_mouse", build_computer_mouse, "Mouse"),
    ("u_pen", build_click_pen, "Pen"),
    ("u_remote", build_remote, "Remote"),
    ("u_camera", build_compact_camera, "Camera"),
    ("u_phone", build_flip_phone, "Phone"),
)
