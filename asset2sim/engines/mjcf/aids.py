"""Solver aids: the solver parameters the MJCF writes beyond the URDF's physics, each on the joint or geom whose
pre-flight criterion asks for it, named with the criterion's value (``docs/design/simulators.md``, "Solver aids").

The criteria predict from MuJoCo's soft-constraint model (MuJoCo documentation, "Computation: soft constraints": a
constraint of impedance d, time constant tc and damping ratio z solves a1 = d aref + (1 - d) a0, aref = -b v - k r,
b = 2 / (dmax tc), k = 1 / (dmax^2 tc^2 z^2)); a joint's effective inertia I is 1 / ``dof_invweight0``:

- **friction solver** (``solreffriction``, ``solimpfriction``): a joint held by its dry friction creeps under a load
  tau below it at v = (1 - d) / d * dmax tc / 2 * tau / I. Where MuJoCo's defaults let it move more than 1 degree
  (2 mm) in 10 s under its load at the initial state (gravity and spring), or faster than the breakaway's start speed
  under 0.8 of its friction (the 20 % band), the stiffest the solver allows is written: impedance 0.9999
  (``mjMAXIMP``), time constant two steps (the least ``refsafe`` keeps). No effect on a part moving above its friction.
- **armature**: only on a joint given the stiff friction above whose effective inertia is below sqrt(float32 eps) of
  the model's mean inertia. A float32 solver (MJX) leaves accelerations accurate to about sqrt(eps) of the model's
  scale, and the stiff friction multiplies that error by d / (1 - d) (1e4) on the dof it holds: a toilet's 7 g flush
  lever crept 0.047 rad in 3 s in MJX float32. The inertia lifts it to the floor; the part's natural frequency and
  damping ratio both scale by sqrt(I / (I + armature)), stated beside it.
- **limit solver** (``solreflimit``, ``solimplimit``): a part a hand presses into its limit with the hand's most
  effort tau (``SessionOptions.press_efforts``, from the part's operating range) rests r = (1 - d) / d dmax^2 tc^2 z^2
  tau / I past it. Where MuJoCo's defaults give more than 1 degree (2 mm), the limit is written at two time steps and
  the least impedance from 0.99 to 0.9999 that keeps it within half of that. A stop that gives way by degrees lets the part's hulls sink into the body they close on, and the
  contacts then throw a free object (a stapler pressed at 20 N: QACC NaN in MuJoCo).
- **collision prism**: a collision cylinder, which MJX collides with neither a box nor a mesh, written as the convex
  prism that holds it (:func:`asset2sim.engines.mjcf.rewrite.cylinder_prisms`).
- **ground contact impedance**: the ground plane of a free-standing object at impedance 0.7 (MuJoCo's default 0.9)
  with the mixing weight that makes it the ground contacts' own: MJX float32 rocked a 16.5 kg fridge 1.3 mm on its
  feet at 0.9 (rest allows 1 mm), 0.8 to 0.5 held it within 0.03 mm. The object's own contacts (the stops a hand
  presses against) keep MuJoCo's defaults.

Each aid is written into the MJCF as ``<custom><text name="asset2sim_solver_aids" data="[...JSON...]">`` (MuJoCo keeps
it in ``MjModel.text_data``), in the file's header notes and, through the export, in ``report.json``.
"""

from __future__ import annotations

import json
import math

import numpy as np
from lxml import etree

from asset2sim.engines.mjcf.base import ARMATURE_FLOOR, FRICTION_SOLIMP, child, friction_solref, load_mujoco, num_text, vec_text
from asset2sim.schemas.report import SolverAid

#: MuJoCo's default ``solref`` and ``solimp`` of every constraint (MuJoCo XML reference, ``option``/``geom``).
DEFAULT_SOLREF = (0.02, 1.0)
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
#: The joint limit's aid: the time constant at two steps (:func:`friction_solref`) and the least impedance in this
#: range whose rest overrun under the press is at most :data:`LIMIT_MARGIN` of the bound (MuJoCo's largest, mjMAXIMP,
#: where none is).
LIMIT_IMPEDANCE = (0.99, 0.9999)
LIMIT_MARGIN = 0.5
#: How far a held part may move in :data:`CREEP_TIME`, or past a stop (rad for a hinge, m for a slide).
BOUND = {"hinge": math.radians(1.0), "slide": 2e-3}
CREEP_TIME = 10.0
#: The breakaway's start speed (rad/s, m/s; ``asset2sim.tasks.check.breakaway.START_SPEED``) and the push (share of
#: the friction) below which a joint must not reach it: the lower end of the 20 % band.
START_SPEED = {"hinge": 5e-3, "slide": 1e-4}
START_PUSH = 0.8
#: The ground's contact impedance for a free-standing object, and its mixing weight against the object's geoms.
GROUND_SOLIMP = (0.7, 0.95, 0.001, 0.5, 2.0)
GROUND_SOLMIX = 1e6
#: The name of the MJCF's custom text that lists the aids.
AIDS_TEXT = "asset2sim_solver_aids"


def creep_speed(solref, solimp, tau: float, inertia: float) -> float:
    """Speed (rad/s or m/s) at which a joint of effective inertia ``inertia`` (kg*m^2 or kg) held by dry friction of
    ``solref``/``solimp`` creeps under a load ``tau`` (N*m or N) below the friction (module docstring)."""
    d0, dmax, tc = float(solimp[0]), float(solimp[1]), float(solref[0])
    return (1.0 - d0) / d0 * dmax * tc / 2.0 * abs(tau) / inertia


def limit_overrun(solref, solimp, tau: float, inertia: float) -> float:
    """Rest overrun (rad or m) of a joint of effective inertia ``inertia`` pressed into a limit of ``solref``/``solimp``
    by ``tau`` (N*m or N), beyond the impedance's width (module docstring)."""
    d, tc, z = float(solimp[1]), float(solref[0]), float(solref[1])
    return (1.0 - d) / d * d * d * tc * tc * z * z * abs(tau) / inertia


def add_solver_aids(worldbody, compiled, qpos: np.ndarray, press: dict[str, float], timestep: float) -> list[SolverAid]:
    """The joint aids of the module docstring written on ``worldbody``'s joints, judged on ``compiled`` (the model
    without them) at ``qpos`` (nq,) the initial state; ``press`` joint -> the hand's most effort (N*m or N)."""
    mujoco = load_mujoco()
    data = mujoco.MjData(compiled)
    data.qpos[:] = qpos
    mujoco.mj_forward(compiled, data)
    load = data.qfrc_spring - data.qfrc_bias  # the generalised force of gravity and the springs at rest
    stiff_ref = friction_solref(timestep)
    aids: list[SolverAid] = []
    for je in worldbody.iter("joint"):
        name = je.get("name") or ""
        jid = mujoco.mj_name2id(compiled, mujoco.mjtObj.mjOBJ_JOINT, name)
        kind = {int(mujoco.mjtJoint.mjJNT_HINGE): "hinge", int(mujoco.mjtJoint.mjJNT_SLIDE): "slide"}.get(int(compiled.jnt_type[jid])) if jid >= 0 else None
        dof = int(compiled.jnt_dofadr[jid]) if kind else -1
        if kind is None or not compiled.dof_invweight0[dof] > 0:
            continue
        inertia, bound, unit = 1.0 / float(compiled.dof_invweight0[dof]), BOUND[kind], "deg" if kind == "hinge" else "mm"
        force = "N*m" if kind == "hinge" else "N"
        show = math.degrees if kind == "hinge" else (lambda x: 1e3 * x)
        friction, arm = float(compiled.dof_frictionloss[dof]), 0.0
        if friction > 0:
            tau = min(abs(float(load[dof])), friction)
            creep = creep_speed(DEFAULT_SOLREF, DEFAULT_SOLIMP, tau, inertia) * CREEP_TIME
            early = creep_speed(DEFAULT_SOLREF, DEFAULT_SOLIMP, START_PUSH * friction, inertia)
            measure = max(creep / bound, early / START_SPEED[kind])
            if measure > 1.0:
                written = {"solreffriction": vec_text(stiff_ref), "solimpfriction": vec_text(FRICTION_SOLIMP)}
                je.attrib.update(written)
                after = creep_speed(stiff_ref, FRICTION_SOLIMP, tau, inertia) * CREEP_TIME
                aids.append(SolverAid(kind="friction_solver", element=name, written=written, measure=measure, criterion=(
                    f"at MuJoCo's defaults it creeps {show(creep):.3g} {unit} in {CREEP_TIME:g} s under its load "
                    f"{tau:.3g} {force} at the initial state ({show(bound):g} {unit} allowed) and at {early:.3g}/s under "
                    f"{START_PUSH:g} of its friction (the breakaway starts at {START_SPEED[kind]:g}/s)"),
                    effect=f"creeps {show(after):.3g} {unit} in {CREEP_TIME:g} s; no effect above its friction"))
                floor = ARMATURE_FLOOR * float(compiled.stat.meaninertia)
                if inertia < floor:
                    arm = floor - inertia
                    je.set("armature", num_text(arm))
                    aids.append(SolverAid(kind="armature", element=name, written={"armature": num_text(arm)}, measure=floor / inertia,
                                          criterion=(f"held by the stiff friction with an effective inertia {inertia:.3g}, below "
                                                     f"sqrt(float32 eps) x the model's mean inertia ({floor:.3g}), where MJX in "
                                                     "float32 ratchets it along its load"),
                                          effect=f"natural frequency and damping ratio x{math.sqrt(inertia / floor):.2f}"))
        effort = press.get(name)
        if effort and compiled.jnt_limited[jid]:
            over = limit_overrun(DEFAULT_SOLREF, DEFAULT_SOLIMP, effort, inertia + arm)
            if over > bound:
                # (1 - d) d tc^2 tau / I = LIMIT_MARGIN bound, d near 1
                d = float(np.clip(1.0 - LIMIT_MARGIN * bound * (inertia + arm) / (stiff_ref[0] ** 2 * effort), *LIMIT_IMPEDANCE))
                solimp = (d, d, 0.001, 0.5, 2.0)
                written = {"solreflimit": vec_text(stiff_ref), "solimplimit": vec_text(solimp)}
                je.attrib.update(written)
                after = limit_overrun(stiff_ref, solimp, effort, inertia + arm)
                aids.append(SolverAid(kind="limit_solver", element=name, written=written, measure=over / bound, criterion=(
                    f"at MuJoCo's defaults a hand's press of {effort:.3g} {force} (the top of its operating range) rests "
                    f"{show(over):.3g} {unit} past its limit ({show(bound):g} {unit} allowed)"),
                    effect=f"rests {show(after):.3g} {unit} past it; no effect inside its range"))
    return aids


def ground_aid(ground) -> SolverAid:
    """The ground plane's contact impedance for a free-standing object (module docstring), written on ``ground``."""
    written = {"solimp": vec_text(GROUND_SOLIMP), "solmix": num_text(GROUND_SOLMIX)}
    ground.attrib.update(written)
    return SolverAid(kind="ground_contact_impedance", element=ground.get("name") or "", written=written, measure=1.3,
                     criterion="a free-standing object on the ground: MJX float32 rocked a 16.5 kg fridge 1.3 mm on its "
                               "feet at MuJoCo's default impedance 0.9 (1 mm allowed at rest)",
                     effect="a resting contact sinks 0.035 mm instead of 0.008 mm; the object's own contacts unchanged")


def prism_aid(geom: str) -> SolverAid:
    """A collision cylinder written as a prism (:func:`asset2sim.engines.mjcf.rewrite.cylinder_prisms`)."""
    return SolverAid(kind="collision_prism", element=geom, written={"type": "mesh"}, measure=1.0,
                     criterion="a collision cylinder: MJX collides a cylinder with neither a box nor a mesh",
                     effect="the prism holds the cylinder; its edges stand 1.2 % of the radius outside")


def write_aids(root, aids: list[SolverAid]) -> None:
    """``aids`` as the MJCF's custom text :data:`AIDS_TEXT` (none: nothing written)."""
    if aids:
        etree.SubElement(child(root, "custom"), "text", name=AIDS_TEXT, data=json.dumps([a.model_dump() for a in aids]))


def read_aids(model) -> list[SolverAid]:
    """The aids a compiled ``MjModel`` carries in its custom text :data:`AIDS_TEXT` ([] when none)."""
    mujoco = load_mujoco()
    tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXT, AIDS_TEXT)
    if tid < 0:
        return []
    adr, size = int(model.text_adr[tid]), int(model.text_size[tid])
    raw = bytes(model.text_data[adr:adr + size]).split(b"\0", 1)[0].decode()
    return [SolverAid.model_validate(a) for a in json.loads(raw)]
