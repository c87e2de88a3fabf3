"""Model-backed overlay synthesis end to end against a local fake
OpenAI-compatible server started by the tests: the refine pipeline with
``--estimator openai``, every network and reply fault ending in a valid output
or a clear per-asset error, the reply used as a prior (mass from geometry,
dynamics from physics, state from the band), the reply cache, missing keys, and
the direct / IVW baselines."""

from __future__ import annotations

import importlib.util
from dataclasses import replace
import base64
import io
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

if importlib.util.find_spec("litellm") is None:  # not imported here: the client imports it quietly
    pytest.skip("model backends need litellm (pip install 'asset2sim[llm]')", allow_module_level=True)

from asset2sim import safexml  # noqa: E402
from asset2sim.schemas.config import RefineConfig  # noqa: E402
from asset2sim.schemas.overlay import Overlay  # noqa: E402
from asset2sim.tasks.synthesize import ivw
from asset2sim.tasks.synthesize import physics  # noqa: E402
from asset2sim.tasks.synthesize import llm_estimator as le  # noqa: E402
from asset2sim.tasks.synthesize.context import build_context  # noqa: E402
from asset2sim.models.errors import ReplyError  # noqa: E402
from asset2sim.tasks.refine import MARKER_NAME, RefineError, refine_asset  # noqa: E402
from asset2sim.tasks.synthesize.validate_overlay import inertia_problems  # noqa: E402
from tests import fake_openai_server as fake  # noqa: E402
from tests.conftest import NO_SHARED, SHARED  # noqa: E402
from tests.helpers import write_hinged_plate  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
PROMPT = "A small box with its lid slightly open."
MAX_ATTEMPTS = 3
BUDGET = MAX_ATTEMPTS * 3  # HTTP tries per call x (first reply + 2 re-asks)
KEYS = ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY", "ANTHROPIC_API_KEY")


def _llm_env(monkeypatch, cache: Path) -> None:
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(cache))
    monkeypatch.setenv("ASSET2SIM_LLM_TIMEOUT_S", "2")
    monkeypatch.setenv("ASSET2SIM_LLM_BACKOFF_S", "0.05")
    monkeypatch.setenv("ASSET2SIM_LLM_MAX_BACKOFF_S", "0.2")
    monkeypatch.setenv("ASSET2SIM_LLM_MAX_ATTEMPTS", str(MAX_ATTEMPTS))
    monkeypatch.setenv("ASSET2SIM_LLM_RENDER_SIZE", "64")
    for k in KEYS:
        monkeypatch.delenv(k, raising=False)


@pytest.fixture(autouse=True)
def llm_env(monkeypatch, tmp_path):
    """Small delays and timeouts for tests, a fresh reply cache (``tmp_path / "llm_cache"``), no API keys."""
    _llm_env(monkeypatch, tmp_path / "llm_cache")


@pytest.fixture
def plate(tmp_path) -> Path:
    return write_hinged_plate(tmp_path / "plate")


@pytest.fixture(scope="module")
def first_refine(tmp_path_factory):
    """The plate refined once with the fake server's default reply, for the tests that read that refine: the server,
    the plate, the output folder, the result and the reply cache folder (a test that refines again works on copies)."""
    root = tmp_path_factory.mktemp("first_refine")
    with pytest.MonkeyPatch.context() as mp, fake.FakeOpenAIServer() as srv:
        _llm_env(mp, root / "llm_cache")
        plate = write_hinged_plate(root / "plate")
        res = refine_asset(plate, PROMPT, root / "out", config(srv), extras=False)
        yield srv, plate, root / "out", res, root / "llm_cache"


def config(server) -> RefineConfig:
    return RefineConfig(estimator="openai", model="m", base_url=server.url)


def files_in(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file()] if folder.exists() else []


def assert_valid_output(out: Path) -> Overlay:
    """The SPEC's output contract, checked from the files."""
    from asset2sim.tasks.ingest import validate_input as vi

    for name in ("mobility.urdf", "initial_state.json", "overlay.json", "report.json", MARKER_NAME):
        assert (out / name).is_file(), name
    assert not [p for p in files_in(out) if p.name.endswith(".tmp")], "temporary files left"
    findings = vi.validate_asset(out)
    assert not vi.has_errors(findings), [f.describe() for f in findings if f.severity == "error"]
    root = safexml.parse_xml_bytes((out / "mobility.urdf").read_bytes())
    limits = {}
    for link in root.findall("link"):
        if link.find("visual") is None and link.find("collision") is None:
            continue
        inertial = link.find("inertial")
        assert inertial is not None, link.get("name")
        assert float(inertial.find("mass").get("value")) > 0
        i = inertial.find("inertia").attrib
        m = np.array([[float(i["ixx"]), float(i["ixy"]), float(i["ixz"])], [float(i["ixy"]), float(i["iyy"]), float(i["iyz"])], [float(i["ixz"]), float(i["iyz"]), float(i["izz"])]])
        assert inertia_problems(m) is None, link.get("name")
    for joint in root.findall("joint"):
        if joint.get("type") in ("revolute", "prismatic", "continuous"):
            dyn = joint.find("dynamics")
            assert dyn is not None and float(dyn.get("damping")) >= 0 and float(dyn.get("friction")) >= 0
            lim = joint.find("limit")
            if lim is not None and joint.get("type") != "continuous":
                limits[joint.get("name")] = (float(lim.get("lower")), float(lim.get("upper")))
    state = json.loads((out / "initial_state.json").read_text())["initial_joint_positions"]
    for name, q in state.items():
        lo, hi = limits.get(name, (-np.inf, np.inf))
        assert lo - 1e-9 <= q <= hi + 1e-9, (name, q, lo, hi)
    return Overlay.model_validate_json((out / "overlay.json").read_text())


# ---------------------------------------------------------------- happy path
def test_refine_with_an_openai_compatible_server(first_refine):
    server, _, out, res, _ = first_refine
    ov = assert_valid_output(out)
    assert server.n_chat == 1
    assert res.report.estimator == "openai" and res.report.model == "openai/m" and res.report.model_queries == 1
    assert (ov.estimator.name, ov.estimator.model, ov.estimator.queries, ov.estimator.tokens) == ("openai", "openai/m", 1, 1200)
    assert ov.estimator.seconds > 0
    assert any("1 model calls" in n for n in res.report.notes)
    # the request: five PNG views of the closed object, the description, the schema constraint
    req = server.requests[0]
    urls = req.image_urls()
    assert len(urls) == 5 and len(set(urls)) >= 2
    from PIL import Image

    for u in urls:
        assert u.startswith("data:image/png;base64,")
        im = Image.open(io.BytesIO(base64.b64decode(u.split(",", 1)[1])))
        assert im.size == (64, 64)
    views = [t for t in req.texts() if t.startswith("view: ")]
    assert [v.split()[1] for v in views] == list(le.VIEWS)
    desc = req.description()
    assert {ln["name"] for ln in desc["links"]} == {"base", "body", "plate"}
    (hinge,) = desc["joints"]
    assert hinge["name"] == "hinge" and hinge["type"] == "revolute" and hinge["requested_band"] == "slightly_open"
    assert desc["request"] == PROMPT and desc["category"] == res.report.category
    plate_desc = next(ln for ln in desc["links"] if ln["name"] == "plate")
    assert plate_desc["volume_m3"] == pytest.approx(0.4 * 0.2 * 0.01, rel=1e-3)
    assert req.body["response_format"]["json_schema"]["name"] == "asset2sim_overlay_reply"
    # the state follows the model's band through the geometric closed end
    assert res.report.requested_bands == {"hinge": "slightly_open"}
    assert 0.05 <= res.report.opening_fractions["hinge"] <= 0.35


def test_rerun_makes_no_calls(first_refine, tmp_path):
    server, plate, done, first, cache = first_refine
    out = shutil.copytree(done, tmp_path / "out")  # the first refine's output and reply cache, copied
    shutil.copytree(cache, tmp_path / "llm_cache")
    again = refine_asset(plate, PROMPT, out, config(server), extras=False, skip_if_complete=False)
    assert server.n_chat == 1
    assert again.report.model_queries == 0 and again.overlay.estimator.tokens == 0
    assert again.overlay.scale == first.overlay.scale
    assert again.overlay.links["plate"].mass == first.overlay.links["plate"].mass
    assert any("1 cached replies" in n for n in again.report.notes)


# ----------------------------------------------------- the reply is a prior
def _ctx(plate: Path, prompt: str = PROMPT):
    return build_context(plate, prompt)


def test_mass_comes_from_geometry_and_material_not_the_models_number(plate):
    from asset2sim.schemas.model_reply import ModelReply

    with _ctx(plate) as (ctx, kin):
        content = fake.valid_reply_content(le.describe(ctx, kin))
        s = content["scale"]["value"]
        geo = {}
        for lr in content["links"]:
            mat = physics.MaterialChoice(name="ABS", density=lr["density"], shell=lr["shell"], wall_thickness=lr["wall_thickness"])
            geo[lr["link"]] = physics.link_physics(ctx.geometry[lr["link"]], s, mat).mass
            lr["mass"]["value"] = geo[lr["link"]] * 2.0  # the model's own number: 2x off, within the agreement band
        ov = le.overlay_from_reply(ctx, kin, ModelReply.model_validate(content)).overlay
        for ln, m in geo.items():
            assert ov.links[ln].mass == pytest.approx(m, rel=1e-9)
            assert inertia_problems(ov.links[ln].inertia.matrix()) is None
        # a model estimate 100x off: the geometry is pulled to within 3x of it, no further
        for lr in content["links"]:
            lr["mass"]["value"] = geo[lr["link"]] * 100.0
        ov2 = le.overlay_from_reply(ctx, kin, ModelReply.model_validate(content)).overlay
        assert ov2.total_mass() == pytest.approx(sum(geo.values()) * 100.0 / le.MASS_AGREEMENT, rel=1e-9)
        assert "every link scaled" in ov2.notes.mass_arithmetic


def test_dynamics_come_from_physics_with_the_models_choices(plate):
    from asset2sim.schemas.model_reply import ModelReply

    with _ctx(plate) as (ctx, kin):
        content = fake.valid_reply_content(le.describe(ctx, kin))
        (j,) = content["joints"]
        j["damping"]["value"] = 999.0  # the model's number is not used by the asset2sim method
        low = dict(j, damping_level="low")
        high = dict(j, damping_level="high", spring=True)
        ov_low = le.overlay_from_reply(ctx, kin, ModelReply.model_validate({**content, "joints": [low]})).overlay
        ov_high = le.overlay_from_reply(ctx, kin, ModelReply.model_validate({**content, "joints": [high]})).overlay
        d_low, d_high = ov_low.joints["hinge"], ov_high.joints["hinge"]
        assert d_low.damping != 999.0 and "physics" in d_low.source
        # c = 2 zeta sqrt(I k): the ratio of damping ratios shows through (spring raises k further)
        assert d_high.damping > d_low.damping * physics.DAMPING_RATIO["high"] / physics.DAMPING_RATIO["low"] * 0.99
        assert d_low.stiffness == 0 and d_high.stiffness > 0
        assert -1.0 <= d_high.spring_reference <= 2.0


def test_the_models_band_wins_and_reaches_the_refined_state(server, plate, tmp_path):
    server.default = fake.valid_reply(band="halfway")
    res = refine_asset(plate, PROMPT, tmp_path / "out", config(server), extras=False)
    assert res.report.requested_bands == {"hinge": "halfway"}
    assert 0.35 <= res.report.opening_fractions["hinge"] <= 0.65
    assert any("the model chose band 'halfway'" in n for n in res.report.notes)


def test_unknown_names_are_reasked(server, plate, tmp_path):
    server.push(fake.valid_reply(lambda d: d["links"][0].update(link="no_such_link")))
    res = refine_asset(plate, PROMPT, tmp_path / "out", config(server), extras=False)
    assert server.n_chat == 2 and res.report.model_queries == 2
    assert "'no_such_link' is not a link" in server.requests[1].body["messages"][-1]["content"]
    assert_valid_output(tmp_path / "out")


# -------------------------------------------- faults: valid output or clear error
JUNK_10MB = b"x" * (10 * 1024 * 1024)
SCENARIOS = {
    # name: (behaviours pushed, ok?, requests expected)
    "429 with Retry-After": ([fake.status(429, headers={"Retry-After": "1"})], True, 2),
    "429 without Retry-After": ([fake.status(429)], True, 2),
    "500": ([fake.status(500)], True, 2),
    "503": ([fake.status(503)], True, 2),
    "503 forever": ([fake.status(503)] * 20, False, MAX_ATTEMPTS),
    "timeout": ([fake.sleep_then(6.0)], True, 2),
    "dropped connection": ([fake.drop()], True, 2),
    "prose": ([fake.text_reply("The box is small and made of plastic; the lid is slightly open.")], True, 2),
    "truncated JSON": ([fake.text_reply('{"category": "Box", "scale": {"value": 0.5, ')], True, 2),
    "NaN": ([fake.json_with_nan()], True, 2),
    "duplicate keys": ([fake.text_reply('{"category": "Box", "category": "Chest"}')], True, 2),
    "extra field": ([fake.valid_reply(lambda d: d.update(confidence=0.9))], True, 2),
    "missing field": ([fake.valid_reply(lambda d: d.pop("scale"))], True, 2),
    "out-of-range values": ([fake.valid_reply(lambda d: (d["links"][0].update(density=-5.0), d["scale"].update(value=1e6)))], True, 2),
    "refusal": ([fake.reply(None, refusal="I can't help with that.")] * 3, False, 3),
    "10 MB reply": ([fake.reply("z" * (10 * 1024 * 1024))], True, 2),
    "10 MB junk body": ([fake.raw(JUNK_10MB)] * 3, False, MAX_ATTEMPTS),
    "prose three times": ([fake.text_reply("I think it is a box.")] * 3, False, 3),
    "nested 100000 deep": ([fake.text_reply("[" * 100_000 + "]" * 100_000)], True, 2),
    "trickled reply": ([fake.trickle(interval_s=0.25)], False, 1),
    "200 MB reply": ([fake.flood(200 << 20)], False, 1),
}


#: The scenarios the fast tier runs, one of each kind (a wait the server asks for, a timeout, a reply that is not
#: JSON, values out of range) and every one that ends in an error (no refine after the estimate); the whole corpus runs
#: in the slow tier (``make test-all``).
FAST_SCENARIOS = {"429 with Retry-After", "timeout", "prose", "out-of-range values"} | {n for n, (_, ok, _) in SCENARIOS.items() if not ok}


@pytest.mark.parametrize("name", [pytest.param(n, marks=[] if n in FAST_SCENARIOS else [pytest.mark.slow]) for n in SCENARIOS])
def test_faults_end_in_valid_output_or_clear_error(server, plate, tmp_path, name, monkeypatch):
    behaviours, ok, n_requests = SCENARIOS[name]
    if name == "timeout":  # the first attempt given up after 1 s (the server answers after 6 s), the retry answered at once
        monkeypatch.setenv("ASSET2SIM_LLM_TIMEOUT_S", "1")
    server.push(*behaviours)
    out = tmp_path / "out"
    if ok:
        res = refine_asset(plate, PROMPT, out, config(server), extras=False)
        ov = assert_valid_output(out)
        assert ov.estimator.name == "openai" and res.report.model_queries >= 1
    else:
        with pytest.raises(RefineError) as ei:
            refine_asset(plate, PROMPT, out, config(server), extras=False)
        assert ei.value.failure_mode == "estimator_failure"
        msg = str(ei.value)
        assert "plate" in msg and "openai/m" in msg
        assert files_in(out) == [], "partial files left"
    assert server.n_chat == n_requests <= BUDGET
    if name == "429 with Retry-After":
        assert server.requests[1].t - server.requests[0].t >= 0.95


def test_a_trickling_server_ends_the_estimate_at_the_deadline(server, plate, tmp_path, capsys):
    from asset2sim.cli import main

    server.push(fake.trickle(interval_s=0.25))  # about 300 bytes: 75 s when only each read is timed
    t0 = time.monotonic()
    rc = main(["refine", str(plate), "--prompt", PROMPT, "--estimator", "openai", "--model", "m", "--base-url", server.url,
               "--out", str(tmp_path / "out"), "--no-extras"])
    took = time.monotonic() - t0
    err = capsys.readouterr().err
    assert rc == 2 and "ESTIMATOR_FAILED" in err and "MODEL_DEADLINE_EXCEEDED" in err, err
    assert server.n_chat == 1 and took < 40.0, took


# ------------------------------------------------------------- credentials
def test_missing_key_fails_before_any_work(plate, tmp_path):
    out = tmp_path / "out"
    stages = []
    with pytest.raises(RefineError) as ei:
        refine_asset(plate, PROMPT, out, RefineConfig(estimator="llm", model="gemini/gemini-2.5-flash"), progress=lambda s, m: stages.append(s))
    assert ei.value.failure_mode == "estimator_failure"
    assert "GEMINI_API_KEY" in str(ei.value)
    assert stages == [] and not out.exists()
    with pytest.raises(RefineError, match="needs --model"):
        refine_asset(plate, PROMPT, out, RefineConfig(estimator="llm"))


def test_cli_missing_key_message(plate, tmp_path, capsys):
    from asset2sim.cli import main

    rc = main(["refine", str(plate), "--prompt", PROMPT, "--estimator", "llm", "--model", "anthropic/claude-sonnet-4-5", "--out", str(tmp_path / "o")])
    assert rc == 2
    assert "ANTHROPIC_API_KEY" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_openai_estimator_prefixes_the_model_and_registers():
    from asset2sim.tasks.synthesize import backends

    assert le.model_string("openai", "m") == "openai/m"
    assert le.model_string("openai", "openai/gpt-4o") == "openai/gpt-4o"
    assert le.model_string("llm", "gemini/gemini-2.5-flash") == "gemini/gemini-2.5-flash"
    est = backends.get_estimator("openai", model="m", base_url="http://127.0.0.1:9/v1")
    assert est.name == "openai" and est.client.config.model == "openai/m"


# ------------------------------------------------------ real objects, the CLI
REAL = [
    ("7236", "I want a microwave with its door halfway open. Low damping for hinge-like behavior."),
    ("100221", "A very small jewelry box or treasure chest with a slightly open rotational lid. Low damping for smooth hinge behavior."),
]


@pytest.mark.slow  # end to end: the command line on dev objects
@pytest.mark.skipif(not SHARED.is_dir(), reason=NO_SHARED)
def test_cli_refine_real_objects_in_process(server, tmp_path, capsys):
    """``asset2sim refine ... --estimator openai`` (the CLI entry point, in this
    process; exports, renders and the HTML report skipped) on two real objects."""
    from asset2sim.cli import main

    for oid, prompt in REAL:
        out = tmp_path / f"out_{oid}"
        rc = main(["refine", str(SHARED / oid), "--prompt", prompt, "--estimator", "openai", "--base-url", server.url,
                   "--model", "m", "--out", str(out), "-q", "--no-extras"])
        assert rc == 0, capsys.readouterr().err[-3000:]
        assert "verdict" in capsys.readouterr().out
        ov = assert_valid_output(out)
        report = json.loads((out / "report.json").read_text())
        assert report["estimator"] == "openai" and report["model_queries"] == 1 and ov.estimator.queries == 1
    assert server.n_chat == len(REAL)


@pytest.mark.slow
@pytest.mark.skipif(not SHARED.is_dir(), reason=NO_SHARED)
def test_cli_refine_real_objects_with_the_fake_server(server, tmp_path):
    """The literal command in a subprocess, the first object with every extra."""
    env = dict(os.environ)
    for i, (oid, prompt) in enumerate(REAL):
        out = tmp_path / f"out_{oid}"
        cmd = [sys.executable, "-m", "asset2sim", "refine", str(SHARED / oid), "--prompt", prompt, "--estimator", "openai",
               "--base-url", server.url, "--model", "m", "--out", str(out), "-q"]
        if i == 1:
            cmd.append("--no-extras")
        proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert "verdict" in proc.stdout
        ov = assert_valid_output(out)
        report = json.loads((out / "report.json").read_text())
        assert report["estimator"] == "openai" and report["model_queries"] == 1
        assert ov.estimator.queries == 1
        if i == 0:
            assert (out / "views" / "front.png").is_file()
    assert server.n_chat == len(REAL)


# ------------------------------------------------------------------ baselines
def test_direct_baseline_is_one_call_applied_as_is(server, plate, tmp_path):
    from asset2sim.tasks.assemble import write

    server.default = fake.valid_reply(lambda d: d["joints"][0]["damping"].update(value=7.5))
    with _ctx(plate) as (ctx, kin):
        client = le.make_client("openai", "m", server.url)
        ov = le.direct_overlay(ctx, kin, client)
        write.write_output(ctx.asset, ov, tmp_path / "direct", ov.initial_joint_positions)  # what make_direct does
    assert (tmp_path / "direct" / "mobility.urdf").is_file()
    assert server.n_chat == 1 and ov.estimator.name == "direct" and ov.estimator.queries == 1
    assert len(server.requests[0].image_urls()) == 5
    assert ov.joints["hinge"].damping == 7.5  # the model's number, no physics
    assert ov.links["plate"].mass == 0.5  # the fake's mass, not the geometry's


def _varying(server_state: dict):
    """A valid reply whose scale, mass and damping vary per request (and are recorded)."""

    def mutate(d):
        k = server_state["n"] = server_state.get("n", 0) + 1
        d["scale"] = {"value": 0.2 + 0.01 * k, "std": 0.01 + 0.002 * k}
        d["joints"][0]["damping"] = {"value": 0.1 * k, "std": 0.05 * (1 + k % 3)}
        server_state.setdefault("scale", []).append((d["scale"]["value"], d["scale"]["std"]))
        server_state.setdefault("damping", []).append((d["joints"][0]["damping"]["value"], d["joints"][0]["damping"]["std"]))

    return fake.valid_reply(mutate)


def test_ivw_baseline_is_25_calls_fused_by_inverse_variance(server, plate, tmp_path):
    from asset2sim.tasks.assemble import write

    st: dict = {}
    server.default = _varying(st)
    with _ctx(plate) as (ctx, kin):
        client = le.make_client("openai", "m", server.url)
        ov = le.ivw_overlay(ctx, kin, client)
        write.write_output(ctx.asset, ov, tmp_path / "ivw", ov.initial_joint_positions)
    assert server.n_chat == 25 and ov.estimator.queries == 25 and ov.estimator.name == "ivw"
    per_view = [r.image_urls() for r in server.requests]
    assert all(len(u) == 1 for u in per_view)
    assert len({u[0] for u in per_view}) == 5  # five different views, five calls each
    assert all(r.body["temperature"] == le.IVW_TEMPERATURE for r in server.requests)
    assert ov.scale == pytest.approx(ivw.fuse(st["scale"]).value)
    assert ov.joints["hinge"].damping == pytest.approx(ivw.fuse(st["damping"]).value)
    assert any("25 usable replies of 25 calls" in n for n in ov.notes.other)


def test_ivw_skips_unusable_replies_and_fails_when_none(server, plate):
    server.push(fake.text_reply("prose"), fake.status(400))
    with _ctx(plate) as (ctx, kin):
        client = le.make_client("openai", "m", server.url)
        ov = le.ivw_overlay(ctx, kin, client, n_views=1, n_calls=3)
        assert "1 usable replies of 3 calls" in " ".join(ov.notes.other)
        server.push(*[fake.text_reply("prose")] * 2)
        with pytest.raises(ReplyError, match="no usable reply"):
            le.ivw_overlay(ctx, kin, client, n_views=2, n_calls=1)


def test_second_estimate_of_the_same_asset_reuses_the_reply(server, plate, monkeypatch):
    """The refine stage may estimate twice (another resting pose): one model call."""
    from asset2sim.tasks.synthesize import backends

    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", "off")  # the memo, not the disk cache
    est = backends.get_estimator("openai", model="m", base_url=server.url)
    with _ctx(plate) as (ctx, kin):
        ea = est.estimate(ctx, kin)
        ctx = replace(ctx, root_rotation=np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]))  # lying on its side
        eb = est.estimate(ctx, kin)
    a, b = ea.overlay, eb.overlay
    assert eb.bands == ea.bands and set(ea.bands) == {"hinge"}
    assert server.n_chat == 1
    assert a.estimator.queries == b.estimator.queries == 1
    assert b.links["plate"].mass == a.links["plate"].mass
    with _ctx(plate, "A box with its lid fully open.") as (ctx2, kin2):
        est.estimate(ctx2, kin2)
    assert server.n_chat == 2


def test_stalled_state_search_asks_the_model_and_keeps_only_improvements(tmp_path):
    """The arm passes through the post whatever the allowed (closed) band: the
    search stalls, the model is asked once for joint proposals, and a proposal
    is applied only if it lowers the objective (it never leaves the band)."""
    from asset2sim.engines.base import SessionOptions
    from asset2sim.engines.registry import open_session
    from asset2sim.schemas.request import BAND_INTERVAL
    from asset2sim.tasks.synthesize import llm_estimator as le
    from asset2sim.tasks.geometry.closed_state import ClosedState
    from asset2sim.tasks.ingest.extract import extract_asset
    from asset2sim.tasks.state.refine_state import refine_initial_state
    from tests.fake_openai_server import FakeOpenAIServer
    from tests.helpers import write_arm_through_post

    asset = extract_asset(write_arm_through_post(tmp_path / "arm"))
    closed = {"hinge": ClosedState(joint="hinge", q_closed=0.0, direction=1.0, open_range=1.0, lower=-1.0, upper=1.0)}
    with FakeOpenAIServer() as server:
        est = le.LLMEstimator(model="m", base_url=server.url, client=le.make_client("openai", "m", server.url, cache_dir=tmp_path / "cache"))

        class Ctx:  # the proposer needs only these
            category = "Generic"
            request = type("R", (), {"text": "a closed thing"})()

        Ctx.asset = asset
        proposer = est.joint_proposer(Ctx)
        s = open_session("pybullet", asset.urdf_path, SessionOptions(fixed_base=True, gravity=False, ground=False))
        try:
            band = BAND_INTERVAL["closed"]
            st = refine_initial_state(s, asset, closed, {"hinge": 0.0}, {"hinge": band}, RefineConfig(penetration_tolerance=1e-6),
                                      proposer=proposer)
        finally:
            s.close()
        assert st.model_queries == 1 and len(server.requests) == 1
        assert "model proposals (1 asked" in st.method
        assert band[0] <= st.result["hinge"] <= band[1]  # the proposal was clipped into the band
        assert st.phi_result <= st.phi_requested
