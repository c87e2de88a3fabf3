"""The joints and links a request's part words name on one object: a label its movable joints
(``priors.request_label_matches``), "all" or a missing label the task-relevant ones (warned). Ordinals count top to
bottom by the moving part's box center, or left / right / front / back facing the front (``docs/design/requests.md``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from asset2sim.schemas.request import DynamicsValue, JointStateRequest
from asset2sim.tasks.interpret import priors
from asset2sim.tasks.interpret.part_labels import BODY_LABELS, canonical_label
from asset2sim.tasks.interpret.part_priors import stand_in_joints
from asset2sim.tasks.interpret.request_values import PART_RX

if TYPE_CHECKING:  # typing only: the context module imports this stage's parser
    from asset2sim.tasks.synthesize.context import EstimationContext


def moving_parts(ctx: "EstimationContext") -> str:
    """The moving parts' labels (else link names), each once, comma-separated; "none" without any."""
    return ", ".join(dict.fromkeys(ctx.asset.link(j.child).semantic_label or j.child for j in ctx.asset.movable_joints())) or "none"


def joints_named(ctx: "EstimationContext", label: str) -> list[str]:
    """Movable joints whose moving link carries ``label`` (``priors.request_label_matches``)."""
    return [j.name for j in ctx.asset.movable_joints() if priors.request_label_matches(ctx.category, label, ctx.asset.link(j.child).semantic_label)]


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
    return priors.request_label_matches(ctx.category, label, ctx.asset.link(link).semantic_label)


def _order_key(order: str, c: np.ndarray) -> float:
    """Sort key of a joint for an ordinal's order (ascending = first); ``c`` the (3,) box center, m."""
    return float({"left_right": -c[1], "right_left": c[1], "front_back": c[0]}.get(order, -c[2]))


def state_targets(ctx: "EstimationContext", jr: JointStateRequest, relevant: list[str], centers: dict[str, np.ndarray],
                  warnings: list[str]) -> list[str]:
    """The joints a state request names: the joint of an override, the movable joints whose part carries the
    label, or for a request that names no part the non-continuous ``relevant`` ones; an ordinal picks among
    them by ``centers`` (joint -> (3,) box center, m). A label no part of the object carries moves nothing
    (warned: [] returned) unless some ``relevant`` joints stand in for it (:func:`stand_ins`, warned).
    Warnings appended to ``warnings``."""
    if jr.selector == "joint":  # an override names the joint itself
        return [jr.joint] if jr.joint in relevant or any(j.name == jr.joint for j in ctx.asset.movable_joints()) else []
    named = jr.names_part
    targets = joints_named(ctx, str(jr.label)) if named else []
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
        targets.sort(key=lambda n: _order_key(jr.order, centers.get(n, np.zeros(3))))
        if -len(targets) <= jr.ordinal < len(targets):
            targets = [targets[jr.ordinal]]
        else:
            warnings.append(f"WARNING: '{jr.phrase}' asks for {jr.label or 'part'} #{jr.ordinal + 1 if jr.ordinal >= 0 else jr.ordinal} "
                            f"({jr.order}) but only {len(targets)} exist; ignored")
            targets = []
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
