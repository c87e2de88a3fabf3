"""An output is verified before it is opened (``contract.verify_output``): ``asset2sim report OUT`` on a damaged
output (a mesh replaced by a FIFO or by a symlink to ``/dev/zero``, a marker entry naming a file outside, a file
changed since, NaN in ``report.json``) ends at once with ``OUTPUT_INCOMPLETE`` (exit 4) before any engine or
renderer touches a file, and leaves ``report.json`` and the marker as they were; a media phase that fails part way
leaves them agreeing. Each case works on a copy of the session's refine of a generated box, media deferred; an
alarm bounds every call (a FIFO opened for reading would block)."""

from __future__ import annotations

import json
import os
import signal
from contextlib import contextmanager
from pathlib import Path

import pytest

from asset2sim import cli
from asset2sim.output_folder import MARKER_NAME, REPORT_NAME
from asset2sim.output_paths import OutputError
from asset2sim.tasks.publish.contract import is_complete, verify_output
from asset2sim.tasks.publish.media import make_media
from tests.helpers import tree_hashes

PROMPT = "a small box with its lid closed"


@contextmanager
def _deadline(seconds: int):
    def fail(*_):
        raise TimeoutError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, fail)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture()
def out(refine_once, tmp_path) -> Path:
    return refine_once("box_lid", PROMPT, extras=True, media=False).copy_to(tmp_path / "out")


def _mesh(out: Path) -> str:
    marker = json.loads((out / MARKER_NAME).read_text())
    return next(rel for rel in marker["files"] if rel.endswith(".obj"))


def _damage_fifo(out: Path, tmp_path: Path) -> str:
    rel = _mesh(out)
    (out / rel).unlink()
    os.mkfifo(out / rel)
    return rel


def _damage_dev_zero(out: Path, tmp_path: Path) -> str:
    rel = _mesh(out)
    (out / rel).unlink()
    (out / rel).symlink_to("/dev/zero")
    return rel


def _damage_marker_outside(out: Path, tmp_path: Path) -> str:
    (tmp_path / "outside").mkdir()
    os.mkfifo(tmp_path / "outside" / "victim.txt")  # opened, it would block
    marker = json.loads((out / MARKER_NAME).read_text())
    marker["files"]["../outside/victim.txt"] = "0" * 64
    (out / MARKER_NAME).write_text(json.dumps(marker))
    return "../outside/victim.txt"


def _damage_changed(out: Path, tmp_path: Path) -> str:
    rel = _mesh(out)
    with open(out / rel, "a") as fh:
        fh.write("v 9 9 9\n")
    return rel


@pytest.mark.parametrize("damage", [_damage_fifo, _damage_dev_zero, _damage_marker_outside, _damage_changed],
                         ids=["fifo", "dev_zero", "marker_outside", "changed"])
def test_report_refuses_a_damaged_output_before_opening_it(out, tmp_path, capsys, damage):
    rel = damage(out, tmp_path)
    before = {p: (out / p).read_bytes() for p in (REPORT_NAME, MARKER_NAME)}
    with _deadline(20):
        with pytest.raises(OutputError) as info:
            verify_output(out)
        assert info.value.code == "OUTPUT_INCOMPLETE" and rel in str(info.value)
        assert not is_complete(out, "x", "y")
        rc = cli.main(["report", str(out)])
    err = capsys.readouterr().err
    assert rc == 4 and "OUTPUT_INCOMPLETE" in err and rel in err, err
    assert {p: (out / p).read_bytes() for p in before} == before
    assert not (out / "views").exists() and not (out / "report.html").exists()


def test_report_names_a_non_finite_number_in_report_json(out, capsys):
    data = json.loads((out / REPORT_NAME).read_text())
    data["metrics"][0]["value"] = float("nan")
    (out / REPORT_NAME).write_text(json.dumps(data))  # NaN, as Python writes it
    marker = json.loads((out / MARKER_NAME).read_text())
    marker["files"][REPORT_NAME] = __import__("hashlib").sha256((out / REPORT_NAME).read_bytes()).hexdigest()
    (out / MARKER_NAME).write_text(json.dumps(marker))  # a marker that vouches for it
    rc = cli.main(["report", str(out)])
    err = capsys.readouterr().err
    assert rc == 4 and "OUTPUT_INCOMPLETE" in err and "$.metrics[0].value" in err, err


def test_a_media_phase_failing_part_way_leaves_report_and_marker_agreeing(out, tmp_path):
    """The clips' folder a symlink out: the renders are made, then the clips' write is refused; ``report.json`` is
    as it was and the folder verifies against its marker."""
    (tmp_path / "elsewhere").mkdir()
    (out / "clips").symlink_to(tmp_path / "elsewhere")
    report = (out / REPORT_NAME).read_bytes()
    with pytest.raises(OutputError) as info:
        make_media(out)
    assert info.value.code == "OUTPUT_SYMLINK_ESCAPES"
    assert (out / REPORT_NAME).read_bytes() == report and json.loads(report)["media"] == "deferred"
    verify_output(out)
    assert tree_hashes(tmp_path / "elsewhere") == {}
