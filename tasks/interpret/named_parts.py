"""The parts a request's words name on one object, matched here, in one place, on the refine's
:class:`PartsContext` (the state, the dynamics, the as-asked tier and an output read back all read the request
through it) and on a task's words (:func:`labelled_joints`): a part word names the movable joints
whose moving link carries its label (:func:`named_joints`, ``part_priors.named_by_word``: its own
label or a category synonym, else the synonym table), "all" or a missing label the task-relevant
ones (warned); an ordinal picks one of them (:func:`pick`), counted top to bottom by the moving
part's box center, or left / right / front / back facing the front, or by size
(``docs/design/requests.md``).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.request import (ORDER_ENDS, DynamicsValue, JointStateRequest, MotionPhrase, RequestSpec,
                                      ordinal_words)
from asset2sim.tasks.interpret.part_labels import BODY_LABELS, canonical_label
from asset2sim.tasks.interpret.part_priors import named_by_word, stand_in_joints
from asset2sim.tasks.interpret.request_values import PART_RX

#: Relative difference of box volume below which two parts are the same size ("the smaller door"
#: names neither).
SAME_SIZE = 0.05


class PartsContext(Protocol):
    """What refine matches part words on (its ``EstimationContext`` is one): the asset (labels,
    joints), its category, each movable joint's moving links (``subtrees``) and their closed boxes
    (``joint_boxes``: joint -> (2, 3) m, scale 1), the resting pose (``root_rotation``) and the request."""

    asset: AssetDescription
    category: str
    subtrees: dict[str, list[str]]
    joint_boxes: dict[str, np.ndarray]
    root_rotation: object
    request: RequestSpec


def part_boxes(ctx: PartsContext) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """(joint -> (3,) center, m, scale 1, the resting pose applied; joint -> volume, m^3, scale 1) of each movable
    joint's moving subtree's box in the closed state (``ctx.joint_boxes``): what ordinals count by (:func:`pick`)."""
    R = np.asarray(ctx.root_rotation, float) if ctx.root_rotation is not None else np.eye(3)
    return ({n: R @ (0.5 * (b[0] + b[1])) for n, b in ctx.joint_boxes.items()},
            {n: float(np.prod(np.maximum(b[1] - b[0], 0.0))) for n, b in ctx.joint_boxes.items()})


def named_joints(category: str, word: str | None, asset: AssetDescription, notes: list[str] | None = None) -> list[str]:
    """Of ``asset``'s movable joints, those whose moving link's label the part ``word`` names
    (``part_priors.named_by_word``), in file order; a label the synonym table gives for it said in
    ``notes``."""
    joints = asset.movable_joints()
    hit, how = named_by_word(category, word, [asset.link(j.child).semantic_label for j in joints])
    if how and notes is not None:
        notes.append(f"{how}: {', '.join(joints[i].name for i in hit)}")
    return [joints[i].name for i in hit]


def pick(jr: JointStateRequest | MotionPhrase, targets: list[str], centers: dict[str, np.ndarray],
         sizes: dict[str, float], warnings: list[str] | None = None,
         notes: list[str] | None = None) -> list[str]:
    """``targets`` (joints) sorted as ``jr.order`` counts, by ``centers`` (joint -> (3,) box center,
    m; ``middle``: along the direction the parts spread most) or ``sizes`` (joint -> box volume,
    m^3, smallest first: order ``size``), then narrowed to the one ``jr.ordinal`` names (negative:
    from the end, "the bottom drawer"); all of them sorted without an ordinal. [] with a warning
    when none is: beyond the count, no middle one of an even count, no smaller one of one part or
    of parts of one size (within :data:`SAME_SIZE`). How it was picked goes to ``notes`` ("top
    drawer = joint_1, the highest of 2 drawers"). ``targets`` is sorted in place."""
    warnings = warnings if warnings is not None else []
    notes = notes if notes is not None else []
    part = jr.label or "part"
    what = f"{jr.label}s" if jr.label else "parts"
    n = len(targets)
    order = jr.order
    if order == "middle":  # along the direction the box centers spread most: world z (also without targets), else y
        c = np.array([centers.get(n, np.zeros(3)) for n in targets])
        order = "vertical" if not targets or np.ptp(c[:, 2]) >= np.ptp(c[:, 1]) else "left_right"
    if order == "size":
        targets.sort(key=lambda t: sizes.get(t, 0.0))
    else:  # ascending = first: -y left to right, +y right to left, +x front to back, else -z top to bottom
        sign, axis = {"left_right": (-1, 1), "right_left": (1, 1), "front_back": (1, 0)}.get(order, (-1, 2))
        targets.sort(key=lambda t: sign * float(centers.get(t, np.zeros(3))[axis]))
    if jr.ordinal is None:
        return targets
    if jr.order == "middle":
        if n < 3 or n % 2 == 0:
            warnings.append(f"WARNING: '{jr.phrase}' asks for the middle {part} but this object "
                            f"has {n} {what}{'' if n < 3 else ' (an even count)'}: none is the middle "
                            "one; not applied")
            return []
        chosen = targets[n // 2]
        notes.append(f"'{jr.phrase}': middle {part} = {chosen}, the middle one of {n} {what} "
                     f"({'top to bottom' if order == 'vertical' else 'left to right'})")
        return [chosen]
    if order == "size" and jr.ordinal in (0, -1) and n >= 2:
        v = [sizes.get(t, 0.0) for t in targets]
        first, second = (v[0], v[1]) if jr.ordinal == 0 else (v[-1], v[-2])
        if min(first, second) >= (1.0 - SAME_SIZE) * max(first, second):
            word = "smaller" if jr.ordinal == 0 else "larger"
            warnings.append(f"WARNING: '{jr.phrase}' asks for the {word} {part} but the {what} are of one size (box volumes "
                            f"{', '.join(f'{x:.3g}' for x in v)} m^3): none is {word}; not applied")
            return []
    if order == "size" and jr.ordinal == 0 and n < 2:
        warnings.append(f"WARNING: '{jr.phrase}' asks for the smaller of several {what} but this "
                        f"object has {n}: not applied")
        return []
    if not -n <= jr.ordinal < n:
        warnings.append(f"WARNING: '{jr.phrase}' asks for "
                        f"{ordinal_words(jr.ordinal, jr.order, jr.label)} but only {n} exist; ignored")
        return []
    chosen = targets[jr.ordinal]
    # the words of the report ("the highest of 2 drawers")
    first_word, last_word = ORDER_ENDS.get(order, ("first", "last"))
    rank = (f"the {first_word}" if jr.ordinal == 0
            else f"the {last_word}" if jr.ordinal == -1 or jr.ordinal == n - 1
            else f"number {jr.ordinal + 1} ({first_word} first)")
    notes.append(f"'{jr.phrase}': {part} = {chosen}, {rank} of {n} {what}")
    return [chosen]


def moving_parts(ctx: PartsContext) -> str:
    """The moving parts' labels (else link names), each once, comma-separated; "none" without
    any."""
    parts = (ctx.asset.link(j.child).semantic_label or j.child for j in ctx.asset.movable_joints())
    return ", ".join(dict.fromkeys(parts)) or "none"


def joints_named(ctx: PartsContext, label: str, notes: list[str] | None = None) -> list[str]:
    """Movable joints whose moving link carries ``label`` (``priors.request_label_matches``), else a
    label the synonym table gives for it (:func:`named_joints`, said in ``notes``)."""
    return named_joints(ctx.category, label, ctx.asset, notes)


def joints_of(ctx: PartsContext, d: DynamicsValue | MotionPhrase, relevant: list[str],
              warnings: list[str] | None = None) -> list[str]:
    """The joints an explicit joint parameter or a word about motion names: its label's (else :func:`stand_ins`;
    none when no part stands in), narrowed to the one its ordinal names ("the main door": :func:`pick` by
    :func:`part_boxes`, why none in ``warnings``), or without a label ``relevant``."""
    if d.label is None:
        return relevant
    names = joints_named(ctx, d.label) or stand_ins(ctx, d.label, relevant)[0]
    if getattr(d, "ordinal", None) is not None:
        names = pick(d, list(names), *part_boxes(ctx), warnings)  # type: ignore[arg-type]
    return names


def stand_ins(ctx: PartsContext, label: str, relevant: list[str]) -> tuple[list[str], str]:
    """The non-continuous ``relevant`` joints a part word the object has no part of still names, and
    how (:func:`~asset2sim.tasks.interpret.part_priors.stand_in_joints`)."""
    asset = ctx.asset
    labelled = [(n, asset.link(asset.joint(n).child).semantic_label) for n in relevant
                if asset.joint(n).type != "continuous"]
    return stand_in_joints(ctx.category, label, labelled)


def unit_fits(d: DynamicsValue, linear: bool) -> bool:
    """Whether a joint parameter's unit fits a prismatic (``linear``) or revolute joint (a value
    without unit fits both)."""
    return d.motion != ("rotational" if linear else "linear")


def link_named(ctx: PartsContext, link: str, label: str | None) -> bool:
    """Whether a property's label names ``link``: None everything, "body" an unmoved or
    body-labelled link."""
    if label is None:
        return True
    if label == "body":
        moving = {ln for links in ctx.subtrees.values() for ln in links}
        return link not in moving or canonical_label(ctx.asset.link(link).semantic_label) \
            in BODY_LABELS
    labels = [ln.semantic_label for ln in ctx.asset.links]
    hit, _ = named_by_word(ctx.category, label, labels)
    return ctx.asset.link(link).semantic_label in {labels[i] for i in hit}


def state_targets(ctx: PartsContext, jr: JointStateRequest, relevant: list[str], warnings: list[str],
                  notes: list[str] | None = None) -> list[str]:
    """The joints a state request names: the joint of an override, the movable joints whose part
    carries the label, or for a request that names no part the non-continuous ``relevant`` ones;
    an ordinal picks among them (:func:`pick`) by the parts' boxes (:func:`part_boxes`: centers, or
    volumes for order ``size``), how it picked in ``notes``. A label no
    part of the object carries moves nothing (warned: [] returned) unless some ``relevant`` joints
    stand in for it (:func:`stand_ins`, warned). Warnings appended to ``warnings``."""
    if jr.selector == "joint":  # an override names the joint itself
        return [jr.joint] if jr.joint in relevant or any(j.name == jr.joint for j in ctx.asset.movable_joints()) else []
    if not jr.names_part:
        targets = [n for n in relevant if ctx.asset.joint(n).type != "continuous"]
    elif not (targets := joints_named(ctx, str(jr.label), notes)):
        targets, how = stand_ins(ctx, str(jr.label), relevant)
        applied = f"applied to {how} {targets}" if targets else "not applied"
        fixed = any(link_named(ctx, ln.name, str(jr.label)) for ln in ctx.asset.links)  # a wheel on a fixed joint
        warnings.append(f"WARNING: the request names a '{jr.label}' ('{jr.phrase}') but "
                        + (f"this {ctx.category}'s {jr.label} is on a fixed joint (it does not move)" if fixed else
                           f"no part of this {ctx.category} carries that label")
                        + f"; its moving parts: {moving_parts(ctx)}; '{jr.phrase}' {applied}")
        if not targets:
            return []
    if jr.ordinal is not None:
        targets = pick(jr, list(targets), *part_boxes(ctx), warnings, notes)
    return targets


def count_warnings(ctx: PartsContext) -> list[str]:
    """Warnings for part counts ("two-drawer") that differ from the movable parts with that
    label."""
    out = []
    for label, n in ctx.request.part_counts.items():
        if not PART_RX.fullmatch(label):
            continue
        have = joints_named(ctx, label)
        if len(have) != n:
            which = f" ({', '.join(have)})" if have else f"; its moving parts: {moving_parts(ctx)}"
            out.append(f"WARNING: the request names {n} {label}(s) but this {ctx.category} has "
                       f"{len(have)} movable {label}(s){which}")
    return out


def labelled_joints(spec: RequestSpec | None, asset: AssetDescription, category: str | None = None) -> list[str]:
    """Movable joints of ``asset`` the request's ``label`` joint states name (:func:`named_joints`), in request then
    file order (repeats kept)."""
    if spec is None:
        return []
    return [n for js in spec.joint_states if js.selector == "label" for n in named_joints(category or "Generic", js.label, asset)]
