"""The model judge of realism (asset2sim.apps.realism.judge) against the local fake OpenAI server:
the messages (rubric, frames as data URIs, both orders), reading replies (JSON, prose, refusals),
order-consistent verdicts only, failures that never stop the run, usage, the reply cache,
judgements.parquet and the ``asset2sim judge`` command."""

from __future__ import annotations

import base64
import hashlib
import importlib.util
import json

import pytest

from asset2sim.apps.realism.scores import read_scores, realism_column

if importlib.util.find_spec("litellm") is None:  # the client imports it on first use
    pytest.skip("model judges need litellm (pip install 'asset2sim[llm]')", allow_module_level=True)

from asset2sim.cli import main  # noqa: E402
from asset2sim.apps.realism import judge as J  # noqa: E402
from asset2sim.apps.realism.judge_reply import read_reply  # noqa: E402
from asset2sim.models.client import LLMClient  # noqa: E402
from asset2sim.models.config import ClientConfig  # noqa: E402
from tests import fake_openai_server as fake  # noqa: E402
from tests import realism_judge_fixtures as fx  # noqa: E402


@pytest.fixture(autouse=True)
def no_keys(monkeypatch):
    for k in ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY", "ANTHROPIC_API_KEY"):
        monkeypatch.delenv(k, raising=False)


@pytest.fixture
def pair_set(tmp_path):
    folder = tmp_path / "set"
    ps = fx.write_judge_pair_set(folder, n_defect=4, n_plain=3)
    return folder, ps


def config(server, tmp_path, model="openai/good-judge", **kw) -> ClientConfig:
    cfg = dict(model=model, base_url=server.url, timeout_s=5.0, max_attempts=1, backoff_s=0.01, cache_dir=tmp_path / "cache")
    cfg.update(kw)
    return ClientConfig(**cfg)


# ----------------------------------------------------------------------------- reading replies
@pytest.mark.parametrize("text, choice", [
    ('{"more_realistic": "A", "reason": "the lid settles"}', "A"),
    ('```json\n{"more_realistic": "b", "reason": "x"}\n```', "B"),
    ('{"more_realistic": "Video B", "reason": "x"}', "B"),
    ('Sure. {"more_realistic": "A", "reason": "smooth"} Hope this helps.', "A"),
    ("Video B looks more realistic: the door swings and settles.", "B"),
    ("After looking at both, the more realistic one is A.", "A"),
    ("I prefer video A; in B the drawer stops dead.", "A"),
    ("Video A is less realistic than the other one.", "B"),
    ("Video A is more realistic than Video B because B slams.", "A"),
    ("**Answer: B**", "B"),
])
def test_replies_that_name_one_video(text, choice):
    r = read_reply(text)
    assert r.choice == choice, r


@pytest.mark.parametrize("text, why", [
    ('{"more_realistic": "C", "reason": "x"}', "without more_realistic"),
    ('{"verdict": "A"}', "without more_realistic"),
    ("Video A is more realistic in the opening, Video B is more realistic at rest.", "both"),
    ("Both videos look equally plausible to me.", "no video"),
    ("Video A shows a lid; Video B shows a lid.", "no video"),
    ("Video A is not more realistic.", "no video"),
    ("I'm sorry, but I can't compare these videos.", "no video"),
    ("", "empty"),
])
def test_ambiguous_or_unusable_replies_are_no_answer(text, why):
    r = read_reply(text)
    assert r.choice is None and why in r.reason, r


def test_refusals_and_filtered_replies_are_no_answer():
    assert read_reply('{"more_realistic": "A"}', refusal="I can't help with that.").choice is None
    assert "refused" in read_reply("", refusal="no").reason
    assert read_reply('{"more_realistic": "A"}', finish_reason="content_filter").choice is None


# ----------------------------------------------------------------------------- the messages
def test_messages_carry_rubric_and_both_sides_frames_in_the_order_asked(pair_set):
    folder, ps = pair_set
    pair = ps.pairs[0]
    fa, fb = J.side_frames(folder, pair, "a"), J.side_frames(folder, pair, "b")
    msgs = J.build_messages(pair, fa, fb)
    assert msgs[0] == {"role": "system", "content": J.RUBRIC}
    parts = msgs[1]["content"]
    labels = [p["text"].split(":")[0] for p in parts if p["type"] == "text" and p["text"].startswith("Video")]
    assert labels == ["Video A", "Video B"]
    urls = [p["image_url"]["url"] for p in parts if p["type"] == "image_url"]
    assert len(urls) == 2 * fx.N_FRAMES and all(u.startswith("data:image/png;base64,") for u in urls)
    sent = [base64.b64decode(u.split(",", 1)[1]) for u in urls]
    assert sent == [(folder / f).read_bytes() for f in pair.a.clips[0].frames + pair.b.clips[0].frames]
    text = json.dumps(msgs)
    assert pair.b.method not in text and "clips/" not in text  # the judge sees neither methods nor file names
    swapped = J.build_messages(pair, fb, fa)[1]["content"]
    assert [p["image_url"]["url"] for p in swapped if p["type"] == "image_url"] == urls[fx.N_FRAMES:] + urls[:fx.N_FRAMES]


# ----------------------------------------------------------------------------- judging
def test_good_judge_keeps_order_consistent_verdicts_counts_usage_and_caches(pair_set, tmp_path):
    folder, ps = pair_set
    broken = fx.broken_digests(folder, ps)
    with fake.FakeOpenAIServer(fx.good_judge(broken), lifetime_s=120) as srv:
        verdicts = J.judge_pairs(folder, [config(srv, tmp_path)], workers=2)
        assert srv.n_chat == 2 * len(ps.pairs)
        assert [v.pair_id for v in verdicts] == [p.pair_id for p in ps.pairs]
        assert all(v.kept and v.first == v.second == v.winner for v in verdicts)
        assert all(v.winner == "asset2sim" for v in verdicts if v.defect)
        assert all((v.calls, v.prompt_tokens, v.completion_tokens) == (2, 2000, 400) for v in verdicts)
        assert {v.family for v in verdicts} == {"good"} and verdicts[0].reason == "scripted"
        # both orders were asked: side a first, then side b first
        shown_first = sorted(tuple(fx.videos(r)["A"]) for r in srv.requests)
        both_sides = sorted(tuple(hashlib.sha256((folder / f).read_bytes()).hexdigest() for f in side.clips[0].frames)
                            for pair in ps.pairs for side in (pair.a, pair.b))
        assert shown_first == both_sides
        assert J.read_judgements(folder) == verdicts
        # the same frames, rubric and model: every answer from the cache, no HTTP call
        again = J.judge_pairs(folder, [config(srv, tmp_path)])
        assert srv.n_chat == 2 * len(ps.pairs)
        assert [v.winner for v in again] == [v.winner for v in verdicts] and all(v.calls == 0 for v in again)
        # another model is another cache key
        J.judge_pairs(folder, [config(srv, tmp_path, model="openai/other")], write=False)
        assert srv.n_chat == 4 * len(ps.pairs)


def test_position_biased_judge_keeps_nothing(pair_set, tmp_path):
    folder, ps = pair_set
    with fake.FakeOpenAIServer(fx.first_judge(), lifetime_s=120) as srv:
        verdicts = J.judge_pairs(folder, [config(srv, tmp_path, model="openai/first")])
    assert not any(v.kept for v in verdicts) and all(v.winner is None for v in verdicts)
    assert all((v.first, v.second) == (v.method_a, v.method_b) for v in verdicts)
    assert "A/B: picked asset2sim" in verdicts[0].reason


def test_order_flipping_prose_refusal_and_timeout_never_stop_the_run(pair_set, tmp_path):
    folder, ps = pair_set
    p = ps.pairs[0]
    with fake.FakeOpenAIServer(fx.first_judge(), lifetime_s=120) as srv:
        client = LLMClient(config(srv, tmp_path, timeout_s=0.5, cache_dir=None))
        # prose in both orders, naming the intact side each time (A first, then B when swapped)
        srv.push(fake.text_reply("Video A looks more realistic; the other one is sluggish."),
                 fake.text_reply("Clearly, the more realistic one is B."))
        v = J.judge_pair(client, folder, p)
        assert v.kept and v.winner == p.a.method
        # order-flipping: the same letter in both orders is two different methods
        srv.push(fx.answer("B"), fx.answer("B"))
        v = J.judge_pair(client, folder, p)
        assert not v.kept and (v.first, v.second) == (p.b.method, p.a.method)
        # a refusal and a time-out: no answer, no exception, the time-out not counted as a call
        srv.push(fake.reply(None, refusal="I can't judge videos."), fake.sleep_then(3.0, fx.answer("A")))
        v = J.judge_pair(client, folder, p)
        assert (v.first, v.second, v.kept) == (None, None, False) and v.calls == 1
        assert "refused" in v.reason and "timeout" in v.reason
        # ambiguous prose and an HTTP error
        srv.push(fake.text_reply("Video A is more realistic early on but Video B is more realistic later."), fake.status(400))
        v = J.judge_pair(client, folder, p)
        assert (v.first, v.second) == (None, None) and "both" in v.reason and "HTTP 400" in v.reason
        # one answered order is not enough
        srv.push(fx.answer("A"), fake.text_reply("I cannot tell."))
        v = J.judge_pair(client, folder, p)
        assert v.first == p.a.method and v.second is None and not v.kept


def test_unusable_answers_are_not_cached(pair_set, tmp_path):
    folder, ps = pair_set
    with fake.FakeOpenAIServer(fx.first_judge(), lifetime_s=120) as srv:
        client = LLMClient(config(srv, tmp_path))
        srv.push(fake.reply(None, refusal="no"), fake.text_reply("no idea"))
        J.judge_pair(client, folder, ps.pairs[0])
        assert not list((tmp_path / "cache").rglob("*.json"))
        v = J.judge_pair(client, folder, ps.pairs[0])  # asked again: answered this time
        assert srv.n_chat == 4 and v.first == ps.pairs[0].a.method
        assert len(list((tmp_path / "cache").rglob("*.json"))) == 2


# ----------------------------------------------------------------------------- inputs
def test_missing_frame_and_bad_pair_sets_name_the_file(pair_set, tmp_path):
    folder, ps = pair_set
    cfg = ClientConfig(model="openai/m", base_url="http://127.0.0.1:9/v1", cache_dir=None)
    (folder / ps.pairs[2].b.clips[0].frames[1]).unlink()
    with pytest.raises(J.JudgeInputError, match=r"front_1\.png: pair .* side b \(defect:drawer_stuck_friction\).*cannot be read"):
        J.judge_pairs(folder, [cfg])
    (folder / ps.pairs[2].b.clips[0].frames[1]).write_bytes(b"GIF89a")
    with pytest.raises(J.JudgeInputError, match="not a PNG"):
        J.judge_pairs(folder, [cfg])
    data = json.loads((folder / "pairs.json").read_text())
    data["pairs"][0]["a"]["clips"][0]["frames"][0] = "../outside.png"
    (folder / "pairs.json").write_text(json.dumps(data))
    with pytest.raises(J.JudgeInputError, match=r"pairs\.json: .*'\.\./outside\.png' is not a relative path inside"):
        J.judge_pairs(folder, [cfg])
    data["pairs"][1]["pair_id"] = data["pairs"][0]["pair_id"]
    (folder / "pairs.json").write_text(json.dumps(data))
    with pytest.raises(J.JudgeInputError, match="appears more than once"):
        J.read_pair_set(folder)
    (folder / "pairs.json").write_text('{"pairs": [{"pair_id": 1}]}')
    with pytest.raises(J.JudgeInputError, match=r"pairs\.json: not a valid pair set: pairs\.0"):
        J.read_pair_set(folder)
    with pytest.raises(J.JudgeInputError, match="no pairs.json"):
        J.find_pair_set(tmp_path)
    assert not (folder / J.JUDGEMENTS_FILE).exists()  # nothing written on bad input


def test_two_judges_with_one_model_name_are_refused(pair_set):
    folder, _ = pair_set
    cfg = ClientConfig(model="openai/m", base_url="http://127.0.0.1:9/v1", cache_dir=None)
    with pytest.raises(ValueError, match="configured twice"):
        J.judge_pairs(folder, [cfg, cfg])


@pytest.mark.parametrize("model, family", [
    ("openai/gpt-4o", "gpt"), ("hosted_vllm/Qwen/Qwen2.5-VL-7B-Instruct", "qwen"), ("ollama/llava:13b", "llava"),
    ("gemini/gemini-2.5-flash", "gemini"), ("anthropic/claude-sonnet-4-5", "claude"), ("openai/4o", "openai"),
])
def test_family_of_model_strings(model, family):
    assert J.family_of(model) == family


def test_judgements_parquet_schema_follows_the_verdict_model(pair_set):
    folder, _ = pair_set
    J.write_judgements(folder, [])
    assert J.read_judgements(folder) == []
    schema = J.judgement_schema()
    assert schema.names == list(J.JudgeVerdict.model_fields)
    assert str(schema.field("first").type) == "string" and str(schema.field("kept").type) == "bool"


# ----------------------------------------------------------------------------- the command
def test_judge_command_two_families_writes_judgements_and_calibration(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    ps = fx.write_judge_pair_set(out / "realism", n_defect=12, n_plain=4)
    broken = fx.broken_digests(out / "realism", ps)
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "cache"))
    judges = {"good-judge": fx.good_judge(broken), "coin": fx.coin_flip_judge(seed=3)}
    with fake.FakeOpenAIServer(fx.by_model(judges), lifetime_s=120) as srv:
        rc = main(["judge", str(out), "--model", "openai/good-judge", "--base-url", srv.url, "--family", "qwen",
                   "--model", "openai/coin", "--base-url", srv.url, "--timeout", "5", "--jobs", "2"])
        assert rc == 0 and srv.n_chat == 4 * len(ps.pairs)
    text = capsys.readouterr().out
    assert "openai/good-judge (family qwen): 16 pairs, 16 kept" in text
    assert "caught 12 of 12 (sensitivity 100 %" in text and "calibrated: yes" in text
    assert "openai/coin (family coin)" in text and "calibrated: no" in text
    assert "agreement qwen (openai/good-judge) vs coin (openai/coin): kappa" in text
    assert "32 model calls, 38400 tokens" in text
    cal = json.loads((out / "realism" / "judge_calibration.json").read_text())
    assert [m["calibrated"] for m in cal["models"]] == [True, False]
    assert len(J.read_judgements(out / "realism")) == 2 * len(ps.pairs)
    written = sorted(p.name for p in (out / "realism").iterdir())
    assert written == ["clips", "judge_calibration.json", "judgements.parquet", "pairs.json", "realism_scores.parquet"]
    # only the calibrated judge's kept plain verdicts become Bradley-Terry scores; the benchmark's column reads them
    scores = read_scores(out / "realism" / "realism_scores.parquet")
    assert {s.source for s in scores} == {"openai/good-judge"} and sum(s.wins for s in scores) == 4
    assert "realism (openai/good-judge)" in text
    column = realism_column(out / "realism", ["human", "asset2sim"])
    assert column["asset2sim"] == "not rated" or "openai/good-judge" in column["asset2sim"]
    assert all("Elo [" in v or v == "not rated" for v in column.values()) and any("Elo [" in v for v in column.values())
    assert realism_column(tmp_path / "nowhere", ["human"]) == {"human": "not rated"}


def test_judge_command_errors(tmp_path, capsys):
    assert main(["judge", str(tmp_path), "--model", "openai/m", "--base-url", "http://127.0.0.1:9/v1"]) == 1
    assert "PAIRS_INVALID" in capsys.readouterr().err
    assert main(["judge", str(tmp_path)]) == 2
    assert "MODEL_REQUIRED" in capsys.readouterr().err
    assert main(["judge", str(tmp_path), "--family", "x", "--model", "openai/m"]) == 2  # a usage error: one line, status 2
    assert "--family must follow the --model" in capsys.readouterr().err
    fx.write_judge_pair_set(tmp_path, 1, 0)
    assert main(["judge", str(tmp_path), "--model", "gemini/gemini-2.5-flash"]) == 2
    err = capsys.readouterr().err
    assert "MODEL_UNAVAILABLE" in err and "GEMINI_API_KEY" in err
    digest = hashlib.sha256((tmp_path / "pairs.json").read_bytes()).hexdigest()
    assert main(["judge", str(tmp_path), "--model", "openai/a", "--model", "openai/a", "--base-url", "http://x/v1"]) == 2
    assert hashlib.sha256((tmp_path / "pairs.json").read_bytes()).hexdigest() == digest  # inputs never modified
