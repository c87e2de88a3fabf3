"""Request parsing time against request length (``tasks.interpret.request``).

Prints the wall time of ``parse_request`` for requests of 1 KiB .. 1 MB built
by repeating a realistic request (sizes, parts, ordinals, states, dynamics,
category words, clause marks), the time per KiB (flat when parsing is linear),
and the time to refuse a request above the length cap
(:data:`~asset2sim.tasks.interpret.request.MAX_REQUEST_CHARS`, raising
``RequestTooLong``). Requests above the cap are timed with the cap lifted for
the measurement only.

    python benchmarks/bench_request.py [--sizes 1024,131072,1000000]
"""

from __future__ import annotations

import argparse
import time

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1024,16384,65536,131072,1000000", help="request lengths in characters")
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


if __name__ == "__main__":
    main()
