"""Stability by design: keep the centre of mass (COM) over the support at the
requested state by moving mass from opened parts to the body, down to the
sourced part-mass fractions (:data:`PART_MASS_FRACTION`) or the envelope
shell mass m = A_env t rho (Roark's Formulas for Stress and Strain, 8th ed.).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from asset2sim.package_data import package_yaml
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.geometry.closed_state import subtree_links
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.prior_tables import MaterialPrior, load_priors
from asset2sim.tasks.state.balance import _balance, _com, _link_world, _signed_margin
from asset2sim.tasks.synthesize import physics, request_apply
from asset2sim.engines.source import SimSource

__all__ = ["PART_MASS_FRACTION", "TRANSFER_NOTE", "design_for_stability", "envelope_masses"]


@dataclass(frozen=True)
class PartFraction:
    """Share of the whole object's mass one part may carry (``lo`` .. ``hi``), with its source."""

    lo: float
    hi: float
    source: str


#: (category, canonical part label) -> the mass fraction of that part (``part_mass_fractions.yaml``, with sources).
PART_MASS_FRACTION: dict[tuple[str, str], PartFraction] = {
    (category, label): PartFraction(**share)
    for category, parts in package_yaml(__package__, "part_mass_fractions.yaml").items() for label, share in parts.items()
}


#: How the design note of a mass transfer begins (:func:`design_for_stability`).
TRANSFER_NOTE = "stability by design: at the requested state"


def envelope_masses(overlay: Overlay, points: dict[str, np.ndarray],
                    geometry: dict[str, LinkGeometry]) -> dict[str, float]:
    """Envelope shell mass (kg) of every shell-material link of ``overlay``: A_env t rho times the link's mass over its
    geometric mass (:func:`asset2sim.tasks.synthesize.physics.link_physics`), capped at its mass; A_env the hull area of
    ``points`` (link -> (N, 3) m, world). Links of other materials, or without geometry or hull, are left out."""
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


def design_for_stability(source: SimSource, asset: AssetDescription, overlay: Overlay, state: dict[str, float],
                         category: str | None, geometry: dict[str, LinkGeometry] | None = None, *,
                         most: bool = False) -> tuple[Overlay, list[str]]:
    """Make a free-standing object balance at ``state`` by its part masses: the
    smallest transfer from the opened parts (each linearly towards its floor:
    the sourced lower fraction, else the envelope shell mass) to the body
    (links no joint moves, scaled up alike) that gives the required margin.
    A mounted or already balanced asset is returned unchanged.

    ``source``: the written URDF (scale baked in, pose applied) of ``overlay``;
    ``state``: joint -> rad or m; ``category``: key of :data:`PART_MASS_FRACTION`;
    ``geometry``: link -> :class:`LinkGeometry` (scale 1) for the envelope shell
    masses (None: only the sourced fractions); ``most``: the whole transfer, every
    opened part at its floor (the lightest its sources allow), for an object that a
    disturbance toppled with less moved (or none, where it balanced statically). Returns (overlay, changes): the
    same overlay and no changes when nothing changed.
    """
    if overlay.mounting is not None and overlay.mounting.fixed:
        return overlay, []
    frames, points = _link_world(source, state)  # measured once: the balance, the transfer and the envelope masses
    bal = _balance(overlay, frames, points)
    if (bal.stable and not most) or len(bal.support) < 3:
        return overlay, []
    # the links a movable joint moves, and link -> the sourced fraction of its opened part
    movable = [j for j in asset.joints if j.is_movable]
    moved = {ln for j in movable for ln in subtree_links(asset, j.child)}
    labels = {ln.name: canonical_label(ln.semantic_label) for ln in asset.links}
    parts = {ln: frac for j in movable
             if (frac := PART_MASS_FRACTION.get((category or "", labels.get(j.child) or ""))) is not None
             for ln in subtree_links(asset, j.child)}
    body = [ln for ln in overlay.links if ln not in moved]
    m_body, total = sum(overlay.links[ln].mass for ln in body), overlay.total_mass()
    # the least mass of each opened link (``floors``, kg) and why (``reasons``: a line per source)
    floors: dict[str, float] = {}
    reasons: list[str] = []
    table = [ln for ln in overlay.links if ln in parts]
    pf = min((parts[ln] for ln in table), key=lambda p: p.lo) if table else None
    if pf is not None:
        m_table = sum(overlay.links[ln].mass for ln in table)
        share = min(1.0, pf.lo * total / max(m_table, 1e-12))
        floors.update({ln: overlay.links[ln].mass * share for ln in table})
        reasons.append(f"sourced range {pf.lo:.0%}-{pf.hi:.0%}: {pf.source}")
    env = envelope_masses(overlay, points, geometry) if geometry else {}
    env_links = [ln for ln in overlay.links if ln in moved and ln not in parts and ln in env
                 and env[ln] < overlay.links[ln].mass * (1 - 1e-9)]
    if env_links:
        floors.update({ln: env[ln] for ln in env_links})
        reasons.append("envelope shell mass (outer area x wall thickness x density) of "
                       + ", ".join(f"{ln} {env[ln]:.3g} kg" for ln in env_links))
    light = [ln for ln in floors if floors[ln] < overlay.links[ln].mass * (1 - 1e-9)]
    if not floors or m_body <= 0 or total <= 0:  # no mass can move
        if bal.margin >= 0:  # inside, only closer to the edge than asked: nothing to say without a sourced ratio
            return overlay, []
        return overlay, [f"centre of mass {bal.margin * 1000:.3g} mm from the support's edge at the requested state "
                         f"(needs >= {bal.required * 1000:.3g} mm inside); no part-mass ratio of {category} to move within"]
    m_part = sum(overlay.links[ln].mass for ln in floors)
    if not light:
        return overlay, [f"centre of mass {bal.margin * 1000:.3g} mm from the support's edge; the opened parts already weigh "
                         f"{m_part / total:.0%} of the object, the lower end of the "
                         + ("sourced range" if pf is not None else "physical range")
                         + (f" ({pf.lo:.0%})" if pf is not None else "")
                         + ": masses kept"]
    span = sum(overlay.links[ln].mass - floors[ln] for ln in light)
    masses_for = partial(_masses, overlay, light, body, floors, m_body, span)

    def held(t: float) -> bool:
        return _signed_margin(bal.support, _com(overlay, frames, masses_for(t))[:2]) >= bal.required

    # not ``held``: a NaN margin is searched on (to the whole transfer)
    if _signed_margin(bal.support, _com(overlay, frames, masses_for(1.0))[:2]) < bal.required:
        return overlay, [f"centre of mass {bal.margin * 1000:.3g} mm from the support's edge; even with the opened parts at "
                         "the lower end of their range (" + "; ".join(reasons) + ") it stays outside: masses kept"]
    # the smallest transfer t in [0, 1] that holds the margin required, in 40 halvings (the margin is monotone in the
    # transfer along this segment)
    lo, t = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + t)
        lo, t = (lo, mid) if held(mid) else (mid, t)
    t = 1.0 if most else t
    new = masses_for(t)
    ov = overlay.model_copy(deep=True)  # the masses moved, inertia scaled alike, noted in the source
    for ln in light + body:
        f = new[ln] / ov.links[ln].mass
        ov.links[ln] = request_apply.scaled_link(ov.links[ln], f, f"; mass x{f:.3g} for stability by design").model_copy(
            update={"mass": new[ln]})
    after = _signed_margin(bal.support, _com(ov, frames)[:2])
    m_after = sum(new[ln] for ln in floors)
    return ov, [f"{TRANSFER_NOTE} the centre of mass was {bal.margin * 1000:.3g} mm from the support's "
                f"edge (needs >= {bal.required * 1000:.3g} mm inside); moved {t * span:.3g} kg from {', '.join(light)} to "
                f"{', '.join(body)} (opened parts {m_part / total:.0%} -> {m_after / total:.0%} of {total:.3g} kg, "
                + "; ".join(reasons) + f"); margin now {after * 1000:.3g} mm; total mass, scale and state unchanged"
                + ("; the whole transfer: a drop or tilt toppled it with less moved" if most else "")]


def _masses(overlay: Overlay, light: list[str], body: list[str], floors: dict[str, float], m_body: float, span: float,
            t: float) -> dict[str, float]:
    """link -> mass (kg), each ``light`` link ``t`` of the way to its floor, the ``body`` scaled up by ``t * span`` kg."""
    out = {ln: lp.mass for ln, lp in overlay.links.items()}
    for ln in light:
        out[ln] -= t * (out[ln] - floors[ln])
    for ln in body:
        out[ln] *= (m_body + t * span) / m_body
    return out
