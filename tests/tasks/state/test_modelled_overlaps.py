"""Parts modelled overlapping where they meet (PartNet-Mobility's meshes often overlap a few mm): an oven's two doors
meeting in the middle, a panel sunk into a rail both fixed to a safe's body. No state in the closed band separates
them (a door closing slides its edge along the other's; nothing moves the panel), so before the writer gave such
contacts clearance at the modelled pose the state search left the penetration (``unresolved_penetration``) or
opened a door to the band's edge and blocked the other (``blocked_joint``)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from asset2sim import urdf
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.assemble import collision_geometry as cg, sliding_clearance as sc
from tests.conftest import SHARED, needs_shared
from tests.unseen_assets import MODELLED_OVERLAP, build_french_door_oven, build_safe_with_panels

TOLERANCE = RefineConfig().penetration_tolerance


def _closed_and_clear(r) -> None:
    """The report ``r`` of a closed request: ready, every joint at its closed end (the state asked), Phi 0."""
    assert r.failure_mode == "none", (r.failure_mode, r.readiness, r.state.collision_changes)
    assert r.state.phi_requested <= TOLERANCE and r.state.phi_result <= TOLERANCE
    assert all(v == 0.0 for v in r.state.result.values()), r.state.result  # no door pushed ajar to clear the overlap
    assert all(m.value <= TOLERANCE * 1000 for m in r.metrics if m.name == "penetration"), [m for m in r.metrics if m.name == "penetration"]


def test_an_ovens_two_doors_overlapping_where_they_meet_stay_closed_without_penetration(refine_once):
    r = refine_once(build_french_door_oven, "A wall oven with both doors closed.", extras=False).report
    _closed_and_clear(r)
    notes = [c for c in r.state.collision_changes if sc.RUNNING_CLEARANCE_NOTE in c and "gap -" in c]
    assert len(notes) == 1 and "'link_0'" in notes[0] and "'link_1'" in notes[0], r.state.collision_changes


def test_a_panel_sunk_into_a_rail_both_fixed_to_the_body_is_cleared(refine_once):
    r = refine_once(build_safe_with_panels, "A closed safe.", extras=False).report
    _closed_and_clear(r)
    notes = [c for c in r.state.collision_changes if "no joint moves them apart" in c]
    assert len(notes) == 1 and notes[0].startswith("link 'link_2'"), r.state.collision_changes  # the smaller part squeezed


def test_an_overlap_deeper_than_a_modelling_one_is_left_with_the_reason(tmp_path, refine_once):
    """Doors 30 mm inside each other (object units) are no modelling overlap: the writer leaves them, and the report
    says which pair is left, how deep, over which intervals its joints were searched, and that no state of them
    separates the pair."""
    r = refine_once(build_french_door_oven(tmp_path / "oven", overlap=0.03), "A wall oven with both doors closed.",
                    extras=False).report
    # the penetration tier fails; the rest tier, graded first, may fail before it (the doors pushing each other)
    assert r.readiness["penetration"] is False and r.failure_mode in {"unresolved_penetration", "joint_not_held"}, (
        r.failure_mode, r.readiness)
    (left,) = [c for c in r.state.collision_changes if "left at the state found" in c]
    assert left.startswith(f"self-penetration {r.state.phi_result * 1000:.3g} mm left at the state found: 'link_0' and 'link_1' ")
    assert "joint_0 over [0, " in left and "joint_1 over [0, " in left and "separates them" in left, left


def _pieces(folder) -> tuple[dict[str, np.ndarray], list[str]]:
    """link -> the vertices (k, 3) of its one collision piece in the object's frame at the modelled pose; notes."""
    model = urdf.read_urdf(folder / "mobility.urdf")
    pieces, notes = cg.link_pieces(model, lambda g: folder / str(g.filename))
    poses = model.link_poses({})
    return {n: p[0].points @ poses[n][:3, :3].T + poses[n][:3, 3] for n, p in pieces.items() if len(p) == 1}, notes


def test_the_clearance_takes_the_overlap_as_modelled_and_leaves_deeper_ones_to_the_state_stage(tmp_path, monkeypatch):
    """At the modelled pose (object units) the first door is squeezed back by the overlap plus the running
    clearance; an overlap deeper than :data:`~sc.MODELLED_OVERLAP` is not a modelling overlap and is left alone."""
    pieces, _ = _pieces(build_french_door_oven(tmp_path / "oven"))
    g, _ = sc.sat_gap(pieces["link_0"], pieces["link_1"])
    assert g == pytest.approx(sc.RUNNING_CLEARANCE, abs=1e-9)
    narrower = np.ptp(pieces["link_1"], axis=0) - np.ptp(pieces["link_0"], axis=0)  # the second door untouched
    assert sorted(narrower) == pytest.approx([0.0, 0.0, sc.RUNNING_CLEARANCE + MODELLED_OVERLAP])
    monkeypatch.setattr(sc, "MODELLED_OVERLAP", MODELLED_OVERLAP / 2)
    pieces, notes = _pieces(build_safe_with_panels(tmp_path / "safe"))
    assert not any("no joint moves them apart" in n for n in notes), notes
    assert sc.sat_gap(pieces["link_2"], pieces["link_1"])[0] == pytest.approx(-MODELLED_OVERLAP)


@pytest.mark.slow  # end to end: a dev object
@needs_shared
def test_a_fridges_doors_modelled_overlapping_where_they_meet_close_without_blocking(tmp_path, refine_once):
    """The mini fridge 11178 with its left door's meshes moved 52.8 mm towards the right door (object units): the
    doors, 42.8 mm apart as shipped, overlap 10 mm where they meet. Before, the state search opened the left door
    to the closed band's edge (0.094 rad) and the right door's sweep was blocked (``blocked_joint``)."""
    src = tmp_path / "fridge"
    shutil.copytree(SHARED / "11178", src)
    text = (src / "mobility.urdf").read_text()
    shipped = 'xyz="0.5038798779540579 -0.757308 -0.3910896986000594"'  # the left door's meshes (its visuals and collisions)
    assert text.count(shipped) == 4
    (src / "mobility.urdf").write_text(text.replace(shipped, f'xyz="{0.5038798779540579 + 0.05283!r} -0.757308 -0.3910896986000594"'))
    r = refine_once(src, "A mini fridge with both doors closed.", extras=False).report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    assert r.state.phi_result <= TOLERANCE
    assert r.state.result["joint_0"] < 0.02 and r.state.result["joint_1"] == 0.0, r.state.result  # closed, not at the band's edge
    assert any("'link_0'" in c and sc.RUNNING_CLEARANCE_NOTE in c and "gap -" in c for c in r.state.collision_changes)
