"""The joints and links a request's part words name on one object: a label its movable joints
(``priors.request_label_matches``), "all" or a missing label the task-relevant ones (warned). Ordinals count top to
bottom by the moving part's box center, or left / right / front / back facing the front (``docs/design/requests.md``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from asset2sim.schemas.request import ORDER_ENDS, DynamicsValue, JointStateRequest, ordinal_words
from asset2sim.tasks.interpret import priors
from asset2sim.tasks.interpret.part_labels import BODY_LABELS, canonical_label
from asset2sim.tasks.interpret.part_priors import named_by_word, stand_in_joints
from asset2sim.tasks.interpret.request_values import PART_RX

if TYPE_CHECKING:  # typing only: the context module imports this stage's parser
    from asset2sim.tasks.synthesize.context import EstimationContext


def moving_parts(ctx: "EstimationContext") -> str:
    """The moving parts' labels (else link names), each once, comma-separated; "none" without any."""
    return ", ".join(dict.fromkeys(ctx.asset.link(j.child).semantic_label or j.child for j in ctx.asset.movable_joints())) or "none"


def joints_named(ctx: "EstimationContext", label: str, notes: list[str] | None = None) -> list[str]:
    """Movable joints whose moving link carries ``label`` (``priors.request_label_matches``), else a label the
    synonym table gives for it (``part_priors.named_by_word``, said in ``notes``)."""
    joints = ctx.asset.movable_joints()
    hit, how = named_by_word(ctx.category, label, [ctx.asset.link(j.child).semantic_label for j in joints])
    if how and notes is not None:
        notes.append(f"{how}: {', '.join(joints[i].name for i in hit)}")
    return [joints[i].name for i in hit]


def joints_of(ctx: "EstimationContext", d: DynamicsValue, relevant: list[str]) -> list[str]:
    """The joints an explicit joint parameter names: its label's (else :func:`stand_ins`; none when no part
    stands in), or without a label ``relevant``."""
    return relevant if d.label is None else (joints_named(ctx, d.label) or stand_ins(ctx, d.label, relevant)[0])


def stand_ins(ctx: "EstimationContext", label: str, relevant: list[str]) -> tuple[list[str], str]:
    """The non-continuous ``relevant`` joints a part word the object has no part of still names, and how
    (:func:`~asset2sim.tasks.interpret.part_priors.stand_in_joints`)."""
    labelled = [(n, ctx.asset.link(ctx.asset.joint(n).child).semantic_label) for n in relevant if ctx.asset.joint(n).type != "continuous"]
    return stand_in_joints(ctx.category, label, labelled)


def unit_fits(d: DynamicsValue, linear: bool) -> bool:
    """Whether a joint parameter's unit fits a prismatic (``linear``) or revolute joint (a value without unit fits both)."""
    return not ((d.motion == "rotational" and linear) or (d.motion == "linear" and not linear))


def link_named(ctx: "EstimationContext", link: str, label: str | None) -> bool:
    """Whether a property's label names ``link``: None everything, "body" an unmoved or body-labelled link."""
    if label is None:
        return True
    if label == "body":
        moving = {ln for links in ctx.subtrees.values() for ln in links}
        return link not in moving or (canonical_label(ctx.asset.link(link).semantic_label) in BODY_LABELS)
    labels = [ln.semantic_label for ln in ctx.asset.links]
    hit, _ = named_by_word(ctx.category, label, labels)
    return ctx.asset.link(link).semantic_label in {labels[i] for i in hit}


#: Relative difference of box volume below which two parts are the same size ("the smaller door" names neither).
SAME_SIZE = 0.05
#: Words for the orders resolved from the geometry, in the report ("the highest of 2 drawers").
_FIRST_WORDS = ORDER_ENDS


def _order_key(order: str, c: np.ndarray) -> float:
    """Sort key of a joint for an ordinal's order (ascending = first); ``c`` the (3,) box center, m."""
    return float({"left_right": -c[1], "right_left": c[1], "front_back": c[0]}.get(order, -c[2]))


def _spread_order(targets: list[str], centers: dict[str, np.ndarray]) -> str:
    """The order along which ``targets``' box centers spread most: ``vertical`` (world z) or ``left_right`` (y)."""
    c = np.array([centers.get(n, np.zeros(3)) for n in targets])
    return "vertical" if np.ptp(c[:, 2]) >= np.ptp(c[:, 1]) else "left_right"


def _pick(jr: JointStateRequest, targets: list[str], centers: dict[str, np.ndarray], sizes: dict[str, float],
          warnings: list[str], notes: list[str]) -> list[str]:
    """The joint an ordinal names among ``targets`` (sorted here), [] with a warning when none: beyond the count,
    no middle one of an even count, no smaller one of one part or of parts of one size (within :data:`SAME_SIZE`).
    How it was picked goes to ``notes`` ("top drawer = joint_1, the highest of 2 drawers")."""
    what = f"{jr.label or 'part'}s" if jr.label else "parts"
    n = len(targets)
    order = _spread_order(targets, centers) if jr.order == "middle" else jr.order
    if order == "size":
        targets.sort(key=lambda t: sizes.get(t, 0.0))
    else:
        targets.sort(key=lambda t: _order_key(order, centers.get(t, np.zeros(3))))
    if jr.order == "middle":
        if n < 3 or n % 2 == 0:
            warnings.append(f"WARNING: '{jr.phrase}' asks for the middle {jr.label or 'part'} but this object has {n} {what}"
                            f"{'' if n < 3 else ' (an even count)'}: none is the middle one; not applied")
            return []
        pick = targets[n // 2]
        notes.append(f"'{jr.phrase}': middle {jr.label or 'part'} = {pick}, the middle one of {n} {what} "
                     f"({'top to bottom' if order == 'vertical' else 'left to right'})")
        return [pick]
    if order == "size" and jr.ordinal in (0, -1) and n >= 2:
        v = [sizes.get(t, 0.0) for t in targets]
        pick, nxt = (v[0], v[1]) if jr.ordinal == 0 else (v[-1], v[-2])
        if min(pick, nxt) >= (1.0 - SAME_SIZE) * max(pick, nxt):
            word = "smaller" if jr.ordinal == 0 else "larger"
            warnings.append(f"WARNING: '{jr.phrase}' asks for the {word} {jr.label or 'part'} but the {what} are of one size "
                            f"(box volumes {', '.join(f'{x:.3g}' for x in v)} m^3): none is {word}; not applied")
            return []
    if order == "size" and jr.ordinal == 0 and n < 2:
        warnings.append(f"WARNING: '{jr.phrase}' asks for the smaller of several {what} but this object has {n}: not applied")
        return []
    if jr.ordinal is None:
        return targets
    if not -n <= jr.ordinal < n:
        warnings.append(f"WARNING: '{jr.phrase}' asks for {ordinal_words(jr.ordinal, jr.order, jr.label)} but only {n} exist; "
                        "ignored")
        return []
    pick = targets[jr.ordinal]
    first, last = _FIRST_WORDS.get(order, ("first", "last"))
    rank = (f"the {first}" if jr.ordinal == 0 else f"the {last}" if jr.ordinal == -1 or jr.ordinal == n - 1
            else f"number {jr.ordinal + 1} ({first} first)")
    notes.append(f"'{jr.phrase}': {jr.label or 'part'} = {pick}, {rank} of {n} {what}")
    return [pick]


def state_targets(ctx: "EstimationContext", jr: JointStateRequest, relevant: list[str], centers: dict[str, np.ndarray],
                  warnings: list[str], sizes: dict[str, float] | None = None, notes: list[str] | None = None) -> list[str]:
    """The joints a state request names: the joint of an override, the movable joints whose part carries the
    label, or for a request that names no part the non-continuous ``relevant`` ones; an ordinal picks among
    them by ``centers`` (joint -> (3,) box center, m) or ``sizes`` (joint -> box volume, m^3: order ``size``),
    how it picked in ``notes``. A label no part of the object carries moves nothing
    (warned: [] returned) unless some ``relevant`` joints stand in for it (:func:`stand_ins`, warned).
    Warnings appended to ``warnings``."""
    if jr.selector == "joint":  # an override names the joint itself
        return [jr.joint] if jr.joint in relevant or any(j.name == jr.joint for j in ctx.asset.movable_joints()) else []
    named = jr.names_part
    targets = joints_named(ctx, str(jr.label), notes) if named else []
    if named and not targets:
        targets, how = stand_ins(ctx, str(jr.label), relevant)
        warnings.append(f"WARNING: the request names a '{jr.label}' ('{jr.phrase}') but no part of this {ctx.category} carries that "
                        f"label; its moving parts: {moving_parts(ctx)}; " + (f"'{jr.phrase}' applied to {how} {targets}" if targets
                                                                               else f"'{jr.phrase}' not applied"))
        if not targets:
            return []
    if not named:
        targets = [n for n in relevant if ctx.asset.joint(n).type != "continuous"]
    if jr.ordinal is not None:
        targets = _pick(jr, list(targets), centers, sizes or {}, warnings, notes if notes is not None else [])
    return targets


def count_warnings(ctx: "EstimationContext") -> list[str]:
    """Warnings for part counts ("two-drawer") that differ from the movable parts with that label."""
    out = []
    for label, n in ctx.request.part_counts.items():
        if not PART_RX.fullmatch(label):
            continue
        have = joints_named(ctx, label)
        if len(have) != n:
            out.append(f"WARNING: the request names {n} {label}(s) but this {ctx.category} has {len(have)} movable {label}(s)"
                       + (f" ({', '.join(have)})" if have else f"; its moving parts: {moving_parts(ctx)}"))
    return out
