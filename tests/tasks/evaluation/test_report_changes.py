""""What asset2sim changed" over a day of one's own objects: robosuite's door (an MJCF fragment declaring masses,
damping and friction loss, its latch drawn inside the door) and a hand-written MJCF cabinet, each drawn and described
as its own file declares it, every physical quantity with its unit, a spring asked for in its own row; the states at
their band's centre unless something moved them, and then why."""

from __future__ import annotations

import html
import re

import pytest

from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.evaluation.report_changes import state_moves
from tests.tasks.ingest import host_layouts as hl

pytest.importorskip("mujoco")

CONFIG = RefineConfig(engines=["pybullet"], clips=False)


def _text(page: str) -> str:
    """The report's text: tags dropped, cells joined by " | ", one table row per line."""
    page = re.sub(r"<(style|script|svg)[^>]*>.*?</\1>", "", page, flags=re.S)
    page = re.sub(r"</tr>|<br/?>|</p>|</h\d>|</li>|</figcaption>", "\n", page)
    return html.unescape(re.sub(r"<[^>]+>", "", re.sub(r"</td>|</th>", " | ", page)))


def _rows(page: str) -> dict[str, list[str]]:
    """"What asset2sim changed" table: what -> [input, output, why]."""
    section = _text(page).split("What asset2sim changed", 1)[1].split("Verdicts", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.split(" | ")]
        if len(cells) >= 4 and cells[0] not in ("what",):
            rows[cells[0]] = cells[1:4]
    return rows


@pytest.fixture(scope="module")
def door(tmp_path_factory, refine_factory):
    """robosuite's door fragment in its package's layout, refined "a door" (report.html made)."""
    base = tmp_path_factory.mktemp("robosuite")
    xml = hl.robosuite_door(base / "robosuite" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    return refine_factory(xml, "A door.", CONFIG)


def test_an_mjcf_input_is_drawn_and_described_as_its_file_declares_it(door):
    """robosuite's door: the input is drawn beside the output (no "could not be drawn", no temporary path), its total
    mass is the 7.854 + 2.435 + 0.1 kg the file declares, its hinge's damping and friction loss are the file's 1 N m s/rad
    and 1 N m, each beside the output's value with its unit; the progress and the report name door.xml, never the
    staged model.urdf."""
    page = (door.out_dir / "report.html").read_text()
    rows = _rows(page)
    assert "<figcaption class='small'>input (door.xml), front</figcaption>" in page
    assert "could not be drawn" not in page and "asset2sim-staged" not in page and "model.urdf" not in page
    assert rows["total mass"][0] == "10.39 kg (as declared: frame 7.854, door 2.435, latch 0.1 kg)", rows["total mass"]
    assert rows["total mass"][1] == f"{door.report.total_mass:.4g} kg"
    damping, friction = rows["door_hinge damping"], rows["door_hinge friction"]
    assert damping[0] == "1 N m s/rad" and friction[0] == "1 N m", (damping, friction)
    jd = door.overlay.joints["door_hinge"]
    assert damping[1] == f"{jd.damping:.4g} N m s/rad" and friction[1] == f"{jd.friction:.4g} N m"
    assert "door_hinge stiffness" not in rows  # no spring on either side
    assert "SPEC" not in page


def test_the_latch_inside_the_door_is_one_story(door):
    """robosuite draws the latch 19 mm inside the door: refine's penetration line, report.html's verdict table and the
    audit of the same file grade it alike (as modelled: it passes), and no page says FAIL beside the verdict's pass."""
    from asset2sim.apps.audit.audit import audit_asset

    m = door.report.metric("parent_child_penetration")
    assert m.value == pytest.approx(19.0, abs=0.5) and m.details["beyond_modelled_mm"] == pytest.approx(0.0, abs=0.05)
    assert m.passed is True and door.report.readiness["penetration"] is True
    text = _text((door.out_dir / "report.html").read_text())
    assert "other checks failing" not in text and "parent_child_penetration | pybullet | 19 | mm | pass" in text
    audit = audit_asset(door.report.source, None).report
    declared = next(c for c in audit.checks if c.physics == "declared")
    assert "parent_child_penetration" not in declared.failures
    assert next(x for x in declared.metrics if x.name == "parent_child_penetration").passed is True


def test_a_spring_asked_for_has_its_own_row_with_its_unit(tmp_path, refine_once):
    """A hand-written cabinet whose request asks for a door spring: the stiffness row shows the file's none and the
    output's spring in N m/rad about its reference; damping and friction rows carry their units."""
    xml = hl.hand_written_cabinet(tmp_path / "cabinet" / "cabinet.xml")
    res = refine_once(xml, "A small cabinet, its door closed, with a stiffness 0.5 N m/rad.", CONFIG)
    rows = _rows((res.out_dir / "report.html").read_text())
    stiffness = rows["door_hinge stiffness"]
    assert stiffness[0] == "none declared" and stiffness[1].startswith("0.5 N m/rad about "), stiffness
    assert "stiffness 0.5" in stiffness[2]
    assert rows["door_hinge damping"][0] == "0.3 N m s/rad" and rows["door_hinge friction"][0] == "0.05 N m"
    assert rows["total mass"][0].endswith("kg)") and "as MuJoCo infers it from the geoms" in rows["total mass"][0]


def test_a_hand_written_cabinet_half_open_stands_at_its_bands_centre(tmp_path, capsys):
    """"a small cabinet with its door half open" on a hand-written MJCF cabinet: nothing had to move the door, so it
    stands at the halfway band's centre (50 % open), as PartNet-Mobility objects do, and nothing says it was moved."""
    from asset2sim.cli import main

    xml = hl.hand_written_cabinet(tmp_path / "cabinet" / "cabinet.xml")
    out = tmp_path / "out"
    assert main(["refine", str(xml), "--prompt", "a small cabinet with its door half open", "--out", str(out),
                 "--engines", "pybullet", "--no-clips"]) == 0
    lines = capsys.readouterr().out.splitlines()
    state = next(ln for ln in lines if ln.startswith("initial state"))
    assert "50 % open" in state and "moved" not in state, state
    assert lines[-1].startswith("report       ") and str(out / "report.html") in lines[-1]  # the summary points to the report
    read = next(ln for ln in lines if "] read " in ln)
    assert f"{xml} (MJCF)" in read and "asset2sim-staged" not in read and "category None" not in read, read
    rows = _rows((out / "report.html").read_text())
    assert rows["door_hinge initial position"][2] == "the request: halfway"  # the band, no move said


def test_a_state_moved_off_its_band_says_why():
    """Stability by design opened a lid elsewhere in its band, or the state search moved a joint: the summary's state
    and the report's row say where to and why; a joint nothing moved is not listed."""
    note = ("stability by design: toppled by a robust-rest disturbance at the bands' targets; joint_0 opened to 0.60 of its "
            "range (allowed 0.60-0.90), where the object stands steadiest: static margin 12.3 -> 20.1 mm (asked >= 15 mm)")
    report = {"initial_joint_positions": {"joint_0": 1.2, "joint_1": 0.3, "joint_2": 0.0}, "design_changes": [note],
              "state": {"requested": {"joint_0": 1.2, "joint_1": 0.1, "joint_2": 0.0}, "method": "local search"}}
    moves = state_moves(report)
    assert moves["joint_0"] == ("moved to 60 % open, off its band's target: toppled by a robust-rest disturbance at the bands' "
                                "targets; the object stands steadiest there: static margin 12.3 -> 20.1 mm")
    assert moves["joint_1"] == "moved by the state search to remove self-penetration (local search)"
    assert "joint_2" not in moves


def test_a_usd_and_a_urdf_input_are_read_as_their_files_declare_them(door):
    """The input side reads every format alike: the door's own USD export (UsdPhysics masses, joint damping in stage
    units) and its URDF give the masses and the hinge's damping they declare, each drawable; a missing input is one
    line naming its file, never a path."""
    from asset2sim.tasks.evaluation.report_changes import read_input

    pytest.importorskip("pxr")
    total = door.report.total_mass
    for path, fmt in ((door.out_dir / "usd" / "mobility.usd", "usd"), (door.out_dir, "urdf")):
        side = read_input(path)
        try:
            assert side.format == fmt and side.error == "" and side.urdf is not None and side.urdf.is_file(), (fmt, side.error)
            masses = [ln.mass for ln in side.physics.links.values() if ln.mass is not None]
            assert sum(masses) == pytest.approx(total, rel=1e-3), fmt
            assert side.physics.joints["door_hinge"].damping == pytest.approx(door.overlay.joints["door_hinge"].damping, rel=1e-3)
        finally:
            side.close()
    gone = read_input(door.out_dir.parent / "moved" / "door.xml")
    assert gone.physics is None and gone.error == "door.xml is no longer where it was read from"
