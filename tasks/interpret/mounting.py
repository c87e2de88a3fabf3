"""How an asset is held in the world: free-standing or mounted.

A faucet is fastened to a sink deck, a door hangs in its frame, a switch sits
in a wall box: simulator users load such assets with a fixed root
(PyBullet ``useFixedBase``, SAPIEN ``fix_root_link``, MJCF without a free
joint). The per-category prior lives in ``asset2sim/priors/mounting.yaml``
(each entry with its source: plumbing, electrical and fenestration codes and
manufacturers' installation guides); categories not listed there are
free-standing (the SPEC's convention: root free, resting on the ground). The
request can override the prior: "a free-standing faucet", "mounted on the
wall", "a built-in dishwasher" (:func:`request_mounting`, a small parser of
its own over the request text).

The decision is a :class:`asset2sim.schemas.overlay.RootMount` carried by the
overlay; the output folder declares it (``initial_state.json`` ``"root"``,
the URDF comment) and every check opens the asset with the root as declared
(:func:`session_root_options`).
"""

from __future__ import annotations

import functools
import re
from importlib import resources
from typing import get_args

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from asset2sim.schemas.overlay import MountingKind, RootMount

__all__ = [
    "FREE",
    "MountingError",
    "MountingPrior",
    "category_mounting",
    "load_mounting_priors",
    "request_mounting",
    "resolve_mounting",
    "session_root_options",
]

FREE: str = "free-standing"
KINDS: tuple[str, ...] = get_args(MountingKind)
_FILE = "mounting.yaml"


class MountingError(ValueError):
    """Bad mounting prior data; the message names the yaml file and key."""


class MountingPrior(BaseModel):
    """One category's entry of ``mounting.yaml``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    kind: MountingKind
    source: str


def _parse_table(data: object, where: str) -> dict[str, MountingPrior]:
    if not isinstance(data, dict):
        raise MountingError(f"{where}: expected a mapping of category -> {{kind, source}}")
    out: dict[str, MountingPrior] = {}
    for cat, entry in data.items():
        try:
            prior = MountingPrior.model_validate(entry)
        except ValidationError as exc:
            raise MountingError(f"{where}: category {cat!r}: {exc}") from exc
        if not prior.source.strip():
            raise MountingError(f"{where}: category {cat!r}: a mounting prior needs its source")
        out[str(cat)] = prior
    return out


@functools.lru_cache(maxsize=1)
def load_mounting_priors() -> dict[str, MountingPrior]:
    """The packaged mounting prior: canonical category -> :class:`MountingPrior`.

    Raises:
        MountingError: the yaml is malformed, a kind is unknown or a source is
            missing (the message names ``mounting.yaml`` and the category).
    """
    text = resources.files("asset2sim.priors").joinpath(_FILE).read_text(encoding="utf-8")
    return _parse_table(yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)), _FILE)  # libyaml when built in


def category_mounting(category: str | None) -> RootMount:
    """The prior of ``category`` (canonical name, e.g. "Faucet"); a category
    without an entry (or None) is free-standing."""
    prior = load_mounting_priors().get(category or "")
    if prior is None:
        return RootMount(kind="free-standing", fixed=False, source=f"category prior: {category or 'unknown category'} is free-standing (SPEC convention)")
    return RootMount(kind=prior.kind, fixed=prior.kind != FREE, source=f"category prior ({category}): {prior.kind}; {prior.source.strip()}")


# Request words. Hyphen, space or nothing between compound parts ("wall-mounted",
# "wall mounted", "freestanding"). Order does not matter: the last mention wins.
_ART = r"(?:(?:a|an|the|its|his|her|their|my|our|your)\s+)?"
_J = r"[-\s]?"
_PATTERNS: list[tuple[str, str]] = [
    (rf"\bnot\s+(?:be\s+)?(?:mounted|fixed|bolted|installed|attached|fastened|built{_J}in)\b", FREE),
    (rf"\b(?:free{_J}standing|stand{_J}alone|unmounted|unfixed|portable)\b", FREE),
    (rf"\b(?:stands?|standing|resting|rests|sitting|sits|placed)\s+(?:freely\s+)?on\s+{_ART}(?:floor|ground|table|desk|counter|countertop|shelf)\b", FREE),
    (rf"\bwall{_J}(?:mounted|mount|hung|fixed)\b", "wall-mounted"),
    (rf"\b(?:mounted|fixed|hung|hanging|bolted|fastened|screwed|attached|installed)\s+(?:on|to|onto|in|into)\s+{_ART}wall\b", "wall-mounted"),
    (rf"\bon\s+{_ART}wall\b", "wall-mounted"),
    (rf"\b(?:counter|deck|sink|countertop|under{_J}counter){_J}(?:mounted|mount|fixed)\b", "counter-mounted"),
    (rf"\b(?:mounted|fixed|bolted|fastened|attached|installed)\s+(?:on|to|onto|in|into|under)\s+{_ART}(?:counter|countertop|sink|deck|cabinet|cabinets)\b", "counter-mounted"),
    (rf"\b(?:built{_J}in|under{_J}counter)\b", "counter-mounted"),
    (rf"\bfloor{_J}(?:mounted|mount|fixed|bolted)\b", "floor-mounted"),
    (rf"\b(?:mounted|fixed|bolted|fastened|anchored|screwed|attached|installed)\s+(?:on|to|onto|in|into)\s+{_ART}(?:floor|ground)\b", "floor-mounted"),
    (rf"\b(?:in|within)\s+{_ART}(?:door\s+|window\s+)?frame\b", "hangs-in-frame"),
    (r"\b(?:mounted|bolted|anchored|installed|fastened)\b", "mounted"),
    (r"\bfixed\s+(?:base|root|in\s+place)\b", "mounted"),
]
_COMPILED = [(re.compile(p), kind) for p, kind in _PATTERNS]


def request_mounting(text: str, category: str | None = None) -> RootMount | None:
    """The mounting a request asks for, or None when it says nothing about it.

    Recognised (English, case-insensitive): free-standing words
    ("free-standing", "freestanding", "standalone", "portable", "not mounted",
    "standing on the floor"), "wall-mounted" / "mounted on the wall" / "on the
    wall", "counter-mounted" / "built-in" / "under-counter", "floor-mounted" /
    "bolted to the floor", "in a frame", and a bare "mounted" / "installed" /
    "fixed in place" (then the kind is the category prior's when that is
    mounted, else "wall-mounted"). When several are present the last mention
    in the text wins; a span already covered by an earlier (more specific)
    pattern is not matched again.
    """
    hits = mounting_mentions(text)
    if not hits:
        return None
    _, kind, phrase = max(hits, key=lambda h: h[0])
    if kind == "mounted":
        prior = category_mounting(category)
        kind = prior.kind if prior.fixed else "wall-mounted"
    return RootMount(kind=kind, fixed=kind != FREE, source=f"request: {phrase.strip()!r} -> {kind}")


def mounting_mentions(text: str) -> list[tuple[int, str, str]]:
    """Every mounting phrase of a request (:func:`request_mounting`'s
    patterns; a span already covered by an earlier, more specific pattern is
    not matched again): (start index in the lower-cased text, kind, the
    phrase as written in lower case), in pattern order. The request parser
    counts these words as understood."""
    low = (text or "").lower()
    taken: list[tuple[int, int]] = []
    hits: list[tuple[int, str, str]] = []
    for rx, kind in _COMPILED:
        for m in rx.finditer(low):
            if any(m.start() < b and a < m.end() for a, b in taken):
                continue
            taken.append((m.start(), m.end()))
            hits.append((m.start(), kind, m.group(0)))
    return hits


def resolve_mounting(category: str | None, text: str, override: str | None = None) -> RootMount:
    """The mounting an override gives (``fixed``: the category prior's kind
    when it is mounted, else wall-mounted; ``free``), else the request's when
    it names one (:func:`request_mounting`), else the category prior
    (:func:`category_mounting`)."""
    if override == "free":
        return RootMount(kind=FREE, fixed=False, source="given by the user: --mount free")
    if override == "fixed":
        prior = category_mounting(category)
        kind = prior.kind if prior.fixed else "wall-mounted"
        return RootMount(kind=kind, fixed=True, source=f"given by the user: --mount fixed -> {kind}")
    return request_mounting(text, category) or category_mounting(category)


def session_root_options(fixed: bool) -> dict[str, bool]:
    """Keyword options of :class:`asset2sim.engines.base.SessionOptions` for a
    root as declared: mounted -> ``fixed_base=True, ground=False`` (the mount
    holds the root where the file puts it: no floor under a wall switch or a
    faucet on its deck; a ground plane at z = 0 would cut through links placed
    below the root's origin); free -> ``{}`` (the SPEC's convention: root
    free, resting on the ground)."""
    return {"fixed_base": True, "ground": False} if fixed else {}
