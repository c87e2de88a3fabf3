"""Every command through the same hostile outputs: a folder it writes into that is a symlink to a folder outside, and a
file it writes that is a hard link of a file outside. Whatever the command, nothing outside changes, and a refusal of
the output guard (``OutputError``: a symlink leading out, a hard link written in place, a folder holding files
asset2sim did not write) is exit status 4 with one line naming its code, never an internal error (status 70). The
table of failures that makes it so: ``asset2sim/commands/_status.py`` ``ERRORS``."""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path

import pytest

from asset2sim import cli, demo_assets
from tests.helpers import tree_hashes

PROMPT = "a small box with its lid closed"
SLOW = pytest.mark.slow  # end to end: the command simulates, renders or starts a flow


def _asset(tmp: Path) -> Path:
    return demo_assets.build_box_with_lid(tmp / "in" / "box_lid")


def _refined(tmp: Path, refine_once) -> Path:
    return refine_once("box_lid", PROMPT, extras=False).copy_to(tmp / "out")


def _pair_set(tmp: Path) -> Path:
    from tests.realism_fixtures import write_pair_set

    write_pair_set(tmp / "pairs", 2)
    return tmp / "pairs"


# command -> (argv, where the symlinked folder or file goes, where the hard link goes), built in tmp
def _audit(tmp, _):
    box = _asset(tmp)
    return ["audit", str(box), "--out", str(tmp / "out"), "--no-sim"], tmp / "out" / "box_lid", tmp / "out" / "audit_assets.parquet"


def _rate(tmp, _):
    folder = _pair_set(tmp)
    return ["rate", str(folder), "--scores"], folder / "ratings.sqlite", folder / "ratings.sqlite"


def _render(tmp, _):
    return ["render", str(_asset(tmp)), "--out", str(tmp / "out"), "--views", "front"], tmp / "out" / "front.png", tmp / "out" / "front.png"


def _refine(tmp, _):
    out = tmp / "out"
    return ["refine", str(_asset(tmp)), "-p", PROMPT, "--out", str(out), "--no-extras", "-q"], out / "textured_objs", out / "mobility.urdf"


def _demo(tmp, _):
    d = tmp / "asset"
    return ["demo", "--asset-out", str(d), "--no-refine"], d / "textured_objs", d / "mobility.urdf"


def _report(tmp, refine_once):
    out = _refined(tmp, refine_once)
    return ["report", str(out), "--force", "--no-clips"], out / "views", out / "report.html"


def _export(tmp, refine_once):
    out = _refined(tmp, refine_once)
    return ["export", str(out)], out / "mjcf", out / "mjcf" / "mobility.xml"


def _evaluate(tmp, _):
    out = tmp / "out"
    return (["evaluate", str(_asset(tmp)), "--out", str(out), "--no-probes", "--no-clips"], out / "views",
            out / "evaluation.json")


def _benchmark(tmp, _):
    _asset(tmp)
    (tmp / "in" / "manifest.csv").write_text(f"id,category,prompt,reference_scale\nbox_lid,Box,{PROMPT},0.5\n")
    out = tmp / "bench"
    return (["benchmark", str(tmp / "in" / "manifest.csv"), "--methods", "defaults", "--out", str(out), "--no-reports"],
            out / "defaults", out / "results.csv")


def _pairs(tmp, refine_once):
    out = _refined(tmp, refine_once)
    return ["pairs", str(out), "--out", str(tmp / "pairs"), "--defects", "mass_x100"], tmp / "pairs" / "clips", tmp / "pairs" / "pairs.json"


def _judge(tmp, _):
    from tests import fake_openai_server as fake
    from tests import realism_judge_fixtures as fx

    folder = tmp / "pairs"
    ps = fx.write_judge_pair_set(folder, n_defect=2, n_plain=0)
    server = fake.FakeOpenAIServer(fx.good_judge(fx.broken_digests(folder, ps)), lifetime_s=120)
    os.environ["ASSET2SIM_LLM_CACHE_DIR"] = "off"
    return (["judge", str(folder), "--model", "openai/judge", "--base-url", server.url], folder / "judgements.parquet",
            folder / "judgements.parquet", server)


def _flow(tmp, _):
    from tests.flows.flowproject import make_project

    catalog = make_project(tmp / "proj", {"box_lid": "box_lid"}, catalog_extra={
        "run": {"workers": 1, "evaluate": False, "dashboard": False}, "tracking": {"enabled": False}})
    return (["flow", "--catalog", str(catalog), "--workers", "1", "--no-progress"], tmp / "proj" / "refined" / "gen",
            tmp / "proj" / "raw" / "box_lid" / "mobility.urdf")


COMMANDS = {"audit": _audit, "rate": _rate, "render": _render, "refine": _refine, "demo": _demo, "report": _report,
            "export": _export, "evaluate": _evaluate, "benchmark": _benchmark, "pairs": _pairs, "judge": _judge, "flow": _flow}
HEAVY = {"report", "export", "evaluate", "benchmark", "pairs", "judge", "flow"}


def _link(kind: str, where: Path, outside: Path) -> None:
    where.parent.mkdir(parents=True, exist_ok=True)
    if kind == "symlink":
        os.symlink(outside / ("secret.txt" if where.suffix else ""), where) if where.suffix else os.symlink(outside, where)
    else:
        os.link(outside / "secret.txt", where)


@pytest.mark.parametrize("kind", ["symlink", "hardlink"])
@pytest.mark.parametrize("command", [pytest.param(c, marks=[SLOW] if c in HEAVY else []) for c in COMMANDS])
def test_every_command_writes_nothing_outside_and_refuses_in_one_line(command, kind, tmp_path, refine_once, capsys):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.txt").write_text("the user's own file\n")
    before = tree_hashes(outside)
    argv, sym, hard, *server = COMMANDS[command](tmp_path, refine_once)
    where = sym if kind == "symlink" else hard
    if where.exists() and where.is_dir():
        shutil.rmtree(where)
    elif where.exists():
        where.unlink()
    _link(kind, where, outside)
    capsys.readouterr()
    with contextlib.ExitStack() as stack:
        for srv in server:  # the model server the judge asks
            stack.enter_context(srv)
        rc = cli.main(argv)
    err = capsys.readouterr().err
    print(command, kind, rc, err[-600:])
    assert rc != 70, err
    assert tree_hashes(outside) == before and (outside / "secret.txt").read_text() == "the user's own file\n"
    if rc == 4:
        lines = [ln for ln in err.splitlines() if ln.startswith(f"asset2sim {command}: ")]
        assert len(lines) == 1 and lines[0].split(": ")[1].startswith("OUTPUT_"), err
