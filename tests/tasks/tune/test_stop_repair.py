"""Collision repair where the joint sweep stops inside the range against a
hull that bulges (tasks.tune.stop_repair), on a generated asset."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.tasks.check.sweep import run_sweep, sweep_metric
from asset2sim.tasks.check.sweep_stalls import blocked_positions, blocked_stops
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.tune import stop_repair

pytest.importorskip("coacd")


def _boxes_obj(boxes: list[tuple[list[float], list[float]]]) -> str:
    """One OBJ (no ``o`` groups: one convex hull in the engines) of axis-aligned boxes (lo, hi), m."""
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4),
             (1, 5, 7), (1, 7, 3)]
    vs, fs = [], []
    for lo, hi in boxes:
        c = [lo, hi]
        n = len(vs)
        vs += [[c[i][0], c[j][1], c[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        fs += [(a + n, b + n, c_ + n) for a, b, c_ in faces]
    return "\n".join([f"v {a} {b} {c_}" for a, b, c_ in vs] + [f"f {a + 1} {b + 1} {c_ + 1}" for a, b, c_ in fs]) + "\n"


def _carriage_over_rail(root: Path) -> Path:
    """z up, m. A base plate (top at z = 0); a rail (10 x 2 x 3 cm) on a flap
    hinged to the base (a sibling of the carriage, held at 0 by the sweep);
    a U-shaped carriage sliding along +x (0..0.2 m): a top bar 1 cm above
    the rail and two legs 1 cm beside it, so the real parts pass. Its one
    mesh is one convex hull, which fills the U and runs into the rail's end
    at half the range."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "base.obj").write_text(_boxes_obj([([-0.25, -0.06, -0.01], [0.25, 0.06, 0.0])]))
    (root / "rail.obj").write_text(_boxes_obj([([0.05, -0.01, 0.001], [0.15, 0.01, 0.03])]))
    (root / "carriage.obj").write_text(_boxes_obj([([-0.15, -0.03, 0.04], [-0.05, 0.03, 0.05]),
                                                   ([-0.15, -0.03, 0.005], [-0.05, -0.02, 0.04]),
                                                   ([-0.15, 0.02, 0.005], [-0.05, 0.03, 0.04])]))
    inertial = '<inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>'

    def link(name: str) -> str:
        return (f'  <link name="{name}">{inertial}<visual><geometry><mesh filename="{name}.obj"/></geometry></visual>'
                f'<collision><geometry><mesh filename="{name}.obj"/></geometry></collision></link>\n')

    urdf = ('<robot name="carriage">\n' + link("base") + link("rail") + link("carriage")
            + '  <joint name="flap" type="revolute"><parent link="base"/><child link="rail"/><axis xyz="0 1 0"/>'
            + '<limit lower="-0.5" upper="0" effort="1000" velocity="1000"/><dynamics damping="0.01" friction="0.05"/></joint>\n'
            + '  <joint name="slide" type="prismatic"><parent link="base"/><child link="carriage"/><axis xyz="1 0 0"/>'
            + '<limit lower="0" upper="0.2" effort="1000" velocity="1000"/><dynamics damping="0.01" friction="0.05"/></joint>\n'
            + "</robot>\n")
    (root / "mobility.urdf").write_text(urdf)
    return root / "mobility.urdf"


def _with_overrides(urdf: Path, overrides) -> Path:
    """A copy of ``urdf`` beside it whose overridden links collide through the repair's pieces."""
    text = urdf.read_text()
    for ln, pieces in overrides.items():
        coll = "".join(f'<collision><geometry><mesh filename="{p.filename}"/></geometry></collision>' for p in pieces)
        text = re.sub(rf'(<link name="{ln}">.*?)<collision>.*?</collision>(</link>)', lambda m: m.group(1) + coll + m.group(2),
                      text, flags=re.S)
    out = urdf.parent / "repaired.urdf"
    out.write_text(text)
    return out


@pytest.mark.slow  # end to end: a refine whose sweep repair runs a CoACD decomposition
def test_a_u_hull_that_stops_on_a_rail_is_decomposed_and_the_sweep_passes(tmp_path):
    urdf = _carriage_over_rail(tmp_path / "src")
    closed = {"slide": (0.0, 1.0, 0.2)}
    state = {"flap": 0.0, "slide": 0.0}
    before = sweep_metric(run_sweep("pybullet", SimObject(UrdfFile(urdf), state), closed))
    assert not before.passed  # the hull of the U runs into the rail's end
    assert 0.3 < blocked_positions(before)["slide"] / 0.2 < 0.6
    stall, goal = blocked_stops(before)["slide"]
    assert goal == pytest.approx(0.2) and stall < goal
    overrides, notes = stop_repair.decompose_for_blocked(
        SimObject(UrdfFile(urdf), state), extract_asset(urdf.parent), before, set(), 1.0, urdf.parent, "collision")
    assert set(overrides) == {"carriage"} and len(overrides["carriage"]) >= 3  # the U in pieces
    assert any("CoACD" in n and "sweep of slide stopped by rail" in n for n in notes)
    after = sweep_metric(run_sweep("pybullet", SimObject(UrdfFile(_with_overrides(urdf, overrides)), state), closed))
    assert after.passed, after.details["failures"]


def test_nothing_is_decomposed_when_the_sweep_passes_or_a_link_was_replaced(tmp_path):
    urdf = _carriage_over_rail(tmp_path / "src")
    state = {"flap": 0.0, "slide": 0.0}
    free = sweep_metric(run_sweep("pybullet", SimObject(UrdfFile(urdf), state), {"flap": (0.0, -1.0, 0.5)}))
    assert free.passed and blocked_stops(free) == {}
    blocked = sweep_metric(run_sweep("pybullet", SimObject(UrdfFile(urdf), state), {"slide": (0.0, 1.0, 0.2)}))
    overrides, notes = stop_repair.decompose_for_blocked(
        SimObject(UrdfFile(urdf), state), extract_asset(urdf.parent), blocked, {"carriage"}, 1.0, urdf.parent, "collision")
    assert overrides == {} and notes == []  # earlier stages' pieces are left alone
