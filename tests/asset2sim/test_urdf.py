"""The shared URDF model: reader (strict / lenient / collect), writer, scaling,
on the 21 real PartNet-Mobility objects and their GenSim2 references."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import NO_SHARED, SHARED
from asset2sim import urdf
from tests.contract_asset import write_contract_asset

DATASET = SHARED
REAL = sorted(DATASET.glob("*/mobility.urdf")) + sorted(DATASET.glob("*/reference_gensim2.urdf"))
needs_dataset = pytest.mark.skipif(not REAL, reason=NO_SHARED)
_NUMBER = re.compile(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


@needs_dataset
@pytest.mark.parametrize("mode", ["strict", "lenient"])
def test_round_trip_of_every_real_urdf(mode):
    assert len(REAL) == 42
    for path in REAL:
        model = urdf.read_urdf(path, mode=mode)
        data = urdf.write_urdf(model)
        again = urdf.parse_urdf_bytes(data, source=str(path), base=path.parent, mode=mode)
        assert again == model, path
        assert urdf.write_urdf(again) == data, path  # the writer's own output is a fixed point
        for style in (urdf.PARTNET_STYLE,):
            assert urdf.parse_urdf_bytes(urdf.write_urdf(model, style=style), mode=mode) == model, path


@needs_dataset
def test_partnet_style_reproduces_partnet_files_up_to_number_spelling():
    """Files in PartNet-Mobility's own layout (``<?xml version="1.0" ?>``,
    tabs, ``/>``, visuals before collisions) come back line for line; only
    the spelling of numbers may differ (``0.0`` / ``0``), never their value."""
    same_layout = 0
    for path in sorted(DATASET.glob("*/mobility.urdf")):
        original = path.read_text().splitlines()
        if original[0] != '<?xml version="1.0" ?>' or any("<!--" in ln or " />" in ln for ln in original):
            continue
        model = urdf.read_urdf(path)
        written = urdf.write_urdf(model, style=urdf.PARTNET_STYLE).decode().splitlines()
        if [_NUMBER.sub("#", ln) for ln in written] != [_NUMBER.sub("#", ln) for ln in original]:
            continue  # another element order (collisions first)
        same_layout += 1
        for a, b in zip(written, original):
            assert [float(x) for x in _NUMBER.findall(a)] == [float(x) for x in _NUMBER.findall(b)], (path, a, b)
    assert same_layout >= 10


@needs_dataset
def test_model_values_match_the_file():
    path = DATASET / "103275" / "mobility.urdf"
    if not path.is_file():
        pytest.skip("103275 not in the dataset")
    model = urdf.read_urdf(path)
    assert model.root == "base" and model.path == path
    for j in model.joints:
        assert j.line is not None and j.parent in model.links and j.child in model.links
        if j.type in ("revolute", "prismatic"):
            assert j.lower == j.limit.lower and j.upper == j.limit.upper
        else:
            assert math.isinf(j.upper)
        assert np.linalg.norm(j.axis) == pytest.approx(1.0)
        assert j.dynamics is None and j.damping == 0.0
    for ln in model.links.values():
        for g in ln.visuals + ln.collisions:
            assert g.kind == "mesh" and g.path.is_file() and np.array_equal(g.scale, np.ones(3))
    assert model.tree_order()[0] == "base" and sorted(model.tree_order()) == sorted(model.links)


def test_writer_output_of_the_contract_asset_reads_back(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.3)
    model = urdf.read_urdf(a.urdf)
    text = a.urdf.read_text()
    assert text.startswith("<?xml version='1.0' encoding='utf-8'?>\n<robot name=\"contract_box\">\n")
    assert "<!-- initial joint positions: initial_state.json -->" in text
    hinge = model.joint("lid_hinge")
    assert (hinge.limit.effort, hinge.limit.velocity, hinge.damping) == (1000.0, 1000.0, 0.02)
    assert model.joint("root_fixed").axis_xyz is None and "<axis" not in text.split('name="root_fixed"')[1].split("</joint>")[0]
    assert urdf.write_urdf(model, comment=" initial joint positions: initial_state.json ") == a.urdf.read_bytes()


def _write(tmp_path: Path, body: str) -> Path:
    p = tmp_path / "r.urdf"
    p.write_text(f'<?xml version="1.0"?>\n<robot name="r">\n{body}\n</robot>\n')
    return p


_LINKS = '<link name="a"/>\n<link name="b"><inertial><mass value="{mass}"/><inertia ixx="1" iyy="1" izz="1"/></inertial></link>\n'
_JOINT = '<joint name="j" type="{type}"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>{limit}</joint>'


def test_errors_name_the_file_line_and_element(tmp_path):
    p = _write(tmp_path, _LINKS.format(mass="heavy") + _JOINT.format(type="revolute", limit='<limit lower="0" upper="1"/>'))
    with pytest.raises(urdf.UrdfError) as e:
        urdf.read_urdf(p)
    assert e.value.code == "NUMBER_MALFORMED" and e.value.link == "b"
    assert str(e.value).startswith(f"{p}:4: link 'b': ") and "'heavy' is not a decimal number" in str(e.value)

    p = _write(tmp_path, _LINKS.format(mass="1") + _JOINT.format(type="revolute", limit=""))
    with pytest.raises(urdf.UrdfError, match=r"r\.urdf:5: joint 'j': a revolute joint needs <limit") as e:
        urdf.read_urdf(p)
    assert e.value.code == "JOINT_LIMIT_MISSING"
    lenient = urdf.read_urdf(p, mode="lenient")  # raw files are graded as they are
    assert lenient.joint("j").limit is None and lenient.joint("j").lower == -math.inf

    p = _write(tmp_path, _LINKS.format(mass="1") + _JOINT.format(type="planar", limit=""))
    assert urdf.read_urdf(p).joint("j").type == "planar"
    with pytest.raises(urdf.UrdfError, match="not supported") as e:
        urdf.read_urdf(p, joint_types=urdf.SIMULATED_JOINT_TYPES)
    assert e.value.joint == "j"

    p = _write(tmp_path, _LINKS.format(mass="1") + '<link name="c"/>')
    with pytest.raises(urdf.UrdfError, match="one root"):
        urdf.read_urdf(p)
    assert urdf.read_urdf(p, mode="lenient").root is None


def test_lenient_mode_still_refuses_numbers_that_do_not_parse(tmp_path):
    p = _write(tmp_path, _LINKS.format(mass="1,5"))
    with pytest.raises(urdf.UrdfError, match="link 'b'"):
        urdf.read_urdf(p, mode="lenient")
    p = _write(tmp_path, _LINKS.format(mass="nan"))
    assert math.isnan(urdf.read_urdf(p, mode="lenient").links["b"].inertial.mass)
    with pytest.raises(urdf.UrdfError, match="NaN"):
        urdf.read_urdf(p)


def test_collect_mode_reports_every_problem_and_goes_on(tmp_path):
    body = (
        '<link name="a"><visual><geometry/></visual></link>\n'
        '<link name="b"><inertial><mass value="-1e999"/></inertial>'
        '<collision><geometry><box size="1 0 1"/></geometry></collision></link>\n'
        '<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 2"/>'
        '<limit lower="1" upper="0" effort="-1"/><dynamics damping="-2"/></joint>'
    )
    problems: list[urdf.Problem] = []
    model = urdf.read_urdf(_write(tmp_path, body), mode="collect", on_problem=problems.append)
    assert [p.code for p in problems] == [
        "GEOMETRY_MISSING", "GEOMETRY_SIZE_NONPOSITIVE", "NUMBER_OVERFLOW", "INERTIA_MISSING", "JOINT_AXIS_NOT_UNIT",
        "JOINT_LIMIT_REVERSED", "JOINT_EFFORT_NEGATIVE", "JOINT_DYNAMICS_NEGATIVE",
    ]
    assert problems[0].line == 3 and problems[0].link == "a" and problems[-1].joint == "j"
    assert model.joint("j").damping == -2.0 and not model.links["b"].collisions[0].complete


def test_collect_mode_keeps_every_link_element_and_orders_materials_after_collisions(tmp_path):
    """Input validation grades every <link> element (unnamed and repeated
    ones too), reads materials after the collisions, knows where a texture
    is written and which limit attributes could not be read."""
    body = (
        '<link name="a"><visual><geometry><box size="1 1 1"/></geometry>'
        '<material name="m"><color rgba="1 0 0"/>\n<texture filename="t.png"/></material></visual>'
        '<collision><geometry/></collision></link>\n'
        '<link><inertial><mass value="1"/></inertial></link>\n'
        '<link name="a"/>\n'
        '<joint name="j" type="revolute"><parent link="a"/><child link="a"/><limit lower="x" upper="1"/></joint>'
    )
    problems: list[urdf.Problem] = []
    model = urdf.read_urdf(_write(tmp_path, body), mode="collect", on_problem=problems.append)
    assert [p.code for p in problems][:3] == ["GEOMETRY_MISSING", "NUMBER_COUNT", "LINK_NAME_MISSING"]
    assert [ln.name for ln in model.link_elements] == ["a", "", "a"] and list(model.links) == ["a"]
    assert model.links["a"] is model.link_elements[0]
    mat = model.links["a"].visuals[0].material
    assert mat.texture == "t.png" and mat.texture_line == mat.line + 1
    assert model.joint("j").limit.unreadable == {"lower"} and model.joint("j").limit.upper == 1.0


@pytest.mark.parametrize(
    "text, code",
    [
        ('<!DOCTYPE r [<!ENTITY x "y">]><robot name="r"/>', "XML_ENTITY_FORBIDDEN"),
        ('<!DOCTYPE r SYSTEM "file:///etc/passwd"><robot name="r"/>', "XML_EXTERNAL_REFERENCE_FORBIDDEN"),
        ('<robot name="r"><link name="a">', "XML_MALFORMED"),
    ],
)
def test_xml_is_hardened(tmp_path, text, code):
    (tmp_path / "x.urdf").write_text(text)
    for mode in ("strict", "lenient"):
        with pytest.raises(urdf.UrdfError) as e:
            urdf.read_urdf(tmp_path / "x.urdf", mode=mode)
        assert e.value.code == code and str(tmp_path / "x.urdf") in str(e.value)
    problems: list[urdf.Problem] = []
    assert urdf.parse_urdf_bytes(text.encode(), mode="collect", on_problem=problems.append) is None
    assert [p.code for p in problems] == [code]


def test_scale_model(tmp_path):
    a = write_contract_asset(tmp_path)
    model = urdf.read_urdf(a.urdf)
    before = urdf.read_urdf(a.urdf)
    urdf.scale_model(model, 0.5)
    lid, post = model.joint("lid_hinge"), model.joint("post_slide")
    assert lid.origin[:3, 3] == pytest.approx(before.joint("lid_hinge").origin[:3, 3] * 0.5)
    assert (lid.lower, lid.upper) == (0.0, 2.0)  # radians do not scale
    assert (post.lower, post.upper) == (0.0, 0.025)
    body, body0 = model.links["body"], before.links["body"]
    assert np.array_equal(body.collisions[0].scale, [0.5, 0.5, 0.5])
    assert body.inertial.mass == body0.inertial.mass
    assert body.inertial.com() == pytest.approx(body0.inertial.com() * 0.5)
    assert body.inertial.inertia == pytest.approx(body0.inertial.inertia * 0.25)
    with pytest.raises(ValueError):
        urdf.scale_model(model, 0.0)


@needs_dataset
def test_reader_agrees_with_yourdfpy_on_every_real_urdf():
    """Independent check of the one reader against yourdfpy (the stack's URDF
    library): same links, joints, types, parents, children, origins, axes,
    limits, dynamics, inertials and mesh references on all 42 real files."""
    import yourdfpy

    def close(a, b):
        return np.allclose(np.asarray(a, float), np.asarray(b, float), atol=1e-12)

    for path in REAL:
        ours = urdf.read_urdf(path, mode="lenient")
        ref = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False,
                                 build_collision_scene_graph=False, load_collision_meshes=False).robot
        assert ours.name == ref.name, path
        assert list(ours.links) == [ln.name for ln in ref.links], path
        for ln in ref.links:
            mine = ours.links[ln.name]
            assert (mine.inertial is None) == (ln.inertial is None), (path, ln.name)
            if ln.inertial is not None:
                assert math.isclose(mine.inertial.mass, ln.inertial.mass), (path, ln.name)
                assert close(mine.inertial.origin, ln.inertial.origin), (path, ln.name)
                assert close(mine.inertial.inertia, ln.inertial.inertia), (path, ln.name)
            for role, theirs in (("visuals", ln.visuals), ("collisions", ln.collisions)):
                geoms = getattr(mine, role)
                assert len(geoms) == len(theirs), (path, ln.name, role)
                for g, t in zip(geoms, theirs):
                    assert close(g.origin, t.origin if t.origin is not None else np.eye(4)), (path, ln.name, role)
                    if t.geometry.mesh is not None:
                        assert g.kind == "mesh" and g.filename == t.geometry.mesh.filename, (path, ln.name)
        assert [j.name for j in ours.joints] == [j.name for j in ref.joints], path
        for j, t in zip(ours.joints, ref.joints):
            where = (path, j.name)
            assert (j.type, j.parent, j.child) == (t.type, t.parent, t.child), where
            assert close(j.origin, t.origin if t.origin is not None else np.eye(4)), where
            if t.axis is not None and j.axis_xyz is not None:
                assert close(j.axis_xyz, t.axis), where
            if t.limit is not None:
                assert j.limit is not None, where
                for f in ("lower", "upper", "effort", "velocity"):
                    a, b = getattr(j.limit, f), getattr(t.limit, f)
                    assert (a is None and b is None) or (a is not None and b is not None and math.isclose(a, b)), (where, f)
            if t.dynamics is not None:
                assert j.dynamics is not None, where
                for f in ("damping", "friction"):
                    a, b = getattr(j.dynamics, f), getattr(t.dynamics, f)
                    assert (a is None and b is None) or (a is not None and b is not None and math.isclose(a, b)), (where, f)


@needs_dataset
def test_clone_is_an_independent_copy_that_keeps_shared_objects_shared(tmp_path):
    """clone_model (the read memo's copy) gives what copy.deepcopy gives: an
    equal model, nothing shared with the original, and an object reached
    twice (a link in links and link_elements) still one object."""
    import copy

    for path in REAL:
        model = urdf.read_urdf(path, mode="collect", on_problem=lambda p: None)
        twin = urdf.clone_model(model)
        assert twin == model == copy.deepcopy(model), path
        assert urdf.write_urdf(twin) == urdf.write_urdf(model), path
        for name, link in twin.links.items():
            assert link is not model.links[name]
            assert any(e is link for e in twin.link_elements) == any(e is model.links[name] for e in model.link_elements)
        for a, b in zip(twin.joints, model.joints):
            assert a is not b and a.origin is not b.origin
        twin.joints[0].origin[0, 3] += 1.0
        twin.links[next(iter(twin.links))].collisions.clear()
        assert twin != model and urdf.write_urdf(model) == urdf.write_urdf(copy.deepcopy(model)), path


def test_a_source_is_a_file_or_a_model_in_memory(tmp_path):
    """model_of gives a copy of a model (the caller's stays as it was) or
    reads a file; path_of gives the file an engine loads."""
    from tests.contract_asset import write_contract_asset

    a = write_contract_asset(tmp_path / "a", lid_angle=0.4)
    read = urdf.read_urdf(a.urdf)
    copy = urdf.model_of(read)
    copy.joints[0].name = "renamed"
    assert read.joints[0].name != "renamed" and urdf.model_of(a.urdf) == read
    assert urdf.path_of(read) == a.urdf == urdf.path_of(str(a.urdf))
