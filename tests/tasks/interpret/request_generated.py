"""Requests generated from structured intents: each intent (the parts, which one of them, the state and its
amount, a size or a mass, a clause that asks nothing) is rendered into English with synonyms, several word
orders, units, negations, hedges and distractor clauses, and its expected parse written from the intent, not
from the parser. ``parse(render(intent))`` must give the intent back (``tests/tasks/interpret/test_request_generated.py``;
rates per phenomenon in ``benchmarks/bench_request.py``). Deterministic: a seeded ``random.Random``.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from asset2sim.schemas.request import RequestSpec

#: Part words -> the canonical label the parser gives them (a synonym keeps its word: "arm" names a stapler's lid
#: only on a stapler, which the parse does not know).
PARTS = {"door": "door", "lid": "lid", "drawer": "drawer", "screen": "screen", "seat": "seat", "cap": "cap",
         "lever": "lever", "flap": "lid", "cover": "lid", "arm": "arm", "hatch": "door", "display": "screen", "tray": "tray"}
#: Which one: word -> (ordinal, order).
WHICH = {"top": (0, "vertical"), "upper": (0, "vertical"), "bottom": (-1, "vertical"), "lower": (-1, "vertical"),
         "second": (1, "vertical"), "first": (0, "vertical"), "left": (0, "left_right"), "right": (0, "right_left"),
         "middle": (0, "middle"), "main": (-1, "size"), "smaller": (0, "size"), "freezer": (0, "size"), "larger": (-1, "size")}
#: Band -> (phenomenon, words), rendered after the part ("the lid slightly open").
BANDS = {
    "closed": [("band", "closed"), ("band", "shut"), ("negation", "not open"), ("negation", "no longer open"),
               ("negation", "not open at all"), ("band", "fully closed")],
    "slightly_open": [("band", "slightly open"), ("band", "ajar"), ("hedge", "barely open"), ("hedge", "mostly closed"),
                      ("hedge", "almost shut"), ("band", "open a crack")],
    "quarter": [("band", "a quarter open"), ("hedge", "open about a quarter of the way")],
    "halfway": [("band", "halfway open"), ("band", "half open"), ("hedge", "open about halfway"), ("hedge", "roughly halfway open"),
                ("negation", "not closed")],
    "mostly": [("band", "open"), ("band", "left open"), ("band", "mostly open"), ("band", "three quarters open")],
    "fully": [("band", "fully open"), ("band", "wide open"), ("band", "open all the way")],
}
#: Band -> words that go before the part ("a slightly open lid").
BEFORE = {"slightly_open": ["slightly open", "barely open"], "halfway": ["half-open", "half open", "partly open"], "mostly": ["open"],
          "fully": ["fully open", "wide open"], "closed": ["closed", "shut"]}
PLURALS = {"hatch": "hatches", "display": "displays", "cover": "covers"}
#: Clauses that ask nothing of the parts or the size (their words may be reported as not understood).
DISTRACTORS = ["for my kitchen", "in a matte finish", "as a gift", "for a photo shoot"]
OBJECTS = ["cabinet", "box", "fridge", "microwave", "toilet", "laptop", "trash can", "suitcase", "stapler", "dishwasher"]
CONNECTORS = [" and ", ", ", "; ", " while ", ", and "]


@dataclass
class Intent:
    """What a generated request asks: states ("label[#ordinal[@order]]=value" as the corpus writes them), sizes
    ("height:0.3"), total mass (kg), the text, and the phenomena its rendering used."""

    text: str
    states: list[str]
    sizes: list[str] = field(default_factory=list)
    mass: float | None = None
    phenomena: list[str] = field(default_factory=list)


def _g(v: float) -> str:
    return f"{v:.4g}"


def _state(rng: random.Random) -> tuple[str, str, str]:
    """(words, expected value, phenomenon) of one state."""
    kind = rng.choice(["band", "band", "band", "angle", "distance", "fraction", "compare"])
    if kind == "band":
        band = rng.choice(list(BANDS))
        ph, words = rng.choice(BANDS[band])
        return words, band, ph
    if kind == "angle":
        deg = rng.choice([15, 20, 30, 45, 60, 75, 90, 110])
        words = rng.choice([f"open {deg} degrees", f"at {deg} degrees", f"opened to {deg}°", f"open {deg} deg",
                            f"open about {deg} degrees"])
        return words, f"angle:{_g(math.radians(deg))}", "unit"
    if kind == "distance":
        n, unit, f = rng.choice([(5, "cm", 1e-2), (10, "cm", 1e-2), (40, "mm", 1e-3), (2, "inches", 0.0254), (3, "in", 0.0254)])
        words = rng.choice([f"open {n} {unit}", f"pulled out {n} {unit}", f"out {n} {unit}"])
        return words, f"distance:{_g(n * f)}", "unit"
    if kind == "fraction":
        words, f = rng.choice([("60 % open", 0.6), ("75 percent open", 0.75), ("two-thirds open", 2 / 3), ("a third open", 1 / 3),
                               ("2/3 open", 2 / 3), ("40% open", 0.4)])
        return words, f"fraction:{_g(f)}", "fraction"
    words, f = rng.choice([("a little less than halfway open", 0.4), ("slightly less than halfway open", 0.4),
                           ("a bit more than halfway open", 0.6), ("just under halfway open", 0.4)])
    return words, f"fraction:{_g(f)}", "hedge"


def generate(n: int, seed: int = 0) -> list[Intent]:
    """``n`` intents and their renderings (1-3 state clauses on different parts, sometimes a size, a mass, a
    distractor clause)."""
    rng = random.Random(seed)
    out: list[Intent] = []
    while len(out) < n:
        k = rng.choice([1, 1, 2, 2, 3])
        words = rng.sample(sorted(PARTS), k)
        labels = [PARTS[w] for w in words]
        if len(set(labels)) < k:
            continue  # two words for one label in one request would be one part asked twice
        clauses, states, ph = [], [], set()
        for w in words:
            which = rng.choice([None, None, None, *sorted(WHICH)])
            st_words, val, p = _state(rng)
            ph.add(p)
            head = PARTS[w]
            if which is not None:
                o, order = WHICH[which]
                head += f"#{o}" + ("" if order == "vertical" else f"@{order}")
                ph.add("ordinal")
            if PARTS[w] != w:
                ph.add("synonym")
            det = rng.choice(["the ", "its ", "the ", "their "])
            form = rng.random()
            if which is None and ":" not in val and form < 0.2 and val in BEFORE:  # the state before the part: "a slightly open lid"
                adj = rng.choice(BEFORE[val])
                clauses.append(f"{'an' if adj[0] in 'aeiou' else 'a'} {adj} {w}")
                ph.add("order")
            elif which is None and form < 0.35:  # a quantifier: "both doors open", "all the lids closed"
                q = rng.choice(["both", "all", "all the", "each", "every"])
                plural = w if q in ("each", "every") else PLURALS.get(w, w + "s")
                clauses.append(f"{q} {plural} {st_words}")
                ph.add("quantifier")
            else:
                clauses.append(f"{det}{which + ' ' if which else ''}{w} {st_words}")
            states.append(f"{head}={val}")
        if k > 1:
            ph.add("compound")
        body = clauses[0]
        for c in clauses[1:]:
            body += rng.choice(CONNECTORS) + c
        obj = rng.choice(OBJECTS)
        sizes, mass = [], None
        pre = ""
        r = rng.random()
        if r < 0.2:
            cm = rng.choice([20, 30, 45, 60])
            pre = f", {cm} cm tall"
            sizes = [f"height:{_g(cm / 100)}"]
            ph.add("unit")
        elif r < 0.35:
            kg = rng.choice([1, 2, 5, 12])
            pre = f" weighing {kg} kg"
            mass = float(kg)
            ph.add("unit")
        tail = (", " + rng.choice(DISTRACTORS)) if rng.random() < 0.25 else ""
        if tail:
            ph.add("distractor")
        text = f"A {obj}{pre} with {body}{tail}."
        out.append(Intent(text=text, states=sorted(states), sizes=sizes, mass=mass, phenomena=sorted(ph)))
    return out


def parsed(spec: RequestSpec) -> tuple[list[str], list[str], float | None]:
    """(states, sizes, total mass) of a parse in the form of :class:`Intent`."""
    states = []
    for js in spec.joint_states:
        head = (js.label or "all") + ("" if js.ordinal is None else f"#{js.ordinal}") + ("" if js.order == "vertical" else f"@{js.order}")
        t = js.target
        val = js.band if t is None else (f"end:{t.end}" if t.kind == "end" else f"{t.kind}:{_g(t.value)}")
        states.append(f"{head}={val}")
    mass = next((p.mass for p in spec.properties if p.label is None and p.mass is not None), None)
    return sorted(states), sorted(f"{s.dimension}:{_g(s.value)}" for s in spec.sizes), mass


def mismatch(intent: Intent, spec: RequestSpec) -> str:
    """"" when the parse gives the intent back (and warns of no contradiction), else what differs."""
    states, sizes, mass = parsed(spec)
    diffs = []
    if states != intent.states:
        diffs.append(f"states {states} != {intent.states}")
    if sizes != intent.sizes:
        diffs.append(f"sizes {sizes} != {intent.sizes}")
    if (mass is None) != (intent.mass is None) or mass is not None and abs(mass - intent.mass) > 1e-9:
        diffs.append(f"mass {mass} != {intent.mass}")
    contra = [w for w in spec.warnings if w.startswith("contradiction")]
    if contra:
        diffs.append(f"warnings {contra}")
    return "; ".join(diffs)
