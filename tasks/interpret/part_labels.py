"""Canonical part labels (``rotation_lid`` -> ``lid``, ``drawers`` -> ``drawer``)
by the rules of ``labels.yaml``; every other prior lookup goes through them."""

from __future__ import annotations

import functools
import re

from asset2sim.prior_tables import load_priors
from asset2sim.schemas.asset import AssetDescription

#: Canonical labels of an object's main body.
BODY_LABELS = frozenset({"body", "base", "frame"})
#: Labels that, in a joint's name (``door_hinge``, ``slider``), name the mechanism rather than the part it moves.
JOINT_WORDS = frozenset({"hinge", "slider"})


def _norm_token(s: str) -> str:
    return re.sub(r"[\s\-]+", "_", s.strip().lower()).strip("_")


@functools.lru_cache(maxsize=4096)
def canonical_label(label: str | None) -> str | None:
    """Canonical part label of a semantic label (``stapler_body`` -> ``body``); unknown labels normalised
    (lower case, ``_``); None or blank gives None."""
    if label is None or not label.strip():
        return None
    table = load_priors().labels
    known = table.labels
    s = _norm_token(label)

    def look(x: str) -> str | None:
        if x in table.aliases:
            return table.aliases[x]
        if x in known:
            return x
        if x.endswith("s") and x[:-1] in known:
            return x[:-1]
        return None

    stripped = s
    changed = True
    while changed:
        changed = False
        for p in table.strip_prefixes:
            if stripped.startswith(p) and len(stripped) > len(p):
                stripped = stripped[len(p):]
                changed = True
    # whole, prefixes stripped, last token first
    cands = [s, stripped, *reversed([t for t in stripped.split("_") if t])]
    return next((hit for cand in cands if (hit := look(cand))), stripped)


def body_label_tokens(label: str) -> list[str]:
    """Prefix words of a body-like label (``suitcase_body`` -> [``suitcase``])."""
    toks = [t for t in _norm_token(label).split("_") if t]
    return toks[:-1] if len(toks) >= 2 and canonical_label(toks[-1]) in BODY_LABELS else []


def label_from_name(name: str | None) -> str | None:
    """A known part label read from a link name (``link_0_handle`` -> ``handle``, ``LidLink`` -> ``lid``) by the
    rules of :func:`canonical_label`, for assets without ``semantics.txt``; None when no word of the name is a
    known label (``labels.yaml``)."""
    if not name:
        return None
    hit = canonical_label(re.sub(r"[^A-Za-z]+", "_", re.sub(r"([a-z])([A-Z])", r"\1_\2", name)))  # camelCase -> camel_Case
    return hit if hit in load_priors().labels.labels else None


def labels_from_names(asset: AssetDescription) -> AssetDescription:
    """``asset`` with part labels read from its link names (:func:`label_from_name`) when it has none (no
    ``semantics.txt``: MJCF, USD and generated URDFs), said in its ``staging_notes``; a moving link whose name holds
    no label or only a body word takes the label of its joint's name (``window_slide`` -> ``window``); unchanged
    when any link has a label or no name holds one."""
    if any(ln.semantic_label for ln in asset.links):
        return asset
    found = {ln.name: lab for ln in asset.links if (lab := label_from_name(ln.name))}
    by_joint = {}
    for j in asset.joints:  # a moving link named for nothing (MJCF's unnamed body_4) takes its joint's name: window_slide
        own = found.get(j.child)
        if j.type != "fixed" and (own is None or own in BODY_LABELS):
            lab = label_from_name(j.name)
            if lab is not None and lab not in BODY_LABELS and lab not in JOINT_WORDS:
                found[j.child] = by_joint[j.child] = lab
    if not found:
        return asset
    links = [ln.model_copy(update={"semantic_label": found.get(ln.name)}) for ln in asset.links]
    note = "part labels read from link names (no semantics.txt): " + ", ".join(
        f"{k} -> {v}" + (" (its joint's name)" if k in by_joint else "") for k, v in found.items())
    return asset.model_copy(update={"links": links, "staging_notes": [*asset.staging_notes, note]})
