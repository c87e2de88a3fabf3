"""Joint limits clipped to what the geometry allows (tasks.geometry.limits), on generated assets."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.cli import main
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from tests.conftest import SHARED, needs_shared
from tests.contract_asset import write_contract_asset
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.check.sweep import run_sweep, sweep_metric
from asset2sim.tasks.geometry import limits
from asset2sim.urdf import read_urdf
from tests.tasks.check.test_sweep import _stapler

STATE = {"lid_hinge": 0.4, "post_slide": 0.0}


def _lid_asset(tmp_path: Path, upper: float) -> Path:
    """The contract box with the lid's raw upper limit set to ``upper`` rad:
    beyond about 3.3 rad the lid swings into the back wall of its own body."""
    a = write_contract_asset(tmp_path, lid_angle=0.4)
    u = Path(a.urdf)
    text = re.sub(r'(<joint name="lid_hinge".*?<limit[^>]*upper=")([^"]+)"', lambda m: m.group(1) + f'{upper}"',
                  u.read_text(), flags=re.S)
    u.write_text(text)
    return u


def _session(urdf: Path, state: dict[str, float]):
    return open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False, initial_state=state))


def test_a_lid_limit_through_its_body_is_clipped_and_the_sweep_passes(tmp_path):
    urdf = _lid_asset(tmp_path, 5.0)
    closed = {"lid_hinge": (0.0, 1.0, 5.0)}
    with _session(urdf, STATE) as sess:
        # the raw far end is inside the body: deeper than the sweep allows
        sess.set_joint_positions({**STATE, "lid_hinge": 5.0})
        assert min(sess.link_distances("lid", "body", 0.0)) < -0.005
        clips = limits.geometric_limits(sess, read_urdf(urdf), closed, STATE)
        c = clips["lid_hinge"]
        assert c.clipped and c.blocked_by == "body"
        assert 2.0 < c.upper < 4.5 and c.lower == 0.0
        assert c.open_range == c.upper - c.q_closed
        sess.set_joint_positions({**STATE, "lid_hinge": c.upper})
        assert min(sess.link_distances("lid", "body", 0.0), default=0.0) > -0.005  # the sweep's bound
    # the URDF carries the clipped limit; the sweep measured against it passes
    text = urdf.read_text()
    urdf.write_text(re.sub(r'(<joint name="lid_hinge".*?<limit[^>]*upper=")([^"]+)"', lambda m: m.group(1) + f'{c.upper}"',
                           text, flags=re.S))
    run = run_sweep("pybullet", SimObject(UrdfFile(urdf), STATE), {"lid_hinge": (c.q_closed, c.direction, c.open_range)})
    m = sweep_metric(run)
    assert m.passed, m.details["failures"]


def test_a_limit_inside_the_geometry_is_kept(tmp_path):
    urdf = _lid_asset(tmp_path, 2.0)
    with _session(urdf, STATE) as sess:
        c = limits.geometric_limits(sess, read_urdf(urdf), {"lid_hinge": (0.0, 1.0, 2.0)}, STATE)["lid_hinge"]
    assert not c.clipped and (c.lower, c.upper, c.open_range) == (0.0, 2.0, 2.0)


def test_a_limit_beyond_the_closed_end_is_clipped(tmp_path):
    """Raw range [-0.6, 2]: closing past 0 pushes the lid into the body's front wall."""
    a = write_contract_asset(tmp_path, lid_angle=0.4)
    u = Path(a.urdf)
    u.write_text(re.sub(r'(<joint name="lid_hinge".*?<limit[^>]*lower=")([^"]+)"', lambda m: m.group(1) + '-0.6"',
                        u.read_text(), flags=re.S))
    with _session(u, STATE) as sess:
        c = limits.geometric_limits(sess, read_urdf(u), {"lid_hinge": (0.0, 1.0, 2.0)}, STATE)["lid_hinge"]
    assert c.upper == 2.0 and -0.1 < c.lower <= 0.0 and c.clipped


def test_clipped_limits_reach_the_overlay(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.4)
    ov = Overlay.model_validate_json((a.root / "overlay.json").read_text())
    clip = limits.LimitClip(joint="lid_hinge", raw_lower=0.0, raw_upper=5.0, lower=0.0, upper=3.3, q_closed=0.0,
                            direction=1.0, open_range=3.3, blocked_by="body", notes=["upper limit 5 -> 3.3"])
    new, notes = limits.apply_clips(ov, {"lid_hinge": clip})
    assert new.joints["lid_hinge"].upper == 3.3 and new.joints["lid_hinge"].lower is None
    assert "upper limit 5 -> 3.3" in new.joints["lid_hinge"].limit_source and notes


def _refined_upper(src: Path, prompt: str, joint: str, out: Path) -> tuple[float, dict, Path]:
    """Refine ``src`` for ``prompt`` into ``out`` (no extras): (the upper
    limit of ``joint`` in the written URDF, the written overlay, ``out``)."""
    main(["refine", str(src), "--prompt", prompt, "--out", str(out), "--no-extras"])
    text = (out / "mobility.urdf").read_text()
    upper = float(re.search(rf'<joint name="{joint}".*?upper="([^"]+)"', text, flags=re.S).group(1))
    return upper, json.loads((out / "overlay.json").read_text()), out


def test_refine_writes_the_clipped_limit_and_reports_it(tmp_path):
    """End to end: a box whose lid's raw limit (5 rad) swings it through its
    own body. refine writes the clipped limit into the URDF and the overlay
    (with why), and its sweep passes against it."""
    src = _lid_asset(tmp_path / "src", 5.0).parent
    (src / "overlay.json").unlink()
    upper, ov, out = _refined_upper(src, "A box with its lid slightly open.", "lid_hinge", tmp_path / "out")
    assert 2.0 < upper < 4.5
    assert ov["joints"]["lid_hinge"]["upper"] == upper and "runs into body" in ov["joints"]["lid_hinge"]["limit_source"]
    report = json.loads((out / "report.json").read_text())
    sweep = next(m for m in report["metrics"] if m["name"] == "joint_sweep")
    assert sweep["passed"] and abs(sweep["details"]["joints"]["lid_hinge"]["q_far"] - upper) < 1e-9


def _stapler_shut_in(root: Path) -> Path:
    """A stapler-like chain (z up): a base plate (top at z = 0); a top arm
    hinged about y at x = 0, z = 0.03 (+q lifts it, 0..1.5 rad); a magazine
    hinged on the top at the same axis, +q swinging it down towards the base,
    its raw limit 2.5 rad. Closed, the magazine lies 4 mm above the base: it
    is shut in under the closed top, and even with the top fully open it
    meets the base long before 2.5 rad (about 1.5 rad)."""
    return _stapler(root, magazine_z=(0.004, 0.0385), magazine_upper=2.5)


def test_a_magazine_limit_through_the_base_is_clipped_with_the_top_open(tmp_path):
    """Step 6 (staplers 102990, 103099): the magazine's raw limit swings it through the
    base whatever the top does. The sweep, which opens the top for a part
    shut in under it, then still stops short of the raw far end; the limit
    is clipped where the magazine meets the base with the top open, and the
    sweep passes against it."""
    urdf = _stapler_shut_in(tmp_path)
    state = {"top": 0.0, "magazine": 0.0}
    closed = {"top": (0.0, 1.0, 1.5), "magazine": (0.0, 1.0, 2.5)}
    raw = sweep_metric(run_sweep("pybullet", SimObject(UrdfFile(urdf), state), closed))
    assert not raw.passed and raw.details["failing"] == ["magazine"]  # the raw range cannot be swept
    with _session(urdf, state) as sess:
        clips = limits.geometric_limits(sess, read_urdf(urdf), closed, state)
        c = clips["magazine"]
        assert c.clipped and c.blocked_by == "base" and c.lower == 0.0
        assert 1.2 < c.upper < 1.7 and "with top open" in c.notes[-1]
        assert not clips["top"].clipped
        sess.set_joint_positions({"top": 1.5, "magazine": c.upper})  # free at the clipped end with the top open
        assert min(sess.link_distances("mag_link", "base", 0.0), default=0.0) > -0.0021
    run = run_sweep("pybullet", SimObject(UrdfFile(urdf), state), {**closed, "magazine": (c.q_closed, c.direction, c.open_range)})
    m = sweep_metric(run)
    assert m.passed, m.details["failures"]
    assert "swept with top open" in next(j for j in run.joints if j.joint == "magazine").range_note


def test_refine_clips_a_shut_in_magazine_to_what_it_reaches(tmp_path):
    """End to end: the raw range swings the magazine through the base even
    with the top open; refine's stage 6b clips the limit against the
    carrying chain opened and writes it; the sweep, opening the top, grades
    the written range: the asset passes, the overlay says why."""
    src = _stapler_shut_in(tmp_path / "src").parent
    upper, ov, out = _refined_upper(src, "A stapler.", "magazine", tmp_path / "out")
    assert 1.2 < upper < 1.7
    assert "even with top open" in ov["joints"]["magazine"]["limit_source"]
    report = json.loads((out / "report.json").read_text())
    sweep = next(m for m in report["metrics"] if m["name"] == "joint_sweep")
    mag = sweep["details"]["joints"]["magazine"]
    assert sweep["passed"] and abs(mag["q_far"] - upper) < 1e-9 and "swept with top open" in mag["range_note"]


@needs_shared
@pytest.mark.slow  # end to end: a dev row refined twice
def test_a_clipped_range_does_not_move_with_the_size_or_the_state_asked(refine_once):
    """Refrigerator 11178, whose freezer (smaller) door runs into the body past about 100 degrees: asked 1.8 m tall with
    the freezer door open 90 degrees, and at its default size with both doors closed, the freezer door's range is
    clipped where its geometry stops it, the same (within 1 %) both times and beyond the 90 degrees asked (a task can
    still open it further), never cut to the state asked; the main door keeps its whole range."""
    tall = refine_once(SHARED / "11178", "A 1.8 m tall refrigerator with its freezer door open about 90 degrees and the main "
                                         "door closed.", extras=False)
    plain = refine_once(SHARED / "11178", "A refrigerator with both doors closed.", extras=False)
    freezer = tall.overlay.joints["joint_1"].upper
    assert freezer is not None and freezer > math.radians(95.0), freezer
    assert plain.overlay.joints["joint_1"].upper == pytest.approx(freezer, rel=0.01)
    assert tall.overlay.joints["joint_0"].upper is None and plain.overlay.joints["joint_0"].upper is None  # not clipped
    assert tall.report.initial_joint_positions["joint_1"] == pytest.approx(math.pi / 2, abs=0.01)
