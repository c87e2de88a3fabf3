"""The model client (asset2sim.models.client) against a local fake
OpenAI-compatible server: retries and Retry-After, timeouts, dropped
connections, strict parsing, re-asks, the reply cache, accounting, credentials."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

if importlib.util.find_spec("litellm") is None:  # not imported here: the client imports it quietly
    pytest.skip("model backends need litellm (pip install 'asset2sim[llm]')", allow_module_level=True)

from asset2sim.array_cache import CacheWarning  # noqa: E402
from asset2sim.schemas.model_reply import ModelReply, reply_json_schema  # noqa: E402
from asset2sim.models import client as lc  # noqa: E402
from asset2sim.models import errors, replies, transport  # noqa: E402
from asset2sim.models.config import ClientConfig  # noqa: E402
from tests import fake_openai_server as fake  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]

DESC = {
    "category": "Box",
    "closed_extents_m": [0.2, 0.2, 0.2],
    "typical_dims_m": [0.3, 0.2, 0.1],
    "links": [{"name": "body", "volume_m3": 0.008, "area_m2": 0.24}],
    "joints": [{"name": "hinge", "requested_band": "slightly_open", "closed_position": 0.0}],
}


def messages(tag: str = "") -> list[dict]:
    return [
        {"role": "system", "content": "answer JSON"},
        {"role": "user", "content": [{"type": "text", "text": f"{tag}\n{fake.DESCRIPTION_MARK}\n{json.dumps(DESC)}"}]},
    ]


class Sleeps(list):
    """A sleep function that records the waits and really sleeps them."""

    def __call__(self, s: float) -> None:
        self.append(s)
        time.sleep(s)


def client(server, tmp_path, sleeps=None, **kw) -> lc.LLMClient:
    cfg = dict(model="openai/m", base_url=server.url, timeout_s=20.0, max_attempts=3, backoff_s=0.05, max_backoff_s=0.2, cache_dir=tmp_path / "cache")
    cfg.update(kw)
    return lc.LLMClient(ClientConfig(**cfg), sleep=sleeps if sleeps is not None else Sleeps())


def ask(c: lc.LLMClient, tag: str = "", **kw):
    return c.ask(messages(tag), ModelReply, schema=reply_json_schema(), schema_name="asset2sim_overlay_reply", **kw)


# ------------------------------------------------------------ strict parsing
@pytest.mark.parametrize(
    "text, match",
    [
        ("Sure! The stapler is about 15 cm long.", "not JSON"),
        ('{"a": 1, "b": [1, 2', "truncated"),
        ('{"a": NaN}', "non-finite"),
        ('{"a": -Infinity}', "non-finite"),
        ('{"a": 1e999}', "non-finite"),
        ('{"a": {"b": 1, "b": 2}}', "duplicate key 'b'"),
        ('{"a": 1} and more', "extra text"),
        ("[1, 2]", "one JSON object"),
    ],
)
def test_strict_json_rejects(text, match):
    with pytest.raises(errors.ReplyInvalid, match=match):
        replies.parse_json_strict(text)


def test_strict_json_accepts_one_fenced_object():
    assert replies.parse_json_strict('```json\n{"a": 1.5}\n```') == {"a": 1.5}


def _valid() -> dict:
    return fake.valid_reply_content(DESC)


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: d.update(extra_field=1), "extra_field: Extra inputs"),
        (lambda d: d.pop("joints"), "joints: Field required"),
        (lambda d: d["links"][0].pop("density"), "links.0.density: Field required"),
        (lambda d: d["links"][0].update(density=-5.0), "links.0.density"),
        (lambda d: d["scale"].update(value=1e6), "scale.value 1000000.0 must be in"),
        (lambda d: d["scale"].update(std=0.0), "scale.std"),
        (lambda d: d["joints"][0]["damping"].update(value=-1.0), "damping.value -1.0 must be in"),
        (lambda d: d["joints"][0].update(band="ajar"), "joints.0.band"),
        (lambda d: d["scale"].update(value="0.2"), "scale.value: Input should be a valid number"),
        (lambda d: d["notes"].update(size="x" * 5000), "at most 2000"),
    ],
)
def test_reply_schema_rejects_extra_missing_and_out_of_range(mutate, match):
    d = _valid()
    mutate(d)
    with pytest.raises(errors.ReplyInvalid) as ei:
        replies.parse_reply(json.dumps(d), ModelReply)
    assert any(match in e for e in ei.value.errors), ei.value.errors


def test_sent_schema_is_closed_and_uses_supported_keywords_only():
    schema = reply_json_schema()
    allowed = {
        "type", "properties", "required", "additionalProperties", "items", "enum", "description",
        "$defs", "$ref", "anyOf", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum", "maxItems",
    }
    n_objects = 0

    def walk(node):
        nonlocal n_objects
        if isinstance(node, dict):
            if node.get("type") == "object":
                n_objects += 1
                assert node["additionalProperties"] is False
                assert sorted(node["required"]) == sorted(node["properties"])
            for k, v in node.items():
                if k in ("properties", "$defs"):
                    for sub in v.values():
                        walk(sub)
                else:
                    assert k in allowed, k
                    walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(schema)
    assert n_objects == 5  # the reply, Estimate, LinkReply, JointReply, ReplyNotes
    # what a model sees must parse back: the fake's valid reply follows it
    replies.parse_reply(json.dumps(_valid()), ModelReply)


# ---------------------------------------------------------------- the network
def test_valid_reply_one_call_tokens_and_request_shape(server, tmp_path):
    c = client(server, tmp_path)
    a = ask(c)
    assert isinstance(a.reply, ModelReply) and a.history == []
    assert (a.usage.calls, a.usage.attempts, a.usage.cached) == (1, 1, 0)
    assert a.usage.total_tokens == 1200 and a.usage.prompt_tokens == 1000
    assert a.usage.cost_usd is None  # "m" is not in litellm's cost table
    req = server.requests[0]
    rf = req.body["response_format"]
    assert rf["type"] == "json_schema" and rf["json_schema"]["schema"] == reply_json_schema()
    assert req.headers["authorization"] == f"Bearer {transport.NO_KEY}"  # local server: no key needed
    assert req.body["temperature"] == 0.0 and req.body["max_tokens"] == c.config.max_tokens


def test_429_with_retry_after_waits_that_long(server, tmp_path):
    server.push(fake.status(429, headers={"Retry-After": "1"}))
    sleeps = Sleeps()
    a = ask(client(server, tmp_path, sleeps))
    assert server.n_chat == 2 and a.usage.attempts == 2 and a.usage.calls == 1
    assert sleeps == [1.0]
    assert server.requests[1].t - server.requests[0].t >= 0.95


def test_retry_after_ms_and_http_date(server, tmp_path):
    server.push(fake.status(429, headers={"retry-after-ms": "300"}))
    sleeps = Sleeps()
    ask(client(server, tmp_path, sleeps))
    assert sleeps == [pytest.approx(0.3)]

    class E(Exception):
        litellm_response_headers = {"retry-after": time.strftime("%a, %d %b %Y %H:%M:%S GMT", time.gmtime(time.time() + 30))}

    assert 25 <= transport.retry_after_s(E()) <= 31


def test_429_without_retry_after_uses_exponential_backoff(server, tmp_path):
    server.push(fake.status(429), fake.status(429))
    sleeps = Sleeps()
    ask(client(server, tmp_path, sleeps, max_attempts=3))
    assert sleeps == [pytest.approx(0.05), pytest.approx(0.1)]
    assert server.n_chat == 3


def test_retry_after_beyond_the_limit_fails_at_once(server, tmp_path):
    server.push(fake.status(429, headers={"Retry-After": "3600"}))
    with pytest.raises(errors.ModelCallError, match="retry after 3600 s") as ei:
        ask(client(server, tmp_path))
    assert server.n_chat == 1 and ei.value.status == 429


@pytest.mark.parametrize("code", [500, 503])
def test_server_errors_are_retried(server, tmp_path, code):
    server.push(fake.status(code))
    a = ask(client(server, tmp_path))
    assert server.n_chat == 2 and a.usage.attempts == 2


def test_persistent_503_gives_up_after_max_attempts(server, tmp_path):
    server.push(*[fake.status(503)] * 10)
    with pytest.raises(errors.ModelCallError, match="gave up after 3 attempts"):
        ask(client(server, tmp_path, max_attempts=3))
    assert server.n_chat == 3


@pytest.mark.parametrize("code", [400, 401, 404])
def test_client_errors_are_not_retried(server, tmp_path, code):
    server.push(fake.status(code))
    with pytest.raises(errors.ModelCallError, match="not retried"):
        ask(client(server, tmp_path))
    assert server.n_chat == 1


def test_timeout_is_retried(server, tmp_path):
    server.push(fake.sleep_then(5.0))
    t0 = time.monotonic()
    a = ask(client(server, tmp_path, timeout_s=0.8))
    assert server.n_chat == 2 and a.usage.attempts == 2
    assert time.monotonic() - t0 < 4.5  # gave up on the slow answer


def test_only_timeouts_end_in_a_clear_error(server, tmp_path):
    server.push(*[fake.sleep_then(5.0)] * 3)
    with pytest.raises(errors.ModelCallError, match="timeout.*gave up after 2 attempts"):
        ask(client(server, tmp_path, timeout_s=0.5, max_attempts=2))


def test_dropped_connection_is_retried(server, tmp_path):
    server.push(fake.drop())
    a = ask(client(server, tmp_path))
    assert server.n_chat == 2 and a.usage.calls == 1


def test_ten_megabyte_junk_body_is_retried_then_fails_clearly(server, tmp_path):
    junk = fake.raw(b"x" * (10 * 1024 * 1024))
    server.push(junk, junk, junk)
    with pytest.raises(errors.ModelCallError, match="gave up after 3 attempts"):
        ask(client(server, tmp_path))
    assert server.n_chat == 3


# ---------------------------------------------------------------- re-asking
@pytest.mark.parametrize(
    "bad, expect",
    [
        (fake.text_reply("Here is my estimate: the object is small."), "not JSON"),
        (fake.text_reply('{"category": "Box", "scale": {"value": 0.2, "std"'), "truncated"),
        (fake.json_with_nan(), "non-finite number NaN"),
        (fake.text_reply('{"category": "Box", "category": "Bin"}'), "duplicate key"),
        (fake.valid_reply(lambda d: d.update(bonus=1)), "Extra inputs"),
        (fake.valid_reply(lambda d: d.pop("links")), "links: Field required"),
        (fake.valid_reply(lambda d: d["links"][0].update(density=1e9)), "density"),
        (fake.reply(None, refusal="I can't help with that."), "the model refused"),
        (fake.reply('{"category": "Bo', finish_reason="length"), "cut off at the token limit"),
        (fake.reply("y" * (10 * 1024 * 1024)), "more than the 1000000 allowed"),
    ],
)
def test_unusable_reply_is_reasked_with_the_problem(server, tmp_path, bad, expect):
    server.push(bad)
    a = ask(client(server, tmp_path))
    assert server.n_chat == 2 and a.usage.calls == 2
    assert len(a.history) == 1 and any(expect in e for e in a.history[0]), a.history
    followup = server.requests[1].body["messages"]
    assert followup[-2]["role"] == "assistant" and len(followup[-2]["content"]) < 5000  # the 10 MB is not sent back
    assert followup[-1]["role"] == "user" and expect in followup[-1]["content"]


def test_three_unusable_replies_end_in_a_reply_error(server, tmp_path):
    server.push(*[fake.text_reply("no JSON today")] * 5)
    with pytest.raises(errors.ReplyError, match="no usable reply after 3 replies") as ei:
        ask(client(server, tmp_path))
    assert server.n_chat == 3 and len(ei.value.history) == 3


def test_accept_rejection_is_reasked_and_replayed_from_cache(server, tmp_path):
    seen = []

    def accept(r):
        seen.append(r)
        if len(seen) == 1:
            raise errors.ReplyInvalid(["links.0.link: 'body' is not a link of the asset"])
        return "ok"

    a = ask(client(server, tmp_path), accept=accept)
    assert a.value == "ok" and server.n_chat == 2
    assert "'body' is not a link" in server.requests[1].body["messages"][-1]["content"]
    # a rerun asks again for the rejected reply (never cached) and replays the accepted one from the cache
    seen.clear()
    b = ask(client(server, tmp_path), accept=accept)
    assert b.value == "ok" and server.n_chat == 3 and b.usage.cached == 1 and b.usage.calls == 1


def test_only_accepted_replies_are_cached_and_the_key_names_the_server(tmp_path):
    """A server whose replies parse but fail validation: nothing is cached, so a rerun against a fixed server (another
    base URL) asks that server and succeeds; the cache key holds the base URL (the same prompt to two servers is two
    entries) but never the API key."""

    def reject(r):
        raise errors.ReplyInvalid(["links.0.link: 'body' is not a link of the asset"])

    with fake.FakeOpenAIServer(lifetime_s=60) as broken, fake.FakeOpenAIServer(lifetime_s=60) as fixed:
        with pytest.raises(errors.ReplyError):
            ask(client(broken, tmp_path), accept=reject)
        assert broken.n_chat == 3 and not list((tmp_path / "cache").rglob("*.json"))
        good = client(fixed, tmp_path)
        assert ask(good).usage.calls == 1 and fixed.n_chat == 1
        assert len(list((tmp_path / "cache").rglob("*.json"))) == 1
        keys = {client(srv, tmp_path).cache_key(messages(), {"a": 1}, 0.0) for srv in (broken, fixed)}
        assert len(keys) == 2
        keyed = lc.LLMClient(replace(good.config, api_key="sk-secret"))
        assert keyed.cache_key(messages(), {"a": 1}, 0.0) == good.cache_key(messages(), {"a": 1}, 0.0)


# ------------------------------------------------------------------- caching
def test_cache_makes_reruns_free_and_keys_on_prompt_images_and_schema(server, tmp_path):
    c = client(server, tmp_path)
    ask(c)
    ask(c)
    assert server.n_chat == 1 and c.usage.cached == 1
    ask(c, tag="another prompt")
    assert server.n_chat == 2
    m1 = messages()
    m2 = messages()
    m2[1]["content"].append({"type": "image_url", "image_url": {"url": "data:image/png;base64,AAAA"}})
    assert c.cache_key(m1, {"a": 1}, 0.0) != c.cache_key(m2, {"a": 1}, 0.0)
    assert c.cache_key(m1, {"a": 1}, 0.0) != c.cache_key(m1, {"a": 2}, 0.0)
    other_model = lc.LLMClient(replace(c.config, model="openai/other"))
    assert other_model.cache_key(m1, {"a": 1}, 0.0) != c.cache_key(m1, {"a": 1}, 0.0)


def test_invalid_replies_are_not_cached_and_corrupt_cache_is_ignored(server, tmp_path):
    c = client(server, tmp_path)
    server.push(*[fake.text_reply("prose")] * 3)
    with pytest.raises(errors.ReplyError):
        ask(c)
    assert not list((tmp_path / "cache").rglob("*.json"))
    ask(c)  # the server answers validly now
    files = list((tmp_path / "cache").rglob("*.json"))
    assert len(files) == 1
    files[0].write_text("{not json")
    n = server.n_chat
    with pytest.warns(CacheWarning, match=r"reply cache: record .* rejected: unreadable .*asking again"):
        ask(c)
    assert server.n_chat == n + 1


def test_cache_disabled(server, tmp_path):
    c = client(server, tmp_path, cache_dir=None)
    ask(c)
    ask(c)
    assert server.n_chat == 2


# ---------------------------------------------------------------- credentials
def test_missing_key_is_a_clear_error(monkeypatch, tmp_path):
    c = lc.LLMClient(ClientConfig(model="gemini/gemini-2.5-flash", cache_dir=None))
    with pytest.raises(errors.MissingCredentials, match="GEMINI_API_KEY"):
        c.check_credentials()
    monkeypatch.setenv("GEMINI_API_KEY", "test-key")
    c.check_credentials()
    with pytest.raises(errors.MissingCredentials, match="OPENAI_API_KEY"):
        lc.LLMClient(ClientConfig(model="openai/gpt-4o-mini")).check_credentials()


def test_local_server_needs_no_key_but_a_provider(tmp_path):
    lc.LLMClient(ClientConfig(model="openai/m", base_url="http://127.0.0.1:9/v1")).check_credentials()
    with pytest.raises(errors.MissingCredentials, match="provider/model"):
        lc.LLMClient(ClientConfig(model="no-such-provider-model")).check_credentials()


def test_config_from_env(monkeypatch, tmp_path):
    monkeypatch.setenv("ASSET2SIM_LLM_TIMEOUT_S", "7.5")
    monkeypatch.setenv("ASSET2SIM_LLM_MAX_ATTEMPTS", "2")
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "c"))
    cfg = ClientConfig.from_env("openai/m", "http://x/v1", backoff_s=0.0)
    assert (cfg.timeout_s, cfg.max_attempts, cfg.cache_dir, cfg.backoff_s) == (7.5, 2, tmp_path / "c", 0.0)
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", "off")
    assert ClientConfig.from_env("openai/m").cache_dir is None
    monkeypatch.setenv("ASSET2SIM_LLM_TIMEOUT_S", "soon")
    with pytest.raises(ValueError, match="ASSET2SIM_LLM_TIMEOUT_S"):
        ClientConfig.from_env("openai/m")
    with pytest.raises(ValueError, match="max_attempts"):
        ClientConfig(model="openai/m", max_attempts=0)


def test_package_imports_without_litellm():
    code = (
        "import sys\n"
        "import asset2sim.models.client, asset2sim.tasks.synthesize.llm_estimator, asset2sim.schemas.model_reply, asset2sim.tasks.synthesize.ivw\n"
        "import asset2sim.tasks.synthesize.estimate, asset2sim.tasks.refine\n"
        "assert 'litellm' not in sys.modules, 'litellm imported at package import'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, timeout=120)


def test_forbidden_litellm_version_is_refused(monkeypatch):
    import importlib.metadata

    real = importlib.metadata.version
    monkeypatch.setattr(importlib.metadata, "version", lambda name: "1.107.0" if name == "litellm" else real(name))
    with pytest.raises(errors.LLMUnavailable, match="1.107.0"):
        transport.import_litellm()
