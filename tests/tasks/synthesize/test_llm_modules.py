"""The model backends split by concern: the client's pieces in the wing ``asset2sim/models/``
(settings, errors, transport, reply parsing, accounting) and the estimator's in this stage (prompts,
reply -> overlay, baselines); the estimator's public names stay importable from ``llm_estimator``,
and the pieces work on their own (no litellm needed here)."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from asset2sim.inert import one_line
from asset2sim.models import client, config, errors, replies, transport, usage
from asset2sim.schemas.model_reply import JointProposalReply, reply_json_schema
from asset2sim.tasks.synthesize import llm_baselines, llm_estimator, llm_overlay, llm_prompt
from asset2sim.tasks.synthesize.context import build_context
from tests.helpers import write_hinged_plate


def test_public_names_are_the_homes_objects() -> None:
    homes = (llm_prompt, llm_overlay, llm_baselines, client)
    for name in llm_estimator.__all__:
        obj = getattr(llm_estimator, name)
        if name in {"LLMEstimator", "OpenAICompatibleEstimator"}:
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
    assert transport.classify(TimeoutError("slow")) == (True, None, "connection error")
    assert transport.classify(_Status(429)) == (True, 429, "HTTP 429")
    assert transport.classify(_Status(503, on_response=True)) == (True, 503, "HTTP 503")
    assert transport.classify(_Status(400)) == (False, 400, "HTTP 400")
    assert transport.classify(KeyError("bug")) == (False, None, "KeyError")
    assert transport.retry_after_s(_Status(429, {"retry-after-ms": "1500"})) == pytest.approx(1.5)
    assert transport.retry_after_s(_Status(429, {"Retry-After": "7"})) == pytest.approx(7.0)
    assert transport.retry_after_s(_Status(429)) is None
    assert one_line(ValueError("a\nb" + "x" * 400), 10) == "a"  # a model error: the first line only
    assert one_line(ValueError("x" * 400), 10) == "xxxxxxx..."
    assert one_line(RuntimeError("HTTP 500: down Traceback (most recent call last):\n  File x")) == "HTTP 500: down"


def test_reply_parsing_and_reask() -> None:
    assert replies.parse_json_strict('```json\n{"a": 1}\n```') == {"a": 1}
    for bad in ('{"a": 1, "a": 2}', '{"a": NaN}', '{"a": 1e999}', "[1]", '{"a": 1} tail', "prose"):
        with pytest.raises(errors.ReplyInvalid):
            replies.parse_json_strict(bad)
    text = replies.reask_text(["x: missing", "y: too large"])
    assert "- x: missing\n- y: too large" in text
    assert replies.excerpt("abcdef", 3) == "abc... [3 more characters omitted]"


def test_usage_since_a_snapshot() -> None:
    u = usage.Usage(calls=1, attempts=2, total_tokens=10, cost_usd=0.5, seconds=1.0)
    before = u.snapshot()
    u.add(usage.Usage(calls=2, attempts=3, cached=1, total_tokens=5, cost_usd=0.25, seconds=0.5))
    d = u.since(before)
    assert (d.calls, d.attempts, d.cached, d.total_tokens) == (2, 3, 1, 5)
    assert d.cost_usd == pytest.approx(0.25) and d.seconds == pytest.approx(0.5)


def test_config_overrides_keep_the_rest() -> None:
    cfg = config.ClientConfig(model="openai/m", timeout_s=5.0)
    new = replace(cfg, max_attempts=2)
    assert (new.model, new.timeout_s, new.max_attempts) == ("openai/m", 5.0, 2)


def test_proposal_messages_summarise_the_stalled_search(tmp_path) -> None:
    plate = write_hinged_plate(tmp_path / "plate")
    schema = reply_json_schema(JointProposalReply)
    with build_context(plate, "a box with its lid slightly open") as (ctx, kin):
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
