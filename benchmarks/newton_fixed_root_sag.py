"""Newton alone (SolverKamino, CPU): a horizontal slide held by Coulomb joint
friction, on a body welded to the world through a light root link, under
gravity. Does the slide stay put?

    python benchmarks/newton_fixed_root_sag.py [--seconds 1.25] [--base-mass 0.025]

The assembly is the shape of a refined under-counter dishwasher (12085): the
world holds a placeholder root link (``--base-mass`` kg, the URDF's grams, its
inertia a 1 cm cube's scaled to that mass) by a fixed joint; the tub (12 kg)
hangs on that link by a second fixed joint; the rack (12.6 kg, pulled 0.2 m out, its
centre of mass 0.1 m further out along the slide and 0.1 m below it) slides along the world's x axis
with 0.25 N of joint friction and no gravity load along the axis. Every
variant is stepped at 1/240 s with Kamino's defaults and prints the rack's
travel and the tub's tilt:

- ``as built``: every link a body, the two welds Kamino's bilateral rows;
- ``root 1 kg``: the same with a 1 kg root link;
- ``tub on the world``: no root link, the tub fixed to the world directly;
- ``collapsed``: ``ModelBuilder.collapse_fixed_joints()`` (root and tub merged
  into the world, the rack's slide on the world).

A reduced-coordinate engine (PyBullet, PhysX articulations, MuJoCo) holds a
fixed base exactly, so no force acts along the slide and 0.25 N holds the rack.
Measured (newton 1.8.0, warp 1.19.0, 1.25 s): as built, rack travel -121 mm,
tub tilt 1.8 deg; root 1 kg, -301 mm (onto the limit), 15 deg; tub on the
world, 0 mm; collapsed, 0 mm. The two welds in a chain are what Kamino does
not hold rigid, whatever the root link weighs; asset2sim's Newton session
therefore welds a fixed root, and the links fixed to it, to the world.
Nothing outside newton and warp is imported.
"""

from __future__ import annotations

import argparse
import math

import numpy as np


def build(newton, wp, base_mass: float | None, collapse: bool):
    """The model (finalized on the CPU), the tub's body index (-1: welded or absent) and the rack's DOF."""
    b = newton.ModelBuilder(gravity=(0.0, 0.0, -9.81))
    cfg = newton.ModelBuilder.ShapeConfig(density=0.0)
    joints = []
    parent = -1
    if base_mass is not None:
        i = base_mass * (0.01 ** 2) / 6.0  # a 1 cm cube of that mass
        base = b.add_link(mass=base_mass, inertia=wp.mat33(i, 0, 0, 0, i, 0, 0, 0, i), label="base")
        joints.append(b.add_joint_fixed(-1, base, label="root"))
        parent = base
    tub = b.add_link(mass=12.0, inertia=wp.mat33(0.58, 0, 0, 0, 0.58, 0, 0, 0, 0.80), com=wp.vec3(0.0, -0.03, -0.19), label="tub")
    b.add_shape_box(tub, hx=0.25, hy=0.25, hz=0.02, xform=wp.transform(wp.vec3(0.0, 0.0, -0.4), wp.quat_identity()), cfg=cfg)
    joints.append(b.add_joint_fixed(parent, tub, label="tub_weld"))
    rack = b.add_link(mass=12.6, inertia=wp.mat33(0.44, 0, 0, 0, 0.52, 0, 0, 0, 0.62), com=wp.vec3(-0.10, 0.07, -0.10), label="rack")
    b.add_shape_box(rack, hx=0.2, hy=0.2, hz=0.02, cfg=cfg)
    joints.append(b.add_joint_prismatic(tub, rack, axis=wp.vec3(1.0, 0.0, 0.0), friction=0.25, limit_lower=-0.3, limit_upper=0.3,
                                        parent_xform=wp.transform(wp.vec3(-0.2, 0.0, 0.3), wp.quat_identity()), label="slide"))
    b.add_articulation(joints)
    if collapse:
        b.collapse_fixed_joints()
    model = b.finalize(device="cpu")
    labels = list(b.body_label)
    return model, (labels.index("tub") if "tub" in labels else -1), int(model.joint_qd_start.numpy()[list(b.joint_label).index("slide")])


def run(newton, wp, base_mass: float | None, collapse: bool, seconds: float) -> tuple[float, float]:
    """(rack travel m, tub tilt deg) after ``seconds`` at 1/240 s."""
    model, tub, dof = build(newton, wp, base_mass, collapse)
    s0, s1, control = model.state(), model.state(), model.control()
    newton.eval_fk(model, model.joint_q, model.joint_qd, s0)
    pipeline = newton.CollisionPipeline(model)
    contacts = pipeline.contacts()
    solver = newton.solvers.SolverKamino(model)
    q0 = float(s0.joint_q.numpy()[dof])
    quat0 = s0.body_q.numpy()[tub][3:7].copy() if tub >= 0 else None
    for _ in range(int(round(seconds * 240))):
        s0.clear_forces()
        pipeline.collide(s0, contacts)
        solver.step(s0, s1, control, contacts, 1.0 / 240.0)
        s0, s1 = s1, s0
    travel = float(s0.joint_q.numpy()[dof]) - q0
    tilt = 0.0
    if tub >= 0:
        d = abs(float(np.dot(quat0, s0.body_q.numpy()[tub][3:7])))
        tilt = math.degrees(2.0 * math.acos(min(1.0, d)))
    return travel, tilt


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=1.25)
    ap.add_argument("--base-mass", type=float, default=0.025)
    args = ap.parse_args()
    import warp as wp

    wp.config.quiet = True
    import newton

    print(f"newton {newton.__version__}, warp {wp.__version__}; {args.seconds:g} s at 1/240 s; slide friction 0.25 N, "
          f"rack 12.6 kg (weight {12.6 * 9.81:.0f} N across the slide)")
    for label, base, collapse in (("as built", args.base_mass, False), ("root 1 kg", 1.0, False),
                                  ("tub on the world", None, False), ("collapsed", args.base_mass, True)):
        travel, tilt = run(newton, wp, base, collapse, args.seconds)
        print(f"{label:<18} rack travel {travel * 1000:+8.3f} mm   tub tilt {tilt:.4f} deg")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
