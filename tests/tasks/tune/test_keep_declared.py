"""``refine --keep-declared``: plausible declared physics kept, implausible replaced, the request's asks win, the
declared size kept when plausible; the default configuration's hash unchanged by the option."""

from __future__ import annotations

import pytest

from asset2sim import cli
from asset2sim.schemas.config import RefineConfig
from asset2sim.formats.mjcf.reader import read_mjcf_asset
from tests.planted_assets import cabinet, write_generated_urdf, write_mjcf

pytest.importorskip("mujoco")


def _declared_masses(xml):
    read = read_mjcf_asset(xml)
    return {n: ln.inertial.mass for n, ln in read.model.links.items() if ln.inertial is not None}


def test_plausible_values_are_kept_and_implausible_ones_replaced(tmp_path, refine_once):
    xml = write_mjcf(tmp_path / "cab", "cabinet", cabinet(drawer_factor=0.01))
    declared = _declared_masses(xml)
    res = refine_once(xml, "a cabinet, door slightly open", RefineConfig(keep_declared=True), extras=False)
    ov = res.overlay
    assert ov.scale == 1.0
    assert ov.links["body"].mass == pytest.approx(declared["body"]) and ov.links["door"].mass == pytest.approx(declared["door"])
    assert ov.links["drawer"].mass > 50 * declared["drawer"]  # the x0.01 mass replaced by the estimate
    kept = [n for n in res.report.notes if n.startswith("keep declared:")]
    assert any("link body" in n for n in kept) and not any("link drawer" in n for n in kept)
    assert "kept as declared" in ov.joints["door_hinge"].source


def test_the_request_wins_over_declared_masses_it_asks_for(tmp_path, refine_once):
    xml = write_mjcf(tmp_path / "cab", "cabinet", cabinet())
    res = refine_once(xml, "a cabinet", RefineConfig(keep_declared=True, overrides={"mass": "30kg"}), extras=False)
    assert res.overlay.total_mass() == pytest.approx(30.0, rel=0.05)
    assert not any(n.startswith("keep declared: link") for n in res.report.notes)


def test_an_implausible_size_keeps_nothing(tmp_path):
    src = write_generated_urdf(tmp_path / "gen_cm", unit=100.0)
    code = cli.main(["refine", str(src), "--prompt", "a cabinet", "--out", str(tmp_path / "out"), "--keep-declared", "--no-extras", "-q"])
    assert code in (0, 3)
    report = (tmp_path / "out" / "report.json").read_text()
    assert "keep declared: nothing kept: its size is implausible" in report


def test_the_option_off_leaves_the_configuration_hash_as_before():
    assert RefineConfig(keep_declared=True).config_hash() != RefineConfig().config_hash()
    assert RefineConfig(keep_declared=False).config_hash() == RefineConfig().config_hash()
