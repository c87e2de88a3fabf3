"""How hard a joint may be to operate: the friction escalation may not exceed.

Escalation (:func:`asset2sim.tasks.check.postcheck.escalate`) raises joint
friction until the requested state holds through robust rest. Unbounded, it
makes parts nobody can open (a laptop screen needing 4 N*m, a drawer needing
130 N): the state holds, the asset is useless for manipulation. This module
bounds the friction by what the probe (:mod:`asset2sim.tasks.check.probes`),
the evaluation's stand-in for a hand or a robot's gripper, can apply.

Definitions (SI units; ``docs/metrics.md``, section "Operable friction"):

- Operating force F_max = max(``min_force``, ``force_factor`` * M g): the
  probe's force limit (:class:`asset2sim.tasks.check.probes.ProbeConfig`;
  ``min_force`` 22.2 N = 5 lbf, the 2010 ADA Standards for Accessible Design,
  section 309.4, the largest force an operable part may need), M the total
  mass of the object (kg), g = 9.81 m/s^2.
- Lever r (revolute joints): the distance from the joint axis to where the
  probe pushes: the corner of the child link's box farthest from the axis
  (:func:`asset2sim.tasks.check.probes._push_geometry` uses the world box of
  the engine; here the box in the link's own frame,
  :class:`asset2sim.schemas.asset.LinkGeometry`, times the overlay's scale).
  Operating effort E = F_max r (N*m); prismatic joints: E = F_max (N).
- Gravity load L: the weight of the moving subtree m_s g times the distance
  from the axis to the child link's center of mass (revolute, the worst case:
  that lever horizontal) or m_s g (prismatic, a vertical slide's worst case).
- Friction cap = min(``OPERABLE_SHARE`` * E - L, the friction above which
  the engine's friction motor locks the joint,
  :func:`asset2sim.tasks.synthesize.physics.max_stable_friction`: F dt / I
  beyond Bullet's joint speed clamp), at least the joint's friction before
  escalation (escalation never lowers a value).
- Tilt floor: a joint that robust rest's tilts move needs friction for the
  extra gravity load a tilt by theta adds: at least the friction before
  escalation plus ``TILT_MARGIN`` m_s g r sin(theta) (revolute, r the lever
  to the child's center of mass; the change of m_s g r cos(phi) when phi
  moves by theta is at most m_s g r sin(theta)) or ``TILT_MARGIN`` m_s g
  sin(theta) (prismatic, a horizontal slide tilted by theta). Escalation by
  factors alone never reaches it from a friction near zero (a horizontal
  drawer's or handle's estimate).
"""

from __future__ import annotations

import numpy as np

from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.check.probes import ProbeConfig
from asset2sim.tasks.geometry.closed_state import subtree_links
from asset2sim.tasks.synthesize.physics import max_stable_friction

GRAVITY = 9.81
"""m/s^2"""
TILT_MARGIN = 2.0
"""Safety factor on the tilt's extra gravity load (dimensionless): static
friction must also stop the motion the tilt has already started."""
OPERABLE_SHARE = 0.7
"""Share of the operating effort that friction plus gravity may take
(dimensionless): the rest is the margin the probe needs to accelerate the part
and to cover the difference between its push point (the child link's box
centre) and the center of mass used here."""


def operating_effort(overlay: Overlay, asset: AssetDescription, joint: str, geometry: dict[str, LinkGeometry],
                     config: ProbeConfig | None = None) -> float:
    """Largest effort the probe applies to ``joint``: F_max r (N*m) for a
    revolute joint, F_max (N) for a prismatic one (module docstring).

    Args:
        overlay: the overlay (link masses kg, ``scale``).
        asset: the description of the same asset (joint axes, tree).
        joint: a movable joint of ``asset``.
        geometry: link -> :class:`LinkGeometry` (boxes at scale 1, link frame).
        config: the probe's force limits (default :class:`ProbeConfig`).

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    cfg = config or ProbeConfig()
    jd = asset.joint(joint)
    total = sum(lp.mass for lp in overlay.links.values())
    f_max = max(cfg.min_force, cfg.force_factor * total * GRAVITY)
    if jd.type == "prismatic":
        return float(f_max)
    return float(f_max * push_lever(overlay, asset, joint, geometry))


def _unit_axis(asset: AssetDescription, joint: str) -> np.ndarray:
    a = np.asarray(asset.joint(joint).axis, float)
    return a / max(float(np.linalg.norm(a)), 1e-12)


def _off_axis(points: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Distances (N,) m of ``points`` (N, 3) from the axis through the origin along unit ``a`` (3,)."""
    return np.linalg.norm(points - np.outer(points @ a, a), axis=1)


def push_lever(overlay: Overlay, asset: AssetDescription, joint: str, geometry: dict[str, LinkGeometry]) -> float:
    """Distance (m) from ``joint``'s axis to the probe's push point on its
    child link (module docstring); 0 when the child has no geometry.

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    g = geometry.get(asset.joint(joint).child)
    if g is None:
        return 0.0
    lo, hi = np.asarray(g.bbox_min, float), np.asarray(g.bbox_max, float)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return float(_off_axis(corners, _unit_axis(asset, joint)).max()) * float(overlay.scale)


def com_lever(overlay: Overlay, asset: AssetDescription, joint: str) -> float:
    """Distance (m) from ``joint``'s axis to its child link's center of mass
    (the overlay's, link frame = joint frame, URDF convention); 0 when the
    child has no physics in the overlay.

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    lp = overlay.links.get(asset.joint(joint).child)
    if lp is None:
        return 0.0
    return float(_off_axis(np.asarray(lp.com, float)[None, :], _unit_axis(asset, joint))[0])


def friction_caps(overlay: Overlay, before: Overlay, asset: AssetDescription, geometry: dict[str, LinkGeometry],
                  config: ProbeConfig | None = None) -> dict[str, float]:
    """Largest joint friction (N*m or N) escalation may set, per movable joint
    of ``overlay`` (module docstring): ``OPERABLE_SHARE`` * E - L, but at
    least the friction of ``before`` (the overlay before any escalation).

    Raises:
        KeyError: a joint of ``overlay`` is not in ``asset``.
    """
    caps: dict[str, float] = {}
    for name, d in overlay.joints.items():
        jd = asset.joint(name)
        if jd.type not in ("revolute", "continuous", "prismatic"):
            continue
        sub_mass = sum(overlay.links[ln].mass for ln in subtree_links(asset, jd.child) if ln in overlay.links)
        load = sub_mass * GRAVITY * (1.0 if jd.type == "prismatic" else com_lever(overlay, asset, name))
        cap = OPERABLE_SHARE * operating_effort(overlay, asset, name, geometry, config) - load
        if d.inertia_axis:  # above it the engine's friction motor locks the joint (a light handle)
            cap = min(cap, max_stable_friction(d.inertia_axis))
        floor = before.joints[name].friction if name in before.joints else d.friction
        caps[name] = float(max(cap, floor))
    return caps


def tilt_floors(overlay: Overlay, before: Overlay, asset: AssetDescription, tilt: float) -> dict[str, float]:
    """Friction (N*m or N) a movable joint of ``overlay`` needs to hold
    through a tilt of ``tilt`` rad (module docstring, "Tilt floor"), from the
    friction of ``before`` (the overlay before escalation).

    Raises:
        KeyError: a joint of ``overlay`` is not in ``asset``.
    """
    floors: dict[str, float] = {}
    for name, d in overlay.joints.items():
        jd = asset.joint(name)
        if jd.type not in ("revolute", "continuous", "prismatic"):
            continue
        sub_mass = sum(overlay.links[ln].mass for ln in subtree_links(asset, jd.child) if ln in overlay.links)
        lever = 1.0 if jd.type == "prismatic" else com_lever(overlay, asset, name)
        base = before.joints[name].friction if name in before.joints else d.friction
        floors[name] = float(base + TILT_MARGIN * sub_mass * GRAVITY * lever * np.sin(abs(tilt)))
    return floors
