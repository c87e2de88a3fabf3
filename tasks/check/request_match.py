"""The request and the category priors as the evaluation applies them; the
request's joint states mapped to joints by their child links' semantic
labels. None of these may stop an evaluation: a failure becomes a note or an empty prior.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from asset2sim.schemas.request import JointStateRequest, MotionPhrase, RequestSpec, StateTarget
from asset2sim.tasks.check.asset_files import MOVABLE, JointInfo
from asset2sim.tasks.interpret import categories, part_priors, size_priors
from asset2sim.tasks.interpret.named_parts import named_joints, pick
from asset2sim.tasks.interpret.request import parse_request


def parse_prompt(prompt: str | None) -> tuple[RequestSpec | None, str | None]:
    """(RequestSpec of ``prompt`` or None, the parser's error or None)."""
    if not prompt:
        return None, None
    try:
        return parse_request(prompt), None
    except Exception as exc:  # a parser failure must not stop the evaluation
        return None, f"request parser failed: {type(exc).__name__}: {exc}"


def category_prior(category: str | None, spec: RequestSpec | None = None) -> dict[str, Any]:
    """Size target and mass prior of ``category`` with the request ``spec``'s
    size words: {"category", "target_dims" (m, largest first), "base_dims" (m),
    "factor", "variant", "base_mass_range" (kg), "note", "source"}, or {} without a prior.
    """
    if not category:
        return {}
    try:
        t = size_priors.target_size(category, spec)
        cat = categories.category_prior(category)
        base_mass = cat.mass_range
        if t.variant:
            var = next((v for v in cat.variants if v.name == t.variant), None)
            if var is not None:
                base_mass = var.mass_range
    except Exception:
        return {}
    return {"category": t.category, "target_dims": [float(x) for x in t.dims], "base_dims": [float(x) for x in t.base_dims],
            "factor": float(t.factor), "variant": t.variant, "base_mass_range": (float(base_mass[0]), float(base_mass[1])),
            "note": t.note, "source": f"asset2sim/priors/categories.yaml: {cat.dims_source}; {cat.mass_source}"}


def scaled_mass_range(prior: dict[str, Any], extents: Any) -> tuple[tuple[float, float] | None, float]:
    """Plausible mass range (kg) for closed-state ``extents`` (3,) m: the base
    range scaled by :func:`~asset2sim.tasks.interpret.size_priors.scale_mass_range`
    with f the geometric mean of extent / base dimension over the two largest
    (f^3 where that rejects f).

    Returns:
        (range or None without a base mass range, f).
    """
    if not prior or not prior.get("base_mass_range"):
        return None, 1.0
    lo, hi = prior["base_mass_range"]
    f = 1.0
    ext = None if extents is None else np.sort(np.asarray(extents, float).ravel())[::-1]
    if ext is not None and len(ext) >= 2 and prior.get("base_dims") and float(ext[0]) > 0:
        base = np.sort(np.asarray(prior["base_dims"], float))[::-1]
        f = float(np.exp(np.mean(np.log(np.maximum(ext[:2], 1e-9) / base[:2]))))
    try:
        return size_priors.scale_mass_range(lo, hi, f), f
    except Exception:
        return (lo * f**3, hi * f**3), f


def recognize_category(prompt: str | None, model_cat: str | None = None, labels: list[str] | None = None) -> str | None:
    """Category from the request, ``model_cat`` and ``labels``; ``model_cat`` when that fails."""
    if not prompt and not model_cat:
        return None
    try:
        m = categories.recognize_category(model_cat, labels or [], prompt or "")
    except Exception:
        return model_cat
    return getattr(m, "name", None) or model_cat


def _named(category: str | None, word: str | None, names: list[str], joints: dict[str, JointInfo],
           semantics: dict[str, tuple[str, str]]) -> list[str]:
    """Of ``names``, the joints whose child's label (``semantics``: link -> (kind, label)) the
    request's part ``word`` names, as refine matches them
    (:func:`~asset2sim.tasks.interpret.named_parts.named_joints`)."""
    labels = [semantics.get(joints[n].child, (None, None))[1] for n in names]
    return named_joints(category or "Generic", word, names, labels)


def _picked(js: JointStateRequest, names: list[str], joints: dict[str, JointInfo],
            centres: dict[str, np.ndarray], volumes: dict[str, float]) -> list[str]:
    """``names`` counted and narrowed as refine's ordinals count
    (:func:`~asset2sim.tasks.interpret.named_parts.pick`), by each child link's ``centres`` and
    ``volumes``."""
    children = {n: joints[n].child for n in names}
    return pick(js, names, {n: centres[c] for n, c in children.items() if c in centres},
                {n: volumes.get(c, 0.0) for n, c in children.items()})


def requested_joints(spec: RequestSpec | None, joints: dict[str, JointInfo], semantics: dict[str, tuple[str, str]],
                     centres: dict[str, np.ndarray], task_joints: list[str],
                     category: str | None = None, volumes: dict[str, float] | None = None
                     ) -> tuple[list[tuple[str, str, str | None, str]], list[str]]:
    """([(joint, band, label, phrase, target)], [phrases that matched no joint])
    of a RequestSpec's joint states: ``all`` every task-relevant joint but a continuous one, ``joint``
    the one named, ``label`` the movable joints whose child's label the word
    names (else the unlabelled task-relevant ones, which it may name, or the
    task-relevant ones standing in for the category's main part the word names,
    ``part_priors.stand_in_joints``; else none: the phrase goes to the second list),
    top to bottom (or as the request's ``order`` counts) by ``centres`` (link -> (3,) m) or ``volumes`` (link ->
    box volume, m^3, order ``size``), ``ordinal`` picking one (negative: from the end; :func:`_picked`); a
    phrase naming a part or joint overrides one naming none, else a later
    phrase overrides an earlier one."""
    out, unmatched = [], []
    if spec is None:
        return out, unmatched
    movable = [n for n, j in joints.items() if j.type in MOVABLE]
    for js in sorted(spec.joint_states, key=lambda js: js.names_part):
        if js.selector == "all":  # a continuous joint (a knob, a wheel) has no open or closed: not "it" (as refine applies it)
            names = [n for n in task_joints if n in movable and joints[n].type != "continuous"]
            if js.ordinal is not None:  # "the second slightly open", "the freezer open": one of them
                names = _picked(js, names, joints, centres, volumes or {})
        elif js.selector == "joint":  # an override names the joint itself
            names = [js.joint] if js.joint in movable else []
        else:
            tm = [(n, semantics.get(joints[n].child, (None, None))[1]) for n in task_joints if n in movable and joints[n].type != "continuous"]
            names = _named(category, js.label, movable, joints, semantics) \
                or part_priors.stand_in_joints(category or "", js.label, tm)[0]
            names = _picked(js, list(names), joints, centres, volumes or {})
        if not names and not (js.selector == "all" and js.band == "closed" and js.target is None):  # nothing opens: closed as it is
            unmatched.append(js.phrase or f"{js.label or 'all'} {js.band}")
        for n in names:
            out.append((n, js.band, semantics.get(joints[n].child, (None, None))[1], js.phrase, js.target))
    dedup: dict[str, tuple[str, str, str | None, str, StateTarget | None]] = {}
    for item in out:
        dedup[item[0]] = item
    return list(dedup.values()), unmatched


def motion_joints(spec: RequestSpec | None, joints: dict[str, JointInfo], semantics: dict[str, tuple[str, str]],
                  task_joints: list[str], category: str | None = None) -> list[tuple[MotionPhrase, list[str]]]:
    """Each word of ``spec`` about a part's motion with the movable joints it applies to, as refine applies it: a word
    naming a part the joints whose child's label names it (:func:`_named`), one naming none ``task_joints``."""
    if spec is None:
        return []
    movable = [n for n, j in joints.items() if j.type in MOVABLE]
    return [(w, [n for n in task_joints if n in movable] if w.label is None else _named(category, w.label, movable, joints, semantics))
            for w in spec.motions]


def labelled_joints(spec: RequestSpec | None, joints: dict[str, JointInfo], semantics: dict[str, tuple[str, str]],
                    category: str | None = None) -> list[str]:
    """Movable joints the request's ``label`` joint states name, in request then file order (repeats kept)."""
    out: list[str] = []
    if spec is None:
        return out
    movable = [n for n, j in joints.items() if j.type in MOVABLE]
    for js in spec.joint_states:
        if js.selector == "label":
            out += _named(category, js.label, movable, joints, semantics)
    return out


def unmatched_properties(spec: RequestSpec | None, joints: dict[str, JointInfo], semantics: dict[str, tuple[str, str]],
                         task_joints: list[str], category: str | None = None) -> list[tuple[str, str]]:
    """(phrase, why) of every mass or material of ``spec`` naming a part no link's label (``semantics``: link ->
    (kind, label)) carries, and every joint parameter naming a part no movable joint's child carries and none stands
    in for (``part_priors.stand_in_joints`` over ``task_joints``)."""
    out: list[tuple[str, str]] = []
    if spec is None:
        return out
    labels = [lab for _, lab in semantics.values()]
    what = category or "object"
    for p in spec.properties:
        if p.label not in (None, "body") and not part_priors.named_by_word(category or "Generic", p.label, labels)[0]:
            out.append((p.phrase, f"names a '{p.label}' but this {what} has no such part"))
    movable = [n for n, j in joints.items() if j.type in MOVABLE]
    for d in spec.dynamics_values:
        if d.label is None or _named(category, d.label, movable, joints, semantics):
            continue
        tm = [(n, semantics.get(joints[n].child, (None, None))[1]) for n in task_joints if n in movable and joints[n].type != "continuous"]
        try:
            stand_in = part_priors.stand_in_joints(category or "", d.label, tm)[0]
        except Exception:  # a prior that cannot be read must not stop the evaluation
            stand_in = []
        if not stand_in:
            out.append((d.phrase, f"names a '{d.label}' but no part of this {what} carries that label"))
    return out


def request_warnings(spec: RequestSpec, unmatched: list[str], category: str | None) -> list[str]:
    """What of the request the output could not honour, in plain words: nothing understood, the parser's
    warnings, ``unmatched`` phrases (:func:`requested_joints`: naming no part of the object) and the words
    no rule used."""
    if not spec.understood:
        return [f"no word of the request was understood: {spec.text[:120]!r}; refined with the category's defaults"]
    out = list(spec.warnings)
    out += [f"'{p}' names no part of this {category or 'object'}: not applied" for p in unmatched]
    if spec.ignored:
        out.append("words not used: " + "; ".join(f"'{g}'" for g in spec.ignored))
    return out
