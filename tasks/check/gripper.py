"""A floating, force- and speed-limited parallel gripper as a bounded-force attachment (the model and its
constants: ``docs/design/metrics.md``, "task_execution" 3). Call :meth:`BoundedGrasp.step_towards` once per
engine step. k and c are capped at ``m_eff / dt^2`` and ``m_eff / dt``, half the stability limits of an
explicit step (omega dt < 2: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. 2006,
ch. I; c dt / m < 2 for explicit Euler), ``m_eff`` a third of the grasped link's mass.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

#: Effective mass at the grasp point as a share of the link's mass (a uniform
#: plate at its far edge: I / L^2 = m / 3).
EFFECTIVE_MASS_SHARE = 1.0 / 3.0


@dataclass(frozen=True)
class GripperLimits:
    """Force and speed limits of a robot gripper and arm (SI units).

    Defaults and their sources:

    - ``max_force_n`` = 70 N: the Franka Emika Panda hand's continuous grasp
      force (Franka Emika, *Panda Datasheet*, 2019, "Hand"); within the
      Robotiq 2F-85's 20-235 N and below ISO/TS 15066:2016 Table A.2's 140 N.
    - ``max_speed_m_s`` = 0.25 m/s: reduced speed of collaborative operation
      (ISO 10218-1:2011, clause 5.6).
    - ``grasp_stiffness_n_m`` = 2000 N/m, ``grasp_damping_n_s_m`` = 40 N s/m:
      an estimate within collaborative arms' Cartesian impedance ranges
      (``franka_ros``; KUKA Sunrise.OS manual); about critical for a 0.2 kg part.
    """

    max_force_n: float = 70.0
    max_speed_m_s: float = 0.25
    grasp_stiffness_n_m: float = 2000.0
    grasp_damping_n_s_m: float = 40.0

    def __post_init__(self) -> None:
        for f in fields(self):  # every limit positive, the damping possibly 0
            v, floor = getattr(self, f.name), ">=" if f.name == "grasp_damping_n_s_m" else ">"
            if not (np.isfinite(v) and (v >= 0 if floor == ">=" else v > 0)):
                raise ValueError(f"GripperLimits.{f.name} must be {floor} 0, got {v!r}")


class BoundedGrasp:
    """A grasp of ``link`` at ``point_link`` ((3,) m, link frame) by a floating
    gripper with ``limits`` (module docstring); the gripper point starts at the grasp point.

    Raises:
        KeyError: unknown link.
        ValueError: ``point_link`` is not 3 finite numbers.
    """

    def __init__(self, session, link: str, point_link: np.ndarray, limits: GripperLimits) -> None:
        p = np.asarray(point_link, float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"link {link!r}: grasp point must be 3 finite numbers (m), got {point_link!r}")
        if link not in session.link_names:
            raise KeyError(f"link {link!r} is not a link of the session")
        self.session, self.link, self.point_link, self.limits = session, link, p, limits
        dt = float(session.options.conventions.timestep)
        m_eff = max(float(session.link_masses().get(link, 0.0)) * EFFECTIVE_MASS_SHARE, 1e-4)
        #: spring constant used, N/m (the limits' value, capped for stable integration)
        self.stiffness = float(min(limits.grasp_stiffness_n_m, m_eff / dt**2))
        #: damping used, N s/m (capped likewise)
        self.damping = float(min(limits.grasp_damping_n_s_m, m_eff / dt))
        self._p_prev = self.grasp_point_world()
        #: world position (3,) m of the gripper point
        self.gripper_point = self._p_prev.copy()
        self._released = False
        #: largest |F| applied so far, N
        self.peak_force_n = 0.0

    def grasp_point_world(self) -> np.ndarray:
        """The grasp point moved with the link, world (3,) m."""
        o, R = self.session.link_frame(self.link)
        return np.asarray(o, float) + np.asarray(R, float) @ self.point_link

    def step_towards(self, target_world: np.ndarray, dt: float, direction: np.ndarray | None = None) -> np.ndarray:
        """Move the gripper point towards ``target_world`` (3,) m by at most
        ``max_speed_m_s * dt`` (``dt`` s until the next call) and apply the
        bounded force on the grasped link for the next engine step; returns it
        ((3,) N). ``direction`` (3,): push or pull along it only.

        Raises:
            RuntimeError: the grasp was released.
            ValueError: ``dt`` <= 0 or a non-finite target.
        """
        if self._released:
            raise RuntimeError(f"grasp of link {self.link!r} was released")
        if not dt > 0:
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        target = np.asarray(target_world, float).reshape(3)
        if not np.all(np.isfinite(target)):
            raise ValueError(f"gripper target must be finite, got {target_world!r}")
        lim = self.limits
        p = self.grasp_point_world()
        v_p = (p - self._p_prev) / dt
        self._p_prev = p
        g0 = self.gripper_point
        step = target - g0
        n = float(np.linalg.norm(step))
        vmax = lim.max_speed_m_s * dt
        if n > vmax:
            step *= vmax / n
        g = g0 + step
        d = None
        if direction is not None:
            d = np.asarray(direction, float).reshape(3)
            nd = float(np.linalg.norm(d))
            if not (np.isfinite(nd) and nd > 0):
                raise ValueError(f"push direction must be a non-zero finite vector, got {direction!r}")
            d = d / nd
            g = p + float((g - p) @ d) * d  # the finger slides with the part across d
        # Stall at the force limit: the spring cannot stretch beyond F_max / k.
        stretch = g - p
        s = float(np.linalg.norm(stretch))
        leash = lim.max_force_n / self.stiffness
        if s > leash:
            g = p + stretch * (leash / s)
        v_g = (g - g0) / dt
        self.gripper_point = g
        force = self.stiffness * (g - p) + self.damping * (v_g - v_p)
        if d is not None:
            force = float(force @ d) * d
        fn = float(np.linalg.norm(force))
        if fn > lim.max_force_n:
            force *= lim.max_force_n / fn
            fn = lim.max_force_n
        if np.all(np.isfinite(force)):
            self.session.apply_link_force(self.link, force, p)
        else:
            force = np.zeros(3)
            fn = 0.0
        self.peak_force_n = max(self.peak_force_n, fn)
        return force

    def release(self) -> None:
        """Open the fingers: no force from now on."""
        self._released = True
