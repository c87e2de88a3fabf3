"""Running clearance: two links that are not parent and child and touch where
they slide past each other (drawers stacked in a cabinet, doors meeting in the
middle) get the moving piece's face moved back :data:`RUNNING_CLEARANCE` from
its neighbour at the modelled pose, so contact margins do not read the touch
as penetration that holds the part; so do two links no movable joint moves
apart (an oven's frame and its panel, both fixed to the body). A contact along
the motion (a stop) is kept."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asset2sim import urdf
from asset2sim.frames import axis_angle_matrix
from asset2sim.tasks.assemble.convex_pieces import Piece, posed
from asset2sim.tasks.assemble.joint_sweep import reference_state
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.geometry.closed_state import tree_path

#: Words every note of :func:`running_clearance` (and of the state stage's clearance repair) carries.
RUNNING_CLEARANCE_NOTE = "running clearance"
#: Running clearance (m) of a sliding contact: PyBullet's two 1 mm hull margins plus 0.5 mm.
RUNNING_CLEARANCE = 0.0025
#: |cos| between a contact normal and the motion of the moving face below which the contact slides (else a stop).
SLIDING_COS = 0.5
#: A squeeze never takes more than this fraction of a piece's width along the contact normal.
MAX_SQUEEZE = 0.5
#: Deepest overlap (m) :func:`swept_clearance` treats as parts modelled touching.
TOUCHING_OVERLAP = 0.0005
#: Deepest overlap (m) at the modelled pose that :func:`running_clearance` clears: parts modelled overlapping where
#: they meet, which no state separates (a joint slides along the contact, or none moves the pair apart): twice the
#: deepest seen on unseen PartNet-Mobility ovens and safes (an oven's two doors meeting, 6 mm). Deeper is not a
#: modelling overlap (a part inside another's hull: the state stage's collision repair).
MODELLED_OVERLAP = 0.012


def sat_gap(p: np.ndarray, q: np.ndarray) -> tuple[float, np.ndarray]:
    """Separating-axis test of two convex point sets (k, 3), (l, 3) m over the
    face normals of both hulls (Gottschalk, Lin and Manocha, "OBBTree",
    SIGGRAPH 1996: the face-normal axes of the SAT for convex polyhedra).
    Returns (gap g m, unit axis n from p to q): g > 0 they are apart by at
    least g; g <= 0 they overlap by at most -g along n.

    Raises:
        ValueError: a set spans no volume.
    """
    return _sat_on(p, q, np.vstack([_normals(p), _normals(q)]))


def _normals(p: np.ndarray) -> np.ndarray:
    """Unit outward face normals (f, 3) of the hull of ``p`` (k, 3). Raises ValueError (no volume)."""
    try:
        n = ConvexHull(p).equations[:, :3]
    except (QhullError, ValueError) as exc:
        raise ValueError("a convex piece spans no volume") from exc
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _sat_on(p: np.ndarray, q: np.ndarray, axes: np.ndarray) -> tuple[float, np.ndarray]:
    """:func:`sat_gap` of ``p`` (k, 3) and ``q`` (l, 3) over the unit ``axes`` (A, 3)."""
    sp, sq = p @ axes.T, q @ axes.T  # (k, A), (l, A)
    ahead = sq.min(axis=0) - sp.max(axis=0)  # q beyond p along +axis
    behind = sp.min(axis=0) - sq.max(axis=0)  # q before p
    gaps = np.maximum(ahead, behind)
    i = int(np.argmax(gaps))
    return float(gaps[i]), axes[i] if ahead[i] >= behind[i] else -axes[i]


def squeeze(p: np.ndarray, n: np.ndarray, delta: float) -> tuple[np.ndarray, float]:
    """Move the face of ``p`` (k, 3) m towards the unit direction ``n`` back
    by ``delta`` m (at most :data:`MAX_SQUEEZE` of its width along ``n``),
    keeping the face towards -n: an affine squeeze along ``n``, so a convex
    piece stays convex. Returns (points (k, 3) m, delta used m)."""
    s = p @ n
    lo, w = float(s.min()), float(np.ptp(s))
    d = min(delta, MAX_SQUEEZE * w)
    if w <= 0 or d <= 0:
        return p, 0.0
    return p - np.outer((s - lo) * (d / w), n), d


def clear_sliding_contact(p: np.ndarray, q: np.ndarray, velocity: Callable[[np.ndarray], np.ndarray],
                          deepest: float = np.inf) -> tuple[np.ndarray, float, float] | None:
    """Running clearance of a moving convex piece ``p`` (k, 3) m against a
    piece ``q`` (l, 3) m of a link it moves past, both in one frame: with the
    gap g and axis n of :func:`sat_gap`, when -``deepest`` < g <
    :data:`RUNNING_CLEARANCE` and the contact slides (|n . t| <
    :data:`SLIDING_COS` |t|, t = ``velocity(c)`` (3,) at the contact face's
    centre c), p's face towards q is moved back along n by
    :data:`RUNNING_CLEARANCE` - g (:func:`squeeze`).

    Returns (squeezed p (k, 3) m, squeeze used m, gap g m), or None when
    the two are not in sliding contact (or the squeeze would move nothing).

    Raises:
        ValueError: a piece spans no volume.
    """
    g, n = sat_gap(p, q)
    if g >= RUNNING_CLEARANCE - 1e-9 or g <= -deepest:  # (rounding of a piece already given clearance)
        return None
    s = p @ n
    # at the contact face's centre
    t = np.asarray(velocity(p[s >= s.max() - 1e-3].mean(axis=0)), float)
    norm = float(np.linalg.norm(t))
    if norm > 1e-9 and abs(float(n @ t)) / norm >= SLIDING_COS:
        return None
    out, used = squeeze(p, n, RUNNING_CLEARANCE - g)
    return (out, used, g) if used > 0 else None


def joint_velocity(joint: urdf.UrdfJoint, T: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """The direction (3,) in which ``joint`` moves a point (3,) m given in the
    frame where its child frame is ``T`` (4, 4): the axis (prismatic), or axis
    x (point - origin) (revolute, continuous)."""
    R, t = T[:3, :3], T[:3, 3]
    axis = R @ joint.axis
    if joint.type == "prismatic":
        return lambda c: axis
    return lambda c: np.cross(axis, np.asarray(c, float) - t)


def _moving_links(model: urdf.UrdfModel, pieces: dict[str, list[Piece]]):
    """(movable joint, a link with pieces it moves, the links with pieces it does not move, parent and
    child of that link excepted), joints in file order: the pairs the clearances look at."""
    adjacent, subtrees = model.adjacent_pairs(), limits.subtrees(model)
    for joint in model.movable_joints:
        moved = subtrees[joint.name]
        for ln in moved:
            if pieces.get(ln):
                yield joint, ln, [o for o in model.links
                                  if o not in moved and pieces.get(o) and frozenset((ln, o)) not in adjacent]


def running_clearance(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], notes: list[str]) -> set[tuple[str, str]]:
    """Give running clearance, in place, to every sliding contact between a
    link a movable joint moves and a link it does not move (parent-child
    pairs excepted), measured at :func:`reference_state`: each moving piece in
    contact with an overlap of at most :data:`MODELLED_OVERLAP` along a face
    that slides (at most :data:`TOUCHING_OVERLAP` against one of its own
    ancestors: a part deeper inside the link that carries it, a latch in the
    body its lid is hinged to, is the state stage's collision repair) is squeezed back (:func:`clear_sliding_contact`) by the first
    joint in file order that moves it, once per pair of pieces; and likewise
    every contact between two links only fixed joints join (nothing moves, so
    nothing is a stop), the smaller of the two squeezed; what a thin piece cannot give
    (:data:`MAX_SQUEEZE`) the other piece's face gives. Notes
    name each change; returns the (moving link, other link) pairs given clearance."""
    pairs: set[tuple[str, str]] = set()
    poses = model.link_poses(reference_state(model))
    done: set[tuple[str, int, str, int]] = set()
    boxes = {ln: [posed(p.points, poses[ln]) for p in pl] for ln, pl in pieces.items()}
    still = lambda c: np.zeros(3)  # noqa: E731  a point of a pair no joint moves apart
    moving = [(f"sliding along {j.name!r}", ln, others, j) for j, ln, others in _moving_links(model, pieces)]
    # then the pairs no state moves apart: a link with pieces and the larger links with pieces that only fixed joints join
    # to it, parent and child excepted, the smaller of each (its pieces' volume; then file order) the one squeezed
    adjacent = model.adjacent_pairs()
    names = sorted(model.links, key=lambda n: sum(p.volume for p in pieces.get(n, [])))
    for i, ln in enumerate(names):
        group = limits.rigid_group(model, ln)
        others = [o for o in names[i + 1:] if o in group and pieces.get(o) and frozenset((ln, o)) not in adjacent]
        if pieces.get(ln) and others:
            moving.append(("no joint moves them apart", ln, others, None))
    for why, ln, others, joint in moving:
        inv = np.linalg.inv(poses[ln])
        velocity = still if joint is None else joint_velocity(joint, inv @ poses[joint.child])
        for other in others:
            To = inv @ poses[other]
            lineal = not all(tree_path(model.joints, ln, other))  # one link carries the other: an empty side of the path
            deepest = TOUCHING_OVERLAP if joint is not None and lineal else MODELLED_OVERLAP
            for k in range(len(pieces[other])):
                for i, P in enumerate(pieces[ln]):
                    Q, qw, pw = pieces[other][k], boxes[other][k], boxes[ln][i]
                    if (ln, i, other, k) in done:
                        continue
                    if np.any(np.minimum(pw.max(axis=0), qw.max(axis=0)) + RUNNING_CLEARANCE
                              < np.maximum(pw.min(axis=0), qw.min(axis=0))):
                        continue  # bounding boxes apart by more than the clearance
                    ql = posed(Q.points, To)
                    try:
                        hit = clear_sliding_contact(P.points, ql, velocity, deepest=deepest)
                    except ValueError:
                        continue
                    if hit is None:
                        continue
                    pts, used, g = hit
                    done.add((ln, i, other, k))
                    try:
                        pieces[ln][i] = Piece.of(pts, P.sources)
                    except (QhullError, ValueError):
                        continue
                    boxes[ln][i] = posed(pieces[ln][i].points, poses[ln])
                    short, n = sat_gap(pts, ql)
                    ql, rest = squeeze(ql, -n, RUNNING_CLEARANCE - short) if short < RUNNING_CLEARANCE - 1e-6 else (ql, 0.0)
                    if rest > 0:  # the rest from the other piece's face, back in its link's frame
                        try:
                            pieces[other][k] = Piece.of((ql - To[:3, 3]) @ To[:3, :3], Q.sources)
                        except (QhullError, ValueError):
                            rest = 0.0
                        boxes[other][k] = posed(pieces[other][k].points, poses[other])
                    if joint is not None:  # a sliding pair (a fixed one slides along nothing)
                        pairs.add((ln, other))
                    notes.append(f"link {ln!r}: collision piece {i} given {used * 1000:.2g} mm {RUNNING_CLEARANCE_NOTE} against "
                                 f"{other!r} (gap {g * 1000:.2g} mm, {why})" + (f", {rest * 1000:.2g} mm from its piece {k}" if rest > 0 else ""))
    return pairs


#: Positions sampled over a revolute joint's range (a continuous joint's full turn) by :func:`swept_clearance`.
SWEPT_SAMPLES = 24
#: Most a piece is shrunk about a joint's axis by :func:`swept_clearance` (fraction of its radius).
MAX_RADIAL_SHRINK = 0.25
#: Gap (m) under which a turning piece touches in PyBullet (its two 1 mm hull margins): :func:`swept_clearance` acts.
SWEPT_TRIGGER = 0.002


def _turns(axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotations (A, 3, 3) by each of ``angles`` (A,) rad about the unit ``axis`` (3,) (:func:`axis_angle_matrix`)."""
    return np.stack([axis_angle_matrix(axis, float(a)) for a in angles]).reshape(-1, 3, 3)


def _swept_gap(p: np.ndarray, q: np.ndarray, origin: np.ndarray, axis: np.ndarray, angles: np.ndarray,
               turns: np.ndarray | None = None, normals: tuple[np.ndarray, np.ndarray] | None = None
               ) -> tuple[float, float, np.ndarray]:
    """(least :func:`sat_gap` m, its angle rad, its axis (3,)) of ``p`` (k, 3) turned by each of ``angles`` (A,)
    about the line (``origin``, ``axis``) against ``q`` (l, 3), one frame, all angles at once (each hull made
    once, ``p``'s face normals turned with it); the first angle of the least gap. ``turns`` (A, 3, 3): the
    rotations of ``angles`` (:func:`_turns`), ``normals``: :func:`_normals` of ``p`` and ``q``; made when None.
    Raises ValueError (no volume)."""
    if not len(angles):
        return np.inf, 0.0, np.zeros(3)
    rt = (_turns(axis, angles) if turns is None else turns).transpose(0, 2, 1)
    np_, nq = (_normals(p), _normals(q)) if normals is None else normals
    axes = np.concatenate([np.matmul(np_, rt), np.broadcast_to(nq, (len(rt),) + nq.shape)], axis=1)  # (A, F, 3)
    at = axes.transpose(0, 2, 1)
    sp, sq = np.matmul(np.matmul(p - origin, rt) + origin, at), np.matmul(q, at)  # (A, k, F), (A, l, F)
    ahead = sq.min(axis=1) - sp.max(axis=1)  # q beyond p along +axis
    behind = sp.min(axis=1) - sq.max(axis=1)
    gaps = np.maximum(ahead, behind)  # (A, F)
    best = gaps.argmax(axis=1)
    a = int(np.argmin(gaps.max(axis=1)))
    i = int(best[a])
    return float(gaps[a, i]), float(angles[a]), (axes[a, i] if ahead[a, i] >= behind[a, i] else -axes[a, i])


def _clear_turning_piece(p: np.ndarray, q: np.ndarray, origin: np.ndarray, axis: np.ndarray, angles: np.ndarray,
                         turns: np.ndarray | None = None, normals: tuple[np.ndarray, np.ndarray] | None = None
                         ) -> tuple[np.ndarray, float, float] | None:
    """``p`` (k, 3) m shrunk about the line (``origin``, unit ``axis``) until, turned by every one of ``angles``
    (rad), it clears ``q`` (l, 3) by :data:`RUNNING_CLEARANCE`. None when it is nearer than that unturned
    (:func:`running_clearance`'s), stays :data:`SWEPT_TRIGGER` away turning, overlaps deeper than
    :data:`TOUCHING_OVERLAP`, meets it head-on (a stop: the motion along the gap's axis, :data:`SLIDING_COS`),
    or would need more than :data:`MAX_RADIAL_SHRINK`. Returns (points, shrink fraction, least gap m before).
    ``turns`` and ``normals``: as :func:`_swept_gap`'s. Raises ValueError (no volume)."""
    turns = _turns(axis, angles) if turns is None else turns
    normals = (_normals(p), _normals(q)) if normals is None else normals
    if _sat_on(p, q, np.vstack(normals))[0] < RUNNING_CLEARANCE - 1e-9:
        return None
    # the answer below, cheaper where it is None: a lower bound of :func:`_swept_gap`'s least gap, the same over q's face
    # normals alone, which do not turn (a gap over some of the axes is at most the gap over all)
    nq = normals[1]
    sp = np.matmul(np.matmul(p - origin, turns.transpose(0, 2, 1)) + origin, nq.T)  # (A, k, F)
    sq = q @ nq.T  # (l, F)
    gaps = np.maximum(sq.min(axis=0) - sp.max(axis=1), sp.min(axis=1) - sq.max(axis=0))  # (A, F)
    if not len(turns) or float(gaps.max(axis=1).min()) >= SWEPT_TRIGGER + 1e-9:
        return None
    g, a, n = _swept_gap(p, q, origin, axis, angles, turns, normals)
    least = g
    if g >= SWEPT_TRIGGER or g <= -TOUCHING_OVERLAP:
        return None
    turned = (p - origin) @ axis_angle_matrix(axis, a)[:3, :3].T + origin  # p turned by a about the line
    s = turned @ n
    face = turned[s >= s.max() - 1e-3].mean(axis=0)
    t = np.cross(axis, face - origin)
    if abs(float(n @ t)) >= SLIDING_COS * max(float(np.linalg.norm(t)), 1e-12):
        return None
    rel = face - origin
    r = float(np.linalg.norm(rel - axis * float(rel @ axis)))
    f = 1.0
    # p's distance from the line times f: an affine map, so a convex piece stays convex
    offset = p - origin
    along = np.outer(offset @ axis, axis)
    for _ in range(4):  # the radius at the contact gives the first shrink; what the samples still find, the next
        f -= (RUNNING_CLEARANCE - g) / max(r, 1e-9)
        if f < 1.0 - MAX_RADIAL_SHRINK:
            return None
        out = origin + along + f * (offset - along)
        g = _swept_gap(out, q, origin, axis, angles, turns, (_normals(out), normals[1]))[0]
        if g >= RUNNING_CLEARANCE - 1e-6:
            return out, 1.0 - f, least
    return None


def swept_clearance(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], notes: list[str]) -> None:
    """Running clearance along the whole turn of every revolute and continuous joint, in place: a piece of a link
    the joint turns (its child; the joints below at :func:`reference_state`) that clears a piece of a link the
    joint does not move by :data:`RUNNING_CLEARANCE` at :func:`reference_state` but comes nearer while it turns
    (a square dial's corners passing a door's top edge: a contact that slides, held by the contact margins) is
    shrunk about the joint's axis (:func:`_clear_turning_piece`) at :data:`SWEPT_SAMPLES` positions over the range
    (a full turn for a continuous joint). Parent-child pairs excepted. Notes name each change."""
    ref = reference_state(model)
    poses = model.link_poses(ref)
    for joint, ln, others in _moving_links(model, pieces):
        if joint.type not in ("revolute", "continuous"):
            continue
        if joint.type == "continuous":
            angles = np.linspace(0.0, 2 * np.pi, SWEPT_SAMPLES, endpoint=False)
        else:
            angles = np.concatenate([[0.0], np.linspace(float(joint.lower), float(joint.upper), SWEPT_SAMPLES) - ref.get(joint.name, 0.0)])
        Tj = poses[joint.child]
        origin, axis = Tj[:3, 3], Tj[:3, :3] @ joint.axis
        axis = axis / max(float(np.linalg.norm(axis)), 1e-12)
        world = {o: [posed(Q.points, poses[o]) for Q in pieces[o]] for o in others}  # they do not change here
        turns, faces = _turns(axis, angles), {}  # the rotations and the other pieces' face normals, made once
        for i, P in enumerate(pieces[ln]):
            pw = posed(P.points, poses[ln])
            rel = pw - origin
            along = rel @ axis
            radius = float(np.linalg.norm(rel - np.outer(along, axis), axis=1).max())
            ends = origin + np.outer([along.min(), along.max()], axis)  # the axis over the piece's extent along it
            box_lo, box_hi = ends.min(axis=0) - radius, ends.max(axis=0) + radius  # holds the piece's whole turn
            own = None  # pw's face normals, made once
            for other in others:
                for k, qw in enumerate(world[other]):
                    if np.any(qw.min(axis=0) > box_hi + RUNNING_CLEARANCE) or np.any(qw.max(axis=0) < box_lo - RUNNING_CLEARANCE):
                        continue
                    try:
                        own = _normals(pw) if own is None else own
                        if (other, k) not in faces:
                            faces[other, k] = _normals(qw)
                        hit = _clear_turning_piece(pw, qw, origin, axis, angles, turns, (own, faces[other, k]))
                    except ValueError:
                        continue
                    if hit is None:
                        continue
                    pts, shrink, g = hit
                    inv = np.linalg.inv(poses[ln])
                    try:
                        pieces[ln][i] = P = Piece.of(posed(pts, inv), P.sources)
                    except (QhullError, ValueError):
                        continue
                    pw, own = pts, None
                    notes.append(f"link {ln!r}: collision piece {i} shrunk {shrink:.1%} about {joint.name!r}'s axis for "
                                 f"{RUNNING_CLEARANCE * 1000:.2g} mm {RUNNING_CLEARANCE_NOTE} against {other!r} over its "
                                 f"turn (it came {g * 1000:.2g} mm from it)")
