"""Property tests: random valid trees round-trip through a URDF writer, and any
single-field corruption of them is rejected with the right code.

Round trip: generate a valid model -> write it -> ``extract_asset`` (A) ->
write it again with a writer -> ``extract_asset`` (B); A and B must describe
the same model (names, tree, joint types, origins as transforms, axes, limits,
effort, velocity, dynamics, geometry, inertials). Writers: yourdfpy's
``write_xml_file`` and the pipeline's own ``asset2sim.tasks.assemble.write.build_urdf``
(at scale 1, with an overlay carrying the given inertials).
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from asset2sim import urdf
from asset2sim.schemas.asset import AssetDescription, Origin
from asset2sim.tasks.ingest import validate_input as vi
from asset2sim.tasks.ingest.extract import extract_asset
from tests import corpus_builder as cb

MESHES = {
    "meshes/a.obj": cb.box_obj(0, 1, 0, 0.5, 0, 0.25),
    "meshes/b.stl": cb.box_stl(-0.1, 0.1, -0.2, 0.2, 0, 0.3),
    "other dir/c d.obj": cb.box_obj(-1, 0, -1, 0, -1, 0),
}
NAME_CHARS = "abcdefxyz0123456789_-.&<>'\" é"

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _f(x: float) -> str:
    return repr(float(x))


def _v(xs) -> str:
    return " ".join(_f(x) for x in xs)


coord = st.floats(-5, 5, allow_nan=False, allow_infinity=False)
angle = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)
positive = st.floats(0.01, 3.0, allow_nan=False, allow_infinity=False)
nonneg = st.floats(0.0, 50.0, allow_nan=False, allow_infinity=False)
# the strategies every draw reuses, built once (a strategy built inside a composite is built and validated again on
# every draw: most of the test's time went there)
xyz3, rpy3, size3 = st.tuples(coord, coord, coord), st.tuples(angle, angle, angle), st.tuples(positive, positive, positive)
unit3 = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1))
names = st.text(NAME_CHARS, min_size=1, max_size=6).map(str.strip).filter(bool)


@st.composite
def origins(draw):
    if draw(st.booleans()):
        return None, None
    return _v(draw(xyz3)), _v(draw(rpy3))


@st.composite
def geoms(draw):
    kind = draw(st.sampled_from(["mesh", "mesh", "box", "cylinder", "sphere"]))
    xyz, rpy = draw(origin)
    g = cb.Geom(kind=kind, xyz=xyz, rpy=rpy)
    if kind == "mesh":
        g.filename = draw(st.sampled_from(sorted(MESHES)))
        if draw(st.booleans()):
            g.scale = _v(draw(size3))
    elif kind == "box":
        g.size = _v(draw(size3))
    elif kind == "cylinder":
        g.radius, g.length = _f(draw(positive)), _f(draw(positive))
    else:
        g.radius = _f(draw(positive))
    return g


def _rpy_matrix(r, p, y):
    import trimesh.transformations as tf

    return tf.euler_matrix(r, p, y, axes="sxyz")[:3, :3]


@st.composite
def inertials(draw):
    """A physically valid inertial: a solid box's principal moments, rotated."""
    m = draw(st.floats(0.01, 10.0))
    a, b, c = draw(size3)
    principal = np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * m / 12.0
    rot = _rpy_matrix(*draw(rpy3))
    inertia = rot @ principal @ rot.T
    return cb.Inertial(
        mass=_f(m),
        ixx=_f(inertia[0, 0]), ixy=_f(inertia[0, 1]), ixz=_f(inertia[0, 2]),
        iyy=_f(inertia[1, 1]), iyz=_f(inertia[1, 2]), izz=_f(inertia[2, 2]),
        xyz=_v(draw(xyz3)) if draw(st.booleans()) else None,
    )


origin, geom_lists, inertial = origins(), st.lists(geoms(), max_size=2), inertials()


@st.composite
def models(draw, min_links: int = 1):
    n = draw(st.integers(min_links, 7))
    lnames = draw(st.lists(names, min_size=n, max_size=n, unique=True))
    jnames = draw(st.lists(names, min_size=n - 1, max_size=n - 1, unique=True))
    links = []
    for name in lnames:
        ln = cb.Link(name, inertial=draw(inertial) if draw(st.booleans()) else None)
        ln.visuals = draw(geom_lists)
        ln.collisions = draw(geom_lists)
        links.append(ln)
    joints = []
    for i in range(1, n):
        parent = lnames[draw(st.integers(0, i - 1))]
        jtype = draw(st.sampled_from(["revolute", "continuous", "prismatic", "fixed"]))
        xyz, rpy = draw(origin)
        j = cb.Joint(jnames[i - 1], jtype, parent, lnames[i], xyz=xyz, rpy=rpy)
        if jtype != "fixed":
            ax = np.array(draw(unit3))
            assume(np.linalg.norm(ax) > 0.1)
            j.axis = _v(ax / np.linalg.norm(ax))
        if jtype in ("revolute", "prismatic"):
            lo, hi = sorted(draw(st.tuples(st.floats(-3, 3), st.floats(-3, 3))))
            assume(hi - lo > 1e-6)
            j.lower, j.upper = _f(lo), _f(hi)
            if draw(st.booleans()):
                j.effort, j.velocity = _f(draw(nonneg)), _f(draw(nonneg))
        if jtype != "fixed" and draw(st.booleans()):
            j.damping, j.friction = _f(draw(nonneg)), _f(draw(nonneg))
        joints.append(j)
    if any(j.type == "prismatic" for j in joints):
        # travel up to 3 must stay within the object's size (JOINT_LIMIT_IMPLAUSIBLE): a 6 m box on the root
        links[0].visuals.append(cb.Geom(kind="box", size="6 6 6"))
    if not any(ln.visuals or ln.collisions for ln in links):
        # an asset without any geometry is refused (ASSET_NO_GEOMETRY): nothing to size, weigh or collide
        links[0].collisions.append(cb.Geom(kind="box", size="0.2 0.2 0.2"))
    # the joint list order is not the tree order in real files: shuffle it
    order = draw(st.permutations(range(len(joints))))
    return cb.Model(name=draw(st.text(NAME_CHARS, min_size=1, max_size=8)), links=links, joints=[joints[k] for k in order])


def _write(folder: Path, model: cb.Model) -> Path:
    folder.mkdir(parents=True)
    for rel, text in MESHES.items():
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text)
    (folder / "mobility.urdf").write_text(cb.render_urdf(model))
    return folder


def _matrix(o: Origin) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = _rpy_matrix(*o.rpy)
    m[:3, 3] = o.xyz
    return m


def _normal(desc: AssetDescription) -> dict:
    """The model as nested plain values; origins as 4x4 transforms."""
    links = {}
    for ln in desc.links:
        gs = []
        for g in ln.visuals + ln.collisions:
            gs.append((g.role, g.kind, g.filename, g.scale, g.size, g.radius, g.length, _matrix(g.origin)))
        gi = ln.given_inertial
        links[ln.name] = (gs, None if gi is None else (gi.mass, np.asarray(gi.inertia), _matrix(gi.origin)))
    joints = {
        j.name: (j.type, j.parent, j.child, _matrix(j.origin), j.axis if j.is_movable else None, j.lower, j.upper,
                 j.effort, j.velocity, j.damping, j.friction)
        for j in desc.joints
    }
    return {"root": desc.root_link, "links": links, "joints": joints}


def _same(a, b, path="$"):
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{path}: keys {sorted(a)} != {sorted(b)}"
        for k in a:
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, (list, tuple)) and not isinstance(a, np.ndarray):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), f"{path}: {a!r} != {b!r}"
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, (float, int, np.ndarray)) and not isinstance(a, bool):
        assert np.allclose(a, b, rtol=1e-9, atol=1e-9), f"{path}: {a!r} != {b!r}"
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def _copy_meshes(src: Path, dst: Path) -> None:
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("*.urdf"))


@SETTINGS
@given(models())
def test_roundtrip_through_yourdfpy_writer(model):
    import yourdfpy

    with tempfile.TemporaryDirectory() as tmp:
        src = _write(Path(tmp) / "src", model)
        findings = vi.validate_asset(src)
        assert not vi.has_errors(findings), [f.describe() for f in findings if f.severity == "error"]
        a = extract_asset(src)
        urdf = yourdfpy.URDF.load(
            str(src / "mobility.urdf"), build_scene_graph=False, load_meshes=False,
            build_collision_scene_graph=False, load_collision_meshes=False, filename_handler=lambda f: f,
        )
        dst = Path(tmp) / "dst"
        _copy_meshes(src, dst)
        urdf.write_xml_file(str(dst / "mobility.urdf"))
        b = extract_asset(dst)
        assert b.robot_name == a.robot_name
        _same(_normal(a), _normal(b))


@pytest.mark.slow  # end to end: 40 generated assets through the pipeline's writer and reader
@SETTINGS
@given(models())
def test_roundtrip_through_pipeline_writer(model):
    """``tasks.write.build_urdf`` at scale 1: the kinematic tree and geometry
    are unchanged; inertials and dynamics are the overlay's."""
    write = pytest.importorskip("asset2sim.tasks.assemble.write")
    from asset2sim.schemas.overlay import EstimatorInfo, Inertia, JointDynamics, LinkPhysics, Overlay

    with tempfile.TemporaryDirectory() as tmp:
        src = _write(Path(tmp) / "src", model)
        a = extract_asset(src)
        links = {}
        for ln in a.links:
            gi = ln.given_inertial
            mass, inertia, com = (gi.mass, np.asarray(gi.inertia), gi.origin.xyz) if gi else (1.0, np.eye(3) * 0.01, (0.0, 0.0, 0.0))
            links[ln.name] = LinkPhysics(mass=mass, inertia=Inertia.from_matrix(inertia), com=com)
        joints = {j.name: JointDynamics(damping=0.25, friction=0.125) for j in a.movable_joints()}
        overlay = Overlay(estimator=EstimatorInfo(name="test"), scale=1.0, links=links, joints=joints)
        dst = Path(tmp) / "dst"
        _copy_meshes(src, dst)
        (dst / "mobility.urdf").write_bytes(write.build_urdf(a, overlay))
        b = extract_asset(dst)
        expected = _normal(a)
        for ln in a.links:
            lp = links[ln.name]
            com = np.eye(4)
            com[:3, 3] = lp.com
            expected["links"][ln.name] = (expected["links"][ln.name][0], (lp.mass, lp.inertia.matrix(), com))
        for j in a.movable_joints():
            t = list(expected["joints"][j.name])
            # build_urdf keeps effort and velocity as the input declares them; a revolute or prismatic joint (or a
            # continuous one with a <limit>) without them gets a passive part's (the URDF format requires both there)
            t[9], t[10] = 0.25, 0.125
            if j.type in ("revolute", "prismatic") or next(x.with_limit for x in model.joints if x.name == j.name):
                t[7] = urdf.PASSIVE_EFFORT if t[7] is None else t[7]
                t[8] = urdf.PASSIVE_VELOCITY if t[8] is None else t[8]
            expected["joints"][j.name] = tuple(t)
        _same(expected, _normal(b))


# ----------------------------------------------------------------------------- corruptions


def _movable(m: cb.Model) -> list[cb.Joint]:
    return [j for j in m.joints if j.type in ("revolute", "continuous", "prismatic")]


def _limited(m: cb.Model) -> list[cb.Joint]:
    return [j for j in m.joints if j.type in ("revolute", "prismatic")]


def _mesh_geoms(m: cb.Model) -> list[cb.Geom]:
    return [g for ln in m.links for g in ln.visuals + ln.collisions if g.kind == "mesh"]


def _boxes(m: cb.Model) -> list[cb.Geom]:
    return [g for ln in m.links for g in ln.visuals + ln.collisions if g.kind == "box"]


def _with_inertial(m: cb.Model) -> list[cb.Link]:
    return [ln for ln in m.links if ln.inertial is not None]


def _pick(data, items):
    assume(items)
    return items[data.draw(st.integers(0, len(items) - 1))]


def _c_xyz_nan(m, d):
    j = _pick(d, m.joints)
    j.xyz, j.rpy = "0 nan 0", j.rpy or "0 0 0"


def _c_rpy_inf(m, d):
    j = _pick(d, m.joints)
    j.xyz, j.rpy = j.xyz or "0 0 0", "0 -inf 0"


def _c_axis_zero(m, d):
    _pick(d, _movable(m)).axis = "0 0 0"


def _c_limit_swap(m, d):
    j = _pick(d, _limited(m))
    j.lower, j.upper = j.upper, j.lower


def _c_overflow(m, d):
    _pick(d, _limited(m)).upper = "1e400"


def _c_effort(m, d):
    _pick(d, _limited(m)).effort = "-1"


def _c_velocity(m, d):
    _pick(d, _limited(m)).velocity = "-0.5"


def _c_damping(m, d):
    j = _pick(d, _movable(m))
    j.damping, j.friction = "-0.1", j.friction or "0"


def _c_parent_unknown(m, d):
    _pick(d, m.joints).parent = "\u2603 no such link"


def _c_child_unknown(m, d):
    _pick(d, m.joints).child = "\u2603 no such link"


def _c_self_loop(m, d):
    j = _pick(d, m.joints)
    j.child = j.parent


def _c_dup_link(m, d):
    assume(len(m.links) >= 2)
    i, k = d.draw(st.lists(st.integers(0, len(m.links) - 1), min_size=2, max_size=2, unique=True))
    m.links[i].name = m.links[k].name


def _c_dup_joint(m, d):
    assume(len(m.joints) >= 2)
    i, k = d.draw(st.lists(st.integers(0, len(m.joints) - 1), min_size=2, max_size=2, unique=True))
    m.joints[i].name = m.joints[k].name


def _c_type(m, d):
    _pick(d, m.joints).type = d.draw(st.sampled_from(["hinge", "slider", "Revolute", "ball", ""]))


def _c_second_parent(m, d):
    child = _pick(d, [ln.name for ln in m.links[1:]])
    m.joints.append(cb.Joint("extra parent joint", "fixed", m.links[0].name, child))


def _c_mass(m, d):
    _pick(d, _with_inertial(m)).inertial.mass = d.draw(st.sampled_from(["-1", "-0.001"]))


def _c_inertia(m, d):
    _pick(d, _with_inertial(m)).inertial.ixx = "-5"


def _c_mesh_escape(m, d):
    _pick(d, _mesh_geoms(m)).filename = d.draw(st.sampled_from(["../a.obj", "meshes/../../a.obj", "../../../../etc/passwd"]))


def _c_mesh_absolute(m, d):
    _pick(d, _mesh_geoms(m)).filename = "/etc/passwd"


def _c_mesh_uri(m, d):
    _pick(d, _mesh_geoms(m)).filename = d.draw(st.sampled_from(["file:///etc/passwd", "http://127.0.0.1:9/a.obj", "package://p/a.obj"]))


def _c_box_empty(m, d):
    _pick(d, _boxes(m)).size = ""


def _c_box_malformed(m, d):
    _pick(d, _boxes(m)).size = d.draw(st.sampled_from(["1 1", "1,1,1", "1 1 0x1", "1 1 1_0"]))


CORRUPTIONS = {
    "xyz_nan": (_c_xyz_nan, "NUMBER_NAN", "error"),
    "rpy_inf": (_c_rpy_inf, "NUMBER_INF", "error"),
    "axis_zero": (_c_axis_zero, "JOINT_AXIS_ZERO", "error"),
    "limit_swap": (_c_limit_swap, "JOINT_LIMIT_REVERSED", "error"),
    "limit_overflow": (_c_overflow, "NUMBER_OVERFLOW", "error"),
    "effort_negative": (_c_effort, "JOINT_EFFORT_NEGATIVE", "error"),
    "velocity_negative": (_c_velocity, "JOINT_VELOCITY_NEGATIVE", "error"),
    "damping_negative": (_c_damping, "JOINT_DYNAMICS_NEGATIVE", "error"),
    "parent_unknown": (_c_parent_unknown, "JOINT_PARENT_UNKNOWN", "error"),
    "child_unknown": (_c_child_unknown, "JOINT_CHILD_UNKNOWN", "error"),
    "self_loop": (_c_self_loop, "JOINT_SELF_LOOP", "error"),
    "duplicate_link": (_c_dup_link, "LINK_NAME_DUPLICATE", "error"),
    "duplicate_joint": (_c_dup_joint, "JOINT_NAME_DUPLICATE", "error"),
    "joint_type": (_c_type, "JOINT_TYPE_INVALID", "error"),
    "second_parent": (_c_second_parent, "LINK_MULTIPLE_PARENTS", "error"),
    "mass_negative": (_c_mass, "INERTIAL_MASS_NONPOSITIVE", "warning"),
    "inertia_indefinite": (_c_inertia, "INERTIA_NOT_POSITIVE_DEFINITE", "warning"),
    "mesh_escape": (_c_mesh_escape, "MESH_PATH_ESCAPES", "error"),
    "mesh_absolute": (_c_mesh_absolute, "MESH_PATH_ABSOLUTE", "error"),
    "mesh_uri": (_c_mesh_uri, "MESH_URI_FORBIDDEN", "error"),
    "box_empty": (_c_box_empty, "NUMBER_EMPTY", "error"),
    "box_malformed": (_c_box_malformed, None, "error"),  # NUMBER_COUNT or NUMBER_MALFORMED
}


#: Each kind of corruption is its own test on this many generated models: every kind runs every time (one
#: test drawing the kind among 22 for 120 models, uniformly, left some kind out of about one run in twelve) on models drawn
#: from the whole space (2-7 links, every joint type, meshes and primitives, with and without inertials).
EXAMPLES_PER_CORRUPTION = 4


@pytest.mark.parametrize("which", sorted(CORRUPTIONS))
@settings(max_examples=EXAMPLES_PER_CORRUPTION, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])
@given(model=models(min_links=2), data=st.data())
def test_single_field_corruption_is_rejected(model, which, data):
    fn, code, severity = CORRUPTIONS[which]
    fn(model, data)
    with tempfile.TemporaryDirectory() as tmp:
        src = _write(Path(tmp) / "src", model)
        findings = vi.validate_asset(src)
        if not vi.has_errors(findings):
            desc = extract_asset(src)  # what validation lets through, extraction must read
            assert not any(ln.given_inertial for ln in desc.links if ln.name in {f.link for f in findings if f.action})
    codes = {f.code: f for f in findings}
    if code is None:
        hit = codes.get("NUMBER_COUNT") or codes.get("NUMBER_MALFORMED")
    else:
        hit = codes.get(code)
    assert hit is not None, f"{which}: expected {code}, got {[f.describe() for f in findings]}"
    assert hit.severity == severity
    if severity == "error":
        assert vi.has_errors(findings)
    else:
        assert hit.action == "replace_with_estimate" and not vi.has_errors(findings)
    assert "INTERNAL_ERROR" not in codes
