"""Third-party checkers (extra ``checkers``; skipped where not installed):
a contract asset passes each of them, and each catches the defect it is run
for."""

from __future__ import annotations

import csv
import importlib.util
import shutil
import sys
from pathlib import Path

import pytest

from asset2sim import urdf
from tests.conftest import SHARED
from tests.contract_asset import write_contract_asset
from asset2sim.tasks.check.third_party import (
    check_drake,
    check_mjcf_doctor,
    check_simcheck,
    check_urdf_parser_py,
    check_urdf_validator,
    run_checkers,
)


def _has_module(name: str) -> bool:
    return importlib.util.find_spec(name) is not None


def _has_command(name: str) -> bool:
    return Path(sys.executable).with_name(name).is_file() or shutil.which(name) is not None


needs_parser = pytest.mark.skipif(not _has_module("urdf_parser_py"), reason="urdfdom-py (urdf_parser_py) not installed")
needs_drake = pytest.mark.skipif(not _has_module("pydrake"), reason="drake not installed")
needs_validator = pytest.mark.skipif(not _has_command("urdf_validate"), reason="urdf-validator not installed")
needs_doctor = pytest.mark.skipif(not _has_command("mjcf-doctor"), reason="mjcf-doctor not installed")
needs_simcheck = pytest.mark.skipif(not _has_command("simcheck"), reason="simcheck not installed")


@pytest.fixture
def contract(tmp_path):
    write_contract_asset(tmp_path, lid_angle=0.4)
    return tmp_path


@needs_parser
def test_urdf_parser_py_parses_the_contract_and_refuses_a_limit_without_effort(contract):
    r = check_urdf_parser_py(contract / "mobility.urdf")
    assert r.passed, r.errors
    assert r.details == {"links": 4, "joints": 3}
    p = contract / "mobility.urdf"
    text = p.read_text()
    bad = text.replace('type="fixed">', 'type="fixed">\n    <limit lower="0" upper="0"/>', 1)
    assert bad != text
    p.write_text(bad)
    r = check_urdf_parser_py(p)
    assert not r.passed and "effort" in r.errors[0]


@needs_drake
def test_drake_loads_the_contract_holds_its_damping_and_ignores_friction(contract):
    r = check_drake(contract / "mobility.urdf")
    assert r.passed, r.errors
    assert r.details["bodies"] == 4 and r.details["joints"] == 2
    assert sorted(r.details["friction_ignored"]) == ["lid_hinge", "post_slide"]
    assert any("friction" in w for w in r.warnings)


@needs_drake
def test_drake_flags_an_inertia_that_breaks_the_triangle_inequality(contract):
    p = contract / "mobility.urdf"
    text = p.read_text()
    old = 'ixx="4.333333333333334e-05" ixy="0.0" ixz="0.0" iyy="4.333333333333334e-05" iyz="0.0" izz="3.3333333333333333e-06"'
    assert old in text
    p.write_text(text.replace(old, 'ixx="1e-05" ixy="0.0" ixz="0.0" iyy="1e-05" iyz="0.0" izz="5e-05"'))
    r = check_drake(p)
    assert not r.passed
    # Drake's parser warns (naming the file line) and replaces the tensor; the check makes it an error
    assert any("triangle inequality" in e and "mobility.urdf:" in e for e in r.errors), r.errors


@needs_validator
def test_urdf_validator_passes_the_contract(contract):
    r = check_urdf_validator(contract / "mobility.urdf")
    assert r.passed, r.errors
    assert r.details["schema"] == "PASS"


@needs_doctor
def test_mjcf_doctor_finds_no_error_in_the_exported_mjcf(contract):
    pytest.importorskip("mujoco")
    from asset2sim.formats.mjcf.export import export_mjcf

    export_mjcf(contract)
    r = check_mjcf_doctor(contract / "mjcf" / "mobility.xml")
    assert r.passed, r.errors
    # the SPEC's 1/240 s step is larger than mjcf-doctor's taste: a warning, documented
    assert all(not w.startswith("timestep_large") or "0.0041" in w for w in r.warnings)


@needs_simcheck
def test_simcheck_passes_the_contract_and_flags_a_lid_of_lead_by_the_ton(contract):
    """simcheck (opt-in) on the contract asset: no error; the lid made 100,000 x heavier is a density error."""
    r = check_simcheck(contract / "mobility.urdf")
    assert r.passed, r.errors
    assert r.details["verdict"] in ("PASS", "WARN")
    p = contract / "mobility.urdf"
    model = urdf.read_urdf(p)
    lid = model.joint("lid_hinge").child
    model.links[lid].inertial.mass *= 1e5
    model.links[lid].inertial.inertia = model.links[lid].inertial.inertia * 1e5
    p.write_bytes(urdf.write_urdf(model))
    r = check_simcheck(p)
    assert any(e.startswith("inertia.density") and lid in e for e in r.errors), r.errors
    assert "simcheck" not in run_checkers(contract)  # opt-in


def test_missing_files_and_packages_are_reported_not_raised(tmp_path):
    write_contract_asset(tmp_path)
    res = run_checkers(tmp_path)
    assert isinstance(res["mjcf-doctor"], str) and "mjcf/mobility.xml" in res["mjcf-doctor"]
    for name, r in res.items():
        assert isinstance(r, str) and r.startswith("skipped") or r.tool == name


ROWS = list(csv.DictReader((SHARED / "manifest.csv").open())) if (SHARED / "manifest.csv").is_file() else []


def _parses_as_a_passive_part(urdf_path: Path) -> None:
    """ROS's parser reads ``urdf_path`` without an error (it warns of the optional ``name`` of a ``<visual>``, which it
    does not know), and every revolute or prismatic limit carries the
    passive part's effort and velocity (``asset2sim.urdf.PASSIVE_EFFORT``, ``PASSIVE_VELOCITY``)."""
    r = check_urdf_parser_py(urdf_path)
    assert r.passed, r.errors
    from urdf_parser_py.urdf import URDF

    robot = URDF.from_xml_string(urdf_path.read_bytes())
    limited = [j for j in robot.joints if j.type in ("revolute", "prismatic")]
    assert limited and all((j.limit.effort, j.limit.velocity) == (urdf.PASSIVE_EFFORT, urdf.PASSIVE_VELOCITY) for j in limited)


@needs_parser
def test_a_refined_urdf_is_read_by_ros_parser(refine_once):
    """A generated laptop refined: ROS's URDF parser (urdf_parser_py, urdfdom's rules) reads its mobility.urdf, whose
    limits carry the effort and velocity the format requires."""
    res = refine_once("laptop", "I want a slightly open laptop. Low damping for smooth operation.", extras=False)
    _parses_as_a_passive_part(res.out_dir / "mobility.urdf")


@needs_parser
@pytest.mark.slow  # end to end: every dev row refined
@pytest.mark.parametrize("row", ROWS, ids=[r["id"] for r in ROWS])
def test_every_dev_rows_refined_urdf_is_read_by_ros_parser(refine_once, row):
    res = refine_once(SHARED / row["id"], row["prompt"], extras=False)
    _parses_as_a_passive_part(res.out_dir / "mobility.urdf")
