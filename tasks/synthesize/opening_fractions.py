"""The opening fraction a request's number or end asks of one joint, from the
geometry. Numbers count from the geometric closed end (a revolute joint's
distance is the gap at the farthest point from the axis, angle = d / r). "up" /
"down" are the highest / lowest box center in world z over the travel (the travel end when
it is within :data:`END_SNAP` of the part's rise of it); a lone "open" of a part its weight carries open (a
drop-down door: :func:`falls_open`) is its open end; "on" /
"off" of a toggle switch its high / low end (NFPA 70 NEC 404.7), of a lid or cap closed / fully open
(put on, taken off), of other parts fully open / closed. A part whose height changes less than :data:`FLAT_TRAVEL`
of the object's size has no up or down.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from asset2sim.schemas.request import StateTarget
from asset2sim.tasks.geometry.closed_state import links_aabb
from asset2sim.tasks.interpret.part_labels import canonical_label

if TYPE_CHECKING:  # typing only: the context module imports this stage's parser
    from asset2sim.engines.base import SimSession
    from asset2sim.tasks.synthesize.context import EstimationContext

#: Height change over the travel (fraction of the largest extent) below which a part has no "up" or "down".
FLAT_TRAVEL = 0.02
#: Labels whose "on"/"off" are their high/low ends (toggle switches).
TOGGLE_LABELS = frozenset({"switch", "toggle", "rocker"})
#: Labels whose "on" is in place (closed) and "off" taken off (fully open): "the cap off", "the lid on".
COVER_LABELS = frozenset({"lid", "cap"})
#: Opening fractions at which a part's weight must turn it open for it to fall open (:func:`falls_open`; the
#: counterbalance's ``spring_holds.DOWNWARD_FRACTIONS``).
FALL_FRACTIONS = (0.25, 0.5, 0.75, 1.0)
#: Samples of the travel searched for the highest / lowest end.
END_SAMPLES = 41
#: A travel end within this share of the part's rise (max - min height over its travel) of the highest (lowest)
#: position is "up" ("down"): a toilet seat raised past upright rests at the end of its travel.
END_SNAP = 0.1


def box_center(ctx: EstimationContext, kin: SimSession, joint: str) -> np.ndarray:
    """(3,) world center (m, scale 1, resting pose applied) of the joint's moving subtree's box at ``kin``'s
    current state; zeros without geometry."""
    R = np.asarray(ctx.root_rotation, float) if ctx.root_rotation is not None else np.eye(3)
    box = links_aabb(kin, ctx.subtrees[joint], ctx.hull_points)
    return np.zeros(3) if box is None else R @ (0.5 * (box[0] + box[1]))


def _radius(ctx: EstimationContext, kin: SimSession, joint: str, state: dict[str, float]) -> float:
    """Largest distance (m, scale 1) of the joint's moving hull points from its axis at ``state`` (``kin`` moved there)."""
    kin.set_joint_positions(state)
    p0, Rc = kin.link_frame(kin.joint_child[joint])
    a = Rc @ np.asarray(kin.joint_axis(joint), float)
    a = a / max(np.linalg.norm(a), 1e-12)
    r = 0.0
    for ln in (ln for ln in ctx.subtrees[joint] if ctx.hull_points.get(ln) is not None):
        pos, R = kin.link_frame(ln)
        w = ctx.hull_points[ln] @ R.T + pos - p0
        r = max(r, float(np.linalg.norm(w - np.outer(w @ a, a), axis=1).max()))
    return r


def _end_fraction(ctx: EstimationContext, kin: SimSession, joint: str, end: str) -> tuple[float | None, str]:
    """Opening fraction of the joint's highest / lowest position in world z (``kin`` moved along its travel, the
    other joints at their closed ends); None and why when it moves flat."""
    cs, closed_state = ctx.closed[joint], ctx.closed_state()
    fr = np.linspace(0.0, 1.0, END_SAMPLES)
    zs = []
    for f in fr:
        kin.set_joint_positions({**closed_state, joint: cs.position(float(f))})
        zs.append(box_center(ctx, kin, joint)[2])
    zs = np.asarray(zs)
    size = float(np.max(ctx.closed_extents)) if len(ctx.closed_extents) else 1.0
    if zs.max() - zs.min() < FLAT_TRAVEL * size:
        return None, f"its height changes by {zs.max() - zs.min():.3g} (< {FLAT_TRAVEL:g} of the object's size) over the travel"
    up = 1.0 if end == "high" else -1.0
    word = "highest" if end == "high" else "lowest"
    i, e = int(np.argmax(up * zs)), (0 if up * zs[0] >= up * zs[-1] else len(zs) - 1)
    if i != e and abs(zs[e] - zs[i]) <= END_SNAP * (zs.max() - zs.min()):
        # a seat or lid raised past upright: "up" is where it rests at the end of its travel, within a tenth of
        # its rise of the very highest point
        return float(fr[e]), (f"the travel end at opening fraction {fr[e]:.3g}, within {END_SNAP:g} of the part's rise of its {word} "
                              f"position in world z (at {fr[i]:.3g})")
    return float(fr[i]), f"{word} position in world z at opening fraction {fr[i]:.3g}"


def weight_moment(ctx: EstimationContext, kin: SimSession, joint: str, state: dict[str, float]) -> float:
    """Moment of gravity (world -z, the resting pose ``ctx.root_rotation`` applied) about a hinge's axis per unit of
    its part's weight, m (> 0: it turns the part open), taken at its moving subtree's box center with ``kin`` (the
    input's kinematics session) moved to ``state`` (joint -> rad or m, input units). Source: the moment of a force
    about an axis, M = a . (r x F) (Meriam & Kraige, Engineering Mechanics: Statics, sec. 2/5)."""
    kin.set_joint_positions(state)
    R = np.asarray(ctx.root_rotation, float) if ctx.root_rotation is not None else np.eye(3)
    p0, Rc = kin.link_frame(kin.joint_child[joint])
    axis = R @ Rc @ np.asarray(kin.joint_axis(joint), float)
    return float(axis @ np.cross(box_center(ctx, kin, joint) - R @ p0, [0.0, 0.0, -1.0])) * float(ctx.closed[joint].direction)


def falls_open(ctx: EstimationContext, kin: SimSession, joint: str) -> bool:
    """Whether a hinged part's own weight carries it open to its open end: its :func:`weight_moment` turns it open
    at each of :data:`FALL_FRACTIONS` of its range (an oven's or a dishwasher's drop-down door, a drop-front lid: the
    parts :func:`~asset2sim.tasks.synthesize.spring_holds.counterbalance` balances), the other joints at their closed
    ends; ``kin`` (the input's kinematics session) is moved."""
    cs = ctx.closed[joint]
    if ctx.asset.joint(joint).type != "revolute" or not cs.open_range > 0:
        return False
    return all(weight_moment(ctx, kin, joint, {**ctx.closed_state(), joint: cs.position(f)}) > 0.0 for f in FALL_FRACTIONS)


def fraction_for(ctx: EstimationContext, kin: SimSession, joint: str, target: StateTarget, scale: float,
                 label: str) -> tuple[float | None, str]:
    """(opening fraction ``target`` asks of ``joint``, how it was decided), None with the reason when it cannot
    be applied; distances in m at ``scale``, ends and distances measured with the other joints at their closed ends;
    ``kin`` (the input's kinematics session) is moved for ends and distances."""
    cs = ctx.closed[joint]
    jt = ctx.asset.joint(joint).type
    if target.kind == "fraction":
        return float(target.value), f"{target.value:.3g} of the opening range"
    if target.kind == "end":
        end = target.end
        canon = canonical_label(label) or label
        if end in ("on", "off"):
            if canon in COVER_LABELS:
                return (0.0 if end == "on" else 1.0), f"'{target.end}' of a {canon}: {'in place, closed' if end == 'on' else 'taken off, fully open'}"
            f, why = _end_fraction(ctx, kin, joint, "high" if end == "on" else "low") if canon in TOGGLE_LABELS else (None, "")
            # a toggle flipped up for on; one that turns flat (a faucet's handle) or another part: as "turned on" / "turned off"
            return (f, why) if f is not None else ((1.0 if end == "on" else 0.0), f"'{target.end}' of a {canon or 'part'}: "
                                                   f"{'fully open' if end == 'on' else 'closed'} ({why or 'not a toggle switch'})")
        return _end_fraction(ctx, kin, joint, str(end))
    if target.kind == "angle":
        if jt == "prismatic":
            return None, f"{np.degrees(target.value):.4g} degrees asked of a sliding joint (it moves in metres)"
        return float(target.value) / max(cs.open_range, 1e-9), (
            f"{np.degrees(target.value):.4g} deg from the closed end of a {np.degrees(cs.open_range):.4g} deg opening range")
    # distance
    if jt == "prismatic":
        rng = cs.open_range * scale
        return float(target.value) / max(rng, 1e-12), f"{target.value:.4g} m from the closed end of a {rng:.4g} m travel"
    r = _radius(ctx, kin, joint, ctx.closed_state()) * scale
    if r <= 0:
        return None, "no geometry to measure a distance on"
    ang = float(target.value) / r
    return ang / max(cs.open_range, 1e-9), (
        f"{target.value:.4g} m gap at the part's farthest point from the axis (r = {r:.4g} m): {np.degrees(ang):.4g} deg")
