"""Mechanical validation of an overlay (SPEC stage 2, whatever produced it):
:func:`validate_overlay` returns a corrected copy and the named issues; an unfixed error is fatal. Codes (fixed ones are warnings):

- ``OVL_SCALE_INVALID``: scale not finite or outside [1e-4, 1e4] (error).
- ``OVL_UNKNOWN_LINK`` / ``OVL_UNKNOWN_JOINT``: names not in the asset (dropped).
- ``OVL_LINK_MISSING``: filled from the geometry (1000 kg/m^3, volume or 3 mm
  shell), else 0.1 % of the total mass.
- ``OVL_MASS_INVALID``: mass not finite or <= 0 (fixed from geometry, else error).
- ``OVL_MASS_TOO_SMALL``: below ``MIN_LINK_MASS_FRACTION`` of the total; raised.
- ``OVL_INERTIA_INVALID``: not finite, not positive definite or violating
  I1 + I2 >= I3 (rtol 1e-9); replaced by the scaled geometry's, else error.
- ``OVL_COM_OUTSIDE``: COM farther than 10 % of the diagonal outside the box.
- ``OVL_JOINT_MISSING``: filled by :func:`conservative_dynamics`.
- ``OVL_DYNAMICS_NEGATIVE``: damping, friction or stiffness < 0 or not finite (error).
- ``OVL_SPRING_REFERENCE``: stiffness > 0 without a reference within ``SPRING_REFERENCE_REACH``
  ranges of the limits (a preloaded balance's reference lies beyond the travel).
- ``OVL_STATE_UNKNOWN_JOINT`` / ``OVL_STATE_OUT_OF_LIMITS``: dropped / projected
  onto the limits (prismatic in output units, input limits x scale).
"""

from __future__ import annotations

import math

import numpy as np

from asset2sim.schemas.asset import AssetDescription, JointDesc, LinkDesc, LinkGeometry
from asset2sim.schemas.overlay import SCALE_RANGE, Inertia, JointDynamics, LinkPhysics, Overlay, ValidationIssue
from asset2sim.tasks.geometry.closed_state import subtree_links

TRIANGLE_RTOL = 1e-9


_SCALE_TEXT = ", ".join(f"{x:.0e}".replace("e+0", "e").replace("e-0", "e-").replace("e+", "e") for x in SCALE_RANGE)  # "1e-4, 1e4"


class OverlayInvalid(ValueError):
    """The overlay has unfixed errors (``errors``: one line each); ``issues`` lists all."""

    def __init__(self, issues: list[ValidationIssue]):
        self.issues = issues
        self.errors = [f"{i.code} at {i.where}: {i.message}" for i in issues if i.severity == "error" and not i.fixed]
        super().__init__("invalid overlay: " + "; ".join(self.errors))


def _raise_fatal(issues: list[ValidationIssue]) -> None:
    """Raise :class:`OverlayInvalid` when any issue is an unfixed error."""
    if (invalid := OverlayInvalid(issues)).errors:
        raise invalid


#: Lightest a link may be, as a fraction of the object's total mass: iterative contact solvers converge slowly
#: on large mass ratios (Erleben, ACM TOG 2007; NVIDIA PhysX SDK guide, "Rigid Body Dynamics: mass ratios").
MIN_LINK_MASS_FRACTION = 1e-3


#: Densest a link may be, as a multiple of its material's density (``materials.yaml``): a part is at most
#: solid; the margin covers the spread of grades within a material family in the tables cited there (ABS
#: 1020-1080, carbon steels 7750-8050 kg/m^3) and metal inserts in plastic parts.
MAX_DENSITY_FACTOR = 1.25
#: Densest any link may be without a known material, kg/m^3 (brass, the densest material of ``materials.yaml``,
#: x :data:`MAX_DENSITY_FACTOR`).
MAX_DENSITY = 8500.0 * MAX_DENSITY_FACTOR

#: Farthest a spring's reference may lie outside its joint's limits, in ranges of the joint (dimensionless): a
#: preloaded balance (a window's constant-force sash balance, ``spring_holds.balance``) refers to a position about
#: 1 / (2 x 0.06) = 8.3 ranges from mid-travel; a reference farther out is a unit or sign error.
SPRING_REFERENCE_REACH = 10.0


def max_density(lp: LinkPhysics) -> float:
    """The densest a link of physics ``lp`` may be, kg/m^3: :data:`MAX_DENSITY_FACTOR` x its material's
    density, :data:`MAX_DENSITY` without one."""
    return lp.density * MAX_DENSITY_FACTOR if lp.density else MAX_DENSITY


def solid_volume(geom: LinkGeometry | None, scale: float) -> float | None:
    """The volume a link's geometry (scale 1) encloses at ``scale``, m^3; None for an open surface or none."""
    if geom is None or not geom.volume > 0 or "open_shell" in geom.volume_method:
        return None
    return geom.volume * scale**3


def _raise_light_links(ov: Overlay, add, asset: AssetDescription, geometry: dict[str, LinkGeometry]) -> None:
    """Raise links below :data:`MIN_LINK_MASS_FRACTION` of the total to that floor (inertia alike), never
    beyond :func:`max_density` over :func:`solid_volume` (a density its material cannot have); the joints of ``asset``
    whose moving subtree got heavier get friction, damping and axis inertia times its ratio."""
    before = {n: lp.mass for n, lp in ov.links.items()}
    masses = {n: lp.mass for n, lp in ov.links.items() if math.isfinite(lp.mass) and lp.mass > 0}
    total = sum(masses.values())
    f = MIN_LINK_MASS_FRACTION
    floor = f * total
    for _ in range(len(masses) + 1):  # the floor of the total *after* raising: f * (heavy + n_light * floor)
        light = [n for n, m in masses.items() if m < floor * (1 - 1e-9)]
        new = f * (total - sum(masses[n] for n in light)) / (1 - f * len(light))
        if math.isclose(new, floor, rel_tol=1e-12):
            break
        floor = new
    for name, lp in list(ov.links.items()):
        if name in masses and lp.mass < floor * (1 - 1e-9):
            vol, rho = solid_volume(geometry.get(name), ov.scale), max_density(lp)
            target = floor if vol is None else min(floor, max(vol * rho, lp.mass))
            why = (f"; not to the floor {floor:.3g} kg: {floor / vol:.3g} kg/m^3 in its {vol * 1e6:.3g} cm^3, denser than "
                   f"its material ({rho:.3g} kg/m^3 at most); the mass ratio stays below the solver floor") if target < floor else ""
            add("OVL_MASS_TOO_SMALL", "warning", name,
                f"mass {lp.mass:.3g} kg is below {MIN_LINK_MASS_FRACTION:g} of the object's {total:.4g} kg; "
                + (f"raised to {target:.3g} kg (inertia scaled alike){why}" if target > lp.mass else f"kept{why}"),
                fixed=target > lp.mass)
            if target <= lp.mass:
                continue
            ov.links[name] = lp.model_copy(update={
                "mass": target, "inertia": Inertia.from_matrix(lp.inertia.matrix() * (target / lp.mass)),
                "source": lp.source + ("; mass raised to the floor by validator" if target == floor else
                                       "; mass raised by validator to the densest its material allows"),
            })
    for jd in asset.movable_joints():
        if (dyn := ov.joints.get(jd.name)) is None:
            continue
        sub = [ln for ln in subtree_links(asset, jd.child) if ln in ov.links]
        m0 = sum(before.get(ln, 0.0) for ln in sub)
        m1 = sum(ov.links[ln].mass for ln in sub)
        if not (m0 > 0 and m1 > m0 * (1 + 1e-9)):
            continue
        r = m1 / m0
        ov.joints[jd.name] = dyn.model_copy(update={
            "friction": dyn.friction * r, "damping": dyn.damping * r,
            "inertia_axis": dyn.inertia_axis * r if dyn.inertia_axis else dyn.inertia_axis,
            "source": dyn.source + f"; friction and damping x{r:.3g} with the moving part's mass raised by the validator",
        })


def inertia_problems(m: np.ndarray) -> str | None:
    """Why a (3, 3) inertia tensor (kg*m^2) is not finite, symmetric, positive definite and within the
    triangle inequality of principal moments (Featherstone, Rigid Body Dynamics Algorithms, 2.13), or None."""
    m = np.asarray(m, float)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        return "not a finite 3x3 tensor"
    if not np.allclose(m, m.T, rtol=1e-9, atol=1e-15):
        return "not symmetric"
    ev = np.linalg.eigvalsh(m)
    if ev[0] <= 0:
        return f"not positive definite (principal moments {ev.tolist()})"
    if ev[0] + ev[1] < ev[2] * (1.0 - TRIANGLE_RTOL):
        return f"principal moments {ev.tolist()} violate the triangle inequality"
    return None


def geometry_inertia(geom: LinkGeometry, mass: float, scale: float, hollow: bool) -> np.ndarray:
    """Inertia (3, 3) kg*m^2 about the COM: per-kg tensor (shell when ``hollow``) x mass x scale^2, made valid
    by a tiny isotropic term (else the bounding box's) if degenerate."""
    m = np.asarray(geom.inertia_shell if hollow else geom.inertia_solid, float) * mass * scale**2
    m = 0.5 * (m + m.T)
    if inertia_problems(m) is not None:
        ext = np.asarray(geom.extents, float) * scale
        iso = mass * max(float(np.max(ext)), 1e-6) ** 2 / 12.0 * 1e-3
        m = m + np.eye(3) * iso
        if inertia_problems(m) is not None:  # fall back to the bounding box
            m = box_inertia(mass, np.maximum(ext, 1e-6))
    return m


def box_inertia(mass: float, extents: np.ndarray) -> np.ndarray:
    """Inertia (3, 3) of a solid box of ``mass`` kg and ``extents`` (3,) m about its center."""
    x, y, z = np.asarray(extents, float)
    return np.diag([mass * (y * y + z * z), mass * (x * x + z * z), mass * (x * x + y * y)]) / 12.0


def _fill_mass(geom: LinkGeometry, s: float) -> float:
    """Mass (kg) of a conservative fill: 1000 kg/m^3 on the larger of the volume and a 3 mm shell; >= 1e-6 kg."""
    return max(max(geom.volume * s**3, geom.area * s**2 * 0.003) * 1000.0, 1e-6)


def conservative_dynamics(joint_type: str) -> JointDynamics:
    """Dynamics for a joint the overlay misses: moderate damping and a small friction."""
    slide = joint_type == "prismatic"
    return JointDynamics(damping=1.0 if slide else 0.05, friction=0.5 if slide else 0.02, stiffness=0.0,
                         source="conservative default")


def validate_overlay(overlay: Overlay, asset: AssetDescription, geometry: dict[str, LinkGeometry] | None = None) -> tuple[Overlay, list[ValidationIssue]]:
    """(corrected copy of ``overlay``, issues) by the SPEC rules for ``asset``; ``geometry`` (link -> scale-1
    geometry) enables fills and fixes.

    Raises:
        OverlayInvalid: when an issue is an unfixed error.
    """
    geometry = geometry or {}
    issues: list[ValidationIssue] = []
    ov = overlay.model_copy(deep=True)

    def add(code, severity, where, message, fixed=False):
        issues.append(ValidationIssue(code=code, severity=severity, where=where, message=message, fixed=fixed))

    s = ov.scale
    if not (math.isfinite(s) and SCALE_RANGE[0] <= s <= SCALE_RANGE[1]):
        add("OVL_SCALE_INVALID", "error", "global", f"scale {s!r} is not a finite value in [{_SCALE_TEXT}]")
        _raise_fatal(issues)
        return ov, issues

    movable = {j.name: j for j in asset.movable_joints()}
    _drop_unknown_names(ov, asset, movable, add)
    total_known = sum(lp.mass for lp in ov.links.values() if math.isfinite(lp.mass) and lp.mass > 0)
    for ln in asset.links:
        lp = ov.links.get(ln.name)
        if lp is None:
            _fill_link(ov, ln, geometry.get(ln.name), s, total_known, add)
        else:
            _check_link(ov, ln.name, lp, geometry.get(ln.name), s, add)
    _raise_light_links(ov, add, asset, geometry)
    # limits in output units (prismatic x scale); continuous joints (-inf, inf)
    limits = {n: (-math.inf, math.inf) if j.type == "continuous" or j.lower is None or j.upper is None
              else (j.lower * s, j.upper * s) if j.type == "prismatic" else (j.lower, j.upper) for n, j in movable.items()}
    for name, jd in movable.items():
        _check_joint(ov, name, jd.type, limits[name], add)
    if ov.initial_joint_positions is not None:
        ov.initial_joint_positions = _checked_state(ov.initial_joint_positions, movable, limits, add)
    _raise_fatal(issues)
    return ov, issues


def _drop_unknown_names(ov: Overlay, asset: AssetDescription, movable: dict[str, JointDesc], add) -> None:
    """Drop the links the asset lacks (error) and the joints that are not movable (warning for a fixed joint, else error)."""
    link_names = {ln.name for ln in asset.links}
    for name in list(ov.links):
        if name not in link_names:
            add("OVL_UNKNOWN_LINK", "error", name, f"overlay names link {name!r}, which {asset.urdf_path.name} does not have")
            del ov.links[name]
    for name in list(ov.joints):
        if name not in movable:
            sev = "warning" if any(j.name == name for j in asset.joints) else "error"
            add("OVL_UNKNOWN_JOINT", sev, name, f"overlay gives dynamics for {name!r}, which is not a movable joint; dropped", fixed=sev == "warning")
            del ov.joints[name]


def _fill_link(ov: Overlay, ln: LinkDesc, geom: LinkGeometry | None, s: float, total_known: float, add) -> None:
    """Fill a missing link from its geometry, else 0.1 % of ``total_known`` (>= 1e-4 kg)."""
    if geom is not None:
        mass = _fill_mass(geom, s)
        ov.links[ln.name] = LinkPhysics(mass=mass, inertia=Inertia.from_matrix(geometry_inertia(geom, mass, s, hollow=False)),
                                        com=tuple(c * s for c in geom.com), material="unknown (conservative fill: 1000 kg/m^3 solid)",
                                        density=1000.0, hollow_fraction=1.0, source="validator fill from geometry")
        why = f"no overlay entry; filled from geometry: {mass:.4g} kg"
    else:
        mass = max(1e-3 * total_known, 1e-4)
        i = mass * 1e-4 * s**2
        ov.links[ln.name] = LinkPhysics(mass=mass, inertia=Inertia(ixx=i, iyy=i, izz=i), com=(0.0, 0.0, 0.0),
                                        material="none (link without geometry)",
                                        source="validator placeholder for a link without geometry")
        why = f"no overlay entry and no geometry analysis; placeholder {mass:.3g} kg"
    if ln.has_geometry:
        add("OVL_LINK_MISSING", "warning", ln.name, why, fixed=True)


def _check_link(ov: Overlay, name: str, lp: LinkPhysics, geom: LinkGeometry | None, s: float, add) -> None:
    """Check a link's mass, inertia and COM: replaced by the scaled geometry's when it exists, else errors."""
    if not (math.isfinite(lp.mass) and lp.mass > 0):
        if geom is None:
            add("OVL_MASS_INVALID", "error", name, f"mass {lp.mass!r} is not a finite value > 0")
            return
        mass = _fill_mass(geom, s)
        add("OVL_MASS_INVALID", "warning", name, f"mass {lp.mass!r} is not > 0; replaced by {mass:.4g} kg from geometry", fixed=True)
        lp = lp.model_copy(update={"mass": mass, "source": lp.source + "; mass fixed by validator"})
    m = lp.inertia.matrix()
    if (prob := inertia_problems(m)) is not None:
        ev = np.linalg.eigvalsh(np.nan_to_num(0.5 * (m + m.T))).tolist()
        if geom is not None:
            new = geometry_inertia(geom, lp.mass, s, (lp.hollow_fraction or 1.0) < 1.0)
            add("OVL_INERTIA_INVALID", "warning", name, f"inertia {prob} (eigenvalues {ev}); replaced by the scaled geometry's inertia", fixed=True)
            lp = lp.model_copy(update={"inertia": Inertia.from_matrix(new), "source": lp.source + "; inertia fixed by validator"})
        else:
            add("OVL_INERTIA_INVALID", "error", name, f"inertia {prob} (eigenvalues {ev})")
    com = np.asarray(lp.com, float)
    if geom is not None:
        lo = np.asarray(geom.bbox_min) * s
        hi = np.asarray(geom.bbox_max) * s
        slack = 0.1 * float(np.linalg.norm(hi - lo))
        if not np.all(np.isfinite(com)) or np.any(com < lo - slack) or np.any(com > hi + slack):
            add("OVL_COM_OUTSIDE", "warning", name, f"center of mass {com.tolist()} m lies outside the link's scaled bounding box; replaced by the geometry's", fixed=True)
            lp = lp.model_copy(update={"com": tuple(c * s for c in geom.com)})
    elif not np.all(np.isfinite(com)):
        add("OVL_COM_OUTSIDE", "error", name, "center of mass is not finite")
    ov.links[name] = lp


def _check_joint(ov: Overlay, name: str, joint_type: str, limits: tuple[float, float], add) -> None:
    """Fill missing dynamics, flag negative ones, and put a spring's reference inside ``limits`` (the initial
    state, else 0 projected onto the limits)."""
    dyn = ov.joints.get(name)
    if dyn is None:
        ov.joints[name] = conservative_dynamics(joint_type)
        add("OVL_JOINT_MISSING", "warning", name, "no dynamics in the overlay; conservative values filled", fixed=True)
        return
    if bad := [k for k in ("damping", "friction", "stiffness") if not (math.isfinite(getattr(dyn, k)) and getattr(dyn, k) >= 0)]:
        add("OVL_DYNAMICS_NEGATIVE", "error", name, f"{', '.join(bad)} must be finite and >= 0 (got " + ", ".join(f"{k}={getattr(dyn, k)!r}" for k in bad) + ")")
        return
    if dyn.stiffness > 0:
        lo, hi = limits
        ref = dyn.spring_reference
        reach = SPRING_REFERENCE_REACH * (hi - lo) if math.isfinite(hi - lo) else 0.0
        if ref is None or not math.isfinite(ref) or not (lo - reach <= ref <= hi + reach):
            new_ref = (ov.initial_joint_positions or {}).get(name, float(np.clip(0.0, lo, hi)))
            add("OVL_SPRING_REFERENCE", "warning", name, f"spring reference {ref!r} missing or more than {SPRING_REFERENCE_REACH:g} "
                f"ranges outside limits [{lo}, {hi}]; set to {new_ref}", fixed=True)
            ov.joints[name] = dyn.model_copy(update={"spring_reference": new_ref})


def _checked_state(state: dict[str, float], movable: dict[str, JointDesc], limits: dict[str, tuple[float, float]], add) -> dict[str, float]:
    """The initial state without unknown joints or non-finite positions, projected onto the scaled limits."""
    out = {}
    for name, q in state.items():
        if name not in movable:
            add("OVL_STATE_UNKNOWN_JOINT", "warning", name, "initial state for a joint that is not movable; dropped", fixed=True)
            continue
        if not math.isfinite(q):
            add("OVL_STATE_OUT_OF_LIMITS", "error", name, f"initial position {q!r} is not finite")
            continue
        lo, hi = limits[name]
        if q < lo or q > hi:
            qn = float(np.clip(q, lo, hi))
            unit = "m" if movable[name].type == "prismatic" else "rad"
            add("OVL_STATE_OUT_OF_LIMITS", "warning", name, f"initial position {q} {unit} outside limits [{lo}, {hi}] (output units); projected to {qn}", fixed=True)
            q = qn
        out[name] = q
    return out
