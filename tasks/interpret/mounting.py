"""How an asset is held: free-standing or mounted (a faucet on its deck: a fixed root). The prior per category is
``asset2sim/priors/mounting.yaml`` (with sources; unlisted: free-standing, the SPEC's convention), the request's words
override it; every check honours the :class:`~asset2sim.schemas.overlay.RootMount` (:func:`asset2sim.engines.base.session_root_options`).
"""

from __future__ import annotations

import functools
import re
from string import Template
from typing import get_args

from pydantic import ValidationError

from asset2sim.engines.base import session_root_options
from asset2sim.schemas import Frozen
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import MountingKind, RootMount
from asset2sim.schemas.request import RequestSpec
from asset2sim.formats import FORMATS, ReadOptions, staging
from asset2sim.tasks.ingest.declared import read_declared
from asset2sim.package_data import package_yaml

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


class MountingPrior(Frozen):
    """One category's entry of ``mounting.yaml``."""

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
        MountingError: malformed yaml, an unknown kind or a missing source (naming the file and category).
    """
    return _parse_table(package_yaml("asset2sim.priors", _FILE), _FILE)


def category_mounting(category: str | None) -> RootMount:
    """The prior of ``category`` (canonical name); without an entry (or None) free-standing."""
    prior = load_mounting_priors().get(category or "")
    if prior is None:
        return RootMount(kind="free-standing", fixed=False, source=f"category prior: {category or 'unknown category'} is free-standing (the measurement convention for objects that stand)")
    return RootMount(kind=prior.kind, fixed=prior.kind != FREE, source=f"category prior ({category}): {prior.kind}; {prior.source.strip()}")


#: The request's words for each mounting (``words.yaml`` ``mounting``), the more specific first; the last mention wins.
_MOUNTING_WORDS = package_yaml(__package__, "words.yaml")["mounting"]
_COMPILED = [(re.compile(Template(p).substitute(_MOUNTING_WORDS["fragments"])), kind) for p, kind in _MOUNTING_WORDS["patterns"]]


def request_mounting(text: str, category: str | None = None) -> RootMount | None:
    """The mounting a request asks for (the last mention wins), or None. A bare "mounted" / "installed" /
    "fixed in place" takes the category prior's kind when that is mounted, else "wall-mounted"."""
    hits = mounting_mentions(text)
    if not hits:
        return None
    _, kind, phrase = max(hits, key=lambda h: h[0])
    if kind == "mounted":
        prior = category_mounting(category)
        kind = prior.kind if prior.fixed else "wall-mounted"
    return RootMount(kind=kind, fixed=kind != FREE, source=f"request: {phrase.strip()!r} -> {kind}")


def mounting_mentions(text: str) -> list[tuple[int, str, str]]:
    """(start, kind, phrase) of every mounting phrase in the lower-cased text, in pattern order; a span an
    earlier (more specific) pattern covers is not matched again."""
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
    """The mounting an override gives (``fixed``: the prior's kind when mounted, else wall-mounted; ``free``),
    else the request's, else the category prior."""
    if override == "free":
        return RootMount(kind=FREE, fixed=False, source="given by the user: --mount free")
    if override == "fixed":
        prior = category_mounting(category)
        kind = prior.kind if prior.fixed else "wall-mounted"
        return RootMount(kind=kind, fixed=True, source=f"given by the user: --mount fixed -> {kind}")
    return request_mounting(text, category) or category_mounting(category)


def declared_mounting(category: str | None, root_fixed: bool | None, what: str) -> RootMount | None:
    """The root as a file declares it (``root_fixed``: an MJCF root without a free joint is welded to the world; a
    USD fixed joint to the world), read as a ``--mount`` override reads (:func:`resolve_mounting`), its source
    naming ``what`` (``the MJCF file``); None when the file does not say."""
    if root_fixed is None:
        return None
    held = "welds the root to the world" if root_fixed else "leaves the root free"
    return resolve_mounting(category, "", "fixed" if root_fixed else "free").model_copy(update={"source": f"{what} {held}"})




def root_mounting(asset: AssetDescription, request: RequestSpec, category: str, reading: ReadOptions) -> RootMount:
    """The root's mounting: ``--mount`` (``request.mount``), else the request's words, else an MJCF file's own
    declaration (a root without a free joint is welded to the world, as MuJoCo compiles it; the file read with
    ``reading``), else the category prior."""
    source = asset.staged_from
    if (request.mount is None and request_mounting(request.text, category) is None
            and source is not None and getattr(FORMATS.get(staging.input_format(source)), "declares_root", False)):
        declared = declared_mounting(category, read_declared(source, asset.urdf_path, reading).root_fixed, "the MJCF file")
        if declared is not None:
            return declared
    return resolve_mounting(category, request.text, request.mount)
