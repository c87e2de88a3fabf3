"""Parity across engines: the same metrics, side by side, skipped engines named."""

from __future__ import annotations

import pytest

from asset2sim.engines import base, registry
from tests.contract_asset import write_contract_asset
from tests.fake_engine import FakeBehaviour, fake_behaviour
from asset2sim.tasks.check.parity import evaluate_engines, parity_table
from tests.conftest import SHARED, needs_shared


def _by_name(results):
    return {m.name: m for m in results}


def test_fake_engine_results_and_table(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.5)
    with fake_behaviour(FakeBehaviour(penetration=0.002, joint_oscillation={"lid_hinge": (0.1, 1.0)})):
        res = evaluate_engines(tmp_path, ["fake"])
    m = _by_name(res["fake"])
    assert m["penetration"].value == pytest.approx(2.0) and m["penetration"].unit == "mm"
    assert m["rest_stability"].passed is True
    assert m["oscillation"].passed is False and m["oscillation"].details["failing"] == ["lid_hinge"]
    assert all(x.engine == "fake" for x in res["fake"])
    (row,) = parity_table(res)
    assert row["engine"] == "fake" and row["status"] == "ok"
    assert row["penetration_mm"] == pytest.approx(2.0) and row["max_depth_mm"] == pytest.approx(2.0)
    assert row["rest_stability"] is True and row["oscillation"] is False and row["failing_joints"] == ["lid_hinge"]


def test_initial_state_and_springs_come_from_the_folder(tmp_path):
    write_contract_asset(tmp_path, lid_angle=0.5, lid_stiffness=1.0, lid_spring_reference=0.1)
    # the fake relaxes a sprung joint to its reference: a drift the rest test records
    res = evaluate_engines(tmp_path, ["fake"])
    drift = _by_name(res["fake"])["rest_stability"].details["joint_drift"]
    assert drift["lid_hinge"] == pytest.approx(0.4, abs=1e-3)
    assert drift["post_slide"] == 0.0
    res = evaluate_engines(tmp_path, ["fake"], initial_state={"lid_hinge": 0.1})
    assert _by_name(res["fake"])["rest_stability"].details["joint_drift"]["lid_hinge"] == pytest.approx(0.0, abs=1e-12)


def test_unavailable_and_unknown_engines_are_skipped_with_the_reason(tmp_path, monkeypatch):
    write_contract_asset(tmp_path)

    def missing(urdf, options):
        raise base.EngineUnavailable("engine 'physx' is not installed (No module named 'sapien')")

    monkeypatch.setitem(base._ENGINES, "physx", missing)
    res = evaluate_engines(tmp_path, ["fake", "physx", "nosuch", "fake"])
    assert list(res) == ["fake", "physx", "nosuch"]
    rows = {r["engine"]: r for r in parity_table(res)}
    assert rows["physx"]["status"] == "skipped" and "sapien" in rows["physx"]["reason"]
    assert rows["nosuch"]["status"] == "skipped" and "unknown engine" in rows["nosuch"]["reason"]
    assert all(m.passed is None for m in res["physx"]) and rows["physx"]["rest_stability"] is None  # no vote


def test_an_engine_that_cannot_load_the_asset_fails(tmp_path, monkeypatch):
    write_contract_asset(tmp_path)

    def broken(urdf, options):
        raise RuntimeError("cannot cook mesh")

    monkeypatch.setitem(base._ENGINES, "broken", broken)
    res = evaluate_engines(tmp_path, ["fake", "broken"])
    rows = {r["engine"]: r for r in parity_table(res)}
    assert rows["broken"]["status"] == "error" and "cannot cook mesh" in rows["broken"]["reason"]
    assert rows["broken"]["rest_stability"] is False and rows["broken"]["oscillation"] is False


def test_each_engine_gives_its_own_verdict(tmp_path, monkeypatch):
    write_contract_asset(tmp_path)
    from tests.fake_engine import FakeSession

    monkeypatch.setitem(base._ENGINES, "calm", lambda u, o: FakeSession(u, o, FakeBehaviour(penetration=0.001)))
    monkeypatch.setitem(base._ENGINES, "shaky", lambda u, o: FakeSession(u, o, FakeBehaviour(penetration=0.004, root_velocity=(0.01, 0, 0))))
    rows = {r["engine"]: r for r in parity_table(evaluate_engines(tmp_path, ["calm", "shaky"]))}
    assert rows["calm"]["max_depth_mm"] == pytest.approx(1.0) and rows["shaky"]["max_depth_mm"] == pytest.approx(4.0)
    assert rows["calm"]["rest_stability"] is True and rows["shaky"]["rest_stability"] is False
    assert rows["calm"]["oscillation"] is True and rows["shaky"]["oscillation"] is True


def test_missing_folder(tmp_path):
    with pytest.raises(FileNotFoundError):
        evaluate_engines(tmp_path, ["fake"])


@pytest.mark.physx
@pytest.mark.mujoco
def test_three_engines_agree_on_a_resting_asset_and_on_a_swinging_one(tmp_path):
    pytest.importorskip("sapien")
    pytest.importorskip("mujoco")
    engines = ["pybullet", "physx", "mujoco"]
    write_contract_asset(tmp_path / "rest", lid_angle=0.6, lid_friction=0.5)
    rows = parity_table(evaluate_engines(tmp_path / "rest", engines))
    assert [r["status"] for r in rows] == ["ok"] * 3
    assert all(r["rest_stability"] and r["oscillation"] for r in rows), rows
    assert all(r["penetration_mm"] == 0.0 for r in rows)
    write_contract_asset(tmp_path / "swing", lid_angle=1.2, lid_friction=0.0, lid_damping=0.0, lid_stiffness=1.0, lid_spring_reference=0.8)
    rows = parity_table(evaluate_engines(tmp_path / "swing", engines))
    assert all(r["oscillation"] is False and r["failing_joints"] == ["lid_hinge"] for r in rows), rows


@pytest.mark.physx
@needs_shared
@pytest.mark.slow  # end to end: a dev object refined on its own
def test_a_chest_resting_still_in_pybullet_rests_still_in_physx(tmp_path):
    """With SAPIEN's default 10 solver iterations the refined treasure chest
    (lid a quarter open) crept on the plane in PhysX (D_pos 1.36 mm, D_ori
    0.0093 rad over the 2 s test) while PyBullet measured 4e-6 m; with
    ManiSkill 3's 15 it rests in both (docs/design/simulators.md)."""
    pytest.importorskip("sapien")
    from asset2sim.tasks.refine import refine_asset

    res = refine_asset(SHARED / "100221", "A box, a quarter open.", tmp_path / "out", extras=False)
    rows = {r["engine"]: r for r in parity_table(evaluate_engines(res.out_dir, ["pybullet", "physx"]))}
    assert rows["pybullet"]["rest_stability"] and rows["physx"]["rest_stability"], rows
    assert rows["physx"]["D_pos_m"] < 0.5e-3 and rows["physx"]["D_ori_rad"] < 3e-3, rows["physx"]
    assert res.report.failure_mode == "none"


def test_without_the_optional_packages_the_pipeline_says_what_it_skipped(tmp_path):
    """In a fresh interpreter where sapien and mujoco cannot be imported: the
    registry leaves them out, parity names them skipped with the reason, the
    MJCF export raises ImportError (refine turns that into a note) and the
    export command exits 2 with the install hint."""
    import subprocess
    import sys

    write_contract_asset(tmp_path)
    code = f"""
import sys
sys.modules['sapien'] = None
sys.modules['mujoco'] = None
from pathlib import Path
from asset2sim.engines.registry import available_engines
from asset2sim.tasks.check.parity import evaluate_engines, parity_table
assert 'physx' not in available_engines() and 'mujoco' not in available_engines(), available_engines()
rows = {{r['engine']: r for r in parity_table(evaluate_engines(Path({str(tmp_path)!r}), ['pybullet', 'physx', 'mujoco']))}}
assert rows['pybullet']['status'] == 'ok' and rows['pybullet']['rest_stability'] is True, rows['pybullet']
for e, module in (('physx', 'sapien'), ('mujoco', 'mujoco')):
    assert rows[e]['status'] == 'skipped' and module in rows[e]['reason'].lower() and "pip install 'asset2sim[" in rows[e]['reason'], rows[e]
from asset2sim.formats.mjcf.export import export_mjcf
try:
    export_mjcf(Path({str(tmp_path)!r}))
except ImportError:
    pass
else:
    raise AssertionError('export without mujoco')
from asset2sim.cli import main
assert main(['export', {str(tmp_path)!r}]) == 2
print('OK')
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().endswith("OK")
    assert "pip install 'asset2sim[mujoco]'" in res.stderr


def _real_outputs():
    from pathlib import Path

    root = Path(__file__).resolve().parents[3]
    found = []
    for base_dir in (root / "data" / "refined", root / "out"):
        if base_dir.is_dir():
            for urdf in sorted(base_dir.glob("**/mobility.urdf")):
                d = urdf.parent
                if (d / "initial_state.json").is_file() and (d / "overlay.json").is_file():
                    found.append(d)
    return found


@pytest.mark.slow
@pytest.mark.parametrize("out_dir", _real_outputs(), ids=lambda p: p.name)
def test_real_outputs_run_in_every_installed_engine(out_dir):
    """A pipeline output loads and runs in every installed engine (parity rows
    with status ok and verdicts for both tests)."""
    engines = [e for e in ("pybullet", "physx", "mujoco") if e in registry.available_engines()]
    rows = parity_table(evaluate_engines(out_dir, engines))
    for r in rows:
        assert r["status"] == "ok", (r["engine"], r["reason"])
        assert r["rest_stability"] is not None and r["oscillation"] is not None
