"""The model-reply cache proves its records (asset2sim.models.client):
each holds its key and the digest of its reply; a tampered, moved or
oversized record is rejected with a CacheWarning, deleted, and the reply is
asked again and stored anew."""

from __future__ import annotations

import json
import shutil
import warnings

import pytest

from asset2sim.array_cache import CacheWarning
from asset2sim.models import client as lc
from asset2sim.models.config import ClientConfig
from asset2sim.models.usage import Completion, Usage


def make(tmp_path, **kw) -> lc.LLMClient:
    return lc.LLMClient(ClientConfig(model="openai/m", cache_dir=tmp_path / "cache", **kw))


def key_of(c: lc.LLMClient, text: str) -> str:
    return c.cache_key([{"role": "user", "content": text}], None, 0.0)


def put(c: lc.LLMClient, key: str, content: str):
    c.cache_put(key, Completion(content, "stop", None, False, key, Usage()))
    return c._cache_path(key)


def read_quietly(c: lc.LLMClient, key: str):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return c.cache_get(key)


def test_tampered_reply_record_is_rejected(tmp_path):
    c = make(tmp_path)
    k = key_of(c, "a stapler")
    p = put(c, k, '{"mass_kg": 0.2}')
    assert read_quietly(c, k)["content"] == '{"mass_kg": 0.2}'
    rec = json.loads(p.read_text())
    rec["content"] = '{"mass_kg": 2.2}'  # an edited reply, its digest kept
    p.write_text(json.dumps(rec))
    with pytest.warns(CacheWarning, match="altered"):
        assert c.cache_get(k) is None
    assert not p.exists()
    put(c, k, '{"mass_kg": 0.2}')
    rec = json.loads(p.read_text())
    del rec["sha256"], rec["key"]  # a record without a proof
    p.write_text(json.dumps(rec))
    with pytest.warns(CacheWarning, match="no key"):
        assert c.cache_get(k) is None


def test_reply_record_moved_to_another_key_is_rejected(tmp_path):
    c = make(tmp_path)
    k1, k2 = key_of(c, "a huge stapler"), key_of(c, "a normal stapler")
    p1 = put(c, k1, '{"scale": 10}')
    p2 = c._cache_path(k2)
    p2.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(p1, p2)
    with pytest.warns(CacheWarning, match="another key"):
        assert c.cache_get(k2) is None
    assert read_quietly(c, k1)["content"] == '{"scale": 10}'


def test_oversized_reply_record_is_rejected(tmp_path):
    c = make(tmp_path, max_reply_chars=100)
    k = key_of(c, "short replies")
    p = put(c, k, "x" * 100)  # the longest reply ever stored
    assert read_quietly(c, k)["content"] == "x" * 100
    p.write_text(" " * c.cache_record_cap() + p.read_text())  # the same record, padded past the cap
    with pytest.warns(CacheWarning, match="unreadable"):
        assert c.cache_get(k) is None
    assert not p.exists()


def test_tampered_record_is_asked_again_and_stored_anew(tmp_path, monkeypatch):
    pytest.importorskip("litellm")
    from asset2sim.schemas.model_reply import ModelReply, reply_json_schema
    from tests import fake_openai_server as fake

    for k in ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY", "ANTHROPIC_API_KEY"):
        monkeypatch.delenv(k, raising=False)
    desc = {
        "category": "Box",
        "closed_extents_m": [0.2, 0.2, 0.2],
        "typical_dims_m": [0.3, 0.2, 0.1],
        "links": [{"name": "body", "volume_m3": 0.008, "area_m2": 0.24}],
        "joints": [{"name": "hinge", "requested_band": "slightly_open", "closed_position": 0.0}],
    }
    msgs = [{"role": "system", "content": "answer JSON"},
            {"role": "user", "content": [{"type": "text", "text": f"{fake.DESCRIPTION_MARK}\n{json.dumps(desc)}"}]}]
    with fake.FakeOpenAIServer(lifetime_s=120) as server:
        c = lc.LLMClient(ClientConfig(model="openai/m", base_url=server.url, timeout_s=5.0, max_attempts=2, backoff_s=0.05,
                                         max_backoff_s=0.2, cache_dir=tmp_path / "cache"))

        def ask():
            return c.ask(msgs, ModelReply, schema=reply_json_schema(), schema_name="asset2sim_overlay_reply")

        first = ask()
        [p] = (tmp_path / "cache").rglob("*.json")
        rec = json.loads(p.read_text())
        reply = json.loads(rec["content"])
        honest = reply["scale"]["value"]
        reply["scale"]["value"] = 11.0 * honest  # a tampered reply (the digest left as it was)
        rec["content"] = json.dumps(reply)
        p.write_text(json.dumps(rec))
        n = server.n_chat
        with pytest.warns(CacheWarning, match="altered"):
            again = ask()
        assert server.n_chat == n + 1 and again.usage.cached == 0 and again.reply == first.reply
        stored = read_quietly(c, rec["key"])  # stored anew, with a proof that holds
        assert stored is not None and json.loads(stored["content"])["scale"]["value"] == honest
