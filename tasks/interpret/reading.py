"""The request read, stage 3 in one call (:func:`interpret`: the parse, the overrides, the
category), and the request parsed by a model into the typed intent
(:class:`~asset2sim.schemas.request.RequestIntent`) beside the offline parser
(``--request-parser model``, ``RefineConfig.request_parser``).

The request text goes to the model of ``--estimator llm`` / ``openai`` with the intent's JSON schema
(as a strict ``json_schema`` response format and in the system prompt) through
:class:`~asset2sim.models.client.LLMClient`, so the call has its deadline, reply size cap, nesting
cap and reply cache (the same text, model and schema give the same reply). The reply is validated
into :class:`RequestIntent` and checked (:func:`intent_problems`); a valid reply replaces the
offline parse's intent fields, and anything else (no model backend, litellm missing, the call
failed, a reply that does not validate) keeps the offline parse. Either way ``RequestSpec.parser``
and ``parse_note`` say which parse was used and why; the note goes to the report's notes
(``tasks.refine.request_notes``). Design: ``docs/design/model_backends.md``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from asset2sim.inert import one_line
from asset2sim.models.client import LLMClient, make_client
from asset2sim.models.errors import LLMError, ReplyInvalid
from asset2sim.prior_tables import load_priors
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.model_reply import reply_json_schema
from asset2sim.schemas.request import RequestIntent, RequestOverrides, RequestSpec
from asset2sim.tasks.interpret.categories import recognize_category
from asset2sim.tasks.interpret.overrides import apply_overrides
from asset2sim.tasks.interpret.request import parse_request
from asset2sim.tasks.interpret.size_priors import size_factor
from asset2sim.package_data import package_text

INTENT_SCHEMA_NAME = "request_intent"

INTENT_MARK = "REQUEST TO PARSE:"
"""Line that precedes the request text in the user message (a test server finds the request after
it)."""

#: Estimators whose model may parse the request.
MODEL_ESTIMATORS = ("llm", "openai")

#: The system prompt of the model's parse (``intent_prompt.txt`` beside this module; ``{materials}``: the material keys).
SYSTEM_PROMPT = package_text(__package__, "intent_prompt.txt").removesuffix("\n")


def intent_schema() -> dict[str, Any]:
    """The JSON schema of :class:`RequestIntent` as sent to model APIs (every property required, no
    additional properties; :func:`asset2sim.schemas.model_reply.reply_json_schema`). A fresh
    dict."""
    return reply_json_schema(RequestIntent)


def intent_messages(text: str, schema: dict[str, Any]) -> list[dict[str, Any]]:
    """OpenAI-format messages: the system prompt with ``schema``, then :data:`INTENT_MARK` and the
    request."""
    system = (SYSTEM_PROMPT.replace("{materials}", ", ".join(sorted(load_priors().materials))) + "\nJSON schema:\n"
              + json.dumps(schema, separators=(",", ":")))
    return [{"role": "system", "content": system},
            {"role": "user", "content": f"{INTENT_MARK}\n{text}"}]


#: The most a target of each kind may ask (fraction, rad, m), its unit and the range as a problem names it.
_TARGET_RANGES = {"fraction": (1.0, "", "0..1"), "angle": (2.0 * math.pi, " rad", "0..2 pi (radians from the closed end)"),
                  "distance": (10.0, " m", "0..10 m")}


def intent_problems(intent: RequestIntent) -> list[str]:
    """What a schema-valid intent still gets wrong, one line each ([] when usable): a joint named (a
    request names parts), a part state without its label, a target without its number or end or out
    of range (a fraction outside 0..1, an angle beyond one turn), a material not in
    ``materials.yaml``, a mass that is not positive."""
    out: list[str] = []
    for i, js in enumerate(intent.joint_states):
        where = f"joint_states[{i}] ({js.phrase!r})"
        if js.selector == "joint":
            out.append(f"{where}: selector 'joint' is for overrides; name the part with selector "
                       "'label'")
        if js.selector == "label" and not (js.label or "").strip():
            out.append(f"{where}: selector 'label' without a label")
        t = js.target
        if t is None:
            continue
        if t.kind == "end":
            if t.end is None:
                out.append(f"{where}: target kind 'end' without its end")
        elif t.value is None or not math.isfinite(t.value):
            out.append(f"{where}: target kind {t.kind!r} without a finite value")
        elif not 0.0 <= t.value <= _TARGET_RANGES[t.kind][0]:
            _, unit, span = _TARGET_RANGES[t.kind]
            out.append(f"{where}: {t.kind} {t.value}{unit} outside {span}")
    known = load_priors().materials
    for i, p in enumerate(intent.properties):
        if p.material is not None and p.material not in known:
            out.append(f"properties[{i}]: material {p.material!r} is not a materials.yaml key")
        if p.mass is not None and not (math.isfinite(p.mass) and p.mass > 0.0):
            out.append(f"properties[{i}]: mass {p.mass} kg is not positive")
    return out


def normalised(intent: RequestIntent) -> RequestIntent:
    """``intent`` with its part labels as the offline parser writes them: stripped, lower case,
    single spaces ("Door " -> "door")."""
    return intent.model_copy(update={k: [x.model_copy(update={"label": x.label and " ".join(x.label.lower().split())})
                                         for x in getattr(intent, k)]
                                     for k in ("joint_states", "properties", "dynamics_values", "part_counts")})


def with_intent(offline: RequestSpec, intent: RequestIntent, note: str) -> RequestSpec:
    """``offline`` with the intent fields of ``intent`` (``size_factor`` from the size class's prior
    factor when the class differs), ``parser`` "model" and ``parse_note`` ``note``; the model's
    phrases are the recognised words when the offline parser recognised none
    (``RequestSpec.understood``)."""
    fields = intent.fields()
    if intent.size_class != offline.size_class:
        fields["size_factor"] = size_factor(intent.size_class)
        fields["size_phrase"] = ""
    if not offline.matched:  # nothing recognised offline: the model's phrases were understood
        phrases = [x.phrase for x in (*intent.joint_states, *intent.sizes, *intent.properties)]
        fields["matched"] = list(dict.fromkeys(" ".join(p.split()) for p in phrases if p.strip()))
    return offline.model_copy(update={**fields, "parser": "model", "parse_note": note})


def parse_request_model(text: str, client: LLMClient,
                        offline: RequestSpec | None = None) -> RequestSpec:
    """The request parsed by ``client``'s model, or the offline parse (``offline``, else
    :func:`parse_request`) with a note on why: one call (no re-ask; the reply cache answers a
    repeat), the reply validated into :class:`RequestIntent` and :func:`intent_problems`.

    Raises:
        TypeError, RequestTooLong: as :func:`parse_request` (before any call).
    """
    offline = offline if offline is not None else parse_request(text)
    if not text.strip():
        return offline.model_copy(update={"parse_note": "request parse: offline (the request is empty; no model call)"})
    schema = intent_schema()

    def accept(intent: RequestIntent) -> RequestIntent:
        if problems := intent_problems(intent):
            raise ReplyInvalid(problems)
        return normalised(intent)

    try:
        answer = client.ask(intent_messages(text, schema), RequestIntent, schema=schema,
                            schema_name=INTENT_SCHEMA_NAME, accept=accept, max_reasks=0)
    except LLMError as exc:  # the call failed, or the reply did not validate (ReplyError lists why)
        why = f"the model's parse was not used: {one_line(exc, 400)}"
        return offline.model_copy(update={"parse_note": f"request parse: offline ({why})"})
    # the same note from the cache: same output
    states = ", ".join(js.words() for js in answer.value.joint_states) or "no states"
    return with_intent(offline, answer.value, f"request parse: model {client.config.model}, "
                       f"validated against the intent schema ({states})")


def parse_request_for(text: str, config: RefineConfig | None = None,
                      client: LLMClient | None = None) -> RequestSpec:
    """The request's parse as ``config.request_parser`` asks: the offline parse (the default), or
    the model's (:func:`parse_request_model`) with ``client``, else a client for ``config``'s
    estimator, model and base URL (knobs and reply cache from the environment,
    :meth:`~asset2sim.models.config.ClientConfig.from_env`). Without a model backend (another
    estimator, no model, litellm or the provider's key missing) the offline parse is kept with a
    note.

    Raises:
        TypeError, RequestTooLong: as :func:`parse_request`.
    """
    config = config or RefineConfig()
    offline = parse_request(text)
    if config.request_parser == "offline":
        return offline
    if client is None:
        if config.estimator not in MODEL_ESTIMATORS or not config.model:
            why = f"estimator {config.estimator!r}" + ("" if config.model else ", no model")
            note = ("request parse: offline (--request-parser model needs --estimator llm or "
                    f"openai with --model; {why})")
            return offline.model_copy(update={"parse_note": note})
        try:
            client = make_client(config.estimator, config.model, config.base_url)
        except (LLMError, ValueError) as exc:
            return offline.model_copy(update={"parse_note": f"request parse: offline (no model backend: {one_line(exc)})"})
    return parse_request_model(text, client, offline)


@dataclass(frozen=True)
class Interpretation:
    """The request and the category of one asset (stage 3)."""

    request: RequestSpec
    category: str
    category_reason: str


def interpret(asset: AssetDescription, prompt: str, category: str | None = None,
              overrides: RequestOverrides | None = None,
              config: RefineConfig | None = None) -> Interpretation:
    """Parse ``prompt`` (``overrides`` win over its words) and recognise the category of ``asset``
    (``category`` wins over the asset's own; else labels and words decide).
    ``config.request_parser`` "model": the model of ``config.estimator`` parses the request, the
    offline parse kept when its parse is not valid (:func:`parse_request_for`).

    Raises:
        OverrideError: an override does not fit the asset.
    """
    spec = apply_overrides(parse_request_for(prompt, config), overrides, asset)
    labels = [ln.semantic_label for ln in asset.links if ln.semantic_label]
    match = recognize_category(category or asset.category, labels, prompt)
    return Interpretation(spec, match.name, match.reason)
