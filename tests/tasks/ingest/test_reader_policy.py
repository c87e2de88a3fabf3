"""One reader policy for MJCF and USD inputs: every file they name (includes, meshes, textures, meshdir, USD
sublayers, references, payloads) and the input file itself is a regular file inside the input's folder, under
the size cap, opened without blocking, or refused with a named code by ``validate`` (fast) and by extraction
(what refine and audit call first). The hostile inputs are generated here: FIFOs, symlinks to ``/dev/zero`` and
out of the folder, absolute and ``../`` paths. Every call that could block runs under an alarm or in a child
process with a time-out, so a regression fails instead of hanging the suite."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.extract import extract_asset_checked
from asset2sim.formats.mjcf.reader import read_mjcf_asset
from asset2sim.tasks.ingest.validate_input import CODES, validate_asset
from tests.helpers import tree_hashes, no_hang

mujoco = pytest.importorskip("mujoco")

#: The most time validate may take on any hostile input here, s.
#: After this an in-process call is interrupted (a hang fails the test), s.
HANG_LIMIT_S = 30

TETRA = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _no_hang(seconds: int = HANG_LIMIT_S):
    """:func:`tests.helpers.no_hang` with this module's limit."""
    return no_hang(seconds)


def _mjcf(folder: Path, name: str = "obj.xml", *, mesh: str = "part.obj", compiler: str = "", extra_asset: str = "",
          body_extra: str = "") -> Path:
    """A two-body MJCF (a base and a hinged lid whose geom is ``mesh``) in ``folder``; ``part.obj`` written beside it."""
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / "part.obj").exists():
        (folder / "part.obj").write_text(TETRA)
    path = folder / name
    path.write_text(f"""<mujoco model="box">{compiler}
  <asset><mesh name="m" file="{mesh}"/>{extra_asset}</asset>
  <worldbody><body name="base" pos="0 0 0.1"><freejoint/><geom type="box" size="0.2 0.2 0.1" mass="2"/>
    <body name="lid" pos="0 0 0.1"><joint name="hinge" type="hinge" axis="0 1 0" range="0 1.5"/>
      <geom type="mesh" mesh="m" mass="0.3"/>{body_extra}</body></body></worldbody>
</mujoco>
""")
    return path


def _secret(tmp_path: Path) -> Path:
    """A mesh outside every input folder: what an input must never pull in."""
    (tmp_path / "elsewhere").mkdir(exist_ok=True)
    p = tmp_path / "elsewhere" / "secret.obj"
    p.write_text(TETRA)
    return p


def _refused(path: Path, code: str) -> list:
    """validate refuses ``path`` with ``code`` (stopped as hung after :func:`_no_hang`'s limit), writing nothing into its folder; extraction
    (refine's and audit's first step) refuses it with the same code."""
    folder = path.parent
    before = tree_hashes(folder) if not any(p.is_fifo() for p in folder.iterdir()) else None
    with _no_hang():
        findings = validate_asset(path)
    codes = [f.code for f in findings if f.severity == "error"]
    assert code in codes, [f.describe() for f in findings]
    assert "INTERNAL_ERROR" not in codes
    with _no_hang(), pytest.raises(AssetError) as info:
        extract_asset_checked(path)
    assert code in info.value.codes, str(info.value)
    if before is not None:
        assert tree_hashes(folder) == before
    return findings


def test_every_new_code_is_documented_in_the_codes_table():
    for code in ("MJCF_PATH_ESCAPES", "USD_LAYER_OUTSIDE_ASSET", "INPUT_NOT_REGULAR_FILE", "INPUT_TOO_LARGE", "INPUT_NOT_FOUND",
                 "INPUT_OUTSIDE_TREE", "INPUT_UNREADABLE", "FORMAT_UNREADABLE"):
        assert code in CODES
    guide = (Path(__file__).resolve().parents[3] / "docs" / "guide" / "validation.md").read_text()
    for code in ("MJCF_PATH_ESCAPES", "USD_LAYER_OUTSIDE_ASSET", "INPUT_NOT_REGULAR_FILE", "INPUT_TOO_LARGE",
                 "YAML_ALIAS_LIMIT"):
        assert f"`{code}`" in guide, code


# ------------------------------------------------------------------------- MJCF: what is still read


def test_an_mjcf_naming_files_inside_its_folder_is_read(tmp_path):
    """Includes, meshdir and textures inside the folder (also through a symlink that stays inside) are read."""
    folder = tmp_path / "in"
    (folder / "meshes").mkdir(parents=True)
    (folder / "meshes" / "lid.obj").write_text(TETRA)
    os.symlink("lid.obj", folder / "meshes" / "alias.obj")
    (folder / "defaults.xml").write_text('<mujocoinclude><default><geom rgba="0.5 0.5 0.5 1"/></default></mujocoinclude>')
    path = _mjcf(folder, mesh="alias.obj", compiler='<compiler meshdir="meshes"/><include file="defaults.xml"/>')
    assert not [f.describe() for f in validate_asset(path) if f.severity == "error"]
    desc, _ = extract_asset_checked(path)
    assert {ln.name for ln in desc.links} == {"base", "lid"}
    read = read_mjcf_asset(path)
    assert {(folder / "meshes" / "lid.obj").resolve(), (folder / "defaults.xml").resolve(), path.resolve()} <= set(read.files)


# ------------------------------------------------------------------------- MJCF: what is refused


def test_mjcf_mesh_at_an_absolute_path_is_refused(tmp_path):
    secret = _secret(tmp_path)
    _refused(_mjcf(tmp_path / "in", mesh=str(secret)), "MJCF_PATH_ESCAPES")


def test_mjcf_mesh_through_dotdot_is_refused(tmp_path):
    _secret(tmp_path)
    _refused(_mjcf(tmp_path / "in", mesh="../elsewhere/secret.obj"), "MJCF_PATH_ESCAPES")


def test_mjcf_meshdir_outside_the_folder_is_refused(tmp_path):
    _secret(tmp_path)
    for meshdir in (str(tmp_path / "elsewhere"), "../elsewhere"):
        _refused(_mjcf(tmp_path / "in", mesh="secret.obj", compiler=f'<compiler meshdir="{meshdir}"/>'), "MJCF_PATH_ESCAPES")


def test_mjcf_mesh_symlinked_out_of_the_folder_is_refused(tmp_path):
    secret = _secret(tmp_path)
    folder = tmp_path / "in"
    folder.mkdir()
    os.symlink(secret, folder / "link.obj")
    _refused(_mjcf(folder, mesh="link.obj"), "MJCF_PATH_ESCAPES")


def test_mjcf_texture_and_include_outside_the_folder_are_refused(tmp_path):
    _secret(tmp_path)
    (tmp_path / "elsewhere" / "sky.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    _refused(_mjcf(tmp_path / "in", extra_asset='<texture name="t" type="2d" file="../elsewhere/sky.png"/>'), "MJCF_PATH_ESCAPES")
    (tmp_path / "elsewhere" / "inc.xml").write_text("<mujocoinclude/>")
    _refused(_mjcf(tmp_path / "in2", compiler='<include file="../elsewhere/inc.xml"/>'), "MJCF_PATH_ESCAPES")
    _refused(_mjcf(tmp_path / "in3", compiler=f'<include file="{tmp_path / "elsewhere" / "inc.xml"}"/>'), "MJCF_PATH_ESCAPES")


def test_mjcf_mesh_and_include_that_are_fifos_are_refused_unread(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    os.mkfifo(folder / "pipe.obj")
    _refused(_mjcf(folder, mesh="pipe.obj"), "INPUT_NOT_REGULAR_FILE")
    folder2 = tmp_path / "in2"
    folder2.mkdir()
    os.mkfifo(folder2 / "pipe.xml")
    _refused(_mjcf(folder2, compiler='<include file="pipe.xml"/>'), "INPUT_NOT_REGULAR_FILE")


def test_mjcf_input_that_is_a_fifo_or_dev_zero_is_refused_unread(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    os.mkfifo(folder / "obj.xml")
    _refused(folder / "obj.xml", "INPUT_NOT_REGULAR_FILE")
    folder2 = tmp_path / "in2"
    folder2.mkdir()
    os.symlink("/dev/zero", folder2 / "obj.xml")
    _refused(folder2 / "obj.xml", "INPUT_NOT_REGULAR_FILE")
    folder3 = tmp_path / "in3"
    folder3.mkdir()
    os.symlink("/dev/zero", folder3 / "part.obj")  # a mesh that is a symlink out of the folder, to a device
    _refused(_mjcf(folder3, mesh="part.obj"), "MJCF_PATH_ESCAPES")


def test_mjcf_mesh_above_the_size_cap_is_refused_unread(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    with open(folder / "huge.obj", "wb") as fh:  # sparse: 65 MiB on paper, nothing on disk
        fh.truncate(65 * 1024 * 1024)
    _refused(_mjcf(folder, mesh="huge.obj"), "INPUT_TOO_LARGE")


def test_the_cli_refuses_hostile_mjcf_fast_in_a_child_process(tmp_path):
    """``asset2sim validate`` in a child process (killed after 60 s: a hang fails the test) on a FIFO input and
    a FIFO mesh: exit 1, the code printed, well within the bound."""
    folder = tmp_path / "in"
    folder.mkdir()
    os.mkfifo(folder / "pipe.obj")
    cases = {_mjcf(folder, "mesh_fifo.xml", mesh="pipe.obj"): "INPUT_NOT_REGULAR_FILE"}
    os.mkfifo(folder / "input_fifo.xml")
    cases[folder / "input_fifo.xml"] = "INPUT_NOT_REGULAR_FILE"
    for path, code in cases.items():
        t = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "asset2sim", "validate", str(path)], capture_output=True, text=True,
                              timeout=60, cwd=tmp_path)
        assert proc.returncode == 1, proc.stdout + proc.stderr
        assert code in proc.stdout
        assert time.perf_counter() - t < 30


def test_the_audit_patch_copies_no_file_from_outside(tmp_path):
    """An MJCF naming a mesh outside its folder is refused by the audit: no patch, the outside file nowhere in it."""
    from asset2sim import cli

    secret = _secret(tmp_path)
    secret.write_text(TETRA + "# secret marker 4711\n")
    path = _mjcf(tmp_path / "in", mesh="../elsewhere/secret.obj")
    with _no_hang(120):
        code = cli.main(["audit", str(path), "--out", str(tmp_path / "audit"), "--no-sim"])
    assert code == 1
    written = [p for p in (tmp_path / "audit").rglob("*") if p.is_file()]
    assert not any(b"4711" in p.read_bytes() for p in written)
    assert not any(p.suffix == ".obj" for p in written)


# ------------------------------------------------------------------------- USD


def _usda(path: Path, header: str = "", body: str = "") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"""#usda 1.0
(
    defaultPrim = "obj"
    metersPerUnit = 1
    upAxis = "Z"
    {header}
)
def Xform "obj" (prepend apiSchemas = ["PhysicsArticulationRootAPI"])
{{
    def Xform "base" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsMassAPI"])
    {{
        float physics:mass = 2
        def Cube "box" (prepend apiSchemas = ["PhysicsCollisionAPI"])
        {{
            double size = 0.3
        }}
    }}
    {body}
}}
""")
    return path


def _layer(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text('#usda 1.0\n\nover "obj"\n{\n}\n')
    return path


@pytest.fixture
def pxr():
    return pytest.importorskip("pxr")


def test_a_usd_with_sublayers_inside_its_folder_is_read(tmp_path, pxr):
    _layer(tmp_path / "in" / "layers" / "extra.usda")
    path = _usda(tmp_path / "in" / "obj.usda", "subLayers = [@./layers/extra.usda@]")
    assert not [f for f in validate_asset(path) if f.severity == "error"]


def test_usd_sublayer_outside_the_folder_is_refused(tmp_path, pxr):
    outside = _layer(tmp_path / "elsewhere" / "extra.usda")
    _refused(_usda(tmp_path / "in" / "obj.usda", f"subLayers = [@{outside}@]"), "USD_LAYER_OUTSIDE_ASSET")
    _refused(_usda(tmp_path / "in2" / "obj.usda", "subLayers = [@../elsewhere/extra.usda@]"), "USD_LAYER_OUTSIDE_ASSET")
    (tmp_path / "in3").mkdir()
    os.symlink(outside, tmp_path / "in3" / "extra.usda")
    _refused(_usda(tmp_path / "in3" / "obj.usda", "subLayers = [@./extra.usda@]"), "USD_LAYER_OUTSIDE_ASSET")


def test_usd_reference_and_payload_outside_the_folder_are_refused(tmp_path, pxr):
    outside = _layer(tmp_path / "elsewhere" / "part.usda")
    ref = f'def Xform "extra" (prepend references = @{outside}@</obj>)\n    {{\n    }}'
    _refused(_usda(tmp_path / "in" / "obj.usda", body=ref), "USD_LAYER_OUTSIDE_ASSET")
    pay = 'def Xform "extra" (prepend payload = @../elsewhere/part.usda@</obj>)\n    {\n    }'
    _refused(_usda(tmp_path / "in2" / "obj.usda", body=pay), "USD_LAYER_OUTSIDE_ASSET")


def test_usd_sublayer_fifo_and_input_fifo_are_refused_unread(tmp_path, pxr):
    folder = tmp_path / "in"
    folder.mkdir()
    os.mkfifo(folder / "pipe.usda")
    _refused(_usda(folder / "obj.usda", "subLayers = [@./pipe.usda@]"), "INPUT_NOT_REGULAR_FILE")
    folder2 = tmp_path / "in2"
    folder2.mkdir()
    os.mkfifo(folder2 / "obj.usda")
    _refused(folder2 / "obj.usda", "INPUT_NOT_REGULAR_FILE")
    folder3 = tmp_path / "in3"
    folder3.mkdir()
    os.symlink("/dev/zero", folder3 / "obj.usda")
    _refused(folder3 / "obj.usda", "INPUT_NOT_REGULAR_FILE")


def test_mjcf_include_loops_and_bombs_are_refused(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "a.xml").write_text('<mujocoinclude><include file="b.xml"/></mujocoinclude>')
    (folder / "b.xml").write_text('<mujocoinclude><include file="a.xml"/></mujocoinclude>')
    _refused(_mjcf(folder, compiler='<include file="a.xml"/>'), "MJCF_INCLUDE_INVALID")
    folder2 = tmp_path / "in2"
    folder2.mkdir()
    (folder2 / "inc.xml").write_text('<!DOCTYPE x [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">]>'
                                     "<mujocoinclude>&b;</mujocoinclude>")
    _refused(_mjcf(folder2, compiler='<include file="inc.xml"/>'), "XML_ENTITY_FORBIDDEN")


# ------------------------------------------------------------------------- --allow-outside-paths


def test_allow_outside_paths_widens_the_tree_only_where_asked(tmp_path, capsys):
    """Meshes shared beside the input (``meshdir="../shared"``, and an absolute path into it) are refused by default
    and read with ``--allow-outside-paths`` naming that folder; another folder stays refused; refine writes an
    output from them and the audit's patch copies them (the allowed files only)."""
    from asset2sim import cli

    shared = tmp_path / "shared"
    shared.mkdir()
    (shared / "lid.obj").write_text(TETRA)
    _secret(tmp_path)
    path = _mjcf(tmp_path / "in", mesh="lid.obj", compiler='<compiler meshdir="../shared"/>')
    assert cli.main(["validate", str(path)]) == 1
    assert "MJCF_PATH_ESCAPES" in capsys.readouterr().out
    assert cli.main(["validate", str(path), "--allow-outside-paths", str(shared)]) == 0
    assert cli.main(["validate", str(path), "--allow-outside-paths", str(tmp_path / "elsewhere")]) == 1
    assert "MJCF_PATH_ESCAPES" in capsys.readouterr().out
    absolute = _mjcf(tmp_path / "in2", mesh=str(shared / "lid.obj"))
    assert cli.main(["validate", str(absolute), "--allow-outside-paths", str(shared)]) == 0
    escaping = _mjcf(tmp_path / "in3", mesh="../elsewhere/secret.obj")
    assert cli.main(["validate", str(escaping), "--allow-outside-paths", str(shared)]) == 1
    assert cli.main(["validate", str(path), "--allow-outside-paths", str(tmp_path / "nosuch")]) == 2
    capsys.readouterr()
    before = tree_hashes(tmp_path / "in")
    code = cli.main(["refine", str(path), "--prompt", "a box", "--out", str(tmp_path / "out"), "--no-extras",
                     "--engines", "pybullet", "--allow-outside-paths", str(shared)])
    assert code in (0, 3), capsys.readouterr().err
    assert (tmp_path / "out" / "mobility.urdf").is_file() and tree_hashes(tmp_path / "in") == before
    code = cli.main(["audit", str(path), "--out", str(tmp_path / "audit"), "--no-sim", "--allow-outside-paths", str(shared)])
    assert code in (0, 3), capsys.readouterr().err
    copied = [p for p in (tmp_path / "audit").rglob("*.obj")]
    assert copied and all(p.read_text() == TETRA for p in copied)


def test_allow_outside_paths_for_a_usd_layer(tmp_path):
    from asset2sim.input_files import allow_outside

    pytest.importorskip("pxr")
    layer = _layer(tmp_path / "shared" / "extra.usda")
    path = _usda(tmp_path / "in" / "obj.usda", f"subLayers = [@{layer}@]")
    _refused(path, "USD_LAYER_OUTSIDE_ASSET")
    with allow_outside(tmp_path / "shared"):
        assert not [f.describe() for f in validate_asset(path) if f.severity == "error"]
    _refused(path, "USD_LAYER_OUTSIDE_ASSET")  # only inside the block
