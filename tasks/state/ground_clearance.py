"""Ground clearance: moving parts of a free-standing object that rest on the
floor (method: docs/design/metrics.md, "Ground clearance and floor-limited
openings"). A collision piece that drags on the ground is raised to
:data:`GROUND_CLEARANCE` above it by an affine squeeze that keeps its top face.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asset2sim.tasks.assemble import write
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.geometry.limits import subtrees
from asset2sim.tasks.state.clearance import ClearanceRepair, link_pieces, write_piece_overrides
from asset2sim.urdf import MOVABLE, UrdfModel

__all__ = ["CONTACT_BAND", "FLOOR_GAP", "GROUND_CLEARANCE", "SUPPORT_AREA", "THIN_OBJECT", "apply_ground_clearance", "floor_limited_state",
           "floor_stops", "ground_clearance"]

#: Floor clearance (m) of a moving part near the ground: levelling and rubber
#: feet lift appliance doors about 1 cm off the floor (manufacturers' drawings).
GROUND_CLEARANCE = 0.01
#: Distance (m) above the ground within which a vertex counts as resting on it.
CONTACT_BAND = 0.0015
#: An object lower than this many :data:`GROUND_CLEARANCE` lies on the floor as a whole.
THIN_OBJECT = 2.0
#: Share of the body's floor contact area from which a thin object's part is support.
SUPPORT_AREA = 0.5
#: Largest angle (rad) of a hinge axis from vertical (a slide axis from horizontal) to move along the ground.
SLIDE_ANGLE = math.radians(30.0)
#: A squeeze never takes more than this fraction of a piece's height.
MAX_SQUEEZE = 0.5


def _floor_area(pieces: list[np.ndarray], z_g: float) -> float:
    """Area (m^2) of the 2-D hull of the vertices of ``pieces`` ((k, 3) m) within
    :data:`CONTACT_BAND` of the ground ``z_g``; 0 when they span none."""
    pts = [W[W[:, 2] <= z_g + CONTACT_BAND, :2] for W in pieces]
    pts = np.vstack(pts) if pts else np.zeros((0, 2))
    if len(pts) < 3:
        return 0.0
    try:
        return float(ConvexHull(pts).volume)
    except (QhullError, ValueError):
        return 0.0


def ground_clearance(model: UrdfModel, urdf: Path | str, state: dict[str, float]) -> ClearanceRepair:
    """Floor clearance for the moving parts of the written URDF ``model`` (file ``urdf``) at ``state`` (rad or m) that rest
    on the ground (module docstring). Raises OSError: a collision file cannot be read."""
    scene = _FloorScene(model, urdf)
    poses = model.link_poses(state)
    world = scene.posed(poses)
    lows = {ln: min(float(W[:, 2].min()) for W in ws) for ln, ws in world.items()}
    rep = ClearanceRepair()
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
        # unless the joint moves its part along the ground: a hinge near vertical, a slide near horizontal (a continuous
        # joint's wheels and knobs roll or spin)
        a = poses[j.parent][:3, :3] @ j.origin[:3, :3] @ j.axis
        az = abs(float(a[2])) / max(float(np.linalg.norm(a)), 1e-12)
        if not (j.type == "revolute" and az >= math.cos(SLIDE_ANGLE)
                or j.type == "prismatic" and az <= math.sin(SLIDE_ANGLE)):
            continue
        n = poses[ln][:3, :3].T @ np.array([0.0, 0.0, -1.0])  # the ground side, link frame
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


@dataclass(frozen=True, slots=True)
class GroundLifted:
    """The result of :func:`apply_ground_clearance`: ``state`` (joint -> rad or m), ``overrides`` (collision
    overrides, link -> piece files; the candidate's own object when unchanged), ``state_notes`` (a line per
    opening the floor stopped), ``collision_notes`` (a line per piece raised off the ground) and ``stops`` (joint ->
    the position, rad or m, where the floor stopped its opening)."""

    state: dict[str, float]
    overrides: Mapping
    state_notes: list[str]
    collision_notes: list[str]
    stops: Mapping[str, float] = field(default_factory=dict)


def apply_ground_clearance(candidate: Candidate, ws: Workspace, closed: dict[str, tuple[float, float, float]]) -> GroundLifted:
    """Refine's step after the state search (nothing for a mounted asset): :func:`floor_limited_state` and
    :func:`ground_clearance` applied to ``candidate``'s model (loaded into ``ws``; new pieces written into its
    folder). ``closed``: joint -> (q_closed, direction, open_range), rad or m.

    Raises OSError: a collision file cannot be read or written.
    """
    overlay, state, overrides = candidate.overlay, dict(candidate.state), candidate.collision_overrides
    if overlay.mounting is not None and overlay.mounting.fixed:
        return GroundLifted(state, overrides, [], [])
    model = ws.model(candidate)
    new_state, state_notes = floor_limited_state(model, model.path, state, closed)
    rep = ground_clearance(ws.model(candidate), model.path, new_state)
    new = overrides
    if rep.pieces:
        new = {**overrides, **write_piece_overrides(rep.pieces, overlay.scale, ws.root, write.collision_folder(candidate.asset), "ground")}
    return GroundLifted(new_state, new, state_notes, rep.notes, {j: q for j, q in new_state.items() if q != state.get(j)})


def ends_at_the_floor(closed: dict[str, ClosedState], stops: Mapping[str, float], bands: dict[str, str]) -> tuple[dict[str, ClosedState], list[str]]:
    """(closed ends, notes): the open range of each joint asked fully open (band ``fully``: "fully open", "all the way",
    "wide open") ending where the floor stops its part (``stops``: joint -> rad or m, :class:`GroundLifted`), as far as
    the part goes where the object stands; the other joints' as they are. ``bands``: joint -> the band asked."""
    out, notes = dict(closed), []
    for j, q in stops.items():
        c = closed.get(j)
        if c is None or bands.get(j) != "fully":
            continue
        reach = max(0.0, float(c.direction * (q - c.q_closed)))
        if not 0.0 < reach < c.open_range:
            continue
        out[j] = replace(c, open_range=reach, notes=[*c.notes, "open end: where the floor stops the part"])
        notes.append(f"{j}: asked fully open, it goes {reach / c.open_range:.0%} of its range where the object stands: the "
                     f"floor stops it there (q = {q:.4g}), its open end")
    return out, notes


#: Gap (m) a moving part keeps above the body's lowest point where the floor
#: limits its opening: PyBullet's 1 mm hull margin plus 1 mm.
FLOOR_GAP = 0.002


class _FloorScene:
    """A URDF's collision pieces posed by joint positions, and the floor its body stands on."""

    def __init__(self, model: UrdfModel, urdf: Path | str):
        root = Path(urdf).parent
        self.model = model
        self.local = {ln: link_pieces(model, root, ln) for ln in model.links}
        self.mover: dict[str, object] = {}  # link -> the nearest movable joint above it (None for the body)
        for name in model.tree_order():
            pj = model.parent_joint(name)
            if pj is None or pj.type in MOVABLE:
                self.mover[name] = pj
            else:
                self.mover[name] = self.mover.get(pj.parent)
        self.body = [ln for ln in model.links if self.mover.get(ln) is None]
        self.subtrees = subtrees(model)  # movable joint -> the links it moves

    def posed(self, poses: dict[str, np.ndarray]) -> dict[str, list[np.ndarray]]:
        """link -> its pieces (k, 3) in the root frame (m) at the link ``poses`` (4, 4); links without pieces left out."""
        return {ln: [P @ poses[ln][:3, :3].T + poses[ln][:3, 3] for P in ps] for ln, ps in self.local.items() if ps}

    def floor(self, q: dict[str, float]) -> float:
        """The body's lowest point (m, root frame) at ``q`` plus :data:`FLOOR_GAP`."""
        return self.lowest(q, self.body) + FLOOR_GAP

    def lowest(self, q: dict[str, float], links) -> float:
        """Lowest point (m, root frame) of ``links`` at ``q``; inf without pieces."""
        world = self.posed(self.model.link_poses(q))
        return min((float(W[:, 2].min()) for ln in links for W in world.get(ln, [])), default=np.inf)


def floor_limited_state(model: UrdfModel, urdf: Path | str, state: dict[str, float],
                        closed: dict[str, tuple[float, float, float]]) -> tuple[dict[str, float], list[str]]:
    """The opening of parts the floor stops, at ``state`` (rad or m): a joint whose subtree reaches below the body's lowest
    point plus :data:`FLOOR_GAP`, but not at its closed end, is bisected (30 halvings) back to the most open position that
    keeps the gap. ``closed``: joint -> (q_closed, direction, open_range). Returns (state, notes): ``state`` itself when
    nothing moved. Raises OSError: a collision file cannot be read."""
    scene = _FloorScene(model, urdf)
    out = dict(state)
    notes: list[str] = []
    for j in model.joints:
        if j.type not in ("revolute", "prismatic") or j.name not in closed or j.name not in out:
            continue
        sub = scene.subtrees[j.name]
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


#: Openings sampled along a range by :func:`floor_stops` before bisecting.
FLOOR_SAMPLES = 32


def floor_stops(model: UrdfModel, urdf: Path | str, state: dict[str, float],
                closed: dict[str, tuple[float, float, float]]) -> dict[str, float]:
    """Where the floor stops the opening of parts, the object resting on its body at ``state`` (rad or m): for each joint of
    ``closed`` (joint -> (q_closed, direction, open_range)) clear of the floor when closed, the opening o at which its
    subtree first reaches the floor (:data:`FLOOR_SAMPLES` samples, then 30 halvings). Returns joint -> o (rad or m) for the
    joints the floor stops before their open end. Raises OSError: a collision file cannot be read."""
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
        sub = scene.subtrees[j.name]

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
