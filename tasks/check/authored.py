"""Authored equals simulated: what each engine holds after loading an output
equals what the output's files say.

:func:`authored_physics` reads the files; :func:`held_by_engines` loads the
folder in each engine (and the exported MJCF / USD with their importers) and
reads the same quantities back; :func:`compare_physics` names every quantity
an engine dropped or rescaled (the importer bugs of IsaacSim issues #841, #842).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim.engines.base import EngineUnavailable, EngineUnsupported, HeldJoint, HeldLink, HeldPhysics, principal_moments
from asset2sim.engines.registry import open_session, read_held_physics
from asset2sim.engines.loading import BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, read_urdf
from asset2sim.refined_asset import RefinedAsset, output_session_options
from asset2sim.output_folder import URDF_NAME

#: The exported files each engine's own importer reads back: (engine, format, path in the output folder).
EXPORTED_FILES: tuple[tuple[str, str, str], ...] = (
    ("mujoco", "mjcf", "mjcf/mobility.xml"),
    ("newton", "usd", "usd/mobility.usd"),
)


@dataclass(frozen=True)
class Tolerances:
    """How close a held value must be to the authored one (PhysX, Newton and USD
    store float32, PyBullet and MuJoCo float64).

    ``rel``: relative, for mass, principal moments (against the link's largest),
    damping, friction and stiffness: about 170 float32 ulps. ``length``:
    absolute for COM, limits, positions and spring references, m or rad.
    ``floor``: absolute below which a damping, friction or stiffness difference is ignored.
    """

    rel: float = 1e-5
    length: float = 1e-6
    floor: float = 1e-9


@dataclass
class Mismatch:
    """One quantity (``quantity``) of ``item`` (``link NAME`` / ``joint NAME``) an
    engine holds differently from the files."""

    item: str
    quantity: str
    held: object
    authored: object

    def __str__(self) -> str:
        return f"{self.item} {self.quantity}: engine holds {self.held}, files say {self.authored}"


@dataclass
class AuthoredCheck:
    """The comparison for one engine and one loaded file: ``status`` ``ok``,
    ``skipped`` or ``error`` (``reason`` says why); ``max_error`` per quantity
    family the largest difference in units of its tolerance (<= 1 passes);
    ``notes`` what was not compared."""

    engine: str
    source: str
    status: str
    links: int = 0
    joints: int = 0
    mismatches: list[Mismatch] = field(default_factory=list)
    max_error: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    how: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool | None:
        """True when compared without a mismatch, None when skipped."""
        if self.status == "skipped":
            return None
        return self.status == "ok" and not self.mismatches


def authored_physics(out_dir: Path) -> HeldPhysics:
    """What an output folder's files say, as a :class:`HeldPhysics` (``engine``
    ``"files"``; a link without ``<inertial>``: PyBullet's 1 kg and unit inertia).

    Raises:
        FileNotFoundError: no ``mobility.urdf``.
        ValueError: invalid ``initial_state.json`` or ``overlay.json``.
    """
    asset = RefinedAsset.existing(out_dir)
    urdf = read_urdf(asset.urdf_path)
    state, springs = asset.initial_state, asset.springs
    links = {}
    for name, link in urdf.links.items():
        ine = link.inertial
        if ine is None or ine.mass is None:
            links[name] = HeldLink(BULLET_DEFAULT_MASS, np.zeros(3), np.sort(np.array(BULLET_DEFAULT_INERTIA, float)))
        else:
            links[name] = HeldLink(float(ine.mass), np.asarray(ine.com(), float), principal_moments(ine.inertia_in_link_axes()))
    joints = {}
    for j in urdf.movable_joints:
        s = springs.get(j.name)
        joints[j.name] = HeldJoint(lower=float(j.lower), upper=float(j.upper), damping=float(j.damping), friction=float(j.friction),
                                   stiffness=s.stiffness if s else 0.0, reference=s.reference if s else None,
                                   position=float(state.get(j.name, 0.0)))
    return HeldPhysics(engine="files", source=str(asset.folder), links=links, joints=joints)


def compare_physics(held: HeldPhysics, authored: HeldPhysics, tol: Tolerances | None = None) -> AuthoredCheck:
    """Compare what an engine holds with what the files say, every link and
    movable joint of ``authored`` (a missing one is a ``missing`` mismatch;
    links welded to the world are not compared, with a note)."""
    tol = tol or Tolerances()
    out = AuthoredCheck(engine=held.engine, source=held.source, status="ok", links=len(authored.links),
                        joints=len(authored.joints), how=dict(held.how))
    worst: dict[str, float] = {}

    def note(family: str, err: float, item: str, quantity: str, held_value, authored_value) -> None:
        worst[family] = max(worst.get(family, 0.0), float(err))
        if err > 1.0:
            out.mismatches.append(Mismatch(item, quantity, held_value, authored_value))

    def off(hv: float, av: float) -> float:
        """|held - authored| of a length or angle in units of its tolerance."""
        return abs(hv - av) / (tol.length + tol.rel * abs(av))

    for name, a in authored.links.items():
        h, item = held.links.get(name), f"link {name}"
        if h is None:
            out.mismatches.append(Mismatch(item, "missing", None, "a body"))
            continue
        if name in held.welded_to_world:  # a fixed root: its mass is never simulated
            out.notes.append(f"{item}: welded to the world, mass and inertia not simulated "
                             f"({held.engine} holds {h.mass:g} kg, files say {a.mass:g} kg); not compared")
            continue
        note("mass", abs(h.mass - a.mass) / (tol.rel * max(abs(a.mass), 1e-300)), item, "mass (kg)", h.mass, a.mass)
        e = float(np.abs(np.asarray(h.com) - a.com).max()) / (tol.length + tol.rel * float(np.abs(a.com).max()))
        note("com", e, item, "center of mass (m)", np.round(h.com, 9).tolist(), np.round(a.com, 9).tolist())
        scale = float(np.abs(a.principal).max())
        e = float(np.abs(np.sort(h.principal) - a.principal).max()) / (tol.rel * max(scale, 1e-300))
        note("inertia", e, item, "principal moments (kg*m^2)", np.sort(h.principal).tolist(), a.principal.tolist())
    for name, a in authored.joints.items():
        h, item = held.joints.get(name), f"joint {name}"
        if h is None:
            out.mismatches.append(Mismatch(item, "missing", None, "a joint"))
            continue
        for q in ("lower", "upper"):
            hv, av = getattr(h, q), getattr(a, q)
            e = (0.0 if hv == av else math.inf) if math.isinf(av) or math.isinf(hv) else off(hv, av)
            note("limits", e, item, f"{q} limit", hv, av)
        for q in ("damping", "friction", "stiffness"):
            hv, av = getattr(h, q), getattr(a, q)
            note(q, abs(hv - av) / (tol.floor + tol.rel * abs(av)), item, q, hv, av)
        if a.reference is not None and a.stiffness != 0.0:
            e = math.inf if h.reference is None else off(h.reference, a.reference)
            note("position", e, item, "spring reference", h.reference, a.reference)
        note("position", off(h.position, a.position), item, "initial position", h.position, a.position)
    out.max_error = worst
    return out


def held_by_engines(out_dir: Path, engines: list[str]) -> list[AuthoredCheck]:
    """Load ``out_dir`` in each engine (no step) and compare what it holds with
    the files, and each of :data:`EXPORTED_FILES` with its engine's importer (the default :class:`Tolerances`). One
    :class:`AuthoredCheck` per (engine, file).

    Raises:
        FileNotFoundError: no ``mobility.urdf``.
        ValueError: invalid ``initial_state.json`` or ``overlay.json``.
    """
    out_dir = Path(out_dir)
    authored = authored_physics(out_dir)
    opts = output_session_options(out_dir)

    def compared(engine: str, fmt: str, held: Callable[[], HeldPhysics]) -> AuthoredCheck:
        """:func:`compare_physics` of what ``held()`` reads back; skipped where the engine or its reader is missing,
        an error where the file does not load."""
        try:
            return compare_physics(held(), authored)
        except (EngineUnavailable, EngineUnsupported, KeyError) as exc:
            return AuthoredCheck(engine, fmt, "skipped", reason=str(exc))
        except Exception as exc:  # the file does not load in this engine
            return AuthoredCheck(engine, fmt, "error", reason=f"{type(exc).__name__}: {exc}")

    def loaded(engine: str) -> HeldPhysics:
        with open_session(engine, out_dir / URDF_NAME, opts) as session:
            return session.held_physics()

    results = [compared(engine, "urdf", lambda engine=engine: loaded(engine)) for engine in dict.fromkeys(engines)]
    for engine, fmt, rel in (e for e in EXPORTED_FILES if e[0] in engines):
        if not (out_dir / rel).is_file():
            results.append(AuthoredCheck(engine, fmt, "skipped", reason=f"{rel} not exported"))
        else:
            results.append(compared(engine, fmt, lambda engine=engine, fmt=fmt, rel=rel: read_held_physics(
                engine, fmt, out_dir / rel, list(authored.links), list(authored.joints))))
    return results
