"""Stability by design: keep the centre of mass over the support at the
requested state, within the request's constraints.

An open laptop screen, an open oven door or a fully opened lid moves the
centre of mass (COM) of a free-standing object backwards or forwards; when it
leaves the support polygon the object tips over whatever the damping. Before
the post-check, :func:`design_for_stability` measures the static balance of
the written asset at its refined state and, when the COM lies outside the
support (or within a small margin of its edge), moves mass from the parts
that opened to the body they hang on, bounded by the sourced part-mass
fractions of :data:`PART_MASS_FRACTION` (a laptop's base holds the battery,
keyboard and mainboard: it outweighs the screen). The total mass, the scale
and the requested state are never changed (the request fixes them); the
inertia tensor of each changed link is scaled with its mass (same geometry,
same COM in the link frame). Every change is reported with its reason.

Where no sourced fraction covers an opened part, its mass may go down to its
**envelope shell mass** (:func:`envelope_masses`): for a part of a shell
material (sheet metal, molded plastic, panels: ``materials.yaml`` ``shell``)
the material lies on its outer surface, m = A_env t rho (thin-shell mass,
Roark's Formulas for Stress and Strain, 8th ed., thin-walled members), A_env
the area of the convex hull of its collision geometry (its outer envelope), t
and rho the material's wall thickness and density, times the factor the
estimate applied to the link (the plausible-mass scaling). The estimate's area
is the mesh's, which counts both faces of a modelled wall and every inner
face; where it saturates the hollow fraction a sheet part becomes solid (a
stapler's sheet-steel arm 3 times its envelope mass), so the envelope mass is
the physical lower end of the part's mass. Needs the links' geometry.

Statics (rigid bodies on a plane under gravity -z): the object rests iff the
vertical projection of its COM lies inside the convex hull of its contact
points (the support polygon); e.g. Featherstone & Orin, "Dynamics", Springer
Handbook of Robotics (2008) section 2.9 / the zero-moment-point condition of
Vukobratovic & Borovac, "Zero-moment point - thirty five years of its life",
IJHR 1(1) 2004 (the static case: ZMP = COM projection).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from asset2sim.engines.base import SessionOptions, open_session
from asset2sim.engines.loading import collision_pieces, read_urdf
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.tasks.interpret.prior_tables import MaterialPrior, load_priors
from asset2sim.tasks.synthesize import physics

if TYPE_CHECKING:
    from asset2sim.tasks.geometry.closed_state import ClosedState

__all__ = ["PART_MASS_FRACTION", "Balance", "design_for_stability", "measure_balance", "steadiest_fractions", "support_polygon"]


@dataclass(frozen=True)
class PartFraction:
    """Share of the whole object's mass one part may carry (``lo`` .. ``hi``),
    with its source."""

    lo: float
    hi: float
    source: str


#: (category, canonical part label) -> the mass fraction of that part.
PART_MASS_FRACTION: dict[tuple[str, str], PartFraction] = {
    ("Laptop", "screen"): PartFraction(
        0.25, 0.40,
        "laptop lids (display panel, cover, hinges, antennas) weigh about 0.3-0.6 kg of 1.2-2.0 kg 13-15 in laptops, "
        "the base carrying the battery (a 50-70 Wh Li-ion pack alone is ~0.2-0.35 kg), keyboard, mainboard and "
        "cooling (teardown part weights, e.g. iFixit teardowns of the MacBook Air 13 and Dell XPS 13; replacement "
        "display-assembly listings); Apple MacBook Air 13 (M1) 1.29 kg total",
    ),
    ("Laptop", "lid"): PartFraction(0.25, 0.40, "as the laptop screen (the lid is the display half)"),
    ("Microwave", "door"): PartFraction(
        0.08, 0.20,
        "countertop microwave doors (glass, metal screen, frame) are ~1-2.5 kg of 10-18 kg ovens (manufacturer "
        "replacement door assemblies and spec sheets, e.g. Panasonic NN-SN, Whirlpool WMC)",
    ),
    ("Oven", "door"): PartFraction(
        0.10, 0.25,
        "oven doors (triple glazing, frame) are ~5-12 kg of 35-70 kg wall ovens and ranges (manufacturer "
        "replacement door assemblies and spec sheets)",
    ),
    ("Toaster", "lever"): PartFraction(0.01, 0.05, "toaster carriage levers are a few tens of grams of a 1-2 kg toaster (spec sheets)"),
}


#: Tilt (rad) from which the object must fall back onto its support: the COM
#: must lie at least h * tan(TILT_RECOVERY_RAD) inside the support's edge (h:
#: COM height above the support), the static tipping angle being
#: atan(margin / h) (Featherstone & Orin 2008, statics of a rigid body on a
#: plane). Twice the 5 deg tilt of the robust-rest trials
#: (``tasks.check.robust_rest``), which must also survive a 2 cm drop and a
#: nudge; see :data:`SUPPORT_MARGIN_FRACTION` for low, wide objects.
TILT_RECOVERY_RAD = math.radians(10.0)


#: Margin (fraction of the support polygon's square-root area) the COM must
#: keep inside its edge whatever its height: measured on the generated tipping
#: laptop (``tests/tasks/check/failure_assets.py``, COM 6 cm high), a margin of
#: 11 mm (h tan 10 deg, 5 % of sqrt-area) still toppled it on the robust-rest
#: drop and backward tilt, 24 mm (10 %) passed every trial.
SUPPORT_MARGIN_FRACTION = 0.10


@dataclass
class Balance:
    """Static balance at one state (world = the written URDF's frame, z up).

    ``com`` (3,) m; ``support`` (K, 2) m support polygon (counter-clockwise);
    ``margin`` m signed distance of the COM's projection to the polygon's
    edge (positive inside); ``required`` m the margin asked for.
    """

    com: np.ndarray
    support: np.ndarray
    margin: float
    required: float

    @property
    def stable(self) -> bool:
        return self.margin >= self.required


def _hull2d(points: np.ndarray) -> np.ndarray:
    """Convex hull (K, 2) counter-clockwise of points (N, 2) (Andrew's
    monotone chain, Comp. Geom. Theory Appl. 1979)."""
    pts = np.unique(np.round(np.asarray(points, float), 9), axis=0)
    if len(pts) < 3:
        return pts
    pts = pts[np.lexsort((pts[:, 1], pts[:, 0]))]

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _signed_margin(poly: np.ndarray, p: np.ndarray) -> float:
    """Signed distance (m) of point ``p`` (2,) to the edge of the convex
    polygon ``poly`` (K, 2, counter-clockwise): positive inside. A degenerate
    polygon (K < 3) gives minus the distance to its points."""
    if len(poly) < 3:
        return -float(np.min(np.linalg.norm(poly - p, axis=1))) if len(poly) else -np.inf
    d = np.inf
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        e = b - a
        n = np.array([-e[1], e[0]]) / max(np.linalg.norm(e), 1e-12)  # inward normal of a CCW polygon
        d = min(d, float(np.dot(p - a, n)))
    return d


#: Largest angle (rad) between a bottom face of the convex hull and the
#: ground for the object to settle onto it without counting as fallen
#: (``tasks.check.metrics.SETTLE_TILT_LIMIT``).
SETTLE_FACE_ANGLE = 0.05


def support_polygon(points: np.ndarray, tol: float, com: np.ndarray | None = None) -> np.ndarray:
    """Support polygon (K, 2) m of collision points (N, 3) resting on the
    ground (meshes' bottoms are rarely exactly flat, so the object settles on
    a face of the points' 3-D convex hull):

    - the face the vertical line through ``com`` (3,) leaves the hull by,
      when its outward normal is within :data:`SETTLE_FACE_ANGLE` of straight
      down (the object tilts onto it and rests there);
    - else (no ``com``, or that face is steep: the object rolls off it) the
      largest such near-horizontal face;
    - else the points within ``tol`` of the lowest one;

    as the 2-D convex hull of the points within ``tol`` m of the face's plane.
    Empty (0, 2) when there are no points."""
    pts = np.asarray(points, float)
    if not len(pts):
        return np.zeros((0, 2))
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):
        hull = None
    if hull is not None:
        eq = hull.equations  # (F, 4): outward unit normal n, offset d; n.x + d <= 0 inside
        flat = eq[:, 2] < -np.cos(SETTLE_FACE_ANGLE)
        plane = None
        if com is not None:
            c = np.asarray(com, float)
            down = eq[:, 2] < -1e-9
            inside = np.all(eq[:, :3] @ c + eq[:, 3] <= 1e-9)
            if inside and down.any():
                t = np.where(down, (eq[:, :3] @ c + eq[:, 3]) / np.where(down, eq[:, 2], -1.0), np.inf)
                exit_face = int(np.argmin(t))
                if flat[exit_face]:
                    plane = eq[exit_face]
        if plane is None and flat.any():
            tri = pts[hull.simplices[flat]]
            area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
            keys = np.round(eq[flat] / np.array([1e-3, 1e-3, 1e-3, 1e-4]))
            _, inv = np.unique(keys, axis=0, return_inverse=True)
            best = int(np.argmax(np.bincount(inv.ravel(), weights=area)))
            plane = eq[flat][inv.ravel() == best][0]
        if plane is not None:
            on = np.abs(pts @ plane[:3] + plane[3]) <= tol
            if on.sum() >= 3:
                return _hull2d(pts[on][:, :2])
    low = pts[pts[:, 2] <= pts[:, 2].min() + tol]
    return _hull2d(low[:, :2])


def _link_world(urdf: Path, state: dict[str, float]) -> tuple[dict, dict[str, np.ndarray]]:
    """Link frames (position (3,), rotation (3, 3)) at ``state`` and every
    link's collision hull points in the world (N, 3), from the written URDF."""
    model = read_urdf(urdf)
    pieces, _ = collision_pieces(model)
    with open_session("pybullet", urdf, SessionOptions(initial_state=dict(state), fixed_base=True, gravity=False, ground=False)) as s:
        return _world_at(s, pieces, state)


def _world_at(session, pieces: dict, state: dict[str, float]) -> tuple[dict, dict[str, np.ndarray]]:
    """:func:`_link_world` in an open fixed-base ``session`` of the URDF whose
    collision ``pieces`` (link -> pieces) are given, its joints set to ``state``."""
    session.set_joint_positions(dict(state))
    frames = {ln: session.link_frame(ln) for ln in session.link_names}
    pts: dict[str, np.ndarray] = {}
    for ln, pcs in pieces.items():
        if ln not in frames:
            continue
        pos, R = frames[ln]
        arr = []
        for pc in pcs:
            if pc.points is None:
                continue
            local = pc.points @ pc.origin[:3, :3].T + pc.origin[:3, 3]
            arr.append(local @ R.T + pos)
        if arr:
            pts[ln] = np.vstack(arr)
    return frames, pts


def _com(overlay: Overlay, frames: dict, masses: dict[str, float] | None = None) -> np.ndarray:
    m_tot, acc = 0.0, np.zeros(3)
    for ln, lp in overlay.links.items():
        if ln not in frames:
            continue
        m = lp.mass if masses is None else masses[ln]
        pos, R = frames[ln]
        acc += m * (pos + R @ np.asarray(lp.com, float))
        m_tot += m
    return acc / max(m_tot, 1e-12)


def measure_balance(urdf: Path | str, overlay: Overlay, state: dict[str, float]) -> Balance:
    """Static balance of the written asset ``urdf`` (scale baked in) at
    ``state`` (rad or m) with the overlay's link masses and COMs. The contact
    band is 1 mm or 0.5 % of the object's height, whichever is larger; the
    margin asked for is the largest of 2 mm (the SPEC's 1 mm rest tolerance
    and PyBullet's contact slop), :data:`SUPPORT_MARGIN_FRACTION` of the
    support polygon's square-root area and h * tan(:data:`TILT_RECOVERY_RAD`)
    (h: the COM's height above the support).

    Raises:
        whatever loading the URDF raises.
    """
    return _balance(overlay, *_link_world(Path(urdf), state))


def _balance(overlay: Overlay, frames: dict, pts: dict[str, np.ndarray]) -> Balance:
    """:func:`measure_balance` from the link frames and world collision points of one state."""
    allp = np.vstack(list(pts.values())) if pts else np.zeros((0, 3))
    if not len(allp):
        com = _com(overlay, frames)
        return Balance(com, np.zeros((0, 2)), -np.inf, 0.0)
    height = float(allp[:, 2].max() - allp[:, 2].min())
    com = _com(overlay, frames)
    poly = support_polygon(allp, max(1e-3, 0.005 * height), com)
    h = max(float(com[2] - allp[:, 2].min()), 0.0)
    area = 0.5 * abs(float(np.dot(poly[:, 0], np.roll(poly[:, 1], -1)) - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))) if len(poly) >= 3 else 0.0
    return Balance(com, poly, _signed_margin(poly, com[:2]), max(2e-3, SUPPORT_MARGIN_FRACTION * np.sqrt(area), h * np.tan(TILT_RECOVERY_RAD)))


#: Opening fractions tried per joint across its allowed interval by
#: :func:`steadiest_fractions` (both ends included).
BAND_SAMPLES = 9
#: Smallest gain of static margin (m) for which :func:`steadiest_fractions`
#: moves a joint within its interval: 2 mm, the SPEC's 1 mm rest tolerance
#: and PyBullet's contact slop (as :func:`measure_balance`'s least margin).
MARGIN_GAIN = 2e-3


def steadiest_fractions(urdf: Path | str, overlay: Overlay, state: dict[str, float], closed: dict[str, "ClosedState"],
                        intervals: dict[str, tuple[float, float]], samples: int = BAND_SAMPLES) -> tuple[dict[str, float], Balance, Balance]:
    """The opening fractions, within what the request allows, at which a
    free-standing object stands steadiest: for each joint of ``intervals``
    (joint -> allowed opening-fraction interval (lo, hi), the requested
    band's, dimensionless) that is opened (lo > 0), ``samples`` fractions
    evenly over its interval with the other joints as found so far, keeping
    the one with the largest static margin (:func:`measure_balance`'s signed
    distance of the COM's projection to the support's edge) when it beats
    the margin before by at least :data:`MARGIN_GAIN`. A fraction at which
    the object's lowest point drops more than 1 mm (an opened part reaching
    below the body: the support would change) is not used. Statics: see the
    module docstring.

    Args:
        urdf: the written URDF (scale baked in).
        overlay: the overlay it was written from (masses, COMs).
        state: joint -> rad or m, the refined state.
        closed: joint -> :class:`~asset2sim.tasks.geometry.closed_state.ClosedState`
            in the URDF's units (its ``position(fraction)``).
        intervals: see above.
        samples: fractions per joint (>= 2).

    Returns:
        (joint -> fraction for the joints moved, :class:`Balance` before,
        :class:`Balance` after); ({}, b, b) for a mounted asset or when
        nothing gains.

    Raises:
        whatever loading the URDF raises.
    """
    model = read_urdf(Path(urdf))
    pieces, _ = collision_pieces(model)
    cur = dict(state)
    with open_session("pybullet", urdf, SessionOptions(initial_state=dict(state), fixed_base=True, gravity=False, ground=False)) as s:
        frames, pts = _world_at(s, pieces, cur)
        before = best = _balance(overlay, frames, pts)
        if overlay.mounting is not None and overlay.mounting.fixed:
            return {}, before, before
        floor = min(float(p[:, 2].min()) for p in pts.values()) if pts else 0.0
        chosen: dict[str, float] = {}
        for name, (lo, hi) in intervals.items():
            cs = closed.get(name)
            if cs is None or name not in cur or not lo > 0 or hi <= lo:
                continue
            top, at = None, None
            for f in np.linspace(lo, hi, max(2, samples)):
                frames, pts = _world_at(s, pieces, {**cur, name: cs.position(float(f))})
                if pts and min(float(p[:, 2].min()) for p in pts.values()) < floor - 1e-3:
                    continue
                b = _balance(overlay, frames, pts)
                if top is None or b.margin > top.margin:
                    top, at = b, float(f)
            if top is not None and top.margin >= best.margin + MARGIN_GAIN:
                best, chosen[name] = top, at
                cur = {**cur, name: cs.position(at)}
    return chosen, before, best


def envelope_masses(overlay: Overlay, points: dict[str, np.ndarray],
                    geometry: dict[str, LinkGeometry]) -> dict[str, float]:
    """Envelope shell mass (kg) of every link of ``overlay`` made of a shell
    material (module docstring): A_env t rho times the factor the estimate
    applied to the link (its mass over the geometric mass
    :func:`asset2sim.tasks.synthesize.physics.link_physics` gives for its
    ``geometry`` and material: the plausible-range scaling, a validator's
    raise, a requested mass), capped at the link's mass. A_env is the
    convex-hull area of its collision points ``points`` (link -> (N, 3) m,
    world, scale baked in). Links of solid or unknown materials, or without
    geometry or a hull, are left out.
    """
    from scipy.spatial import ConvexHull, QhullError

    by_name: dict[str, MaterialPrior] = {m.name: m for m in load_priors().materials.values()}
    out: dict[str, float] = {}
    for ln, lp in overlay.links.items():
        mat = by_name.get(lp.material)
        pts, geom = points.get(ln), geometry.get(ln)
        if mat is None or not mat.shell or pts is None or len(pts) < 4 or geom is None:
            continue
        try:
            area = float(ConvexHull(pts).area)
        except (QhullError, ValueError):
            continue
        choice = physics.MaterialChoice(name=mat.name, density=mat.density, shell=True, wall_thickness=mat.wall_thickness)
        try:
            raw = physics.link_physics(geom, overlay.scale, choice).mass
        except ValueError:
            continue
        if not raw > 0:
            continue
        out[ln] = float(min(lp.mass, area * mat.wall_thickness * mat.density * lp.mass / raw))
    return out


def _subtree(asset: AssetDescription, link: str) -> set[str]:
    out, todo = {link}, [link]
    while todo:
        cur = todo.pop()
        for j in asset.joints:
            if j.parent == cur and j.child not in out:
                out.add(j.child)
                todo.append(j.child)
    return out


def design_for_stability(
    urdf: Path | str,
    asset: AssetDescription,
    overlay: Overlay,
    state: dict[str, float],
    category: str | None,
    geometry: dict[str, LinkGeometry] | None = None,
) -> tuple[Overlay, list[str]]:
    """Make a free-standing object balance at ``state`` by its part masses.

    When the COM's projection is outside the support polygon (or closer to its
    edge than :class:`Balance`'s required margin), mass is moved from the
    links of the opened parts that :data:`PART_MASS_FRACTION` covers (the
    child link of a movable joint with that label, and its subtree) to the
    links that are moved by no joint (the body), each side scaled
    proportionally, down to the part's sourced lower fraction at most, and
    from the other opened parts of shell materials down to their envelope
    shell mass (module docstring; each opened link moves linearly towards its
    floor, the body scaled up alike); the smallest transfer that balances the
    object is used. Total mass, scale and
    state are unchanged. A mounted asset (``overlay.mounting.fixed``) and an
    object already balanced are returned unchanged.

    Args:
        urdf: the written URDF (scale baked in, the resting pose applied).
        asset: the input's description (tree and semantic labels).
        overlay: the overlay the URDF was written from.
        state: joint -> rad or m, the refined initial state.
        category: canonical category (the key of :data:`PART_MASS_FRACTION`).
        geometry: link -> :class:`LinkGeometry` (scale 1): opened parts no
            sourced fraction covers may go down to their envelope shell mass
            (:func:`envelope_masses`); None: only the sourced fractions.

    Returns:
        (overlay, changes): the new overlay (the same object when nothing
        changed) and what changed and why (empty when nothing did).
    """
    if overlay.mounting is not None and overlay.mounting.fixed:
        return overlay, []
    bal = measure_balance(urdf, overlay, state)
    if bal.stable or len(bal.support) < 3:
        return overlay, []
    movable = [j for j in asset.joints if j.type in ("revolute", "prismatic", "continuous")]
    moved: set[str] = set()
    for j in movable:
        moved |= _subtree(asset, j.child)
    labels = {ln.name: canonical_label(ln.semantic_label) for ln in asset.links}
    parts: dict[str, PartFraction] = {}
    for j in movable:
        pf = PART_MASS_FRACTION.get((category or "", labels.get(j.child) or ""))
        if pf is not None:
            for ln in _subtree(asset, j.child):
                parts[ln] = pf
    body = [ln for ln in overlay.links if ln not in moved]
    total = overlay.total_mass()
    m_body = sum(overlay.links[ln].mass for ln in body)
    floors: dict[str, float] = {}  # link -> the least mass it may take
    reasons: list[str] = []
    table = [ln for ln in overlay.links if ln in parts]
    pf = min((parts[ln] for ln in table), key=lambda p: p.lo) if table else None
    if pf is not None:
        m_table = sum(overlay.links[ln].mass for ln in table)
        share = min(1.0, pf.lo * total / max(m_table, 1e-12))
        floors.update({ln: overlay.links[ln].mass * share for ln in table})
        reasons.append(f"sourced range {pf.lo:.0%}-{pf.hi:.0%}: {pf.source}")
    env = envelope_masses(overlay, _link_world(Path(urdf), state)[1], geometry) if geometry else {}
    env_links = [ln for ln in overlay.links if ln in moved and ln not in parts and ln in env
                 and env[ln] < overlay.links[ln].mass * (1 - 1e-9)]
    if env_links:
        floors.update({ln: env[ln] for ln in env_links})
        reasons.append("envelope shell mass (outer area x wall thickness x density) of "
                       + ", ".join(f"{ln} {env[ln]:.3g} kg" for ln in env_links))
    light = [ln for ln in floors if floors[ln] < overlay.links[ln].mass * (1 - 1e-9)]
    m_part = sum(overlay.links[ln].mass for ln in floors)
    if not floors or m_body <= 0 or total <= 0:
        if bal.margin >= 0:  # inside, only closer to the edge than asked: nothing to say without a sourced ratio
            return overlay, []
        return overlay, [f"centre of mass {bal.margin * 1000:.3g} mm from the support's edge at the requested state "
                         f"(needs >= {bal.required * 1000:.3g} mm inside); no part-mass ratio of {category} to move within"]
    if not light:
        return overlay, [f"centre of mass {bal.margin * 1000:.3g} mm from the support's edge; the opened parts already weigh "
                         f"{m_part / total:.0%} of the object, the lower end of the "
                         + ("sourced range" if pf is not None else "physical range") + (f" ({pf.lo:.0%})" if pf is not None else "")
                         + ": masses kept"]
    frames, _ = _link_world(Path(urdf), state)
    span = sum(overlay.links[ln].mass - floors[ln] for ln in light)

    def masses_for(t: float) -> dict[str, float]:
        out = {ln: lp.mass for ln, lp in overlay.links.items()}
        for ln in light:
            out[ln] -= t * (out[ln] - floors[ln])
        for ln in body:
            out[ln] *= (m_body + t * span) / m_body
        return out

    def margin(t: float) -> float:
        return _signed_margin(bal.support, _com(overlay, frames, masses_for(t))[:2])

    if margin(1.0) < bal.required:
        return overlay, [f"centre of mass {bal.margin * 1000:.3g} mm from the support's edge; even with the opened parts at "
                         "the lower end of their range (" + "; ".join(reasons) + ") it stays outside: masses kept"]
    lo, hi = 0.0, 1.0
    for _ in range(40):  # the margin is monotone in the transfer along this segment
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if margin(mid) >= bal.required else (mid, hi)
    new = masses_for(hi)
    ov = overlay.model_copy(deep=True)
    for ln in light + body:
        lp = ov.links[ln]
        f = new[ln] / lp.mass
        ov.links[ln] = lp.model_copy(update={
            "mass": new[ln],
            "inertia": lp.inertia.model_copy(update={k: getattr(lp.inertia, k) * f for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}),
            "source": lp.source + f"; mass x{f:.3g} for stability by design",
        })
    after = _signed_margin(bal.support, _com(ov, frames)[:2])
    moved_kg = hi * span
    m_after = sum(new[ln] for ln in floors)
    change = (
        f"stability by design: at the requested state the centre of mass was {bal.margin * 1000:.3g} mm from the support's edge "
        f"(needs >= {bal.required * 1000:.3g} mm inside); moved {moved_kg:.3g} kg from {', '.join(light)} to {', '.join(body)} "
        f"(opened parts {m_part / total:.0%} -> {m_after / total:.0%} of {total:.3g} kg, " + "; ".join(reasons) + "); "
        f"margin now {after * 1000:.3g} mm; total mass, scale and state unchanged"
    )
    return ov, [change]
