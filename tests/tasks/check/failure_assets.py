"""Generated assets that reproduce refine's failure modes.

- :func:`build_tall_faucet`: a tall, thin fixture whose spout reaches far past
  its small foot: it tips over when free-standing, rests when mounted.
- :func:`build_tipping_laptop`: a laptop with a shallow, light base and a
  large screen; fully open, the screen leans back past the rear feet and
  (with volume-proportional masses) tips the body.
- :func:`build_interlocked_box`: a box whose lid carries an inner skirt that
  hangs inside the body; the body's single mesh is one convex hull, so every
  lid state near closed penetrates until the collision geometry is repaired.
- :func:`build_edge_standing_case`: a slim document case modelled standing
  on its narrow edge: at rest as modelled, toppled by a 5 deg tilt.

Built with the demo generator's geometry (:mod:`asset2sim.demo_geometry`),
PartNet-Mobility layout (y up, the base joint's rpy turns it z up).
"""

from __future__ import annotations

from pathlib import Path

from asset2sim import atomic
from asset2sim.demo_assets import _serialise
from asset2sim.demo_geometry import DemoArticulation, DemoJoint, DemoLink, Part, Pose, box_xyz, open_box

_BASE_RPY = "1.570796326794897 0 -1.570796326794897"
_GREY = (0.6, 0.62, 0.65)
_DARK = (0.15, 0.15, 0.17)


def _write(obj: DemoArticulation, out_dir: Path, one_hull: tuple[str, ...] = ()) -> Path:
    """Write ``obj``; the OBJ of each part named in ``one_hull`` keeps a single
    ``o`` group (PyBullet: one convex hull over all its boxes)."""
    out_dir = Path(out_dir)
    for rel, data in _serialise(obj).items():
        text = data.decode() if rel.endswith(".obj") else ""
        if any(f"o {name}/piece0" in text for name in one_hull):
            data = "\n".join(ln for ln in text.splitlines() if not ln.startswith("o ") or ln.endswith("/piece0")).encode() + b"\n"
        atomic.write_bytes(out_dir / rel, data)
    return out_dir


def build_tall_faucet(out_dir: Path) -> Path:
    """Faucet (object units = m at scale 1): a 5 cm square foot, a 40 cm stem
    and a 30 cm spout reaching out to one side; a lever handle on a hinge at
    the top. Units are y up (PartNet-Mobility)."""
    base = [
        Part("faucet_base-1", [box_xyz(-0.025, 0.025, 0.0, 0.01, -0.025, 0.025)], _GREY),
        Part("stem-2", [box_xyz(-0.01, 0.01, 0.01, 0.40, -0.01, 0.01)], _GREY),
        Part("spout-3", [box_xyz(-0.01, 0.01, 0.38, 0.40, 0.01, 0.30), box_xyz(-0.01, 0.01, 0.30, 0.38, 0.28, 0.30)], _GREY),
    ]
    lever = [Part("switch-4", [box_xyz(-0.008, 0.008, 0.402, 0.412, -0.10, 0.0)], _DARK)]
    obj = DemoArticulation(
        asset_id="tall_faucet", category="Faucet", robot_name="tall_faucet",
        links=[DemoLink("link_0", "hinge", "switch", lever), DemoLink("link_1", "static", "faucet_base", base)],
        joints=[
            DemoJoint("joint_1", "fixed", "base", "link_1", rpy=_BASE_RPY),
            DemoJoint("joint_0", "revolute", "link_1", "link_0", origin=(0.0, 0.412, 0.0), axis=(0.0, 1.0, 0.0), lower=-1.0, upper=1.0),
        ],
    )
    return _write(obj, out_dir)


def build_tipping_laptop(out_dir: Path) -> Path:
    """Laptop: a thin 30 x 18 cm base (1.2 cm thick, four rubber feet) and a 30 x 30 cm, 1.2 cm
    thick screen hinged at the rear edge that opens up to 2.4 rad (past
    vertical): fully open, the screen's centre of mass lies behind the rear
    feet."""
    hinge = (0.0, 0.012, -0.09)
    base = [Part("base-1", [box_xyz(-0.15, 0.15, 0.0, 0.012, -0.09, 0.09)], _GREY),
            Part("feet-3", [box_xyz(x0, x0 + 0.02, -0.003, 0.0, z0, z0 + 0.02)
                            for x0 in (-0.14, 0.12) for z0 in (-0.085, 0.065)], _DARK)]
    closed_screen = [box_xyz(-0.15, 0.15, 0.013, 0.025, -0.09, 0.21)]
    # modelled closed over the base, reaching 12 cm past its front edge (a large lid)
    screen = [Part("screen-2", closed_screen, _DARK, Pose(axis=(-1.0, 0.0, 0.0), angle=0.0, pivot=hinge))]
    obj = DemoArticulation(
        asset_id="tipping_laptop", category="Laptop", robot_name="tipping_laptop",
        links=[DemoLink("link_0", "hinge", "screen", screen), DemoLink("link_1", "free", "laptop_base", base)],
        joints=[
            DemoJoint("joint_1", "fixed", "base", "link_1", rpy=_BASE_RPY),
            DemoJoint("joint_0", "revolute", "link_1", "link_0", origin=hinge, axis=(-1.0, 0.0, 0.0), lower=0.0, upper=2.4),
        ],
    )
    return _write(obj, out_dir)


def build_interlocked_box(out_dir: Path) -> Path:
    """Box (20 x 12 x 20 cm, open top, walls 1 cm, the body ONE mesh group)
    with a hinged lid and, in the lid's middle, a turn latch whose 2 cm
    shaft reaches through the lid into the box. The body's collision hull is then a solid
    block: the latch (a grandchild of the body, so the pair is checked)
    penetrates it at every state of the closed band, whatever the latch's
    angle; only a convex decomposition of the body (walls) resolves it."""
    hinge = (0.0, 0.12, -0.1)
    body = [Part("box_body-1", [b for p in open_box(-0.1, 0.1, 0.0, 0.12, -0.1, 0.1, 0.01, "w", _GREY) for b in p.boxes], _GREY)]
    lid = [Part("lid-2", [box_xyz(-0.1, 0.1, 0.1205, 0.1305, -0.1, 0.1)], _DARK)]
    latch = [Part("knob-3", [box_xyz(-0.015, 0.015, 0.131, 0.136, -0.015, 0.015), box_xyz(-0.005, 0.005, 0.10, 0.131, -0.005, 0.005)], _GREY)]
    obj = DemoArticulation(
        asset_id="interlocked_box", category="Box", robot_name="interlocked_box",
        links=[DemoLink("link_0", "hinge", "rotation_lid", lid), DemoLink("link_2", "hinge", "knob", latch),
               DemoLink("link_1", "free", "box_body", body)],
        joints=[
            DemoJoint("joint_1", "fixed", "base", "link_1", rpy=_BASE_RPY),
            DemoJoint("joint_0", "revolute", "link_1", "link_0", origin=hinge, axis=(-1.0, 0.0, 0.0), lower=0.0, upper=1.8),
            DemoJoint("joint_2", "revolute", "link_0", "link_2", origin=(0.0, 0.011, 0.1), axis=(0.0, 1.0, 0.0), lower=-1.5, upper=1.5),
        ],
    )
    return _write(obj, out_dir, one_hull=("box_body-1",))


def build_edge_standing_case(out_dir: Path) -> Path:
    """Suitcase-category slim case (40 x 30 x 2.4 cm, object units = m at
    scale 1) modelled standing on its 40 x 2.4 cm edge, a carry handle hinged
    on the top edge. The centre of mass is 1.2 cm from either long edge of
    the support at 15 cm height: it rests, but tips past its edge at
    atan(1.2 / 15) = 4.6 deg, so a 5 deg tilt (robust rest) topples it."""
    body = [Part("suitcase_body-1", [box_xyz(-0.2, 0.2, 0.0, 0.3, -0.012, 0.012)], _GREY)]
    handle = [Part("handle-2", [box_xyz(-0.06, 0.06, 0.30, 0.31, -0.005, 0.005)], _DARK)]
    obj = DemoArticulation(
        asset_id="edge_standing_case", category="Suitcase", robot_name="edge_standing_case",
        links=[DemoLink("link_0", "hinge", "handle", handle), DemoLink("link_1", "free", "suitcase_body", body)],
        joints=[
            DemoJoint("joint_1", "fixed", "base", "link_1", rpy=_BASE_RPY),
            DemoJoint("joint_0", "revolute", "link_1", "link_0", origin=(0.0, 0.3, 0.0), axis=(1.0, 0.0, 0.0), lower=-1.5, upper=1.5),
        ],
    )
    return _write(obj, out_dir)
