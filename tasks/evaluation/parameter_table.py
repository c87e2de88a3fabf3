"""The physical parameters of an evaluated asset as a table: :func:`parameter_rows` (parameter, where, value,
unit, source) from ``overlay.json`` and ``report.json`` when present, else from the URDF and the engine defaults;
:func:`parameter_table` its HTML.
"""

from __future__ import annotations

from typing import Any

from asset2sim.tasks.check.plausibility import joint_unit
from asset2sim.tasks.evaluation.html_blocks import fmt, table
from asset2sim.tasks.evaluation.report_changes import esc, escalated


def parameter_rows(ev) -> list[dict[str, Any]]:
    """Every physical parameter of the evaluated asset as {parameter, where, value, unit, source}: from ``overlay.json``
    (and ``report.json``) when present, else from the URDF and the engine defaults."""
    ctx = ev._context
    rows: list[dict[str, Any]] = []

    def add(parameter: str, where: str, value: Any, unit: str, source: str) -> None:
        """One row."""
        rows.append({"parameter": parameter, "where": where, "value": value, "unit": unit, "source": source})

    add("scale", "global", ev.scale, "-", ev.scale_source)
    # step 1: the joint parameters each check round changed
    ov, rep = ctx.overlay, ctx.report
    joints = {j.name: j for j in ctx.model.joints}
    types = {j.name: j.type for j in ctx.model.joints}
    escal = escalated(rep)
    # step 2: masses, inertias and joint dynamics from the overlay (the URDF's value where escalation changed it)
    est = ((ov or {}).get("estimator") or {}).get("name")
    by_estimator = f"estimator {est}" if est else "overlay"
    if ov:
        for ln, lp in (ov.get("links") or {}).items():
            src, where = lp.get("source") or by_estimator, f"link {ln}"
            add("mass", where, lp.get("mass"), "kg", src)
            if lp.get("density") is not None:
                add("density", where, lp["density"], "kg/m^3", src)
            inertia = lp.get("inertia") or {}
            add("inertia (ixx, iyy, izz)", where, ", ".join(fmt(inertia.get(k)) for k in ("ixx", "iyy", "izz")), "kg*m^2", src)
            add("center of mass", where, ", ".join(fmt(c) for c in lp.get("com", [])), "m", src)
            if lp.get("material"):
                add("material", where, lp["material"], "-", src)
        for jn, jd in (ov.get("joints") or {}).items():
            for k in ("damping", "friction", "stiffness"):
                src = jd.get("source") or by_estimator
                if (jn, k) in escal:
                    src = (f"changed after check round {escal[(jn, k)].get('round', 0)} (the checks failed; "
                           "see What asset2sim changed)")
                val = jd.get(k)
                # the URDF written after escalation is what is simulated
                if k in ("damping", "friction") and jn in joints:
                    fv = getattr(joints[jn], k)
                    if val is not None and abs(fv - val) > 1e-12:
                        val, src = fv, src + " (URDF value differs from overlay; URDF shown)"
                add(k, f"joint {jn}", val, joint_unit(types.get(jn, "revolute"), k), src)
    # step 3: without an overlay, the URDF's values and the engine defaults
    else:
        for ln, li in ctx.model.links.items():
            declared = li.inertial is not None and li.inertial.mass is not None
            if declared or li.collisions or li.visuals:
                add("mass", f"link {ln}", li.inertial.mass if declared else 1.0, "kg",
                    "URDF <inertial>" if declared else "engine default (1 kg, inertia diag(1,1,1) kg*m^2)")
        for jd in ctx.model.movable_joints:
            for k in ("damping", "friction"):
                v = getattr(jd.dynamics, k, None)
                add(k, f"joint {jd.name}", 0.0 if v is None else v, joint_unit(jd.type, k),
                    "URDF <dynamics>" if v is not None else "engine default (0)")
            add("stiffness", f"joint {jd.name}", 0.0, joint_unit(jd.type, "stiffness"), "none (URDF has no springs)")
    # step 4: the initial joint positions and the limits
    state_src = ev.initial_state_source
    if rep and rep.get("state"):
        state_src = f"refinement ({rep['state'].get('method', '')})"
    elif ov and ov.get("initial_joint_positions"):
        state_src = by_estimator
    elif ctx.baseline and ctx.baseline.get("initial_state_rule"):
        state_src = f"baseline rule: {ctx.baseline['initial_state_rule']}"
    for jn, q in ev.initial_state.items():
        add("initial position", f"joint {jn}", q, joint_unit(types.get(jn, "revolute"), "position"), state_src)
    for jd in ctx.model.joints:
        if jd.type in ("revolute", "prismatic"):
            clipped = ((ov or {}).get("joints") or {}).get(jd.name, {}).get("limit_source") or ""
            add("limits", f"joint {jd.name}", f"[{fmt(jd.lower)}, {fmt(jd.upper)}]", joint_unit(jd.type, "position"),
                f"refine: {clipped}" if clipped else "the input's URDF <limit>")
    return rows


def parameter_table(ev) -> str:
    return table(("where", "parameter", "value", "unit", "source"), (
        f"<tr><td>{esc(r['where'])}</td><td>{esc(r['parameter'])}</td><td class='num'>{fmt(r['value'])}</td>"
        f"<td>{esc(r['unit'])}</td><td class='small'>{esc(r['source'])}</td></tr>" for r in parameter_rows(ev)))
