"""The report's account of what asset2sim changed: the input and the output side by side, and every
change (scale, masses, joint limits, the joint state, joint dynamics, collision pieces, the root) with
its reason, read from the output's ``report.json`` and ``overlay.json``. Joint states are shown from the
closed end, in degrees or millimetres, and as the percentage open (the opening fraction); limits in the
joint's own coordinate (radians with degrees, or millimetres).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable

import numpy as np

from asset2sim.tasks.check.as_asked import quantity_text
from asset2sim.tasks.check.asset_files import find_urdf, parse_urdf
from asset2sim.tasks.geometry.render import render_views
from asset2sim.engines.source import UrdfFile
from asset2sim.inert import html_text

#: Views shown for the input and the output, side by side.
COMPARED_VIEWS = ("perspective", "front")


def esc(x: Any) -> str:
    """HTML-escaped text of ``x`` (empty for None): :func:`asset2sim.inert.html_text`, the one escaping of user-derived
    text in HTML (quotes and control characters included)."""
    return "" if x is None else html_text(x)


def position_text(q: float | None, jtype: str) -> str:
    """A joint position for people: ``"0.309 rad (17.7 deg)"`` (revolute, continuous) or
    ``"12.5 mm"`` (prismatic); ``"-"`` for None. ``q`` in rad or m."""
    if q is None or not math.isfinite(float(q)):
        return "-"
    if jtype == "prismatic":
        return f"{float(q) * 1000.0:.4g} mm"
    return f"{float(q):.4g} rad ({math.degrees(float(q)):.1f} deg)"


def from_closed_text(q: float | None, q_closed: float | None, jtype: str) -> str:
    """How far a joint stands from its closed end, for people: ``"20.8 deg from closed"`` (revolute,
    continuous) or ``"12.5 mm from closed"`` (prismatic), |q - q_closed| with ``q`` and ``q_closed`` in rad or m;
    :func:`position_text` of ``q`` (the joint's own coordinate, labelled so) when the closed end is unknown."""
    if q is None or not math.isfinite(float(q)):
        return "-"
    if q_closed is None or not math.isfinite(float(q_closed)):
        return f"joint position {position_text(q, jtype)}"
    d = abs(float(q) - float(q_closed))
    if jtype == "prismatic":
        return f"{d * 1000.0:.4g} mm from closed"
    return f"{math.degrees(d):.1f} deg from closed"


def opening_text(fraction: float | None) -> str:
    """An opening fraction (0 closed .. 1 fully open) as ``"11 % open"``; empty for None."""
    return "" if fraction is None else f"{100.0 * float(fraction):.0f} % open"


def _limits_text(lo: float | None, hi: float | None, jtype: str) -> str:
    return f"[{position_text(lo, jtype)}, {position_text(hi, jtype)}]"


def _row(what: str, before: str, after: str, why: str) -> str:
    return (f"<tr><td>{esc(what)}</td><td>{esc(before)}</td><td>{esc(after)}</td>"
            f"<td class='small'>{esc(why)}</td></tr>")


def _input_joints(report: dict[str, Any]) -> dict[str, Any]:
    """The input URDF's joints (``asset_files.JointInfo`` by name); {} when the input cannot be read."""
    try:
        return parse_urdf(UrdfFile(find_urdf(Path(report["source"]))))[1]
    except Exception:
        return {}


def change_rows(report: dict[str, Any], overlay: dict[str, Any] | None, joint_types: dict[str, str]) -> list[str]:
    """The table rows (HTML) of every change refine made, each with its reason: scale, total mass, joint
    limits clipped to the geometry, the joint state, damping and friction raised or lowered by the checks,
    collision pieces, stability by design and the root's mounting."""
    ov = overlay or {}
    notes = ov.get("notes") or {}
    rows = [_row("scale", "1 (the input's units)", f"{float(report.get('scale', 1.0)):.4g}", notes.get("size", ""))]
    rows.append(_row("total mass", "none given (or not plausible)", f"{float(report.get('total_mass', 0.0)):.4g} kg",
                     "; ".join(x for x in (notes.get("mass_arithmetic"), notes.get("material")) if x)))
    before = _input_joints(report)
    for name, jd in (ov.get("joints") or {}).items():
        src = str(jd.get("limit_source") or "")
        if src.startswith("clipped"):
            jt = joint_types.get(name, "revolute")
            old = before.get(name)
            k = float(report.get("scale", 1.0)) if jt == "prismatic" else 1.0  # the input's lengths at the output's scale
            lo, hi = (None, None) if old is None else (old.lower, old.upper)
            lo, hi = (None if x is None else float(x) * k for x in (lo, hi))
            new_lo, new_hi = (lo if jd.get("lower") is None else jd["lower"]), (hi if jd.get("upper") is None else jd["upper"])
            rows.append(_row(f"{name} limits", _limits_text(lo, hi, jt) if old else "as the input declares",
                             _limits_text(new_lo, new_hi, jt), src.split(": ", 1)[-1]))
    fractions = report.get("opening_fractions") or {}
    bands = report.get("requested_bands") or {}
    state = report.get("state") or {}
    closed = report.get("closed_positions") or {}
    for name, q in (report.get("initial_joint_positions") or {}).items():
        jt = joint_types.get(name, "revolute")
        moved = abs(float((state.get("requested") or {}).get(name, q)) - float(q)) > 1e-9
        asked = next((q for q in ((report.get("request") or {}).get("quantities") or []) if str(q.get("what", "")).startswith(f"{name} ")), None)
        why = (f"the request: '{asked.get('phrase')}'" if asked else
               f"the request: {bands[name].replace('_', ' ')}" if name in bands else "not asked: closed")
        if moved:
            why += f"; moved by the state search to remove self-penetration ({state.get('method', '')})"
        rows.append(_row(f"{name} initial position", "as modelled (0)",
                         f"{from_closed_text(q, closed.get(name), jt)}, {opening_text(fractions.get(name))}".rstrip(", "), why))
    changed: dict[tuple[str, str], tuple[float, str]] = {}
    for rnd in report.get("escalation") or []:
        for joint, ch in (rnd.get("changes") or {}).items():
            for k, v in ch.items():
                changed[(joint, k)] = (v, f"after check round {rnd.get('round')}: {rnd.get('reason', '')}")
    for (joint, k), (v, why) in changed.items():
        rows.append(_row(f"{joint} {k}", "estimated", f"{float(v):.4g}", why))
    for line in (state.get("collision_changes") or []):
        rows.append(_row("collision pieces", "", "", line))
    for line in report.get("design_changes") or []:
        rows.append(_row("stability by design", "", "", line))
    mount = report.get("mounting") or {}
    if mount:
        rows.append(_row("root", "", f"{mount.get('kind', '')}{' (fixed)' if mount.get('fixed') else ''}", mount.get("source", "")))
    return rows


def before_after(report: dict[str, Any], after: dict[str, np.ndarray] | None, img: Callable[[np.ndarray, str], str]) -> str:
    """The input as modelled (every joint at 0, its own scale) beside the output at its initial state,
    :data:`COMPARED_VIEWS` each; ``after``: the output's renders (view -> (H, W, 3) uint8); ``img``: an
    (image, caption) -> HTML function. A note when the input cannot be drawn."""
    figs = []
    size = next(((a.shape[1], a.shape[0]) for a in (after or {}).values()), (256, 256))
    try:
        src = render_views(find_urdf(Path(report["source"])), {}, views=COMPARED_VIEWS, size=size)
        figs += [img(src[v], f"input, {v}") for v in COMPARED_VIEWS]
    except Exception as exc:
        figs.append(f"<p class='small'>the input could not be drawn ({esc(type(exc).__name__)}: {esc(exc)})</p>")
    figs += [img(after[v], f"output, {v}") for v in COMPARED_VIEWS if after and v in after]
    return "<div class='views'>" + "".join(figs) + "</div>"


def changes_section(report: dict[str, Any] | None, overlay: dict[str, Any] | None, joint_types: dict[str, str],
                    after: dict[str, np.ndarray] | None, img: Callable[[np.ndarray, str], str]) -> str:
    """The report's "What asset2sim changed" section (HTML); empty without a ``report.json``."""
    if not report:
        return ""
    table = ("<table><tr><th>what</th><th>input</th><th>output</th><th>why</th></tr>"
             + "".join(change_rows(report, overlay, joint_types)) + "</table>")
    return "<h2>What asset2sim changed</h2>" + before_after(report, after, img) + table + understood(report.get("request"))


def understood(found: dict[str, Any] | None) -> str:
    """The request as refine understood it (``report.json``'s ``request``): what it asked, each phrase with what it set
    (states, and words about motion with the damping, friction and stiffness they left), each number asked against
    what the output has, the words no rule used; empty without findings."""
    if not found:
        return ""
    rows = [_row("asked", "", a, "") for a in found.get("asked") or []]
    rows += [_row("phrase", "", p, "") for p in found.get("phrases") or []]  # each state and each word about motion, as applied
    for q in found.get("quantities") or []:
        unit = q.get("unit", "")
        frame = " from the closed end" if q.get("kind") == "state" and unit in ("rad", "m") else ""
        got = "-" if q.get("achieved") is None else quantity_text(q["achieved"], unit) + frame
        asked = "-" if q.get("asked") is None else quantity_text(q["asked"], unit) + frame
        rows.append(_row(f"{q.get('what')} ('{q.get('phrase', '')}')", asked, got,
                         ("within tolerance" if q.get("within_tolerance") else "MISSED") + (f": {q['why']}" if q.get("why") else "")))
    if found.get("ignored"):
        rows.append(_row("words not used", "", "", "; ".join(found["ignored"])))
    if not rows:
        return ""
    return ("<h3>The request as understood</h3><table><tr><th>what</th><th>asked</th><th>output</th><th>note</th></tr>"
            + "".join(rows) + "</table>")
