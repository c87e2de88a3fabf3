"""Ground clearance: moving parts of a free-standing object that rest on the
floor.

PartNet-Mobility models the doors of refrigerators, microwaves and cabinets,
and the bottom drawers of cabinets, flush with the body's bottom face: at
rest the door's lowest edge lies on the ground plane exactly as the body's
does. Real ones clear the floor (a refrigerator stands on levelling feet
under a toe grille, a countertop microwave on rubber feet, a cabinet on a
plinth or feet), so the door swings and the drawer slides without touching
the floor. In a simulator the flush part carries part of the object's weight
and, when it is opened, drags on the ground with the ground's friction: the
body is pulled along and rocks (refrigerator 11178, the generated microwave).

Method (the written URDF, at the refined state, root resting pose applied,
z up; collision pieces as the writer wrote them):

1. The ground is the lowest collision vertex over every link, z_g. The body
   (the links no movable joint moves) must itself reach the ground (its
   lowest vertex within :data:`CONTACT_BAND` of z_g): an object that stands
   on parts that move (wheels, legs, a suitcase on its casters) is left as
   it is. So is a part of an object lower than :data:`THIN_OBJECT`
   clearances whose own floor contact spans at least :data:`SUPPORT_AREA`
   of the body's (a half of a pair of pliers lying flat: that part is half
   of what the object lies on, not a door over a floor); a smaller part of
   such an object (a lighter's lid) is raised as a door is.
2. A piece P of a link moved by joint j *drags* on the ground when its
   lowest vertex is less than :data:`GROUND_CLEARANCE` above z_g and j
   moves it along the ground: a revolute (not continuous) joint whose axis is within
   :data:`SLIDE_ANGLE` of vertical (a side-hinged door) or a prismatic joint
   whose axis is within :data:`SLIDE_ANGLE` of horizontal (a drawer). A
   horizontal hinge lifts its part off the floor or rolls it (a wheel), it
   does not drag it.
3. P's bottom face is raised by delta = z_g + :data:`GROUND_CLEARANCE` -
   min_z(P) (an affine squeeze of P along the world vertical that keeps its
   top face, so the piece stays convex), never by more than
   :data:`MAX_SQUEEZE` of P's height. Visual meshes, masses and the state are
   unchanged.

The pieces of the changed links are written beside the URDF as the writer's
collision overrides (link -> every mesh collision of the link).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.assemble import write
from asset2sim.tasks.state.clearance import link_pieces, write_piece_overrides
from asset2sim.urdf import UrdfModel, read_urdf

__all__ = ["CONTACT_BAND", "FLOOR_GAP", "GROUND_CLEARANCE", "SUPPORT_AREA", "THIN_OBJECT", "GroundClearance", "apply_ground_clearance", "floor_limited_state",
           "floor_stops", "ground_clearance"]

#: Floor clearance (m) given to a moving part that rests on or near the
#: ground: the levelling feet of refrigerators and the rubber feet of
#: countertop appliances lift their doors about 1 cm and more off the floor
#: (manufacturers' installation instructions and dimension drawings show the
#: door bottom above the toe grille / feet). 5 mm was not enough: refrigerator
#: 11178 rocks 0.5 deg on its uneven bottom onto a door 4.4 mm up, which dragged.
GROUND_CLEARANCE = 0.01
#: Distance (m) above the ground within which a vertex counts as resting on it.
CONTACT_BAND = 0.0015
#: An object whose height above the ground is below this many
#: :data:`GROUND_CLEARANCE` lies on the floor as a whole (module docstring,
#: step 1): 2, i.e. 2 cm.
THIN_OBJECT = 2.0
#: Area of a moving part's floor contact, as a share of the body's, from
#: which the part of a thin object is part of its support (module
#: docstring, step 1): half (a generated pair of pliers' moving half 1.18,
#: a USB stick's cover 1.34, a lighter's lid 0.41).
SUPPORT_AREA = 0.5
#: Largest angle (rad) between a hinge axis and the vertical (or a slide axis
#: and the horizontal) for the joint to move its part along the ground.
SLIDE_ANGLE = math.radians(30.0)
#: A squeeze never takes more than this fraction of a piece's height.
MAX_SQUEEZE = 0.5


@dataclass
class GroundClearance:
    """Pieces with floor clearance for the links that needed it."""

    pieces: dict[str, list[np.ndarray]] = field(default_factory=dict)
    """link -> every mesh collision piece of the link (k, 3) m in the link frame"""
    notes: list[str] = field(default_factory=list)


def _moving_joint(model: UrdfModel) -> dict[str, object]:
    """link -> the nearest movable joint above it (None for the body)."""
    out: dict[str, object] = {}
    for name in model.tree_order():
        pj = model.parent_joint(name)
        if pj is None:
            out[name] = None
        elif pj.type in ("revolute", "continuous", "prismatic"):
            out[name] = pj
        else:
            out[name] = out.get(pj.parent)
    return out


def _floor_area(pieces: list[np.ndarray], z_g: float) -> float:
    """Area (m^2) of the 2-D convex hull of the vertices of ``pieces``
    ((k, 3) m, world) within :data:`CONTACT_BAND` of the ground ``z_g``; 0
    when they span none."""
    pts = [W[W[:, 2] <= z_g + CONTACT_BAND, :2] for W in pieces]
    pts = np.vstack(pts) if pts else np.zeros((0, 2))
    if len(pts) < 3:
        return 0.0
    try:
        return float(ConvexHull(pts).volume)
    except (QhullError, ValueError):
        return 0.0


def _drags(joint, R_parent_joint: np.ndarray) -> bool:
    """The joint moves its part along the ground (module docstring, step 2)."""
    a = R_parent_joint @ np.asarray(joint.axis, float)
    az = abs(float(a[2])) / max(float(np.linalg.norm(a)), 1e-12)
    if joint.type == "revolute":
        return az >= math.cos(SLIDE_ANGLE)
    if joint.type == "prismatic":
        return az <= math.sin(SLIDE_ANGLE)
    return False  # continuous: wheels and knobs roll or spin


def ground_clearance(model: UrdfModel, urdf: Path | str, state: dict[str, float]) -> GroundClearance:
    """Floor clearance for the moving parts of the written URDF ``model``
    (file ``urdf``, its collision files beside it) at ``state`` (rad or m)
    that rest on the ground (module docstring).

    Raises:
        OSError: a collision file cannot be read.
    """
    scene = _FloorScene(model, urdf)
    poses = model.link_poses(state)
    world = scene.posed(poses)
    lows = {ln: min(float(W[:, 2].min()) for W in ws) for ln, ws in world.items()}
    rep = GroundClearance()
    if not lows:
        return rep
    z_g = min(lows.values())
    top = max(float(W[:, 2].max()) for ws in world.values() for W in ws)
    mover = scene.mover
    body_low = [lows[ln] for ln in lows if mover.get(ln) is None]
    if not body_low or min(body_low) > z_g + CONTACT_BAND:
        return rep  # the object stands on parts that move (wheels, legs): their contact is the support
    thin = top - z_g < THIN_OBJECT * GROUND_CLEARANCE
    body_area = _floor_area([W for ln, ws in world.items() if mover.get(ln) is None for W in ws], z_g) if thin else 0.0
    for ln, ws in world.items():
        j = mover.get(ln)
        if j is None:
            continue
        if thin and _floor_area(ws, z_g) >= SUPPORT_AREA * body_area:
            continue  # half of what a flat-lying object lies on: part of its support
        if not _drags(j, poses[j.parent][:3, :3] @ j.origin[:3, :3]):
            continue
        R = poses[ln][:3, :3]
        n = R.T @ np.array([0.0, 0.0, -1.0])  # the ground side, link frame
        own = [P.copy() for P in scene.local[ln]]
        changed = False
        for i, W in enumerate(ws):
            zmin = float(W[:, 2].min())
            if zmin >= z_g + GROUND_CLEARANCE - 1e-4:
                continue  # already clear of the floor
            height = float(np.ptp(W[:, 2]))
            delta = min(z_g + GROUND_CLEARANCE - zmin, MAX_SQUEEZE * height)
            if height <= 0 or delta <= 0:
                continue
            s = own[i] @ n  # distance towards the ground; the top face (s.min()) stays
            top = float(s.min())
            own[i] = own[i] - np.outer((s - top) * (delta / height), n)
            changed = True
            rep.notes.append(f"{ln}: collision piece {i} raised {delta * 1000:.2g} mm to {GROUND_CLEARANCE * 1000:.2g} mm above the "
                             f"ground (it ended {(zmin - z_g) * 1000:.2g} mm above the body's lowest point and {j.name} moves it "
                             f"along the ground: it dragged on the floor; real ones clear the floor on feet)")
        if changed:
            rep.pieces[ln] = own
    return rep


def apply_ground_clearance(asset: AssetDescription, overlay: Overlay, out_dir: Path, urdf: Path, state: dict[str, float],
                           overrides: dict, closed: dict[str, tuple[float, float, float]],
                           root_rotation=None) -> tuple[dict[str, float], dict, list[str], list[str]]:
    """Refine's step after the state search (nothing for a mounted asset,
    which has no ground): write the output with ``overrides``; limit the
    opening of parts the floor stops (:func:`floor_limited_state`); raise the
    collision pieces of moving parts that drag on the floor
    (:func:`ground_clearance`); write the output again when anything changed.

    Args:
        closed: joint -> (q_closed, direction, open_range), rad or m.

    Returns:
        (state, collision overrides, state notes, collision notes): the
        inputs themselves and empty notes when nothing changed.

    Raises:
        OSError: a collision file cannot be read or written.
    """
    if overlay.mounting is not None and overlay.mounting.fixed:
        return state, overrides, [], []
    write.write_output(asset, overlay, out_dir, state, copy=False, collision_overrides=overrides, root_rotation=root_rotation)
    new_state, state_notes = floor_limited_state(read_urdf(urdf), urdf, state, closed)
    rep = ground_clearance(read_urdf(urdf), urdf, new_state)
    new = overrides
    if rep.pieces:
        new = {**overrides, **write_piece_overrides(rep.pieces, overlay.scale, out_dir, write.collision_folder(asset), "ground")}
    if rep.pieces or state_notes:
        write.write_output(asset, overlay, out_dir, new_state, copy=False, collision_overrides=new, root_rotation=root_rotation)
    return new_state, new, state_notes, rep.notes


#: Gap (m) a moving part keeps above the body's lowest point when the floor
#: limits its opening (:func:`floor_limited_state`): PyBullet's 1 mm hull
#: margin plus 1 mm.
FLOOR_GAP = 0.002


def _lowest(world: dict[str, list[np.ndarray]], links) -> float:
    vals = [float(W[:, 2].min()) for ln in links for W in world.get(ln, [])]
    return min(vals) if vals else np.inf


class _FloorScene:
    """The collision pieces of a URDF posed by joint positions, with the floor
    its body stands on (the body: links no movable joint moves)."""

    def __init__(self, model: UrdfModel, urdf: Path | str):
        root = Path(urdf).parent
        self.model = model
        self.local = {ln: link_pieces(model, root, ln) for ln in model.links}
        self.mover = _moving_joint(model)
        self.body = [ln for ln in model.links if self.mover.get(ln) is None]

    def posed(self, poses: dict[str, np.ndarray]) -> dict[str, list[np.ndarray]]:
        """link -> its pieces (k, 3) in the root frame (m) at the link ``poses`` (4, 4); links without pieces left out."""
        return {ln: [P @ poses[ln][:3, :3].T + poses[ln][:3, 3] for P in ps] for ln, ps in self.local.items() if ps}

    def world_at(self, q: dict[str, float]) -> dict[str, list[np.ndarray]]:
        """:meth:`posed` at joint positions ``q``."""
        return self.posed(self.model.link_poses(q))

    def subtree(self, joint) -> list[str]:
        """The links ``joint`` (a URDF joint) moves: its child and every link below."""
        sub, stack = [], [joint.child]
        while stack:
            ln = stack.pop()
            sub.append(ln)
            stack.extend(c.child for c in self.model.children(ln))
        return sub

    def floor(self, q: dict[str, float]) -> float:
        """Height (m, root frame) a moving part keeps above: the body's lowest
        point at ``q`` plus :data:`FLOOR_GAP`."""
        return _lowest(self.world_at(q), self.body) + FLOOR_GAP

    def lowest(self, q: dict[str, float], links) -> float:
        """Lowest point (m, root frame) of ``links`` at ``q``; inf without pieces."""
        return _lowest(self.world_at(q), links)


def floor_limited_state(model: UrdfModel, urdf: Path | str, state: dict[str, float],
                        closed: dict[str, tuple[float, float, float]]) -> tuple[dict[str, float], list[str]]:
    """The opening of parts that the floor stops, at ``state`` (rad or m).

    A pedal pressed "fully open" or a lid folded down past the body's bottom
    reaches below the floor the body stands on: placed on the ground, the
    object then stands on that part and its weight pushes the part back
    (trash can 102181's foot pad). On a real floor the part stops at the floor. For each movable joint j whose subtree's lowest
    collision vertex is below the body's lowest (links no movable joint
    moves) plus :data:`FLOOR_GAP`, while at its closed end the subtree is
    above it, q_j is moved towards the closed end (bisection on the opening,
    30 halvings) to the most open position whose subtree keeps that gap; the
    other joints stay at ``state``. ``closed``: joint -> (q_closed,
    direction, open_range).

    Returns (state, notes): ``state`` itself and no notes when nothing moved.

    Raises:
        OSError: a collision file cannot be read.
    """
    scene = _FloorScene(model, urdf)
    out = dict(state)
    notes: list[str] = []
    for j in model.joints:
        if j.type not in ("revolute", "prismatic") or j.name not in closed or j.name not in out:
            continue
        sub = scene.subtree(j)
        floor = scene.floor(out)
        low = scene.lowest(out, sub)
        if not np.isfinite(floor) or low >= floor:
            continue
        q_closed = closed[j.name][0]
        if scene.lowest({**out, j.name: q_closed}, sub) < floor:
            continue  # the part reaches the floor even closed: it is part of the support
        q_state = out[j.name]  # bisected: the fraction of the way from q_closed to the state's q
        lo = _last_clear(lambda f: scene.lowest({**out, j.name: q_closed + f * (q_state - q_closed)}, sub) >= floor, 0.0, 1.0)
        q_new = q_closed + lo * (q_state - q_closed)
        notes.append(f"{j.name}: opening limited by the floor, {q_state:.4g} -> {q_new:.4g} "
                     f"({'m' if j.type == 'prismatic' else 'rad'}): at the requested state {j.child} reached "
                     f"{(floor - FLOOR_GAP - low) * 1000:.2g} mm below the body's bottom, so the object stood on it "
                     "and its weight pushed it back; a real one stops at the floor")
        out[j.name] = float(q_new)
    return (out, notes) if notes else (state, [])


#: Openings sampled along a joint's range when looking for where the floor
#: stops its part (:func:`floor_stops`), before bisecting the first step
#: that reaches the floor.
FLOOR_SAMPLES = 32


def floor_stops(model: UrdfModel, urdf: Path | str, state: dict[str, float],
                closed: dict[str, tuple[float, float, float]]) -> dict[str, float]:
    """Where the floor stops the opening of parts, with the object resting on
    its body at ``state`` (rad or m).

    For each movable joint j of ``closed`` (joint -> (q_closed, direction,
    open_range)) whose subtree is above the floor at its closed end (the
    body's lowest point plus :data:`FLOOR_GAP`, as in
    :func:`floor_limited_state`; a part below it even closed is part of the
    support): the opening o (from q_closed along ``direction``, 0 < o <=
    open_range) at which the subtree first reaches the floor, the other
    joints at ``state``: :data:`FLOOR_SAMPLES` openings along the range, then
    30 halvings of the first step that reaches it. A suitcase standing on
    its back edge whose lid opens downwards, a lid folded down past the
    body's bottom: on a real floor the part stops there, so an operation
    cannot open it further with the object resting as it is.

    Returns:
        joint -> o (rad or m) for the joints the floor stops before their
        open end; 0 when the part touches the floor right away.

    Raises:
        OSError: a collision file cannot be read.
    """
    scene = _FloorScene(model, urdf)
    joints = {j.name: j for j in model.joints}
    floor = scene.floor(state)
    out: dict[str, float] = {}
    if not np.isfinite(floor):
        return out
    for name, (q_closed, direction, open_range) in closed.items():
        j = joints.get(name)
        if j is None or j.type not in ("revolute", "prismatic") or not open_range > 0:
            continue
        sub = scene.subtree(j)

        def clear(o: float) -> bool:
            return scene.lowest({**state, name: q_closed + direction * o}, sub) >= floor

        if not clear(0.0):
            continue  # part of the support
        good = 0.0
        for k in range(1, FLOOR_SAMPLES + 1):
            o = open_range * k / FLOOR_SAMPLES
            if clear(o):
                good = o
                continue
            out[name] = float(_last_clear(clear, good, o))
            break
    return out


def _last_clear(clear, good: float, bad: float) -> float:
    """``good`` after 30 halvings of [good, bad], each keeping ``clear(good)`` true."""
    for _ in range(30):
        mid = 0.5 * (good + bad)
        good, bad = (mid, bad) if clear(mid) else (good, mid)
    return good
