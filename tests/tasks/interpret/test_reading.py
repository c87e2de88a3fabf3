"""The request parsed by a model into the typed intent (asset2sim.tasks.interpret.reading) against a local fake
OpenAI-compatible server (127.0.0.1, no network): a valid reply is used and said in the report's notes; a schema
violation, garbage, an out-of-range amount, HTTP 500 or a missing backend keep the offline parse with a note; the
reply cache gives the same parse again without a call; the offline path is unchanged."""

from __future__ import annotations

import importlib.util
import json
import math
import typing

import pytest

if importlib.util.find_spec("litellm") is None:
    pytest.skip("model backends need litellm (pip install 'asset2sim[llm]')", allow_module_level=True)

from asset2sim.schemas.config import RefineConfig  # noqa: E402
from asset2sim.schemas.request import INTENT_FIELDS, RequestIntent, RequestSpec  # noqa: E402
from asset2sim.tasks.ingest.extract import extract_asset  # noqa: E402
from asset2sim.tasks.interpret.request import parse_request  # noqa: E402
from asset2sim.tasks.refine import request_notes  # noqa: E402
from asset2sim.models import client as lc  # noqa: E402
from asset2sim.models.config import ClientConfig  # noqa: E402
from asset2sim.tasks.interpret import reading as lr  # noqa: E402
from tests import fake_openai_server as fake  # noqa: E402
from tests.conftest import SHARED as DEV, needs_shared  # noqa: E402

FRIDGE = "a fridge with the freezer door open 90 degrees and the main door closed"


def client(server, tmp_path, **kw) -> lc.LLMClient:
    cfg = dict(model="openai/m", base_url=server.url, timeout_s=5.0, max_attempts=1, cache_dir=tmp_path / "cache")
    cfg.update(kw)
    return lc.LLMClient(ClientConfig(**cfg), sleep=lambda s: None)


def fridge_intent(text: str) -> dict:
    """What a model reads in FRIDGE: the freezer door (the smallest door) open 90 degrees, the main (largest) closed."""
    intent = RequestIntent(category_hint="Refrigerator", joint_states=[
        {"selector": "label", "label": "door", "ordinal": 0, "order": "size", "band": "fully",
         "target": {"kind": "angle", "value": math.pi / 2}, "phrase": "freezer door open 90 degrees"},
        {"selector": "label", "label": "door", "ordinal": -1, "order": "size", "band": "closed", "phrase": "main door closed"},
    ])
    return json.loads(intent.model_dump_json())


def test_intent_has_the_request_spec_fields_and_types():
    spec_fields, intent_fields = RequestSpec.model_fields, RequestIntent.model_fields
    assert set(intent_fields) == set(INTENT_FIELDS)
    for name in INTENT_FIELDS:
        if name == "part_counts":  # a dict in the parse, a list in the intent (a strict JSON schema has no open maps)
            continue
        assert typing.get_args(spec_fields[name].annotation) == typing.get_args(intent_fields[name].annotation) or \
            spec_fields[name].annotation == intent_fields[name].annotation, name
    spec = parse_request("a two-drawer cabinet with the top drawer open 5 cm, made of oak, 40 cm tall and 12 kg")
    intent = RequestIntent.of(spec)
    assert [c.model_dump() for c in intent.part_counts] == [{"label": "drawer", "count": 2}]
    assert {k: getattr(spec, k) for k in INTENT_FIELDS} == intent.fields()
    schema = lr.intent_schema()
    assert schema["additionalProperties"] is False and set(schema["required"]) == set(INTENT_FIELDS)


def test_valid_reply_is_used_and_noted(server, tmp_path):
    server.default = fake.intent_reply(fridge_intent)
    c = client(server, tmp_path)
    offline = parse_request(FRIDGE)
    spec = lr.parse_request_model(FRIDGE, c)
    assert spec.parser == "model" and server.n_chat == 1
    assert [js.short() for js in spec.joint_states] == ["door#0@size=90 deg from closed", "door#-1@size=closed"]
    assert spec.category_hint == "Refrigerator" and spec.text == FRIDGE and spec.ignored == offline.ignored
    assert "request parse: model openai/m, validated against the intent schema" in spec.parse_note
    assert spec.parse_note in request_notes(spec)
    sent = server.requests[-1]
    assert sent.request_text() == FRIDGE
    fmt = sent.body["response_format"]
    assert fmt["type"] == "json_schema" and fmt["json_schema"]["schema"] == lr.intent_schema()
    again = lr.parse_request_model(FRIDGE, client(server, tmp_path))  # a new client, the same reply cache: no call
    assert server.n_chat == 1 and again == spec  # the same parse, note included


@pytest.mark.parametrize("behaviour, why", [
    (fake.intent_reply(lambda t: {**fridge_intent(t), "damping": "sticky"}), "damping"),  # a schema violation
    (fake.intent_reply(lambda t: {**fridge_intent(t), "colour": "red"}), "colour"),  # a field the schema has not
    (fake.reply("the freezer door is open, the main door closed"), "the reply is not JSON"),  # garbage, not JSON
    (fake.intent_reply(lambda t: {**fridge_intent(t), "joint_states": [
        {**fridge_intent(t)["joint_states"][0], "target": {"kind": "fraction", "value": 1.5, "end": None}}]}), "fraction 1.5 outside 0..1"),
    (fake.intent_reply(lambda t: {**fridge_intent(t), "properties": [
        {"label": None, "mass": None, "material": "unobtainium", "phrase": "x"}]}), "'unobtainium' is not a materials.yaml key"),
    (fake.status(500), "500"),
])
def test_invalid_reply_keeps_the_offline_parse(server, tmp_path, behaviour, why):
    server.push(behaviour)
    spec = lr.parse_request_model(FRIDGE, client(server, tmp_path))
    offline = parse_request(FRIDGE)
    assert server.n_chat == 1  # one call, no re-ask
    assert spec.parser == "offline"
    assert spec.model_copy(update={"parse_note": ""}) == offline
    assert spec.parse_note.startswith("request parse: offline (the model's parse was not used: ") and why in spec.parse_note
    assert spec.parse_note in request_notes(spec)


def test_missing_backend_and_default(tmp_path):
    text = "A microwave with its door open about halfway and its shelf pulled out."
    assert lr.parse_request_for(text, RefineConfig()) == parse_request(text)  # the default: the offline parse, no note
    spec = lr.parse_request_for(text, RefineConfig(request_parser="model"))  # estimator offline: no model backend
    assert spec.parser == "offline" and "needs --estimator llm or openai with --model" in spec.parse_note
    assert spec.model_copy(update={"parse_note": ""}) == parse_request(text)
    spec = lr.parse_request_for(text, RefineConfig(request_parser="model", estimator="llm", model="gemini/gemini-2.5-flash"))
    assert spec.parser == "offline" and "no model backend" in spec.parse_note and "GEMINI_API_KEY" in spec.parse_note
    assert RefineConfig().config_hash() == RefineConfig(request_parser="offline").config_hash() != \
        RefineConfig(request_parser="model").config_hash()


@needs_shared
def test_interpret_on_a_dev_refrigerator(server, tmp_path, monkeypatch):
    """The model's parse reaches the estimation context of a real asset through the refine configuration."""
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "cache"))
    server.default = fake.intent_reply(fridge_intent)
    folder = next(p for p in sorted(DEV.iterdir()) if (p / "meta.json").is_file()
                  and json.loads((p / "meta.json").read_text()).get("model_cat") == "Refrigerator")
    asset = extract_asset(folder, asset_id=folder.name)
    cfg = RefineConfig(estimator="openai", model="m", base_url=server.url, request_parser="model")
    meaning = lr.interpret(asset, FRIDGE, None, None, cfg)
    assert meaning.request.parser == "model" and meaning.category == "Refrigerator"
    assert [js.short() for js in meaning.request.joint_states] == ["door#0@size=90 deg from closed", "door#-1@size=closed"]
    assert server.n_chat == 1
    assert lr.interpret(asset, FRIDGE, None, None, RefineConfig()).request == parse_request(FRIDGE)


def test_every_corpus_parse_is_a_valid_model_reply():
    """The offline parse of every corpus request, sent as a model would (JSON of the intent), validates strictly,
    passes the checks and gives the same parse back: the schema and the checks refuse no intent the parser makes."""
    from asset2sim.models.replies import parse_reply
    from tests.tasks.interpret.request_corpus import load_corpus

    entries = load_corpus()
    assert len(entries) >= 100
    for e in entries:
        offline = parse_request(e["text"])
        intent = parse_reply(RequestIntent.of(offline).model_dump_json(), RequestIntent)
        assert lr.intent_problems(intent) == [], e["id"]
        assert lr.normalised(intent) == intent, e["id"]
        back = lr.with_intent(offline, intent, "note")
        assert back.model_copy(update={"parser": "offline", "parse_note": ""}) == offline, e["id"]


def test_request_parser_is_a_refine_option_and_a_config_field(tmp_path):
    """``--request-parser model`` (``request_parser: model`` in a ``--config`` file) asks the model to parse; unset,
    the configuration is the offline parser's; another value is refused."""
    from asset2sim.cli import build_parser
    from asset2sim.commands.refine import options

    parser = build_parser("refine")
    base = ["refine", "in", "--prompt", "a box", "--out", "o", "--estimator", "openai", "--model", "m"]
    assert options(parser.parse_args(base)).request_parser == "offline"
    assert options(parser.parse_args([*base, "--request-parser", "model"])).request_parser == "model"
    cfg = tmp_path / "refine.yaml"
    cfg.write_text("request_parser: model\n")
    assert options(parser.parse_args([*base, "--config", str(cfg)])).request_parser == "model"
    with pytest.raises(SystemExit):
        parser.parse_args([*base, "--request-parser", "guess"])


def test_a_request_only_the_model_understands(server, tmp_path):
    """A request the offline parser recognises no word of, which the model reads: the model's phrases are what was
    understood (no "request not understood" warning), the words stay listed as the offline parser left them."""
    text = "la porte du frigo grande ouverte"
    assert not parse_request(text).understood
    server.push(fake.intent_reply(lambda t: json.loads(RequestIntent(category_hint="Refrigerator", joint_states=[
        {"selector": "label", "label": " Door", "band": "fully", "phrase": "porte grande ouverte"}]).model_dump_json())))
    spec = lr.parse_request_model(text, client(server, tmp_path))
    assert spec.parser == "model" and spec.understood and spec.matched == ["porte grande ouverte"]
    assert [js.short() for js in spec.joint_states] == ["door=fully"]
    notes = request_notes(spec)
    assert notes[0] == spec.parse_note and not any("not understood" in n for n in notes)


def test_refine_applies_the_models_parse_and_says_so(server, tmp_path, monkeypatch):
    """A refine with ``request_parser`` "model" against the fake server: the intent call (answered with the hinge
    30 degrees from closed where the words say "slightly open") and the overlay call; the 30 degrees are what the
    refined asset has and the report's notes name the model's parse."""
    from asset2sim.tasks.refine import refine_asset
    from tests.helpers import write_hinged_plate

    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("ASSET2SIM_LLM_RENDER_SIZE", "64")
    thirty = {"selector": "all", "band": "quarter", "target": {"kind": "angle", "value": math.pi / 6}, "phrase": "lid slightly open"}
    intent = fake.intent_reply(lambda t: json.loads(RequestIntent(joint_states=[thirty]).model_dump_json()))
    overlay = fake.valid_reply()
    server.default = lambda srv, req: (intent if req.request_text() is not None else overlay)(srv, req)
    plate = write_hinged_plate(tmp_path / "plate")
    cfg = RefineConfig(estimator="openai", model="m", base_url=server.url, request_parser="model")
    res = refine_asset(plate, "A small box with its lid slightly open.", tmp_path / "out", cfg, extras=False)
    assert server.n_chat == 2 and sum(r.request_text() is not None for r in server.requests) == 1
    assert any(n.startswith("request parse: model openai/m, validated against the intent schema (every task-relevant part 30 deg from closed)")
               for n in res.report.notes), res.report.notes
    asked = [q for q in res.report.request.quantities if q.kind == "state"]
    assert len(asked) == 1 and asked[0].asked == pytest.approx(math.pi / 6) and asked[0].within_tolerance, asked
