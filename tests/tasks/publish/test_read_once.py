"""Every input read once, through the reader policy: an MJCF input (a model file, an include, a mesh) is read when the
refine begins; its files are then swapped for FIFOs (a writer that never comes) and an include naming
``/etc/passwd``, mid-run (at the refine's first stage message). The host write-back (``mjcf/host/``, its diff and
the package's file), compiled by MuJoCo from a private copy of the bytes read, is written from those bytes, and
nothing opens the swapped paths (a FIFO opened for reading would block: the alarm ends a regression). The audit's
MJCF patch takes its meshes from the same bytes."""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

import pytest

from tests.helpers import no_hang

mujoco = pytest.importorskip("mujoco")

from asset2sim.formats.mjcf.files import MjcfSources, gather_mjcf, staged_sources  # noqa: E402
from asset2sim.tasks.refine import refine_asset  # noqa: E402

MAIN = textwrap.dedent("""\
    <mujoco model="chest">
      <compiler angle="radian"/>
      <asset><mesh name="lid_mesh" file="lid.obj"/></asset>
      <worldbody>
        <body name="base" pos="0 0 0.1">
          <freejoint/>
          <geom type="box" size="0.2 0.15 0.1" mass="2"/>
          <include file="lid.xml"/>
        </body>
      </worldbody>
    </mujoco>
    """)
LID = textwrap.dedent("""\
    <mujoco>
      <body name="lid" pos="-0.2 0 0.1">
        <joint name="hinge" type="hinge" axis="0 1 0" range="-1.5 0"/>
        <geom type="mesh" mesh="lid_mesh" mass="0.3"/>
      </body>
    </mujoco>
    """)


def _lid_obj() -> str:
    v = [(x, y, z) for x in (0.0, 0.4) for y in (-0.15, 0.15) for z in (0.0, 0.02)]
    faces = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    return "".join(f"v {x} {y} {z}\n" for x, y, z in v) + "".join("f " + " ".join(map(str, f)) + "\n" for f in faces)


@pytest.fixture()
def chest(tmp_path) -> Path:
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "chest.xml").write_text(MAIN)
    (folder / "lid.xml").write_text(LID)
    (folder / "lid.obj").write_text(_lid_obj())
    return folder / "chest.xml"


def _swap(folder: Path) -> None:
    """Every file of the input a FIFO; the include now names a file outside."""
    for name in ("chest.xml", "lid.obj"):
        (folder / name).unlink()
        os.mkfifo(folder / name)
    (folder / "lid.xml").write_text(LID.replace('mesh="lid_mesh"', 'mesh="lid_mesh"/><include file="/etc/passwd"'))


def test_the_host_write_back_compiles_from_the_bytes_read_before(chest, tmp_path):
    swapped: list[str] = []

    def progress(stage: str, message: str) -> None:
        if not swapped:  # the first message comes after the input was read and staged
            _swap(chest.parent)
            swapped.append(stage)

    out = tmp_path / "out"
    with no_hang(60):
        result = refine_asset(chest, "a chest with its lid closed", out, extras=False, progress=progress)
    assert swapped
    host = out / "mjcf" / "host"
    assert (host / "chest.xml").is_file() and (host / "chest.diff").is_file(), result.report.notes
    assert any(n.startswith("host MJCF: mjcf/host/chest.xml") for n in result.report.notes)
    written = (host / "chest.xml").read_text()
    assert "passwd" not in written and "/etc" not in (host / "chest.diff").read_text()
    assert (host / "files" / "lid.xml").is_file()  # the package's own file, from the bytes read
    assert "passwd" not in (host / "files" / "lid.xml").read_text()


def test_staged_sources_come_back_from_the_snapshot_alone(chest):
    """A stage in another process (the flow's refine after its prepare) finds the bytes in the staged folder's
    snapshot, each checked against its SHA-256; a changed copy is not used."""
    from asset2sim.tasks.ingest import extract
    from asset2sim.formats import staging

    asset, _ = extract.extract_asset_checked(chest)
    snap = asset.urdf_path.parent / staging.SOURCE_DIR
    sources, extra = MjcfSources.from_snapshot(snap)
    assert sources.files == gather_mjcf(chest).files and extra["angle"] == "radian"
    assert staged_sources(asset.urdf_path)[0].files == sources.files
    (snap / "files" / "0").write_bytes(b"changed")
    with pytest.raises(ValueError, match="changed"):
        MjcfSources.from_snapshot(snap)


def test_the_input_hash_comes_from_the_bytes_read_and_equals_a_fresh_hash(chest):
    """The input hash of an MJCF input is made from the bytes the reader kept (no second read), and is the hash the
    files give when hashed afresh (catalog rows and completed outputs stay valid)."""
    from asset2sim.atomic import sha256_files
    from asset2sim.tasks.ingest import extract

    asset, _ = extract.extract_asset_checked(chest)
    files = [*staged_read_files(asset)]
    folder = asset.urdf_path.parent
    assert asset.input_hash == sha256_files(files, named=lambda p: f"<staged>/{p.relative_to(folder).as_posix()}"
                                            if p.is_relative_to(folder) else str(p))


def staged_read_files(asset) -> list[Path]:
    """The files the refine hashed: the input's (as read) and the staged URDF and meshes made of them."""
    from asset2sim.formats import staging

    read = staging.read_of(asset.urdf_path)
    staged_files = [asset.urdf_path, *sorted((asset.urdf_path.parent / staging.MESH_DIR).glob("*.obj"))]
    return [*read.files, *staged_files]
