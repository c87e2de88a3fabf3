"""The model-backend modules split by concern (settings, errors, transport,
reply parsing, accounting; prompts, reply -> overlay, baselines): the public
names stay importable from ``llm_client`` / ``llm_estimator``, and the pieces
work on their own (no litellm needed here)."""

from __future__ import annotations

import json

import pytest

from asset2sim.schemas.model_reply import JointProposalReply, reply_json_schema
from asset2sim.tasks.synthesize import (
    llm_baselines,
    llm_client,
    llm_config,
    llm_errors,
    llm_estimator,
    llm_overlay,
    llm_prompt,
    llm_reply,
    llm_transport,
    llm_usage,
)
from asset2sim.tasks.synthesize.context import build_context
from tests.helpers import write_hinged_plate


@pytest.mark.parametrize(
    ("facade", "homes", "own"),
    [
        (llm_client, (llm_config, llm_errors, llm_transport, llm_reply, llm_usage), {"LLMClient", "CACHE_FORMAT", "make_client",
                                                                                  "model_string"}),
        (llm_estimator, (llm_prompt, llm_overlay, llm_baselines, llm_client), {"LLMEstimator", "OpenAICompatibleEstimator"}),
    ],
)
def test_public_names_are_the_homes_objects(facade, homes, own) -> None:
    for name in facade.__all__:
        obj = getattr(facade, name)
        if name in own:
            assert all(not hasattr(h, name) for h in homes), name
        else:
            assert any(vars(h).get(name) is obj and getattr(obj, "__module__", h.__name__) == h.__name__ for h in homes), name


class _Status(Exception):
    def __init__(self, status: int, headers: dict[str, str] | None = None, on_response: bool = False):
        super().__init__(f"status {status}")
        if on_response:
            self.response = type("R", (), {"status_code": status, "headers": headers or {}})()
        else:
            self.status_code = status
            self.headers = headers or {}


def test_transport_classifies_faults() -> None:
    assert llm_transport.classify(TimeoutError("slow")) == (True, None, "connection error")
    assert llm_transport.classify(_Status(429)) == (True, 429, "HTTP 429")
    assert llm_transport.classify(_Status(503, on_response=True)) == (True, 503, "HTTP 503")
    assert llm_transport.classify(_Status(400)) == (False, 400, "HTTP 400")
    assert llm_transport.classify(KeyError("bug")) == (False, None, "KeyError")
    assert llm_transport.retry_after_s(_Status(429, {"retry-after-ms": "1500"})) == pytest.approx(1.5)
    assert llm_transport.retry_after_s(_Status(429, {"Retry-After": "7"})) == pytest.approx(7.0)
    assert llm_transport.retry_after_s(_Status(429)) is None
    assert llm_transport.short_error(ValueError("a\nb" + "x" * 400), 10) == "a"  # the first line only
    assert llm_transport.short_error(ValueError("x" * 400), 10) == "xxxxxxx..."
    assert llm_transport.short_error(RuntimeError("HTTP 500: down Traceback (most recent call last):\n  File x")) == "HTTP 500: down"


def test_reply_parsing_and_reask() -> None:
    assert llm_reply.parse_json_strict('```json\n{"a": 1}\n```') == {"a": 1}
    for bad in ('{"a": 1, "a": 2}', '{"a": NaN}', '{"a": 1e999}', "[1]", '{"a": 1} tail', "prose"):
        with pytest.raises(llm_errors.ReplyInvalid):
            llm_reply.parse_json_strict(bad)
    text = llm_reply.reask_text(["x: missing", "y: too large"])
    assert "- x: missing\n- y: too large" in text
    assert llm_reply.excerpt("abcdef", 3) == "abc... [3 more characters omitted]"


def test_usage_since_a_snapshot() -> None:
    u = llm_usage.Usage(calls=1, attempts=2, total_tokens=10, cost_usd=0.5, seconds=1.0)
    before = u.snapshot()
    u.add(llm_usage.Usage(calls=2, attempts=3, cached=1, total_tokens=5, cost_usd=0.25, seconds=0.5))
    d = u.since(before)
    assert (d.calls, d.attempts, d.cached, d.total_tokens) == (2, 3, 1, 5)
    assert d.cost_usd == pytest.approx(0.25) and d.seconds == pytest.approx(0.5)


def test_config_overrides_keep_the_rest() -> None:
    cfg = llm_config.ClientConfig(model="openai/m", timeout_s=5.0)
    new = llm_config.with_overrides(cfg, max_attempts=2)
    assert (new.model, new.timeout_s, new.max_attempts) == ("openai/m", 5.0, 2)


def test_proposal_messages_summarise_the_stalled_search(tmp_path) -> None:
    plate = write_hinged_plate(tmp_path / "plate")
    schema = reply_json_schema(JointProposalReply)
    with build_context(plate, "a box with its lid slightly open") as ctx:
        msgs = llm_prompt.proposal_messages(
            ctx,
            {"hinge": 0.1234567891, "other": 0.0},
            [{"link_a": "body", "link_b": "plate", "depth_m": 0.00123456789}],
            {"hinge": (-1.0, 2.0)},
            schema,
        )
    assert [m["role"] for m in msgs] == ["system", "user"]
    assert msgs[0]["content"].endswith(json.dumps(schema))
    mark, body = msgs[1]["content"].split("\n", 1)
    assert mark == llm_prompt.PROPOSAL_MARK
    info = json.loads(body)
    assert info["joints"] == [{"name": "hinge", "type": "revolute", "part": None, "current": 0.123457, "allowed": [-1.0, 2.0]}]
    assert info["colliding_link_pairs"] == [{"link_a": "body", "link_b": "plate", "penetration_m": 0.001235}]
    assert info["request"] == "a box with its lid slightly open"
