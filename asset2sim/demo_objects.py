"""The six demo objects (:data:`DEMO_OBJECTS`) built from boxes
(:mod:`asset2sim.demo_geometry`), each with its category, manifest prompt and
closed joint positions. Moving parts keep at least 0.005 units from their
parent in the closed state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from asset2sim.demo_geometry import DemoArticulation, DemoJoint, DemoLink, Part, Pose, Vec3, box_xyz, open_box

#: rpy of PartNet-Mobility's fixed joint base -> body (y-up object frame to z-up).
_PARTNET_BASE_RPY = "1.570796326794897 0 -1.570796326794897"

_WOOD = (0.62, 0.45, 0.3)
_DARK = (0.15, 0.15, 0.17)
_GREY = (0.6, 0.62, 0.65)
_WHITE = (0.9, 0.9, 0.88)
_GLASS = (0.25, 0.3, 0.35)
_METAL = (0.75, 0.76, 0.78)
_GREEN = (0.3, 0.5, 0.35)


def _demo(asset_id: str, category: str, links: list[DemoLink], joints: list[DemoJoint]) -> DemoArticulation:
    """The articulation ``demo_<asset_id>``."""
    return DemoArticulation(asset_id=asset_id, category=category, robot_name=f"demo_{asset_id}", links=links, joints=joints)


def _part(name: str, color: tuple[float, float, float], *boxes: tuple[float, ...], pose: Pose | None = None) -> Part:
    """The part ``name`` of ``color`` made of ``boxes`` (each x0, x1, y0, y1, z0, z1 in object units, :func:`box_xyz`)."""
    return Part(name, [box_xyz(*b) for b in boxes], color, pose)


def _parts(prefix: str, color: Vec3, first: int, *boxes: tuple[float, ...]) -> list[Part]:
    """The parts ``<prefix>-<first>``, ``<prefix>-<first + 1>`` ... of ``color``, one box each (as :func:`_part`)."""
    return [_part(f"{prefix}-{n}", color, box) for n, box in enumerate(boxes, first)]


def _base_joint(name: str, body: str) -> DemoJoint:
    """PartNet-Mobility's fixed joint ``base`` -> ``body`` (y-up object frame to z-up)."""
    return DemoJoint(name, "fixed", "base", body, rpy=_PARTNET_BASE_RPY)


def _hinged(asset_id: str, category: str, moving: tuple, body: tuple, hinge: Vec3, axis: Vec3, lower: float,
            upper: float) -> DemoArticulation:
    """A body ``link_1`` (its semantic joint kind, label and parts), hung from ``base``, and one part ``link_0`` (its
    label and parts) on the revolute ``joint_0`` about ``axis`` through ``hinge``, limits ``lower`` / ``upper`` rad."""
    return _demo(asset_id, category, [DemoLink("link_0", "hinge", *moving), DemoLink("link_1", *body)], [
        DemoJoint("joint_0", "revolute", "link_1", "link_0", origin=hinge, axis=axis, lower=lower, upper=upper),
        _base_joint("joint_1", "link_1"),
    ])


def _box_with_lid() -> DemoArticulation:
    # Body: x [-0.5, 0.5], y [-0.3, 0.22], z [-0.35, 0.35], walls 0.03.
    body = open_box(-0.5, 0.5, -0.3, 0.22, -0.35, 0.35, 0.03, "box_body", _WOOD)
    # Lid (closed at 0): plate on top with 0.005 clearance, side skirts outside
    # the walls, a front lip with a pull tab (one OBJ, two pieces).
    hinge = (0.0, 0.225, -0.35)
    lid = [
        _part("lid_top-6", _WOOD, (-0.525, 0.525, 0.225, 0.255, -0.35, 0.375)),
        *_parts("lid_skirt", _WOOD, 7, (-0.525, -0.505, 0.18, 0.225, -0.35, 0.375), (0.505, 0.525, 0.18, 0.225, -0.35, 0.375)),
        _part("lid_lip-9", _METAL, (-0.505, 0.505, 0.18, 0.225, 0.355, 0.375), (-0.08, 0.08, 0.19, 0.21, 0.375, 0.405)),
    ]
    return _hinged("box_lid", "Box", ("rotation_lid", lid), ("free", "box_body", body), hinge, (-1.0, 0.0, 0.0), -0.5, 1.9)


#: Thickness of a demo drawer's bottom panel, object units (:func:`_drawer`).
DRAWER_BOTTOM = 0.01


def _drawer(front_y: tuple[float, float], box_y: tuple[float, float], n: int) -> list[Part]:
    """A drawer closed at z = 0.405: front panel spanning ``front_y`` (object
    units), open-topped drawer box spanning ``box_y``, U-shaped handle (one OBJ,
    three pieces). Built as drawer boxes are: a 0.03 front, 0.02 sides and back
    and a 0.01 bottom panel (at the demo's scale of about 0.57: 17 mm, 11 mm and
    6 mm; a drawer bottom is a 1/4 in hardboard or plywood panel let into the
    sides, AWI Architectural Woodwork Standards, drawer construction)."""
    y0, y1 = front_y
    by0, by1 = box_y
    t = DRAWER_BOTTOM
    front = _part(f"drawer_front-{n}", _WOOD, (-0.495, 0.495, y0, y1, 0.405, 0.435))
    box = [
        _part(f"drawer_bottom-{n + 1}", _WOOD, (-0.46, 0.46, by0, by0 + t, -0.36, 0.405)),
        *_parts("drawer_side", _WOOD, n + 2, (-0.46, -0.44, by0 + t, by1, -0.36, 0.405),
                (0.44, 0.46, by0 + t, by1, -0.36, 0.405)),
        _part(f"drawer_back-{n + 4}", _WOOD, (-0.44, 0.44, by0 + t, by1, -0.36, -0.34)),
    ]
    ym = 0.5 * (y0 + y1)
    handle = _part(f"handle-{n + 5}", _METAL,
        (-0.16, -0.13, ym - 0.015, ym + 0.015, 0.435, 0.475),
        (0.13, 0.16, ym - 0.015, ym + 0.015, 0.435, 0.475),
        (-0.165, 0.165, ym - 0.015, ym + 0.015, 0.47, 0.495),
    )
    return [front, *box, handle]


def _cabinet_two_drawers() -> DemoArticulation:
    # Carcass x [-0.5, 0.5], y [-0.55, 0.55], z [-0.4, 0.4], open front,
    # 0.03 boards, a divider at y = 0.
    t = 0.03
    body = [
        *_parts("board", _WOOD, 1,
                (-0.5, -0.5 + t, -0.55, 0.55, -0.4, 0.4),
                (0.5 - t, 0.5, -0.55, 0.55, -0.4, 0.4),
                (-0.5 + t, 0.5 - t, 0.55 - t, 0.55, -0.4, 0.4),
                (-0.5 + t, 0.5 - t, -0.55, -0.55 + t, -0.4, 0.4),
                (-0.5 + t, 0.5 - t, -0.55 + t, 0.55 - t, -0.4, -0.4 + t)),
        _part("shelf-6", _WOOD, (-0.5 + t, 0.5 - t, -0.015, 0.015, -0.4 + t, 0.4)),
    ]
    # Drawer boxes clear the divider (|y| <= 0.015), the top board (y >= 0.52)
    # and the bottom board (y <= -0.52) by at least 0.01.
    # the top drawer, then the bottom one
    drawers = [_drawer((0.02, 0.545), (0.03, 0.465), 10), _drawer((-0.545, -0.02), (-0.51, -0.1), 20)]
    links = [*(DemoLink(f"link_{i}", "slider", "drawer", d) for i, d in enumerate(drawers)),
             DemoLink("link_2", "heavy", "furniture_body", body)]
    return _demo("cabinet_2drawer", "StorageFurniture", links, [
        *(DemoJoint(f"joint_{i}", "prismatic", "link_2", f"link_{i}", axis=(0.0, 0.0, 1.0), lower=0.0, upper=0.5)
          for i in (0, 1)),
        _base_joint("joint_2", "link_2"),
    ])


#: Angle (rad) at which the laptop screen is modelled (open), measured from closed.
LAPTOP_MODEL_OPENING = math.radians(105.0)


def _laptop_base() -> list[Part]:
    """The laptop's base: x [-0.55, 0.55], z [-0.38, 0.38], y [-0.056, 0.004]
    with feet, rim, deck, keyboard and touchpad."""
    return [
        _part("base_bottom-1", _GREY, (-0.55, 0.55, -0.05, -0.04, -0.38, 0.38)),
        _part("base_rim-2", _GREY, (-0.55, 0.55, -0.04, -0.01, 0.37, 0.38), (-0.55, 0.55, -0.04, -0.01, -0.38, -0.37)),
        _part("base_rim-3", _GREY, (-0.55, -0.54, -0.04, -0.01, -0.37, 0.37), (0.54, 0.55, -0.04, -0.01, -0.37, 0.37)),
        _part("base_deck-4", _GREY, (-0.55, 0.55, -0.01, 0.0, -0.38, 0.38)),
        _part("keyboard-5", _DARK, (-0.45, 0.45, 0.0, 0.004, -0.3, 0.02), (-0.12, 0.12, 0.0, 0.002, 0.1, 0.3)),
        _part("feet-6", _DARK,
            (-0.5, -0.44, -0.056, -0.05, -0.33, -0.27),
            (0.44, 0.5, -0.056, -0.05, -0.33, -0.27),
            (-0.5, -0.44, -0.056, -0.05, 0.27, 0.33),
            (0.44, 0.5, -0.056, -0.05, 0.27, 0.33),
        ),
    ]


def _laptop_screen(hinge: tuple[float, float, float]) -> list[Part]:
    """The laptop's screen, designed in its closed pose (lying on the base,
    display down, 0.006 above the keyboard), then rotated open about the hinge
    line (x axis through ``hinge``) by :data:`LAPTOP_MODEL_OPENING`."""
    pose = Pose(axis=(-1.0, 0.0, 0.0), angle=LAPTOP_MODEL_OPENING, pivot=hinge)
    return [
        _part("screen_cover-7", _GREY, (-0.55, 0.55, 0.03, 0.04, -0.38, 0.38), pose=pose),
        _part("bezel-8", _DARK,
            (-0.55, -0.51, 0.01, 0.03, -0.38, 0.38),
            (0.51, 0.55, 0.01, 0.03, -0.38, 0.38),
            (-0.52, 0.52, 0.01, 0.03, 0.34, 0.38),
            (-0.52, 0.52, 0.01, 0.03, -0.38, -0.34),
            pose=pose,
        ),
        _part("display-9", _GLASS, (-0.51, 0.51, 0.015, 0.03, -0.34, 0.34), pose=pose),
    ]


def _laptop() -> DemoArticulation:
    hinge = (0.0, 0.025, -0.38)  # x axis through y = 0.025, z = -0.38
    links = [DemoLink("link_0", "free", "laptop_base", _laptop_base()), DemoLink("link_1", "hinge", "screen", _laptop_screen(hinge))]
    return _demo("laptop", "Laptop", links, [
        _base_joint("joint_0", "link_0"),
        DemoJoint("joint_1", "revolute", "link_0", "link_1", origin=hinge, axis=(-1.0, 0.0, 0.0), lower=-LAPTOP_MODEL_OPENING, upper=0.35),
    ])


def _microwave() -> DemoArticulation:
    # Body x [-0.6, 0.6], y [-0.35, 0.35], z [-0.4, 0.4]; cavity on the left
    # (x < 0.25), control panel on the right; open front at z = 0.4.
    t = 0.03
    body = [
        *_parts("frame", _WHITE, 1,
                (-0.6, 0.6, -0.35, -0.35 + t, -0.4, 0.4),
                (-0.6, 0.6, 0.35 - t, 0.35, -0.4, 0.4),
                (-0.6, -0.6 + t, -0.35 + t, 0.35 - t, -0.4, 0.4),
                (0.6 - t, 0.6, -0.35 + t, 0.35 - t, -0.4, 0.4),
                (-0.6 + t, 0.6 - t, -0.35 + t, 0.35 - t, -0.4, -0.4 + t),
                (0.25, 0.25 + t, -0.35 + t, 0.35 - t, -0.4 + t, 0.4)),
        _part("control_panel-7", _DARK, (0.25 + t, 0.6 - t, -0.35 + t, 0.35 - t, 0.37, 0.4), (0.36, 0.48, 0.12, 0.2, 0.4, 0.42)),
    ]
    # Turntable tray: a fixed (static) child link resting inside the cavity.
    tray_center = (-0.16, -0.3, 0.0)
    tray = [_part("tray-8", _GLASS, (-0.4, 0.08, -0.31, -0.3, -0.24, 0.24), (-0.2, -0.12, -0.314, -0.31, -0.04, 0.04))]
    # Door (closed at 0): frame pieces around a recessed window, handle on the
    # free edge; hinge on the left at the body's front-left edge.
    hinge = (-0.6, 0.0, 0.405)
    door = [
        *_parts("door_frame", _WHITE, 9,
                (-0.6, 0.245, -0.35, -0.25, 0.405, 0.445),
                (-0.6, 0.245, 0.25, 0.35, 0.405, 0.445),
                (-0.6, -0.5, -0.25, 0.25, 0.405, 0.445),
                (0.145, 0.245, -0.25, 0.25, 0.405, 0.445)),
        _part("window-13", _GLASS, (-0.5, 0.145, -0.25, 0.25, 0.415, 0.435)),
        _part("handle-14", _METAL,
            (0.18, 0.22, -0.2, -0.16, 0.445, 0.485),
            (0.18, 0.22, 0.16, 0.2, 0.445, 0.485),
            (0.175, 0.225, -0.205, 0.205, 0.48, 0.505),
        ),
    ]
    links = [DemoLink("link_0", "hinge", "door", door), DemoLink("link_1", "static", "tray", tray),
             DemoLink("link_2", "heavy", "microwave_body", body)]
    return _demo("microwave", "Microwave", links, [
        DemoJoint("joint_0", "revolute", "link_2", "link_0", origin=hinge, axis=(0.0, -1.0, 0.0), lower=0.0, upper=1.75),
        DemoJoint("joint_1", "fixed", "link_2", "link_1", origin=tray_center),
        _base_joint("joint_2", "link_2"),
    ])


def _trash_can() -> DemoArticulation:
    # Bin x [-0.35, 0.35], y [-0.6, 0.5], z [-0.35, 0.35], walls 0.025.
    body = open_box(-0.35, 0.35, -0.6, 0.5, -0.35, 0.35, 0.025, "body", _GREEN)
    body.append(_part("rim-6", _GREEN, (-0.35, 0.35, -0.6, -0.57, 0.35, 0.37)))
    # Lid closed at 0; axis +x so opening is a *negative* angle.
    hinge = (0.0, 0.505, -0.35)
    lid = [
        _part("lid-7", _GREEN, (-0.375, 0.375, 0.505, 0.535, -0.35, 0.37)),
        *_parts("lid_skirt", _GREEN, 8, (-0.375, -0.355, 0.47, 0.505, -0.35, 0.37), (0.355, 0.375, 0.47, 0.505, -0.35, 0.37)),
        _part("lid_lip-10", _DARK, (-0.355, 0.355, 0.46, 0.505, 0.355, 0.37), (-0.06, 0.06, 0.47, 0.49, 0.37, 0.4)),
    ]
    return _hinged("trash_can", "TrashCan", ("lid", lid), ("free", "trashcan_body", body), hinge, (1.0, 0.0, 0.0), -1.9, 0.0)


def _door_in_frame() -> DemoArticulation:
    # Frame: two posts x [-0.3, -0.26] and [0.26, 0.3], a header y [0.66, 0.7], all z [-0.035, 0.035]; no threshold
    # (the door stands on the floor at y = -0.7, its panel 0.005 above it).
    frame = _parts("door_frame", _WOOD, 1,
                   (-0.3, -0.26, -0.7, 0.7, -0.035, 0.035),
                   (0.26, 0.3, -0.7, 0.7, -0.035, 0.035),
                   (-0.26, 0.26, 0.66, 0.7, -0.035, 0.035))
    # Door (closed at 0): stiles and rails around a thinner centre panel, 0.005 inside the frame on every side, its
    # front flush with the frame's; a lever handle near the free edge. The hinge line is the panel's front edge on
    # the left post, so the door swings out (+z) past 90 deg clear of the post.
    hinge = (-0.255, 0.0, 0.035)
    door = [
        *_parts("door", _WHITE, 4,
                (-0.255, -0.205, -0.695, 0.655, 0.005, 0.035),
                (0.205, 0.255, -0.695, 0.655, 0.005, 0.035),
                (-0.205, 0.205, 0.605, 0.655, 0.005, 0.035),
                (-0.205, 0.205, -0.695, -0.6, 0.005, 0.035)),
        _part("panel-8", _WHITE, (-0.205, 0.205, -0.6, 0.605, 0.012, 0.028)),
        _part("handle-9", _METAL, (0.17, 0.19, -0.05, -0.02, 0.035, 0.06), (0.1, 0.19, -0.05, -0.03, 0.06, 0.075)),
    ]
    return _hinged("door", "Door", ("rotation_door", door), ("static", "door_frame", frame), hinge, (0.0, -1.0, 0.0), 0.0, 1.75)


#: The manipulation task of each demo category (the manifest's ``task`` column),
#: worded as the dev manifest words it.
CATEGORY_TASKS: dict[str, str] = {
    "Box": "close the box lid",
    "StorageFurniture": "close the cabinet drawer",
    "Laptop": "close the laptop",
    "Microwave": "close the microwave door",
    "TrashCan": "open the trashcan lid",
    "Door": "open the door",
}


@dataclass(frozen=True)
class DemoObject:
    """One entry of the demo dataset: id, category, builder, manifest prompt
    and task (:data:`CATEGORY_TASKS` of its category)."""

    asset_id: str
    category: str
    prompt: str
    make: Callable[[], DemoArticulation]
    closed_positions: dict[str, float]
    """Ground truth for tests: joint -> closed position (rad or m, object units).
    Not written into the asset folder (the pipeline must find it itself)."""

    @property
    def task(self) -> str:
        """The manipulation task of this object's category."""
        return CATEGORY_TASKS[self.category]


DEMO_OBJECTS: tuple[DemoObject, ...] = (
    DemoObject("box_lid", "Box", "A small box with its lid slightly open. Low damping hinge.", _box_with_lid, {"joint_0": 0.0}),
    DemoObject("cabinet_2drawer", "StorageFurniture", "A small two-drawer cabinet with the first drawer closed and the second slightly "
               "open, with low damping sliding joints.", _cabinet_two_drawers, {"joint_0": 0.0, "joint_1": 0.0}),
    DemoObject("laptop", "Laptop", "I want a slightly open laptop. Low damping for smooth operation.", _laptop,
               {"joint_1": -LAPTOP_MODEL_OPENING}),
    DemoObject("microwave", "Microwave", "A microwave with its door halfway open. Low damping for hinge-like behavior.", _microwave,
               {"joint_0": 0.0}),
    DemoObject("trash_can", "TrashCan", "A very small trash can with its lid closed. The lid hinge holds its position.", _trash_can,
               {"joint_0": 0.0}),
    DemoObject("door", "Door", "A 12 kg interior door in its frame, slightly open.", _door_in_frame, {"joint_0": 0.0}),
)
