"""The force plausibility check of task execution (``operating_force``): the task's peak force against the part's
real operating range (:mod:`asset2sim.tasks.interpret.operating_forces`, ``asset2sim/priors/operating_forces.yaml``).
"""

from __future__ import annotations

from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.task_execution import TaskRun
from asset2sim.tasks.interpret.operating_forces import load_operating_forces, operating_range


def _inside(v: float | None, r: tuple[float, float] | None) -> bool | None:
    if r is None or v is None:
        return None
    return bool(r[0] <= v <= r[1])


def force_metric(run: TaskRun, category: str | None, link_labels: dict[str, str | None]) -> MetricResult:
    """``operating_force``: the peak operating force (N) and torque (N m) of
    every attempt that moved a joint, against :func:`operating_range` of the
    category and the grasped child link's label (``link_labels``: link ->
    semantic label; a parent-side grasp takes the category's default). Value:
    the largest peak operating force; ``passed`` None when nothing moved.
    """
    t = load_operating_forces()
    rows = []
    bad = []
    for a in run.attempts:
        if not a.moved:
            continue
        label = link_labels.get(a.link) if a.side == "child" else None
        r, where = operating_range(category, label, t)
        f_ok = _inside(a.peak_operating_force_n, r.force_n)
        tau = a.peak_torque_nm
        t_ok = _inside(tau, r.torque_nm)
        ok = f_ok is not False and t_ok is not False
        rows.append({"joint": a.joint, "action": a.action, "peak_operating_force_n": a.peak_operating_force_n,
               "peak_gripper_force_n": a.peak_force_n, "peak_torque_nm": tau,
               "force_range_n": list(r.force_n) if r.force_n else None,
               "torque_range_nm": list(r.torque_nm) if r.torque_nm else None,
               "range_of": where, "sources": [t.sources[s] for s in r.sources], "estimate": r.estimate, "passed": ok})
        if not ok:
            what = []
            if f_ok is False:
                what.append(f"force {a.peak_operating_force_n:.1f} N outside {r.force_n[0]:g}-{r.force_n[1]:g} N")
            if t_ok is False:
                what.append(f"torque {tau:.2f} N m outside {r.torque_nm[0]:g}-{r.torque_nm[1]:g} N m")
            bad.append(f"{a.joint} {a.action}: {', '.join(what)} ({where})")
    return MetricResult(
        name="operating_force", value=max((r["peak_operating_force_n"] for r in rows), default=None), unit="N",
        passed=(not bad) if rows else None,
        threshold="the task's peak operating force (and torque about the axis) inside the real operating range of the "
                  "category and part (asset2sim/priors/operating_forces.yaml)",
        details={"attempts": rows, "failures": bad, "category": category}, engine=run.engine)
