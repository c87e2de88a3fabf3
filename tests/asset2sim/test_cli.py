"""The console script: refine and demo end to end, as a user runs them, and
the exit statuses of the top-level handler (one line, code and path; a
traceback only with --debug)."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from asset2sim import atomic, demo_assets
from asset2sim.cli import command_names, main
from asset2sim.commands.refine import wall_time_text
from asset2sim.schemas.report import FAILURE_MODES
from asset2sim.tasks.check.verdict import TIERS
from asset2sim.tasks import refine as refine_mod
from asset2sim.formats.mjcf import export as export_mjcf
from asset2sim.tasks.publish import refine_report
from asset2sim.tasks.interpret.request import MAX_REQUEST_CHARS
from tests.conftest import SHARED, needs_shared
from tests.helpers import tree_hashes


def run(*args, timeout=600):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "asset2sim", *args], capture_output=True, text=True, timeout=timeout, env=env)


@pytest.mark.slow  # end to end: the command line
def test_demo_runs_without_data(tmp_path):
    out = tmp_path / "demo"
    p = run("demo", "--out", str(out), "--no-extras")
    assert p.returncode == 0, p.stderr
    assert "interaction-ready" in p.stdout
    for stage in ("read", "geometry", "state", "checks"):
        assert stage in p.stdout
    report = json.loads((out / "report.json").read_text())
    assert report["failure_mode"] == "none"
    # the demo box is given its category's task: every tier the post-check measures passed, none n/a
    # (the probes are the evaluation's, which --no-extras skips)
    assert report["task"] == "close the box lid" and "task         close the box lid" in p.stdout
    assert all(v is True for t, v in report["readiness"].items() if t != "probes"), report["readiness"]
    for tier in ("task", "force", "robust_rest", "sweep"):
        assert tier in report["readiness"]
    assert "task PASS, force PASS" in p.stdout


@pytest.mark.slow  # end to end: the command line
@needs_shared
def test_refine_command_prints_summary_and_writes_contract(tmp_path):
    out = tmp_path / "stapler"
    p = run("refine", str(SHARED / "103275"), "--prompt", "I want a slightly open stapler.", "--out", str(out))
    # written either way; 3 when a readiness tier fails (the raw stapler's body joint cannot be driven
    # through its range: joint sweep), and then the terminal and report.json name the same mode
    assert p.returncode in (0, 3), p.stderr
    for word in ("scale", "total mass", "initial state", "penetration", "stability", "manipulation", "verdict"):
        assert word in p.stdout
    for name in ("mobility.urdf", "initial_state.json", "overlay.json", "report.json"):
        assert (out / name).is_file()
    mode = json.loads((out / "report.json").read_text())["failure_mode"]
    assert (p.returncode == 0) == (mode == "none")
    assert ("interaction-ready" if mode == "none" else f"NOT READY: {mode}") in p.stdout


@pytest.mark.slow  # end to end: the command line
@needs_shared
def test_a_request_not_met_exits_3_and_prints_the_phrase(tmp_path, capsys):
    """As asked: "its drawer open" on a stapler (no drawer) is not applied; refine exits 3 (NOT_READY), names
    ``request_not_met`` and prints the phrase; joint states are printed from their closed ends."""
    out = tmp_path / "o"
    assert main(["refine", str(SHARED / "103275"), "--prompt", "A stapler with its drawer open.", "--out", str(out),
                 "--no-extras", "-q"]) == 3
    text = capsys.readouterr().out
    assert "NOT READY: request_not_met" in text and "request FAIL" in text
    assert text.count("'drawer open': not applied") == 1, text  # said once, in "why it failed"
    assert "from closed" in text and "% open" in text
    report = json.loads((out / "report.json").read_text())
    assert report["failure_mode"] == "request_not_met" and report["readiness"]["request"] is False


def test_refine_bad_input_exits_nonzero_with_named_error(tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "mobility.urdf").write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/><child link='missing'/></joint></robot>")
    p = run("refine", str(bad), "--out", str(tmp_path / "o"))
    assert p.returncode == 1
    assert "JOINT_CHILD_UNKNOWN" in p.stderr and "invalid input" in p.stderr and "mobility.urdf" in p.stderr


# ------------------------------------------------------------------ exit statuses (in process)

PROMPT = "A small box with its lid slightly open."


@pytest.fixture()
def box(tmp_path):
    return demo_assets.build_box_with_lid(tmp_path / "in" / "box_lid")


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.startswith(("asset2sim ", "asset2sim:"))]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize(
    "where, code",
    [("input", "OUTPUT_IS_INPUT"), ("inside", "OUTPUT_INSIDE_INPUT"), ("parent", "OUTPUT_CONTAINS_INPUT"), ("file", "OUTPUT_NOT_A_FOLDER"), ("devnull", "OUTPUT_NOT_A_FOLDER")],
)
def test_output_location_problems_exit_4_with_code_and_path(box, tmp_path, capsys, where, code):
    (tmp_path / "f").write_text("x")
    out = {"input": box, "inside": box / "o", "parent": box.parent, "file": tmp_path / "f", "devnull": Path("/dev/null")}[where]
    before = tree_hashes(tmp_path)
    assert main(["refine", str(box), "--out", str(out), "--no-extras", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert line.startswith(f"asset2sim refine: {code}: ") and str(out) in line  # labelled by its own code
    assert "invalid_input" not in line
    assert tree_hashes(tmp_path) == before


def test_foreign_files_need_overwrite(box, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(out), "--no-extras", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert "OUTPUT_NOT_EMPTY" in line and "keep.txt" in line and "--overwrite" in line
    assert "overwrite=True" not in line
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(out), "--no-extras", "-q", "--overwrite"]) == 0
    assert (out / "keep.txt").read_text() == "mine" and (out / "mobility.urdf").is_file()


def test_invalid_input_exits_1_and_long_request_2(box, tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "mobility.urdf").write_text("<robot name='x'><link name='a'/><link name='b'/></robot>")
    assert main(["refine", str(bad), "--out", str(tmp_path / "o1"), "--no-extras"]) == 1
    lines = capsys.readouterr().err.splitlines()  # one line per problem: 2 orphan links, two roots, no geometry
    assert len(lines) == 4 and len(set(lines)) == 4, lines
    for line in lines:
        assert line.startswith("asset2sim refine: ") and "invalid input" in line and line.count(str(bad)) == 1, line
        code = line.split(": ")[1]
        assert code and code == code.upper() and " " not in code, line
    assert any("link 'a' is connected by no joint" in line and "link 'a': link 'a'" not in line for line in lines), lines
    assert main(["refine", str(box), "--prompt", "x" * (MAX_REQUEST_CHARS + 1), "--out", str(tmp_path / "o2"), "--no-extras"]) == 2
    assert "REQUEST_TOO_LONG" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "o2").exists()  # refused before any work


def test_written_but_not_interaction_ready_exits_3(box, tmp_path, capsys, monkeypatch):
    from asset2sim.tasks.check.verdict import Readiness

    monkeypatch.setattr(refine_report, "readiness", lambda metrics: Readiness({"rest": False}, ["rest_stability@pybullet"], "unstable"))
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 3
    assert "NOT READY: unstable" in capsys.readouterr().out
    assert (tmp_path / "o" / "mobility.urdf").is_file()


def test_unwritable_output_exits_4(box, tmp_path, capsys, monkeypatch):
    def read_only(path):
        raise OSError(errno.EROFS, "Read-only file system", str(path))

    monkeypatch.setattr(atomic, "_create_temp", read_only)
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert "OUTPUT_WRITE_FAILED [EROFS]" in line and str(tmp_path / "o") in line


@pytest.mark.parametrize("name", ["report.html", "report.json"])
def test_full_disk_while_writing_the_report_exits_4_with_enospc(name, box, tmp_path, capsys, monkeypatch):
    """A full disk met by the report writer (``report.html`` among the extras,
    ``report.json`` after the post-check) is the documented
    ``OUTPUT_WRITE_FAILED [ENOSPC]`` naming the file, not ``OUTPUT_INCOMPLETE``
    (which the missing ``report.html`` gave, the error having become a note). Without the sweep clips, which it
    does not check."""
    monkeypatch.setattr(refine_mod.media_phase.render, "render_views", lambda *a, **k: None)
    monkeypatch.setattr(export_mjcf, "export_mjcf", lambda *a, **k: None)
    real = atomic._create_temp

    def full_disk(path):
        if path.name == name:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path)

    monkeypatch.setattr(atomic, "_create_temp", full_disk)
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(tmp_path / "o"), "--no-clips", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert "OUTPUT_WRITE_FAILED [ENOSPC]" in line and name in line, line
    assert not (tmp_path / "o" / ".asset2sim-complete.json").exists()


def test_internal_error_exits_70_with_a_log_and_traceback_only_with_debug(box, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ASSET2SIM_LOG_DIR", str(tmp_path / "logs"))

    def boom(*a, **k):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(refine_mod, "refine_asset", boom)
    assert main(["refine", str(box), "--out", str(tmp_path / "o")]) == 70
    line = _one_line(capsys.readouterr().err)
    assert "INTERNAL_ERROR" in line and "ZeroDivisionError" in line
    (log,) = (tmp_path / "logs").iterdir()
    assert str(log) in line and "Traceback" in log.read_text() and "a bug" in log.read_text()
    assert main(["refine", str(box), "--out", str(tmp_path / "o"), "--debug"]) == 70
    assert "Traceback" in capsys.readouterr().err
    assert main(["--debug", "refine", str(box), "--out", str(tmp_path / "o")]) == 70
    assert "Traceback" in capsys.readouterr().err


# ------------------------------------------------------------------ one line format for every command


def _fields(line: str) -> tuple[str, str, str]:
    """(command, CODE, rest) of ``asset2sim COMMAND: CODE: PATH: message``."""
    prog, code, rest = line.split(": ", 2)
    return prog, code, rest


def test_validation_failure_names_path_once_and_codes_once(tmp_path, capsys):
    from tests import corpus_builder as cb

    asset = cb.CASES_BY_NAME["format_off_mesh"].build(tmp_path / "off")  # visual and collision: 2 errors, one code
    assert main(["refine", str(asset), "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("asset2sim ")]
    assert len(lines) == 2 and len(err.splitlines()) == 2 and "Traceback" not in err, err  # one line per problem
    for line, element in zip(lines, ("mobility.urdf:24: link 'lid': <visual>", "mobility.urdf:30: link 'lid': <collision>")):
        prog, code, rest = _fields(line)
        assert prog == "asset2sim refine" and code == "MESH_FORMAT_UNSUPPORTED"
        assert rest.startswith(f"{asset}: invalid input: {element}") and rest.count(str(asset)) == 1, line
        assert " | " not in line and "validation error(s)" not in line


def test_a_mistyped_path_gets_the_close_names_of_its_folder(tmp_path, capsys):
    """A name one or two letters off one in its folder: the error names the close ones; nothing close, nothing said."""
    for name in ("box_lid", "laptop", "cabinet_2drawer"):
        (tmp_path / name).mkdir()
    assert main(["refine", str(tmp_path / "box_lidd"), "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert line.endswith("no such file or folder; did you mean box_lid?"), line
    assert main(["validate", str(tmp_path / "zzzz")]) == 1
    assert "did you mean" not in capsys.readouterr().out


def test_a_wrong_path_is_named_once(tmp_path, capsys):
    missing = tmp_path / "no_such_asset"
    assert main(["refine", str(missing), "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert line == f"asset2sim refine: ASSET_NOT_FOUND: {missing}: invalid input: no such file or folder", line
    assert main(["validate", str(missing)]) == 1
    out = capsys.readouterr().out
    assert out.splitlines()[0].count(str(missing)) == 1, out
    for argv in (["render", str(missing), "--out", str(tmp_path / "v")], ["evaluate", str(missing)], ["audit", str(missing)],
                 ["export", str(missing)]):
        assert main(argv) in (1, 2), argv
        line = _one_line(capsys.readouterr().err)
        assert line.count(str(missing)) == 1, line


# ------------------------------------------------------------------ usage errors as in well-kept command lines


@pytest.mark.parametrize("argv, prog, bad, meant", [
    (["refine", "{box}", "--promt", "a box", "--out", "{out}"], "asset2sim refine", "--promt", "--prompt"),
    (["refine", "{box}", "--outt", "{out}"], "asset2sim refine", "--outt", "--out"),  # not "--out is required"
    (["--verbsoe", "refine", "{box}", "--out", "{out}"], "asset2sim", "--verbsoe", "--verbose"),
    (["evaluate", "{box}", "--engins", "pybullet"], "asset2sim evaluate", "--engins", "--engines"),
])
def test_a_mistyped_option_is_named_with_the_closest_one(box, tmp_path, capsys, argv, prog, bad, meant):
    argv = [a.format(box=box, out=tmp_path / "o") for a in argv]
    assert main(argv) == 2
    cap = capsys.readouterr()
    line = _one_line(cap.err)
    assert len(cap.err.splitlines()) == 1 and not cap.out, cap.err  # one line, no usage block
    assert line.startswith(f"{prog}: OPTION_UNKNOWN: unknown option {bad}; did you mean {meant}?"), line
    assert "required" not in line
    assert not (tmp_path / "o").exists()


def test_a_mistyped_command_is_named_with_the_closest_one(capsys):
    assert main(["refyne", "x"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("asset2sim: COMMAND_UNKNOWN: unknown command 'refyne'; did you mean refine?"), line
    assert main(["zzzz"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "did you mean" not in line and "refine" in line  # nothing close: the commands are listed


def test_other_usage_errors_are_one_line_and_abbreviations_still_work(box, tmp_path, capsys):
    assert main(["refine", str(box)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("asset2sim refine: USAGE_INVALID: ") and "--out" in line
    assert main(["refine", str(box), "--promp", PROMPT, "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 0  # a prefix


def test_help_lists_every_exit_status(capsys):
    from asset2sim.commands import _status

    assert main(["--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    statuses = {v for k, v in vars(_status).items() if k.isupper() and isinstance(v, int) and not isinstance(v, bool)}
    assert {1, 2, 3, 4, 5, 70, 130} <= statuses
    for status in statuses | {0}:
        assert f"{status} {_status.EXIT_STATUSES[status]}" in text, (status, text)


@pytest.mark.parametrize("name", command_names())
def test_each_command_help_lists_its_exit_statuses(name, capsys):
    """``asset2sim COMMAND --help`` ends with the command's own exit statuses and those every command shares (a
    usage error, an internal error, 130 interrupted), as ``asset2sim --help`` lists them all."""
    import importlib

    module = importlib.import_module(f"asset2sim.commands.{name}")
    assert main([name, "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    text = text.replace("- ", "-")  # argparse wraps after a hyphen
    assert "exit statuses: " in text and "130 interrupted" in text and "70 internal error" in text, text
    assert module.EXITS and 0 in module.EXITS
    for status, meaning in module.EXITS.items():
        assert f"{status} {' '.join(meaning.split())}" in text, (status, text)


def test_failures_outside_the_project_is_one_prefixed_line(tmp_path):
    p = subprocess.run([sys.executable, "-m", "asset2sim", "failures"], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                       env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2])))
    assert p.returncode == 2 and not p.stdout, (p.stdout, p.stderr)
    assert p.stderr.splitlines() == [p.stderr.strip()] and p.stderr.startswith("asset2sim failures: CATALOG_NOT_FOUND: catalog.yaml: ")
    assert "--catalog" in p.stderr and "Errno" not in p.stderr


def test_a_size_without_a_unit_suggests_plausible_units(box, tmp_path, capsys):
    assert main(["refine", str(box), "--size", "30", "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "OVERRIDE_INVALID" in line and "30cm (0.3 m)" in line and "30m " not in line and "30m)" not in line, line
    assert "size: size:" not in line


def test_a_missing_part_is_said_once_per_summary(tmp_path, capsys):
    """A laptop asked for its drawer open (it has none): the summary says so once (why it failed), not again as NOT AS
    ASKED, a request line and a request warning."""
    laptop = demo_assets.build_object("laptop", tmp_path / "in" / "laptop")
    out = tmp_path / "o"
    assert main(["refine", str(laptop), "--prompt", "A laptop with its screen open 100 degrees and its drawer open.",
                 "--out", str(out), "--no-extras", "--engines", "pybullet", "-q"]) == 3
    captured = capsys.readouterr()
    lines = captured.out.splitlines()
    said = [ln for ln in lines if "the request names a 'drawer'" in ln]
    assert len(said) == 1 and said[0].startswith("why it failed request_not_met"), lines
    assert not any(ln.startswith("NOT AS ASKED") for ln in lines)
    assert lines[-1].startswith("report       ") and "asset2sim report" in lines[-1]  # --no-extras: how to make it


@pytest.mark.parametrize("given, code, says", [
    (["--estimator", "ofline"], "ESTIMATOR_UNAVAILABLE", "--estimator ofline: no such estimator; did you mean offline? (known: "),
    (["--material", "unobtainium"], "OVERRIDE_UNKNOWN_MATERIAL", "--material 'unobtainium': not a known material ("),
    (["--state", "wing=30deg"], "OVERRIDE_UNKNOWN_JOINT", "--state wing=30deg: the asset has no movable joint or part named 'wing'"),
    (["--mass", "30"], "OVERRIDE_INVALID", "unit missing in '30'"),
])
def test_an_option_error_is_one_sentence_naming_the_option(box, tmp_path, capsys, given, code, says):
    """An option's error is one line and one sentence: the option as given, what is wrong, what would do; no Python
    list or nested quotes (``"unknown estimator 'ofline'; known: ['llm', ...]"``) and no temporary path."""
    assert main(["refine", str(box), "--out", str(tmp_path / "o"), *given, "-q", "--no-extras"]) == 2
    line = _one_line(capsys.readouterr().err)
    prog, got, rest = _fields(line)
    assert got == code and says in rest, line
    assert "['" not in line and '"' not in line and "asset2sim-staged" not in line and str(box) not in line, line
    assert not (tmp_path / "o").exists()


def test_estimator_and_engine_errors_have_codes(box, tmp_path, capsys):
    assert main(["refine", str(box), "--out", str(tmp_path / "o"), "--estimator", "bogus", "-q"]) == 2
    assert _fields(_one_line(capsys.readouterr().err))[1] == "ESTIMATOR_UNAVAILABLE"
    assert main(["refine", str(box), "--out", str(tmp_path / "o"), "--engines", "pybullet,foo", "-q"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert _fields(line)[1] == "ENGINE_UNKNOWN" and "foo" in line and "mujoco" in line and "physx" in line
    assert not (tmp_path / "o").exists()
    from asset2sim.commands._status import parse_engines

    assert parse_engines("pybullet, physx,mujoco,physx") == ["pybullet", "physx", "mujoco"]  # known: kept (skipped later if absent)


def test_proc_self_output_exits_4(box, capsys):
    assert main(["refine", str(box), "--out", "/proc/self/x", "--no-extras", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert _fields(line)[1].startswith("OUTPUT_WRITE_FAILED")


def test_output_file_that_is_a_folder_is_named_not_its_temp_file(box, tmp_path, capsys):
    out = tmp_path / "out"
    (out / "mobility.urdf").mkdir(parents=True)
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(out), "--no-extras", "-q", "--overwrite"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert "OUTPUT_WRITE_FAILED [EISDIR]" in line and str(out / "mobility.urdf") in line and ".tmp" not in line


def test_fifo_marker_exits_4_without_hanging(box, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / ".asset2sim-complete.json")
    p = run("refine", str(box), "--prompt", PROMPT, "--out", str(out), "--no-extras", "-q", timeout=120)
    assert p.returncode == 4, p.stderr
    assert "OUTPUT_RECORD_NOT_A_FILE" in p.stderr and "Traceback" not in p.stderr


def test_quiet_still_prints_warnings(box, tmp_path, capsys):
    assert main(["refine", str(box), "--prompt", "Ich möchte eine leicht geöffnete Kiste.", "--out", str(tmp_path / "o"),
                 "--no-extras", "-q"]) == 0
    cap = capsys.readouterr()
    assert "request not understood" in cap.err
    assert "] extract" not in cap.out  # progress stays quiet


def test_other_commands_use_the_one_line_format(box, tmp_path, capsys):
    cases = [
        (["render", str(box), "--out", "/dev/null"], 4, "OUTPUT_NOT_A_FOLDER"),
        (["render", str(box), "--views", "front,side", "--out", str(tmp_path / "v")], 2, "VIEW_UNKNOWN"),
        (["evaluate", str(tmp_path / "missing")], 2, "EVALUATION_INPUT_INVALID"),
        (["evaluate", str(box), "--engines", "foo"], 2, "ENGINE_UNKNOWN"),
        (["export", str(tmp_path / "missing")], 2, "NOT_AN_OUTPUT_FOLDER"),
        (["validate", str(box), "--error", "NO_SUCH_CODE"], 2, "CODE_UNKNOWN"),
    ]
    for argv, status, code in cases:
        assert main(argv) == status, argv
        cap = capsys.readouterr()
        line = _one_line(cap.err)
        assert line.startswith(f"asset2sim {argv[0]}: {code}: "), line
        assert "error:" not in cap.out


# ------------------------------------------------------------------ only the command given is imported


def test_requested_command_is_found_before_any_option():
    from asset2sim.cli import command_names, requested_command

    assert {"refine", "flow", "benchmark", "evaluate"} <= set(command_names())
    assert requested_command(["refine", "x", "--out", "y"]) == "refine"
    assert requested_command(["--debug", "render", "x"]) == "render"
    assert requested_command(["--help"]) is None and requested_command([]) is None
    assert requested_command(["refyne", "x"]) is None  # unknown: every command is listed in the usage error


@pytest.mark.slow  # end to end: every command's import, in child processes
def test_a_command_imports_only_its_own_module():
    code = ("import sys; from asset2sim.cli import build_parser; p = build_parser(only='refine'); "
            "print(sorted(m for m in sys.modules if m.startswith('asset2sim.commands.') and not m.split('.')[-1].startswith('_'))); "
            "print(sorted(m for m in ('prefect', 'dask', 'mlflow', 'litellm', 'matplotlib', 'sapien', 'mujoco', 'pxr', 'pandas') if m in sys.modules))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    commands_line, heavy_line = p.stdout.strip().splitlines()
    assert commands_line == "['asset2sim.commands.refine']"
    assert heavy_line == "[]", heavy_line  # refine's imports stay light until a stage needs a simulator or exporter
    full = run("--help")
    assert full.returncode == 0 and all(c in full.stdout for c in ("refine", "flow", "benchmark", "failures"))
    bad = run("refyne")
    assert bad.returncode == 2 and "COMMAND_UNKNOWN" in bad.stderr and "did you mean refine?" in bad.stderr


def test_fast_exit_runs_the_exit_handlers_flushes_and_keeps_the_code(tmp_path):
    """fast_exit skips only the interpreter's teardown: an atexit handler
    still runs, buffered Python and C output still reaches the pipe, and the
    exit status is the command's."""
    marker = tmp_path / "atexit_ran"
    code = (
        "import atexit, ctypes, sys\n"
        f"atexit.register(lambda: open({str(marker)!r}, 'w').write('ok'))\n"
        "sys.stdout.write('python buffered')\n"
        "ctypes.CDLL(None).printf(b' c buffered')\n"
        "from asset2sim.cli import fast_exit\n"
        "fast_exit(3)\n"
        "print('never')\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 3, p.stderr
    assert marker.read_text() == "ok"
    assert "python buffered" in p.stdout and "c buffered" in p.stdout and "never" not in p.stdout


def test_a_thread_the_interpreter_waits_for_falls_back_to_a_normal_exit(tmp_path):
    """A non-daemon thread still running: fast_exit leaves the exit to
    sys.exit, which waits for the thread (its output is not lost)."""
    code = (
        "import threading, time, sys\n"
        "def late():\n"
        "    time.sleep(0.3); print('thread finished', flush=True)\n"
        "threading.Thread(target=late).start()\n"
        "from asset2sim.cli import fast_exit\n"
        "fast_exit(4)\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 4 and "thread finished" in p.stdout


def test_open_containers_is_a_refine_option_off_by_default_and_part_of_the_configuration_hash(tmp_path):
    """``--open-containers`` (``open_containers: true`` in a ``--config`` file) turns the option on; off, the
    configuration hash is the one of every configuration before the option existed."""
    from asset2sim.cli import build_parser
    from asset2sim.commands.refine import options
    from asset2sim.schemas.config import RefineConfig

    parser = build_parser("refine")
    plain = options(parser.parse_args(["refine", "in", "--prompt", "a bucket", "--out", "o"]))
    opened = options(parser.parse_args(["refine", "in", "--prompt", "a bucket", "--out", "o", "--open-containers"]))
    assert plain.open_containers is False and opened.open_containers is True
    assert RefineConfig(open_containers=False).config_hash() == RefineConfig().config_hash() != opened.config_hash()
    cfg = tmp_path / "refine.yaml"
    cfg.write_text("open_containers: true\n")
    assert options(parser.parse_args(["refine", "in", "--prompt", "a bucket", "--out", "o", "--config", str(cfg)])).open_containers


def test_body_and_mjcf_angle_are_refine_options_and_config_fields_outside_the_default_hash(tmp_path):
    """``--body`` and ``--mjcf-angle`` (``body:`` and ``mjcf: {angle: ...}`` in a ``--config`` file) set how an MJCF
    input is read; unset, the configuration hash is the one of every configuration before the options existed."""
    from asset2sim.cli import build_parser
    from asset2sim.commands.refine import options
    from asset2sim.schemas.config import RefineConfig

    parser = build_parser("refine")
    base = ["refine", "in.xml", "--prompt", "a drawer", "--out", "o"]
    plain = options(parser.parse_args(base))
    asked = options(parser.parse_args([*base, "--body", "drawer_link", "--mjcf-angle", "radian"]))
    assert (plain.body, plain.mjcf.angle) == (None, None)
    assert (asked.body, asked.mjcf.angle) == ("drawer_link", "radian")
    assert RefineConfig(body=None, mjcf={"angle": None}).config_hash() == RefineConfig().config_hash() != asked.config_hash()
    cfg = tmp_path / "refine.yaml"
    cfg.write_text("body: box\nmjcf:\n  angle: degree\n")
    from_file = options(parser.parse_args([*base, "--config", str(cfg)]))
    assert (from_file.body, from_file.mjcf.angle) == ("box", "degree")
    with pytest.raises(SystemExit):
        parser.parse_args([*base, "--mjcf-angle", "grad"])


# ------------------------------------------------------------------ one explanation per failure: penetration


def test_a_child_inside_its_parent_is_explained_once_in_the_terminal_and_the_report(tmp_path, capsys):
    """A lid clear of a bar of its body as modelled, asked open 0.5 rad: it lies inside the bar (parent-child
    penetration, which the self-contact Phi skips). The terminal's penetration line names both kinds, the verdict is
    unresolved_penetration with one "why it failed" line (the links, the depth against 5 mm, what to do), and
    report.html says the same, with no line saying there is no penetration."""
    import html
    import re

    from tests.tasks.assemble.test_collision_geometry import _asset, _box

    slab, bar = _box([0, 0, 0], [0.1, 0.1, 0.01]), _box([0.0, 0.0, 0.07], [0.1, 0.06, 0.09])
    asset = _asset(tmp_path / "barred", [slab, bar], [_box([0.02, 0.02, 0.02], [0.08, 0.08, 0.05])])
    out = tmp_path / "o"
    assert main(["refine", str(asset), "--state", "hinge=0.5rad", "--out", str(out), "--no-clips", "--engines", "pybullet,physx",
                 "-q"]) == 3
    lines = capsys.readouterr().out.splitlines()
    assert "verdict      NOT READY: unresolved_penetration" in "\n".join(lines)
    pen = [ln for ln in lines if ln.startswith("penetration  ")]
    assert len(pen) == 1 and "self-contact 0.000 mm (pybullet) pass" in pen[0], pen
    assert re.search(r"parent-child \d+\.\d+ mm \(pybullet, body/lid; \d+\.\d+ mm beyond its modelled pose\) FAIL", pen[0]), pen
    why = [ln.removeprefix("why it failed ") for ln in lines if ln.startswith("why it failed ")]
    assert len(why) == 1, lines
    assert re.match(r"unresolved_penetration \(penetration tier\): parent-child penetration \(pybullet\): link 'lid' is \d+\.\d mm inside its parent 'body' .*"
                    r"\(fails above 5 mm\)\. Ask for a state .*--state", why[0]), why
    report = json.loads((out / "report.json").read_text())
    assert report["failure_mode"] == "unresolved_penetration"
    text = html.unescape((out / "report.html").read_text())
    assert "<h2>Why it failed</h2>" in text and f"<li>{why[0]}</li>" in text  # the terminal's sentence, word for word
    assert "no self-penetration at the initial state" not in text
    assert "A child inside its parent (pybullet; " in text and "penetration tier: <b>FAIL</b>" in text
    engine = [ln for ln in lines if ln.startswith("engine pybullet")]
    assert engine and "failing here: parent_child_penetration" in engine[0] and " ok" not in engine[0], engine
    # the evidence: the lid and its body drawn in colour at the initial state and as modelled, as robust rest's trials are
    assert "<h3>penetration (parent-child, pybullet): 'lid' inside its parent 'body'" in text
    for caption in ("at the initial state, perspective", "at the initial state, front", "as modelled, perspective"):
        assert f"<figcaption class='small'>{caption}</figcaption>" in text, caption
    assert "SPEC" not in text


@pytest.mark.slow  # end to end: the command line, twice per input
@pytest.mark.parametrize("kind", ["mjcf", "urdf"])
def test_two_refines_of_one_input_into_two_folders_are_the_same_bytes(tmp_path, kind):
    """robosuite's door (MJCF, staged in a new temporary folder per process) and a demo laptop (URDF) refined by two
    processes into two folders at different depths: every file but timings.json holds the same bytes, and none names
    its output folder, the other one or a temporary staging folder (a moved output names no place it is not)."""
    from tests.tasks.ingest.host_layouts import robosuite_door

    if kind == "mjcf":
        pytest.importorskip("mujoco")
        src = robosuite_door(tmp_path / "in" / "robosuite" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
        prompt = "A door, slightly open."
    else:
        src = demo_assets.build_object("laptop", tmp_path / "in" / "laptop")
        prompt = "A laptop with its screen open 100 degrees."
    outs = [tmp_path / "a", tmp_path / "deeper" / "b"]
    for out in outs:
        p = run("refine", str(src), "--prompt", prompt, "--out", str(out), "--engines", "pybullet", "-q")
        assert p.returncode in (0, 3), p.stderr
    files = sorted(str(f.relative_to(outs[0])) for f in outs[0].rglob("*") if f.is_file())
    assert files == sorted(str(f.relative_to(outs[1])) for f in outs[1].rglob("*") if f.is_file())
    differ = [f for f in files if (outs[0] / f).read_bytes() != (outs[1] / f).read_bytes()]
    assert differ == ["timings.json"], differ
    for f in files:
        data = (outs[1] / f).read_bytes()
        for place in (str(outs[0]).encode(), str(outs[1]).encode(), b"asset2sim-staged", b"asset2sim-input-"):
            assert place not in data, (f, place)
        if f.endswith((".json", ".html", ".txt", ".urdf", ".xml", ".diff")):  # words a user reads: no "SPEC"
            assert b"SPEC" not in data, f


def test_refine_json_prints_one_object_for_scripts(box, tmp_path, capsys):
    """``refine --json``: stdout is one JSON object (the output folder, the verdict and each tier, the report), no
    progress lines and no summary."""
    code = main(["refine", str(box), "--prompt", PROMPT, "--out", str(tmp_path / "o"), "--no-extras", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == (0 if out["ready"] else 3) and out["out_dir"] == str(tmp_path / "o")
    assert out["failure_mode"] in FAILURE_MODES and set(out["readiness"]) == set(TIERS)
    assert Path(out["report"]).is_file() and json.loads(Path(out["report"]).read_text())["failure_mode"] == out["failure_mode"]


def test_the_wall_time_line_names_stages_as_the_progress_lines_do():
    """``shut_repair`` and ``sweep_repair`` are the progress lines' ``repair``, said once with their summed time."""
    text = wall_time_text({"extract": 0.1, "shut_repair": 1.0, "refine_state": 2.0, "sweep_repair": 0.5})
    assert text == "read 0.10s, repair 1.50s, state 2.00s" and "_" not in text
@pytest.mark.parametrize("argv, code", [
    (["render", "{box}", "--out", "{box}"], "OUTPUT_IS_INPUT"),
    (["render", "{box}/mobility.urdf", "--out", "{box}/views"], "OUTPUT_INSIDE_INPUT"),
    (["evaluate", "{box}", "--out", "{box}"], "OUTPUT_IS_INPUT"),
    (["evaluate", "{box}", "--out", "{box}/eval"], "OUTPUT_INSIDE_INPUT"),
])
def test_render_and_evaluate_refuse_the_input_folder_as_out(box, argv, code, capsys):
    """As refine and audit do: status 4, one line, nothing written into the input."""
    before = tree_hashes(box)
    assert main([a.format(box=box) for a in argv]) == 4
    line = _one_line(capsys.readouterr().err)
    assert line.startswith(f"asset2sim {argv[0]}: {code}: "), line
    assert tree_hashes(box) == before
