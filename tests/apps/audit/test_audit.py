"""``asset2sim audit`` end to end: a folder of MJCF objects with planted errors (every planted error flagged, no
correct value flagged, the patch loads in MuJoCo and rests there), correct objects left alone, URDF and USD
inputs, the dataset's physics-less URDFs, the catalog, and the input never touched."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from asset2sim import cli
from asset2sim.flows import audit_catalog
from asset2sim.schemas.audit import AuditReport
from asset2sim.schemas.config import SimConventions
from asset2sim.apps.audit.audit import AUDIT_JSON, AUDIT_MD, AuditError, audit_asset
from asset2sim.apps.audit.batch import find_assets
from asset2sim.formats import staging
from asset2sim.formats.mjcf.reader import read_mjcf_asset
from asset2sim.urdf import read_urdf, write_urdf
from tests.tasks.ingest import host_layouts as hl
from tests.planted_assets import cabinet, storage_box, trash_can, write_mjcf, write_planted_folder

mujoco = pytest.importorskip("mujoco")


def _tree_digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(folder).as_posix().encode() + p.read_bytes())
    return h.hexdigest()


def _rests_in_mujoco(xml: Path, seconds: float = 3.0) -> tuple[float, float]:
    """(position drift m, orientation drift rad) of the root body over the SPEC's rest test in MuJoCo: settle 1 s
    from the file's pose, then ``seconds - 1`` s measured."""
    model = mujoco.MjModel.from_xml_path(str(xml))
    data = mujoco.MjData(model)
    conv = SimConventions()
    steps = int(conv.settle_time / model.opt.timestep)
    mujoco.mj_step(model, data, nstep=steps)
    p0, q0 = data.xpos[1].copy(), data.xquat[1].copy()
    mujoco.mj_step(model, data, nstep=int((seconds - conv.settle_time) / model.opt.timestep))
    dq = abs(float(np.dot(q0, data.xquat[1])))
    return float(np.linalg.norm(data.xpos[1] - p0)), float(2 * np.arccos(min(1.0, dq)))


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    root = tmp_path_factory.mktemp("planted")
    inputs = root / "in"
    expected = write_planted_folder(inputs)
    write_mjcf(inputs / "correct_box", "storage_box", storage_box())
    write_mjcf(inputs / "correct_cabinet", "cabinet", cabinet())
    write_mjcf(inputs / "correct_trash_can", "trash_can", trash_can())
    before = _tree_digest(inputs)
    out = root / "out"
    code = cli.main(["audit", str(inputs), "--out", str(out), "--jobs", "2"])
    return inputs, out, expected, before, code


def _report(out: Path, name: str) -> AuditReport:
    return AuditReport.model_validate_json((out / name / AUDIT_JSON).read_text())


@pytest.mark.slow  # end to end: the planted corpus through the command line
def test_every_planted_error_is_flagged_and_no_correct_value(planted):
    inputs, out, expected, _, code = planted
    assert code == 3  # implausible values found
    for name, (where, quantity, what) in expected.items():
        report = _report(out, name)
        flagged = {(v.where, v.quantity) for v in report.implausible}
        assert (where, quantity) in flagged, f"{name}: {what} not flagged; flagged {flagged}"
        # the only other flags: the same part, or the object's total mass a planted x100 mass makes implausible
        extra = {f for f in flagged if f[0] != where and f != ("object", "mass")}
        assert not extra, f"{name}: correct values flagged: {extra}"
        if ("object", "mass") in flagged:
            assert quantity == "mass" and what == "mass x100"
    for name in ("correct_box", "correct_cabinet", "correct_trash_can"):
        report = _report(out, name)
        assert not report.implausible, [(v.where, v.quantity, v.reason) for v in report.implausible]
        assert report.patch is None and not (out / name / "patch").exists()


@pytest.mark.slow  # end to end: the planted corpus through the command line
def test_the_patch_loads_in_mujoco_rests_there_and_audits_clean(planted, tmp_path):
    _, out, expected, _, _ = planted
    conv = SimConventions()
    for name in expected:
        report = _report(out, name)
        assert report.patch and report.patch.endswith(".xml")
        xml = out / name / report.patch
        d_pos, d_ori = _rests_in_mujoco(xml)
        assert d_pos <= conv.stability_pos_tol and d_ori <= conv.stability_ori_tol, (name, d_pos, d_ori)
        patched = next(c for c in report.checks if c.physics == "patched")
        assert next(m for m in patched.metrics if m.name == "rest_stability").passed, name
        again = audit_asset(xml, tmp_path / name, simulate=False).report
        assert not again.implausible, (name, [(v.where, v.quantity, v.reason) for v in again.implausible])
        for v in report.values:  # the patch writes what the report says it writes
            if v.patched is not None and v.quantity == "mass":
                link = v.where.removeprefix("link ")
                if v.where.startswith("link "):
                    m = mujoco.MjModel.from_xml_path(str(xml))
                    assert m.body(link).mass[0] == pytest.approx(v.patched, rel=1e-5)


@pytest.mark.slow  # end to end: the planted corpus through the command line
def test_the_report_shows_declared_estimate_band_and_the_changes(planted):
    _, out, _, _, _ = planted
    report = _report(out, "cabinet_light_drawer")
    drawer = next(v for v in report.values if v.where == "link drawer" and v.quantity == "mass")
    # the audit weighs the drawer as a drawer box (11 mm particle board by area, materials.yaml drawer_box), the
    # planted one has 12 mm walls and a 16 mm front: the estimate is within a few percent of the planted mass
    assert drawer.factor == pytest.approx(0.01, rel=0.05) and drawer.low is not None and drawer.high is not None
    assert drawer.low <= drawer.patched <= drawer.high
    text = (out / "cabinet_light_drawer" / AUDIT_MD).read_text()
    assert "## Changes in the patch" in text and "| link drawer | mass |" in text
    spring = _report(out, "storage_box_spring_lid")
    lid = next(v for v in spring.values if v.where == "joint lid_hinge" and v.quantity == "damping")
    assert lid.declared == 0.0 and lid.patched > lid.low


@pytest.mark.slow  # end to end: the planted corpus through the command line
def test_the_input_folder_is_unchanged(planted):
    inputs, _, _, before, _ = planted
    assert _tree_digest(inputs) == before


@pytest.mark.slow  # end to end: the planted corpus through the command line
def test_the_catalog_holds_one_row_per_asset_and_per_value(planted):
    _, out, expected, _, _ = planted
    assets = pd.read_parquet(out / audit_catalog.ASSETS_PARQUET)
    values = pd.read_parquet(out / audit_catalog.VALUES_PARQUET)
    assert len(assets) == len(expected) + 3
    assert set(assets["failure_mode"]) <= set(audit_catalog.AUDIT_MODES)
    by_cat = audit_catalog.failure_modes_by_category(assets)
    assert by_cat.loc["total", list(audit_catalog.AUDIT_MODES)].sum() == len(assets)
    assert by_cat.loc["total", audit_catalog.DECLARED_NOT_READY] == (assets["declared_passed"] == False).sum()  # noqa: E712
    assert by_cat.loc["StorageFurniture", "implausible_values"] == 2
    bad = audit_catalog.implausible_by_category(values)
    assert bad.loc["TrashCan", "density"] == 1 and bad.loc["Box", "inertia"] == 1
    assert set(values["verdict"]) <= {"plausible", "implausible", "not_declared"}


def _urdf_asset(folder: Path, part, name: str) -> Path:
    """A URDF asset (model.urdf + meshes) staged from the MJCF object ``part`` builds."""
    src = write_mjcf(folder.parent / f"{name}-mjcf", name, part)
    staging.stage(read_mjcf_asset(src), folder)
    return folder


def test_a_urdf_with_a_wrong_mass_gets_a_urdf_patch(tmp_path):
    asset = _urdf_asset(tmp_path / "cab", cabinet(), "cabinet")
    model = read_urdf(asset / staging.STAGED_URDF)
    model.links["door"].inertial.mass *= 100.0
    model.links["door"].inertial.inertia = model.links["door"].inertial.inertia * 100.0
    (asset / staging.STAGED_URDF).write_bytes(write_urdf(model))
    res = audit_asset(asset, tmp_path / "out")
    flagged = {(v.where, v.quantity) for v in res.report.implausible}
    assert ("link door", "mass") in flagged and all(w in ("link door", "object") for w, _ in flagged)
    patched = read_urdf(tmp_path / "out" / res.report.patch)
    assert patched.links["door"].inertial.mass == pytest.approx(model.links["door"].inertial.mass / 100.0, rel=0.5)
    assert patched.links["drawer"].inertial.mass == pytest.approx(model.links["drawer"].inertial.mass)  # untouched
    # the patch's meshes were copied where it looks for them
    assert all(g.path is not None and g.path.is_file() for ln in patched.links.values() for g in ln.collisions if g.kind == "mesh")


def test_a_dataset_urdf_without_physics_is_reported_missing_and_patched(shared_dataset, tmp_path):
    asset = shared_dataset / "100221"
    res = audit_asset(asset, tmp_path / "out", simulate=False)
    masses = [v for v in res.report.values if v.quantity == "mass" and v.where.startswith("link ")]
    assert masses and all(v.verdict == "not_declared" for v in masses)
    patched = read_urdf(tmp_path / "out" / res.report.patch)
    assert all(ln.inertial is not None and ln.inertial.mass > 0 for name, ln in patched.links.items()
               if ln.collisions or ln.visuals)


def test_a_usd_with_a_planted_mass_is_flagged_and_patched_in_usd(tmp_path):
    pytest.importorskip("pxr")
    from asset2sim.formats.usd.export import export_usd

    asset = _urdf_asset(tmp_path / "box", storage_box(), "storage_box")
    model = read_urdf(asset / staging.STAGED_URDF)
    model.links["lid"].inertial.mass *= 0.01  # the mass edited, the inertia tensor left as it was
    (asset / "mobility.urdf").write_bytes(write_urdf(model))
    (asset / staging.STAGED_URDF).unlink()
    usd = export_usd(asset, check=False).path
    res = audit_asset(usd, tmp_path / "out")
    flagged = {(v.where, v.quantity) for v in res.report.implausible}
    assert flagged == {("link lid", "mass"), ("link lid", "inertia")}  # the stale tensor too
    assert res.report.patch.endswith(".usda")
    checks = {c.physics: c for c in res.report.checks}
    assert checks["patched"].passed
    again = audit_asset(tmp_path / "out" / res.report.patch, tmp_path / "again", simulate=False).report
    assert not again.implausible
    lid = next(v for v in again.values if v.where == "link lid" and v.quantity == "mass")
    first = next(v for v in res.report.values if v.where == "link lid" and v.quantity == "mass")
    assert lid.declared == pytest.approx(first.patched, rel=1e-6)  # the USD holds the value the report gives
    # the generator's solid lid: the estimate is one board of the prior's thickness, within 10 % of it
    assert lid.declared == pytest.approx(model.links["lid"].inertial.mass * 100.0, rel=0.1)


def test_an_unreadable_asset_is_one_failed_row_not_a_stopped_batch(tmp_path):
    good = tmp_path / "in" / "good"
    write_mjcf(good, "storage_box", storage_box())
    bad = tmp_path / "in" / "bad"
    bad.mkdir(parents=True)
    (bad / "broken.xml").write_text("<mujoco><worldbody><body name='a'><joint type='ball'/><geom size='.1'/></body></worldbody></mujoco>")
    code = cli.main(["audit", str(tmp_path / "in"), "--out", str(tmp_path / "out"), "--no-sim"])
    assert code == 1
    assets = pd.read_parquet(tmp_path / "out" / audit_catalog.ASSETS_PARQUET).set_index("asset_id")
    assert assets.loc["good", "failure_mode"] == "none"
    assert assets.loc["bad", "failure_mode"] == "audit_failed" and "broken.xml" in assets.loc["bad", "error"]


def test_an_output_inside_the_input_is_refused(tmp_path):
    src = write_mjcf(tmp_path / "box", "storage_box", storage_box())
    with pytest.raises(AuditError, match="inside the input"):
        audit_asset(src, tmp_path / "box" / "audit")


def test_assets_are_found_in_a_package_tree(tmp_path):
    tree = tmp_path / "pkg"
    write_mjcf(tree / "objects" / "box", "storage_box", storage_box())
    write_mjcf(tree / "objects", "cabinet", cabinet())
    write_mjcf(tree / "objects", "trash_can", trash_can())
    shutil.copytree(_urdf_asset(tmp_path / "u", cabinet(), "cabinet"), tree / "urdf" / "cab")
    found = {t.asset_id: t.path for t in find_assets([tree])}
    assert set(found) == {"objects__cabinet", "objects__trash_can", "objects__box", "urdf__cab"}
    assert found["urdf__cab"].is_dir() and found["objects__box"].name == "storage_box.xml"
    assert [t.asset_id for t in find_assets([tree / "objects" / "box"])] == ["box"]
    json.dumps([str(p) for p in found.values()])


def test_a_meta_world_scene_is_audited_as_refine_reads_it_and_its_patch_stays_in_the_package(tmp_path):
    """Meta-World's window (generated layout: its scene includes ``../scene/basic_scene.xml`` from the package's
    asset folder) is audited as refine reads it, not refused for the include; its 6 g sash (six 1 g geoms, as
    Meta-World writes it) is flagged, and the patch compiles with the package's files beside it."""
    xml = hl.metaworld_window(tmp_path / "in")
    before = _tree_digest(tmp_path / "in")
    res = audit_asset(xml, tmp_path / "out", simulate=False)
    flagged = [f"{v.where}: {v.quantity}" for v in res.report.values if v.verdict == "implausible"]
    (slide,) = read_mjcf_asset(xml).model.movable_joints
    assert f"link {slide.child}: mass" in flagged, flagged
    assert res.report.patch is not None
    assert _tree_digest(tmp_path / "in") == before
