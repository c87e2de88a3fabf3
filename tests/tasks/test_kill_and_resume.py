"""``asset2sim refine`` killed with SIGKILL at random moments leaves no
truncated output, never writes the input, and a rerun completes.

After every kill, each file in the output folder is checked to be complete:
JSON parses, URDF/MJCF parse (hardened parser) and the output folder
validates, copied meshes/materials/textures are byte-identical to the input's,
generated OBJ pieces parse to the end, PNGs verify, HTML is closed. The
input tree's hashes never change. Temporary files of the atomic writer
(``.<name>.<random>.tmp``) left by a kill are tolerated and counted (they are
not output files).

Each kill comes a random time after a random progress line of the run (so the
machine's load does not decide whether it lands before the end). The default
run kills 4 times; ``-m slow`` runs 20 kills.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from asset2sim import safexml
from asset2sim.tasks.ingest import validate_input as vi
from tests import corpus_builder as cb
from tests.helpers import tree_hashes

refine = pytest.importorskip("asset2sim.tasks.refine")

TMP_NAME = re.compile(r"^\..+\.[A-Za-z0-9_]+\.tmp$")
PROMPTS = {"box_lid": "a small box with its lid slightly open", "corpus": "a cabinet with the drawer slightly open"}


def _assets(root: Path) -> dict[str, Path]:
    from asset2sim import demo_assets

    return {"box_lid": demo_assets.build_box_with_lid(root / "in" / "box_lid"), "corpus": cb.build_valid(root / "in" / "corpus")}


def _cmd(asset: Path, out: Path, prompt: str, force: bool, quiet: bool = True) -> list[str]:
    cmd = [sys.executable, "-m", "asset2sim", "refine", str(asset), "--out", str(out), "--prompt", prompt] + (["--quiet"] if quiet else [])
    return cmd + (["--force"] if force else [])


def _popen(asset: Path, out: Path, prompt: str, force: bool, quiet: bool) -> subprocess.Popen:
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONHASHSEED="0")
    return subprocess.Popen(_cmd(asset, out, prompt, force, quiet), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True, env=env)


def _progress_lines(asset: Path, out: Path, prompt: str) -> int:
    """A complete ``--force`` run; returns how many progress lines (``[  1.23s] stage ...``) it printed."""
    proc = _popen(asset, out, prompt, force=True, quiet=False)
    stdout, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err.decode(errors="replace")[-2000:]
    return sum(1 for line in stdout.decode(errors="replace").splitlines() if line.startswith("["))


def _run(asset: Path, out: Path, prompt: str, force: bool = True, kill_at: tuple[int, float] | None = None) -> int | None:
    """Run refine in its own process group; with ``kill_at`` = (k, d), SIGKILL
    the group d s after its k-th progress line (k = 0: d s after the start):
    moments anchored to the run's own progress, so the machine's load does
    not decide whether a kill comes before the end. Returns the exit code
    (negative when killed)."""
    proc = _popen(asset, out, prompt, force, quiet=kill_at is None)
    if kill_at is None:
        _out, err = proc.communicate(timeout=600)
        assert proc.returncode == 0, err.decode(errors="replace")[-2000:]
        return proc.returncode
    k, delay = kill_at
    seen = 0
    while seen < k:
        line = proc.stdout.readline()
        if not line:  # the run ended first
            break
        seen += line.startswith(b"[")
    try:
        proc.wait(timeout=delay)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    proc.stdout.close()
    proc.stderr.close()
    return proc.returncode


def check_output_complete(out: Path, asset: Path) -> dict[str, int]:
    """Assert every file under ``out`` is complete; returns counts by kind."""
    counts: dict[str, int] = {}
    if not out.exists():
        return counts
    for p in sorted(out.rglob("*")):
        if p.is_dir():
            continue
        rel = p.relative_to(out)
        if TMP_NAME.match(p.name):
            counts["tmp_leftover"] = counts.get("tmp_leftover", 0) + 1
            continue
        data = p.read_bytes()
        src = asset / rel
        suf = p.suffix.lower()
        if src.is_file() and not src.is_symlink() and suf in (".obj", ".mtl", ".stl", ".png", ".jpg", ".jpeg"):
            assert data == src.read_bytes(), f"{rel}: copy differs from the input (truncated?)"
            kind = "copied"
        elif suf == ".json":
            json.loads(data)
            kind = "json"
        elif suf == ".urdf":
            assert safexml.parse_xml_bytes(data, source=str(rel)).tag == "robot"
            kind = "urdf"
        elif suf == ".xml":
            safexml.parse_xml_bytes(data, source=str(rel))
            kind = "xml"
        elif suf == ".obj":
            scan = vi.scan_mesh_file(p)
            bad = set(scan.defects) & {"MESH_MALFORMED", "MESH_BAD_INDEX", "MESH_NO_FACES"}
            assert not bad and data.endswith(b"\n"), f"{rel}: incomplete OBJ {scan.defects}"
            kind = "obj"
        elif suf == ".png":
            from PIL import Image

            with Image.open(p) as im:
                im.verify()
            kind = "png"
        elif suf == ".html":
            assert data.rstrip().endswith(b"</html>"), f"{rel}: HTML not closed"
            kind = "html"
        else:
            assert data, f"{rel}: empty file of unchecked type"
            kind = "other:" + suf
        counts[kind] = counts.get(kind, 0) + 1
    if (out / "mobility.urdf").is_file():
        findings = vi.validate_asset(out)
        assert not vi.has_errors(findings), [f.describe() for f in findings if f.severity == "error"]
    marker = out / refine.MARKER_NAME
    if marker.is_file():
        m = json.loads(marker.read_text())
        counts["marker_valid" if refine.is_complete(out, m["input_hash"], m["config_hash"]) else "marker_stale"] = 1
    return counts


def _kill_runs(tmp_path: Path, n_kills: int, seed: int) -> None:
    assets = _assets(tmp_path)
    before = {k: tree_hashes(a) for k, a in assets.items()}
    outs = {k: tmp_path / "out" / k for k in assets}
    # one complete run per asset, then a second, warm one (caches filled, as the killed runs find them) counts the
    # progress lines and their mean gap: a kill comes a random time after a random progress line
    lines, gaps = {}, {}
    for k, a in assets.items():
        _run(a, outs[k], PROMPTS[k], force=False)
        counts = check_output_complete(outs[k], a)
        assert counts.get("marker_valid") == 1, counts
        t = time.perf_counter()
        lines[k] = _progress_lines(a, outs[k], PROMPTS[k])
        gaps[k] = (time.perf_counter() - t) / max(lines[k], 1)
    rng = random.Random(seed)
    log = []
    names = sorted(assets)
    for i in range(n_kills):
        k = names[i % len(names)]
        out = outs[k] if i % 4 != 3 else tmp_path / "fresh" / f"{k}_{i}"  # some runs start from an empty folder
        at = (rng.randrange(lines[k]), rng.uniform(0.0, gaps[k]))
        old = i % 4 != 3 and check_output_complete(out, assets[k]).get("marker_valid") == 1
        rc = _run(assets[k], out, PROMPTS[k], force=True, kill_at=at)
        counts = check_output_complete(out, assets[k])
        if old:  # --force over a complete output: a kill leaves the old output or the complete new one
            assert counts.get("marker_valid") == 1, (k, at, rc, counts)
        log.append((k, (at[0], round(at[1], 2)), rc, counts))
        assert tree_hashes(assets[k]) == before[k], f"input {k} changed"
    print("\n".join(map(str, log)))
    assert sum(1 for e in log if e[2] == -signal.SIGKILL) >= n_kills // 2, "most runs should have been killed mid-way"
    # a rerun after the kills completes, and a second rerun skips
    for k, a in assets.items():
        _run(a, outs[k], PROMPTS[k], force=False)
        counts = check_output_complete(outs[k], a)
        assert counts.get("marker_valid") == 1, counts
        m = json.loads((outs[k] / refine.MARKER_NAME).read_text())
        from asset2sim.tasks.ingest.extract import extract_asset

        assert m["input_hash"] == extract_asset(a).input_hash
        assert tree_hashes(a) == before[k]


@pytest.mark.slow  # end to end: the command line killed and rerun
def test_refine_killed_at_random_moments(tmp_path):
    _kill_runs(tmp_path, n_kills=4, seed=5)


@pytest.mark.slow
def test_refine_killed_20_times(tmp_path):
    _kill_runs(tmp_path, n_kills=20, seed=20260)


@pytest.mark.slow  # end to end: the command line
def test_refine_refuses_output_inside_input(tmp_path):
    asset = cb.build_valid(tmp_path / "asset")
    before = tree_hashes(asset)
    (tmp_path / "link_into_input").symlink_to(asset / "meshes")
    for out in (asset, asset / "out", asset / "meshes" / "deeper", tmp_path / "link_into_input" / "x"):
        proc = subprocess.run(_cmd(asset, out, "open", force=False), capture_output=True, timeout=300)
        assert proc.returncode == 4, (out, proc.stderr[-500:])  # output location problem (docs/guide/outputs.md, exit statuses)
        assert proc.stderr.startswith(b"asset2sim refine: OUTPUT_"), proc.stderr[-500:]
        assert tree_hashes(asset) == before
    assert not (asset / "out").exists() and not (asset / "meshes" / "deeper").exists()


def test_refine_refuses_invalid_input_before_writing(tmp_path):
    """``refine`` runs validation first: a refused asset writes nothing."""
    asset = cb.CASES_BY_NAME["path_absolute_etc_passwd"].build(tmp_path / "asset")
    out = tmp_path / "out"
    proc = subprocess.run(_cmd(asset, out, "open", force=False), capture_output=True, timeout=300)
    assert proc.returncode != 0
    assert b"MESH_PATH_ABSOLUTE" in proc.stderr
    assert not out.exists()
