"""The ovphysx engine: the USD export as NVIDIA's USD runtime (PhysX on ovstage) reads it. PhysX holds each joint's
friction as the effort the files declare (the export's PhysxJointAxisAPI), so a loaded lid stays, an overloaded one
falls, and each joint breaks away at its friction; without those attributes PhysX holds no friction at all."""

from __future__ import annotations

import pytest

from asset2sim.engines.base import EngineUnavailable, SessionOptions
from asset2sim.engines.registry import available_engines, known_engines, open_session
from asset2sim.engines.source import UrdfFile
from asset2sim.extras import install_hint
from asset2sim.tasks.check.parity import engine_breakaway, evaluate_engines, parity_table
from asset2sim.formats.usd.export import export_usd
from tests.contract_asset import write_contract_asset


def _need_ovphysx() -> None:
    pytest.importorskip("pxr", reason=install_hint(ModuleNotFoundError("pxr", name="pxr")))
    if "ovphysx" not in available_engines():
        try:
            import ovphysx  # noqa: F401
        except ImportError as exc:
            pytest.skip(install_hint(exc))


def test_ovphysx_is_known_and_names_its_extra():
    assert "ovphysx" in known_engines()
    assert install_hint(ModuleNotFoundError("No module named 'ovphysx'", name="ovphysx")) == (
        "ovphysx (PhysX on OpenUSD) is not installed: pip install 'asset2sim[ovphysx]'")


def test_the_usd_export_holds_what_physx_reads(tmp_path):
    """PhysX holds the lid's 0.5 N*m and the post's 2 N as static and dynamic friction efforts; the lid, loaded by
    0.16 N*m, stays over 3 s; each joint breaks away within 20 % of its friction; the parity row says it all."""
    _need_ovphysx()
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.5, lid_damping=0.0)
    export_usd(tmp_path)
    with open_session("ovphysx", a.urdf, SessionOptions(initial_state=dict(a.initial_state))) as s:
        held = s.held_friction()
        assert held["lid_hinge"][:2] == pytest.approx((0.5, 0.5), rel=1e-6)
        assert held["post_slide"][:2] == pytest.approx((2.0, 2.0), rel=1e-6)
        assert s.joint_positions()["lid_hinge"] == pytest.approx(0.6, abs=1e-5)
        s.step(720)
        assert s.joint_positions()["lid_hinge"] == pytest.approx(0.6, abs=2e-3)
    got = engine_breakaway(UrdfFile(a.urdf), "ovphysx", SessionOptions(initial_state=dict(a.initial_state)))
    assert got["measured"] and got["passed"], got
    row = parity_table(evaluate_engines(tmp_path, ["ovphysx"]))[0]
    assert row["status"] == "ok" and row["rest_stability"] and all(row["joints_held"].values()), row
    assert row["penetration_mm"] is None  # contacts are not read from ovphysx: not measured, not failed


def _strip(path, prefixes: tuple[str, ...]) -> None:
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    for prim in stage.Traverse():
        for attr in prim.GetAttributes():
            if attr.GetName().startswith(prefixes):
                prim.RemoveProperty(attr.GetName())
    stage.GetRootLayer().Save()


@pytest.mark.parametrize(("removed", "held"), [(("newton:friction",), 0.5), (("newton:friction", "physxJointAxis:"), 0.0)],
                         ids=["physx-attributes-alone", "usdphysics-alone"])
def test_physx_reads_the_friction_the_export_authors_for_it(tmp_path, removed, held):
    """The PhysX attributes alone (``newton:friction``, which ovphysx also reads, removed) hold the lid's 0.5 N*m; a
    file with neither (as an export writing only UsdPhysics and its own namespace would be) holds no friction, and
    the lid falls shut."""
    _need_ovphysx()
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.5, lid_damping=0.0)
    _strip(export_usd(tmp_path).path, removed)
    with open_session("ovphysx", a.urdf, SessionOptions(initial_state=dict(a.initial_state))) as s:
        assert s.held_friction()["lid_hinge"][:2] == pytest.approx((held, held), rel=1e-6)
        s.step(240)
        lid = s.joint_positions()["lid_hinge"]
    assert (lid == pytest.approx(0.6, abs=2e-3)) if held else lid < 0.05


def test_a_folder_without_the_usd_export_is_skipped_with_the_reason(tmp_path):
    """A refine's candidate or an output not exported has no USD to run: parity names the engine skipped, why, and
    how to export it."""
    _need_ovphysx()
    a = write_contract_asset(tmp_path)
    with pytest.raises(EngineUnavailable, match="export OUT --format usd"):
        open_session("ovphysx", a.urdf, SessionOptions(initial_state=dict(a.initial_state)))
    row = parity_table(evaluate_engines(tmp_path, ["ovphysx"]))[0]
    assert row["status"] == "skipped" and "--format usd" in row["reason"]
