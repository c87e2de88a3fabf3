"""Nothing written outside ``--out``: MuJoCo's log never lands in the working directory, an audit never writes
into its input, the model reply cache stays out of the input like the array cache, a staging folder left by a
killed ``--force`` run is removed by the next run, and a cache entry whose proof holds but whose JSON carries NaN
is computed again instead of failing every rerun (``tests/tasks/geometry/test_analyze.py``). Child processes run
with a time-out."""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from asset2sim import cli, demo_assets
from asset2sim import output_folder as of
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.refine import refine_asset
from tests import fake_openai_server as fake
from tests.helpers import tree_hashes

PROMPT = "a small box with its lid closed"

NAN_KEYFRAME = """<mujoco model="box">
  <worldbody><body name="base" pos="0 0 0.1"><freejoint/><geom type="box" size="0.2 0.2 0.1" mass="2"/>
    <body name="lid" pos="0 0 0.1"><joint name="hinge" type="hinge" axis="0 1 0" range="0 1.5"/>
      <geom type="box" size="0.2 0.2 0.01" pos="0.2 0 0" mass="0.3"/></body></body></worldbody>
  <keyframe><key name="initial" qpos="0 0 0.1 1 0 0 0 nan"/></keyframe>
</mujoco>
"""


@pytest.fixture()
def box(tmp_path):
    return demo_assets.build_box_with_lid(tmp_path / "in" / "box_lid")


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")} if folder.exists() else set()


# ------------------------------------------------------------------ MuJoCo's log
@pytest.mark.slow  # end to end: the command line
def test_mujoco_warnings_write_no_log_into_the_working_directory(tmp_path):
    """Refining and auditing an MJCF whose keyframe holds NaN, in a child process whose working directory is
    empty: MuJoCo warns, and no ``MUJOCO_LOG.TXT`` (or anything else) appears there; the NaN is not an initial state."""
    pytest.importorskip("mujoco")
    (tmp_path / "in").mkdir()
    xml = tmp_path / "in" / "nan.xml"
    xml.write_text(NAN_KEYFRAME)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    for args in (["refine", str(xml), "--prompt", "a box", "--out", str(tmp_path / "out"), "--no-extras", "--engines", "pybullet,mujoco"],
                 ["audit", str(xml), "--out", str(tmp_path / "audit"), "--no-sim"]):
        proc = subprocess.run([sys.executable, "-m", "asset2sim", *args], capture_output=True, text=True, timeout=300, cwd=cwd)
        assert proc.returncode in (0, 3), proc.stdout[-2000:] + proc.stderr[-2000:]
        assert _files(cwd) == set(), args[0]
    report = (tmp_path / "out" / "report.json").read_text()
    assert "not a number: not used" in report


def test_the_mujoco_module_the_project_loads_logs_no_file(tmp_path, monkeypatch):
    pytest.importorskip("mujoco")
    from asset2sim.engines.mjcf.base import load_mujoco

    monkeypatch.chdir(tmp_path)
    mujoco = load_mujoco()
    m = mujoco.MjModel.from_xml_string(NAN_KEYFRAME)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_step(m, d)  # "Nan, Inf or huge value in QPOS": a warning
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


# ------------------------------------------------------------------ audit --out
def test_audit_out_equal_to_or_inside_the_input_is_refused(tmp_path, box, capsys):
    before = tree_hashes(box)
    for out, why in ((box, "OUTPUT_IS_INPUT"), (box / "audit", "OUTPUT_INSIDE_INPUT"), (box.parent, "OUTPUT_CONTAINS_INPUT")):
        code = cli.main(["audit", str(box), "--out", str(out), "--no-sim"])
        err = capsys.readouterr().err
        assert code == 4, err
        assert why in err
        assert tree_hashes(box) == before and not (box / "audit").exists()
    assert cli.main(["audit", str(box), "--out", str(tmp_path / "beside"), "--no-sim"]) in (0, 3)  # beside it: written
    assert (tmp_path / "beside" / "audit_assets.parquet").is_file() and tree_hashes(box) == before
    # an MJCF file: its folder is the input
    (tmp_path / "m").mkdir()
    xml = tmp_path / "m" / "nan.xml"
    xml.write_text(NAN_KEYFRAME)
    before = tree_hashes(xml.parent)
    assert cli.main(["audit", str(xml), "--out", str(xml.parent), "--no-sim"]) == 4
    assert "OUTPUT_IS_INPUT" in capsys.readouterr().err
    assert tree_hashes(xml.parent) == before


# ------------------------------------------------------------------ the reply cache
def test_the_reply_cache_is_kept_out_of_the_input(tmp_path, box, monkeypatch):
    """ASSET2SIM_LLM_CACHE_DIR inside the input: a refine with a model estimator writes no reply record there
    (a CacheWarning names it); the same folder outside the input is used."""
    for k in ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY", "ANTHROPIC_API_KEY"):
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("ASSET2SIM_LLM_TIMEOUT_S", "5")
    monkeypatch.setenv("ASSET2SIM_LLM_RENDER_SIZE", "64")
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(box / "llm_cache"))
    before = tree_hashes(box)
    with fake.FakeOpenAIServer(lifetime_s=300) as server:
        config = RefineConfig(estimator="openai", model="m", base_url=server.url, engines=["pybullet"])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            refine_asset(box, PROMPT, tmp_path / "out", config, extras=False)
        assert tree_hashes(box) == before and not (box / "llm_cache").exists()
        assert any("reply cache" in str(w.message) and "llm_cache" in str(w.message) for w in caught)
        monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "llm_cache"))
        refine_asset(box, PROMPT, tmp_path / "out2", config, extras=False)
        assert list((tmp_path / "llm_cache").rglob("*.json"))


# ------------------------------------------------------------------ a killed --force run's staging folder
def _leftover(out: Path) -> Path:
    """The staging folder a ``--force`` run killed mid-way leaves: its ownership record and a file."""
    staging = of.staging_folder(out.resolve())
    staging.mkdir()
    (staging / of.RECORD_NAME).write_text('{"version": 1, "files": ["mobility.urdf"]}')
    (staging / "mobility.urdf").write_text("<robot name='half'/>")
    return staging


def test_a_plain_rerun_removes_a_killed_force_runs_staging_folder(tmp_path, box):
    out = tmp_path / "out"
    config = RefineConfig(engines=["pybullet"])
    refine_asset(box, PROMPT, out, config, extras=False)
    staging = _leftover(out)
    res = refine_asset(box, PROMPT, out, config, extras=False)  # complete: skipped, and the leftovers removed
    assert res.skipped
    assert not staging.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in", "out"]


def test_a_staging_folder_a_live_run_holds_is_left_alone(tmp_path, box):
    out = tmp_path / "out"
    config = RefineConfig(engines=["pybullet"])
    refine_asset(box, PROMPT, out, config, extras=False)
    staging = _leftover(out)
    fd = os.open(staging, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a running --force holds it
        assert not of.remove_stale_staging(out)
        assert staging.is_dir()
    finally:
        os.close(fd)
    assert of.remove_stale_staging(out) and not staging.exists()


def test_a_user_folder_named_like_a_staging_folder_is_kept(tmp_path, box):
    out = tmp_path / "out"
    refine_asset(box, PROMPT, out, RefineConfig(engines=["pybullet"]), extras=False)
    mine = of.staging_folder(out.resolve())
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    assert not of.remove_stale_staging(out)
    assert (mine / "notes.txt").read_text() == "mine"


def test_a_cached_reply_record_with_nan_is_asked_again(tmp_path):
    """A reply record whose digest holds but whose JSON carries NaN is rejected (deleted, a CacheWarning) and
    the model asked again, instead of being replayed."""
    from asset2sim import array_cache
    from asset2sim.schemas.model_reply import ModelReply, reply_json_schema
    from asset2sim.models import client as lc
    from asset2sim.models.config import ClientConfig

    def ask(client):
        return client.ask(messages, ModelReply, schema=reply_json_schema(), schema_name="asset2sim_overlay_reply")

    with fake.FakeOpenAIServer(lifetime_s=120) as server:
        client = lc.LLMClient(ClientConfig(model="openai/m", base_url=server.url, timeout_s=5.0, max_attempts=1,
                                              cache_dir=tmp_path / "cache"))
        desc = {"category": "Box", "closed_extents_m": [0.2, 0.2, 0.2], "typical_dims_m": [0.3, 0.2, 0.1],
                "links": [{"name": "body", "volume_m3": 0.008, "area_m2": 0.24}],
                "joints": [{"name": "hinge", "requested_band": "slightly_open", "closed_position": 0.0}]}
        messages = [{"role": "system", "content": "answer JSON"},
                    {"role": "user", "content": f"{fake.DESCRIPTION_MARK}\n{json.dumps(desc)}"}]
        ask(client)
        (record,) = (tmp_path / "cache").rglob("*.json")
        record.write_text(record.read_text().replace('"tokens": ', '"tokens": NaN, "was": '))
        assert "NaN" in record.read_text()
        n = server.n_chat
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            ask(client)
        assert server.n_chat == n + 1 and client.usage.cached == 0
        assert any(issubclass(w.category, array_cache.CacheWarning) for w in caught)
        assert "NaN" not in record.read_text()
