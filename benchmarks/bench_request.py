"""Request parsing time against request length (``tasks.interpret.request``).

Prints the wall time of ``parse_request`` for requests of 1 KiB .. 1 MB built
by repeating a realistic request (sizes, parts, ordinals, states, dynamics,
category words, clause marks), the time per KiB (flat when parsing is linear),
and the time to refuse a request above the length cap
(:data:`~asset2sim.tasks.interpret.request.MAX_REQUEST_CHARS`, raising
``RequestTooLong``). Requests above the cap are timed with the cap lifted for
the measurement only.

It then parses the request corpus (``tests/data/request_corpus.yaml``:
requests over the dev objects, the demo assets and generated objects) and
prints the share of parses that match their expected parse, the misses, and
the parse time per request; the rate per phenomenon (synonym, ordinal,
quantifier, compound, negation, hedge, fraction, unit, volume, missing part;
the rest "general"), an entry counting when its parse matches and, for the
hand-written entries, the request resolved on its object sets the expected
joints (no refine); and 600 requests generated from structured intents
(``tests/tasks/interpret/request_generated.py``), the share whose parse gives
the intent back, per phenomenon; ``--outcomes N`` also refines the first N corpus
entries that have an expected outcome (``all``: every one; dev objects
included, minutes) and prints how many land (numbers within 5 %, bands in
their interval, sizes, masses, materials, damping levels, warnings).

``--model URL`` also parses the corpus and the generated requests with the model path
(``--request-parser model``: ``tasks/interpret/reading.py``) against the OpenAI-compatible server at URL
(``--model-name``, default ``m``; 127.0.0.1 for a local server) and prints the parse rate per phenomenon of
both paths side by side, with the calls made and the replies the offline parse replaced; ``--model fake``
starts a local fake server (``tests/fake_openai_server.py``) that answers each request with the offline
parser's own intent: it measures the plumbing (schema, validation, reply cache, fallbacks), not a model.

    python benchmarks/bench_request.py [--sizes 1024,131072,1000000] [--outcomes 10|all] [--model fake|URL]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from asset2sim.tasks.interpret import request

SENTENCE = (
    "I want a very small two-drawer under-desk office cabinet, with the first drawer closed and the second "
    "slightly open; its door halfway open, low damping sliding joints and a lid that holds its position. "
)


def text_of(n: int) -> str:
    """A request of exactly ``n`` characters."""
    return (SENTENCE * (n // len(SENTENCE) + 1))[:n]


def time_parse(text: str, repeat: int) -> float:
    """Best wall time (s) of ``repeat`` parses."""
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        request.parse_request(text)
        best = min(best, time.perf_counter() - t)
    return best


def corpus(outcomes: str | None) -> None:
    """Parse match rate of the corpus (and optionally its outcomes)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.tasks.interpret.request_corpus import (apply_misses, load_corpus, parse_misses, phenomena_of,  # the test corpus tools
                                                      rates_by_phenomenon, run_outcome)

    entries = load_corpus()
    t = time.perf_counter()
    misses = parse_misses(entries)
    secs = time.perf_counter() - t
    print(f"corpus: {len(entries) - len(misses)}/{len(entries)} parses match ({1 - len(misses) / len(entries):.1%}); "
          f"{1000 * secs / len(entries):.2f} ms per request")
    for m in misses:
        print("  MISS", m)
    with tempfile.TemporaryDirectory() as tmp:
        applied = [e for e in entries if e.get("apply")]
        t = time.perf_counter()
        rates = rates_by_phenomenon(entries, Path(tmp))
        secs = time.perf_counter() - t
        print(f"per phenomenon (parse, and the joints it sets where the entry says; {len(applied)} entries resolved on their "
              f"objects in {secs:.1f} s):")
        for ph, (ok, n) in sorted(rates.items(), key=lambda kv: (kv[0] == "general", kv[0])):
            print(f"  {ph:<13} {ok:>4}/{n:<4} {ok / n:6.1%}")
        for e in applied:
            m = apply_misses(e, Path(tmp))
            if m:
                print(f"  APPLY MISS {e['id']} {e['object']} {','.join(phenomena_of(e))} {e['text']!r}: {'; '.join(m)}")
    from collections import Counter

    from tests.tasks.interpret.request_generated import generate, mismatch

    intents = generate(600)
    misses = [(i, m) for i in intents if (m := mismatch(i, request.parse_request(i.text)))]
    total = Counter(p for i in intents for p in i.phenomena)
    missed = Counter(p for i, _ in misses for p in i.phenomena)
    print(f"generated from structured intents: {len(intents) - len(misses)}/{len(intents)} parse back to their intent; per phenomenon:")
    for ph, n in sorted(total.items()):
        print(f"  {ph:<13} {n - missed[ph]:>4}/{n:<4} {(n - missed[ph]) / n:6.1%}")
    for i, m in misses:
        print(f"  GENERATED MISS {i.text!r}: {m}")
    if not outcomes:
        return
    todo = [e for e in entries if "outcome" in e]
    if outcomes != "all":
        todo = todo[: int(outcomes)]
    missed = 0
    with tempfile.TemporaryDirectory() as tmp:
        for e in todo:
            t = time.perf_counter()
            m = run_outcome(e, Path(tmp))
            missed += bool(m)
            print(f"  {e['id']} {time.perf_counter() - t:6.1f}s {e['object']:<22} {'OK' if not m else 'MISS ' + '; '.join(m)}  {e['text']!r}")
    print(f"outcomes: {len(todo) - missed}/{len(todo)} land ({1 - missed / max(len(todo), 1):.1%})")


def model_path(target: str, model_name: str) -> None:
    """The corpus and the generated requests through the model path against ``target`` (a base URL, or ``fake``: a
    local server echoing the offline parse), the parse rate per phenomenon of both paths."""
    import contextlib
    import json
    from collections import Counter

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from asset2sim.schemas.request import RequestIntent
    from asset2sim.models.client import LLMClient
    from asset2sim.models.config import ClientConfig
    from asset2sim.tasks.interpret.reading import parse_request_model
    from tests import fake_openai_server as fake
    from tests.tasks.interpret.request_corpus import load_corpus, parse_rates
    from tests.tasks.interpret.request_generated import generate, mismatch

    entries = load_corpus()
    intents = generate(600)
    with contextlib.ExitStack() as stack:
        if target == "fake":
            echo = fake.intent_reply(lambda text: json.loads(RequestIntent.of(request.parse_request(text)).model_dump_json()))
            srv = stack.enter_context(fake.FakeOpenAIServer(echo, max_requests=len(entries) + len(intents) + 10, lifetime_s=3600))
            url, what = srv.url, "a local fake server that answers with the offline parser's intent (plumbing, not a model)"
        else:
            url, what = target, f"the server at {target}"
        client = LLMClient(ClientConfig.from_env("openai/" + model_name, url, cache_dir=None))
        kinds: Counter[str] = Counter()

        def parse(text: str):
            spec = parse_request_model(text, client)
            kinds[spec.parser] += 1
            return spec

        t = time.perf_counter()
        offline_rates, model_rates = parse_rates(entries), parse_rates(entries, parse)
        g_total = Counter(p for i in intents for p in i.phenomena)
        g_off = Counter(p for i in intents if mismatch(i, request.parse_request(i.text)) for p in i.phenomena)
        g_mod = Counter(p for i in intents if mismatch(i, parse(i.text)) for p in i.phenomena)
        secs = time.perf_counter() - t
    print(f"model path against {what}: {client.usage.calls} calls, {kinds['model']} model parses used, "
          f"{kinds['offline']} kept offline, {secs:.1f} s")
    print(f"  {'corpus':<13} {'offline':>14} {'model path':>14}")
    for ph in sorted(offline_rates, key=lambda k: (k == "general", k)):
        (a, n), (b, _) = offline_rates[ph], model_rates[ph]
        print(f"  {ph:<13} {a:>4}/{n:<4} {a / n:5.1%} {b:>4}/{n:<4} {b / n:5.1%}")
    print(f"  {'generated':<13} {'offline':>14} {'model path':>14}")
    for ph, n in sorted(g_total.items()):
        print(f"  {ph:<13} {n - g_off[ph]:>4}/{n:<4} {(n - g_off[ph]) / n:5.1%} {n - g_mod[ph]:>4}/{n:<4} {(n - g_mod[ph]) / n:5.1%}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1024,16384,65536,131072,1000000", help="request lengths in characters")
    ap.add_argument("--outcomes", default=None, help="refine the first N corpus entries with an outcome ('all': every one)")
    ap.add_argument("--model", default=None, help="also run the model path: an OpenAI-compatible base URL, or 'fake' (a local "
                    "server echoing the offline parse)")
    ap.add_argument("--model-name", default="m", help="the server's model name (sent as openai/NAME)")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    request.parse_request(SENTENCE)  # priors and regexes loaded once, outside the timings
    cap = request.MAX_REQUEST_CHARS
    print(f"length cap {cap} characters (RequestTooLong above it)")
    print(f"{'characters':>11} {'seconds':>9} {'ms per KiB':>11}  note")
    for n in sizes:
        text = text_of(n)
        note = ""
        if n > cap:
            request.MAX_REQUEST_CHARS = n  # measure the parser itself
            note = "above the cap: timed with the cap lifted"
        try:
            secs = time_parse(text, 3 if n <= 131072 else 1)
        finally:
            request.MAX_REQUEST_CHARS = cap
        print(f"{n:>11} {secs:>9.3f} {1000 * secs / (n / 1024):>11.3f}  {note}")
    over = text_of(cap + 1)
    t = time.perf_counter()
    try:
        request.parse_request(over)
        refused = "accepted (unexpected)"
    except request.RequestTooLong as exc:
        refused = f"refused: {exc}"
    print(f"{cap + 1:>11} {time.perf_counter() - t:>9.6f} {'':>11}  {refused}")
    corpus(args.outcomes)
    if args.model:
        model_path(args.model, args.model_name)


if __name__ == "__main__":
    main()
