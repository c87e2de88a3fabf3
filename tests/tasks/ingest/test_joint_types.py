"""Every joint type of URDF is carried through refine or refused at validation.

Floating and planar joints passed ``asset2sim validate`` and then ended
``asset2sim refine`` with ``INTERNAL_ERROR`` (exit 70) and a partial output
folder: refine wrote a URDF its own balance stage (which reads URDFs as the
engines do, :data:`asset2sim.urdf.SIMULATED_JOINT_TYPES`) refused. They are
now refused by the validator (``JOINT_TYPE_UNSUPPORTED``, naming the file,
line and joint), so ``refine`` exits 1 with one line and writes nothing.
Continuous and fixed joints are carried through; a ``<mimic>`` stays refused
(``JOINT_MIMIC_UNSUPPORTED``). The cases are those of the malformed corpus
(:mod:`tests.corpus_builder`).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from asset2sim import cli, urdf
from asset2sim.tasks.ingest import validate_input as vi
from tests import corpus_builder as cb
from tests.helpers import tree_hashes

#: Corpus cases refused for their joint type -> the joint the finding names.
REFUSED = {
    "joint_type_floating_below_root": "handle_fix",
    "joint_type_floating_from_root": "lid_hinge",
    "joint_type_planar": "drawer_slide",
}


def _lid_joint_of_type(jtype: str):
    """A builder of the corpus's valid asset with ``lid_hinge`` made a
    ``jtype`` joint written as the URDF specification asks: an axis for
    every type but fixed and floating (planar: the plane's normal), limits
    on revolute and prismatic only."""
    keep_axis = jtype not in ("fixed", "floating")
    keep_limits = jtype in ("revolute", "prismatic")
    values = {"type": jtype}
    if not keep_axis:
        values["axis"] = None
    if not keep_limits:
        values.update(lower=None, upper=None, effort=None, velocity=None)
    if jtype in ("fixed", "floating", "planar"):
        values.update(damping=None, friction=None)
    return cb._model_case(cb._attr("joint", "lid_hinge", **values))


@pytest.mark.parametrize("jtype", urdf.JOINT_TYPES)
def test_every_urdf_joint_type_is_one_the_engines_read_or_is_refused(jtype, tmp_path):
    """Each of the six types of the URDF specification is either one the
    engines (and refine's stages) read, accepted, or refused by validation
    with ``JOINT_TYPE_UNSUPPORTED``: no type passes validation that a later
    stage cannot read."""
    asset = _lid_joint_of_type(jtype)(tmp_path / "asset")
    errors = [f for f in vi.validate_asset(asset) if f.severity == "error"]
    if jtype in urdf.SIMULATED_JOINT_TYPES:
        assert errors == [], [f.describe() for f in errors]
    else:
        assert [(f.code, f.joint) for f in errors] == [("JOINT_TYPE_UNSUPPORTED", "lid_hinge")], [f.describe() for f in errors]


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_floating_and_planar_joints_are_refused_naming_the_file_and_joint(name, tmp_path, capsys):
    """``validate`` and ``refine`` refuse a floating or planar joint with exit
    status 1 and a line naming the code, the file, the line and the joint;
    refine writes no output folder (it used to exit 70 with a partial one)
    and the input is unchanged."""
    joint = REFUSED[name]
    asset = cb.CASES_BY_NAME[name].build(tmp_path / "asset")
    before = tree_hashes(asset)
    (f,) = [f for f in vi.validate_asset(asset) if f.code == "JOINT_TYPE_UNSUPPORTED"]
    jtype = "planar" if "planar" in name else "floating"
    assert (f.severity, f.file, f.joint) == ("error", "mobility.urdf", joint)
    assert f.line is not None and f"a {jtype} joint" in f.message and 'type="fixed"' in f.message
    assert cli.main(["validate", str(asset)]) == 1
    out = capsys.readouterr().out
    assert re.search(rf"JOINT_TYPE_UNSUPPORTED\s+mobility\.urdf:{f.line}\s+joint '{joint}'", out), out
    status = cli.main(["refine", str(asset), "--out", str(tmp_path / "out"), "--no-extras", "-q"])
    err = capsys.readouterr().err
    assert status == 1, err
    lines = [ln for ln in err.splitlines() if ln.startswith("asset2sim refine")]
    assert len(lines) == 1 and "JOINT_TYPE_UNSUPPORTED" in lines[0] and f"joint {joint!r}" in lines[0], err
    assert "INTERNAL_ERROR" not in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()
    assert tree_hashes(asset) == before


@pytest.mark.parametrize("jtype", ["continuous", "fixed"])
def test_continuous_and_fixed_joints_are_carried_through(jtype, tmp_path, capsys):
    """A continuous or a fixed lid joint refines to its normal verdict and
    the output URDF keeps the joint's type (a continuous joint without
    lower/upper stops)."""
    asset = cb.ACCEPTED[f"joint_{jtype}"](tmp_path / "asset")
    out = tmp_path / "out"
    status = cli.main(["refine", str(asset), "--out", str(out), "--no-extras", "-q"])
    err = capsys.readouterr().err
    assert status in (0, 3), err
    assert "Traceback" not in err
    written = urdf.read_urdf(out / "mobility.urdf", joint_types=urdf.SIMULATED_JOINT_TYPES)
    lid = written.joint("lid_hinge")
    assert lid.type == jtype
    if jtype == "continuous":
        assert lid.limit is None or (lid.limit.lower is None and lid.limit.upper is None)
    assert {j.name: j.type for j in written.joints}["drawer_slide"] == "prismatic"


def test_a_mimic_joint_is_refused_naming_the_joint_and_its_leader(tmp_path, capsys):
    """Refine cannot honour a coupling (its state search, the post-check
    simulators and the initial state treat every joint as free), so a
    ``<mimic>`` is refused with ``JOINT_MIMIC_UNSUPPORTED`` naming the file,
    the joint and the joint it mimics, not dropped; refine writes nothing."""
    asset = cb.CASES_BY_NAME["mimic_joint"].build(tmp_path / "asset")
    (f,) = [f for f in vi.validate_asset(asset) if f.code == "JOINT_MIMIC_UNSUPPORTED"]
    assert (f.severity, f.file, f.joint) == ("error", "mobility.urdf", "lid2_hinge") and "'lid_hinge'" in f.message
    status = cli.main(["refine", str(asset), "--out", str(tmp_path / "out"), "--no-extras", "-q"])
    err = capsys.readouterr().err
    assert status == 1 and "JOINT_MIMIC_UNSUPPORTED" in err and "INTERNAL_ERROR" not in err, err
    assert not Path(tmp_path / "out").exists()
