"""The report's account of what asset2sim changed: the input and the output side by side, and every
change (scale, masses, joint limits, the joint state, joint dynamics, collision pieces, the root) with
its reason, read from the output's ``report.json`` and ``overlay.json``. Joint states are shown from the
closed end, in degrees or millimetres, and as the percentage open (the opening fraction); limits in the
joint's own coordinate (radians with degrees, or millimetres).
"""

from __future__ import annotations

import math
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from asset2sim.tasks.check.as_asked import quantity_text
from asset2sim.tasks.ingest.partnet_mobility import find_urdf
from asset2sim.tasks.geometry.render import render_views
from asset2sim.tasks.ingest import declared as declared_mod
from asset2sim.tasks.synthesize.request_findings import DYNAMICS_UNITS
from asset2sim.formats import staging
from asset2sim.inert import html_text, one_line
from asset2sim.tasks.evaluation.html_blocks import figure, table

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
    return f"{float(q) * 1000.0:.4g} mm" if jtype == "prismatic" else f"{float(q):.4g} rad ({math.degrees(float(q)):.1f} deg)"


def from_closed_text(q: float | None, q_closed: float | None, jtype: str) -> str:
    """How far a joint stands from its closed end, for people: ``"20.8 deg from closed"`` (revolute,
    continuous) or ``"12.5 mm from closed"`` (prismatic), |q - q_closed| with ``q`` and ``q_closed`` in rad or m;
    :func:`position_text` of ``q`` (the joint's own coordinate, labelled so) when the closed end is unknown."""
    if q is None or not math.isfinite(float(q)):
        return "-"
    if q_closed is None or not math.isfinite(float(q_closed)):
        return f"joint position {position_text(q, jtype)}"
    d = abs(float(q) - float(q_closed))
    return f"{d * 1000.0:.4g} mm from closed" if jtype == "prismatic" else f"{math.degrees(d):.1f} deg from closed"


def opening_text(fraction: float | None) -> str:
    """An opening fraction (0 closed .. 1 fully open) as ``"11 % open"``; empty for None."""
    return "" if fraction is None else f"{100.0 * float(fraction):.0f} % open"


def _limits_text(lo: float | None, hi: float | None, jtype: str) -> str:
    return f"[{position_text(lo, jtype)}, {position_text(hi, jtype)}]"


def _row(what: str, before: str, after: str, why: str) -> str:
    return (f"<tr><td>{esc(what)}</td><td>{esc(before)}</td><td>{esc(after)}</td>"
            f"<td class='small'>{esc(why)}</td></tr>")


@dataclass
class InputSide:
    """The input as its own file declares it, for the input column and picture of "What asset2sim changed":
    ``name`` the file the user gave (its name), ``format`` ``urdf`` / ``mjcf`` / ``usd``; ``physics`` what it
    declares (:func:`asset2sim.tasks.ingest.declared.read_declared`; None when it cannot be read, ``error`` then says
    why in one line); ``urdf`` a URDF of it to draw (the input's own, or the MJCF or USD file staged as one in
    ``_tmp``, removed by :meth:`close`)."""

    name: str
    format: str = "urdf"
    physics: declared_mod.DeclaredPhysics | None = None
    urdf: Path | None = None
    error: str = ""
    _tmp: tempfile.TemporaryDirectory | None = field(default=None, repr=False)

    def close(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None


def read_input(source: Path | str | None) -> InputSide:
    """The input at ``source`` (``report.json``'s ``source``: a URDF folder or file, an MJCF or USD file) read as its
    file declares it and made drawable; never raises: what cannot be read is said in ``error``."""
    if not source:
        return InputSide(name="the input", error="report.json names no input")
    path = Path(source)
    if not path.exists():
        return InputSide(name=path.name, error=f"{path.name} is no longer where it was read from")
    side = InputSide(name=path.name)
    try:
        other = staging.other_format_file(path)
        if other is not None:
            side.format = other[1]
            side.physics = declared_mod.read_declared(other[0])
            side._tmp = tempfile.TemporaryDirectory(prefix="asset2sim-input-")
            side.urdf = staging.stage(side.physics.read, side._tmp.name).urdf_path
        else:
            side.urdf = find_urdf(path)
            side.physics = declared_mod.read_declared(path, side.urdf)
    except Exception as exc:  # the table says what could not be read; the output side stands alone
        side.error = f"{path.name} could not be read ({type(exc).__name__}: {one_line(exc).replace(str(path), path.name)})"
    return side


def _declared_mass(side: InputSide) -> str:
    """The input's total mass as its file declares it: ``10.39 kg (as declared: frame 7.854, door 2.435, latch 0.1 kg)``,
    the mass the simulator would infer from geoms, or ``none declared``."""
    dp = side.physics
    if dp is None:
        return side.error or "-"
    declared, inferred = ({n: ln.mass for n, ln in dp.links.items() if ln.how == how and ln.mass is not None}
                          for how in ("declared", "inferred"))
    if not declared and not inferred:
        return "none declared"
    total = sum(declared.values()) + sum(inferred.values())
    parts = ", ".join(f"{n} {m:.4g}" for n, m in {**declared, **inferred}.items())
    how = "as declared" if not inferred else ("as MuJoCo infers it from the geoms" if not declared else
                                              f"declared for {len(declared)} link(s), inferred from the geoms for {len(inferred)}")
    return f"{total:.4g} kg ({how}: {parts} kg)"


def _dynamics_text(v: float, quantity: str, jtype: str, reference: float | None) -> str:
    """A joint's ``quantity`` ``v`` (``damping``, ``friction``, ``stiffness``) with its unit for a joint of type ``jtype``
    (:data:`~asset2sim.tasks.synthesize.request_findings.DYNAMICS_UNITS`: revolute and continuous share theirs); a
    spring's with the position it pulls toward (``reference``)."""
    text = f"{v:.4g} {DYNAMICS_UNITS[quantity][jtype == 'prismatic']}"
    if quantity == "stiffness" and reference is not None:
        text += f" about {position_text(reference, jtype)}"
    return text


def state_moves(report: dict[str, Any]) -> dict[str, str]:
    """joint -> why its initial state is not where its request put it (the band's centre, or the number asked), in one
    clause: stability by design opened it elsewhere within its band (``design_changes``: the reason and the margin), the
    floor stopped its opening (``design_changes``), or the state search moved it to remove self-penetration
    (``state``: asked vs found). Joints nothing moved are not
    listed. ``report``: ``report.json`` as a dict."""
    out: dict[str, str] = {}
    positions = report.get("initial_joint_positions") or {}
    for note in report.get("design_changes") or []:
        if not str(note).startswith("stability by design"):
            continue
        head, _, rest = str(note).partition("; ")
        for name in positions:
            m = re.search(rf"(?<![\w-]){re.escape(name)} opened to (\d+(?:\.\d+)?) of its range(?: \(allowed [^)]*\))?", rest)
            if m:
                where = rest.split(", where the object stands steadiest", 1)[1].split(" (asked")[0] if "stands steadiest" in rest else ""
                out[name] = (f"moved to {100 * float(m.group(1)):.0f} % open, off its band's target: "
                             f"{head.removeprefix('stability by design: ')}"
                             + (f"; the object stands steadiest there{where}" if where else "")
                             + ("; the least opening its band allows" if "the least its band allows" in note else ""))
    for note in report.get("design_changes") or []:  # the floor stopped the opening (tasks.state.ground_clearance)
        name, _, rest = str(note).partition(": opening limited by the floor, ")
        if rest and name in positions:
            out.setdefault(name, "stopped by the floor, where a real one stops")
    state = report.get("state") or {}
    for name, q in positions.items():
        asked = (state.get("requested") or {}).get(name)
        if name not in out and asked is not None and abs(float(asked) - float(q)) > 1e-9:
            out[name] = f"moved by the state search to remove self-penetration ({state.get('method', '')})"
    return out


def escalated(report: dict[str, Any] | None) -> dict[tuple[str, str], dict[str, Any]]:
    """(joint, quantity) -> the last check round that changed it (its entry of ``report.json``'s ``escalation``)."""
    return {(joint, k): rnd for rnd in (report or {}).get("escalation") or [] for joint, ch in (rnd.get("changes") or {}).items()
            for k in ch}


def change_rows(report: dict[str, Any], ov: dict[str, Any], joint_types: dict[str, str], side: InputSide) -> list[str]:
    """The table rows (HTML) of every change refine made, each with its reason, the input column as the input's own
    file declares it (``side``, :func:`read_input`): scale, total mass, joint limits clipped to the geometry, the joint
    state, every movable joint's damping, friction and (when either side has a spring) stiffness with their units,
    collision pieces, stability by design and the root's mounting; ``ov``: ``overlay.json`` as a dict."""
    notes = ov.get("notes") or {}
    rows = [_row("scale", "1 (the input's units)", f"{float(report.get('scale', 1.0)):.4g}", notes.get("size", "")),
            _row("total mass", _declared_mass(side), f"{float(report.get('total_mass', 0.0)):.4g} kg",
                 "; ".join(x for x in (notes.get("mass_arithmetic"), notes.get("material")) if x))]
    before = getattr(side.physics, "joints", {})
    for name, jd in (ov.get("joints") or {}).items():
        src = str(jd.get("limit_source") or "")
        if src.startswith("clipped"):
            jt = joint_types.get(name, "revolute")
            old = before.get(name)
            k = float(report.get("scale", 1.0)) if jt == "prismatic" else 1.0  # the input's lengths at the output's scale
            lo, hi = (None if x is None else float(x) * k for x in ((None, None) if old is None else (old.lower, old.upper)))
            rows.append(_row(f"{name} limits", _limits_text(lo, hi, jt) if old else "as the input declares",
                             _limits_text(lo if jd.get("lower") is None else jd["lower"],
                                          hi if jd.get("upper") is None else jd["upper"], jt), src.split(": ", 1)[-1]))
    fractions = report.get("opening_fractions") or {}
    bands = report.get("requested_bands") or {}
    closed = report.get("closed_positions") or {}
    moves = state_moves(report)
    for name, q in (report.get("initial_joint_positions") or {}).items():
        jt = joint_types.get(name, "revolute")
        asked = next((q for q in ((report.get("request") or {}).get("quantities") or []) if str(q.get("what", "")).startswith(f"{name} ")), None)
        why = (f"the request: '{asked.get('phrase')}'" if asked else
               f"the request: {bands[name].replace('_', ' ')}" if name in bands else "not asked: closed")
        if name in moves:
            why += f"; {moves[name]}"
        start = getattr(side.physics, "initial_state", {}).get(name)
        rows.append(_row(f"{name} initial position", "as modelled (0)" if start is None else
                         f"{position_text(start, jt)} (the file's keyframe)",
                         f"{from_closed_text(q, closed.get(name), jt)}, {opening_text(fractions.get(name))}".rstrip(", "), why))
    changed = escalated(report)
    for name, jd in (ov.get("joints") or {}).items():
        jt = joint_types.get(name, "revolute")
        dj = before.get(name)
        spring = float(jd.get("stiffness") or 0.0) > 0 or (dj is not None and (dj.stiffness or 0.0) > 0)
        for k in ("damping", "friction", "stiffness")[:3 if spring else 2]:
            rnd = changed.get((name, k))
            why = (f"after check round {rnd.get('round')}: {rnd.get('reason', '')}" if rnd
                   else _source_of(str(jd.get("source") or ""), k))
            declared = getattr(dj, k, None)  # none declared: a simulator's default 0
            out = float(jd.get(k) or 0.0)
            rows.append(_row(f"{name} {k}", "-" if side.physics is None else "none declared" if declared is None
                             else _dynamics_text(float(declared), k, jt, dj.reference),
                             _dynamics_text(out, k, jt, jd.get("spring_reference") if out > 0 else None), why))
    rows += [_row("collision pieces", "", "", line) for line in (report.get("state") or {}).get("collision_changes") or []]
    rows += [_row("stability by design", "", "", line) for line in report.get("design_changes") or []]
    mount = report.get("mounting") or {}
    if mount:
        rows.append(_row("root", "", f"{mount.get('kind', '')}{' (fixed)' if mount.get('fixed') else ''}", mount.get("source", "")))
    return rows


def before_after(side: InputSide, after: dict[str, np.ndarray] | None) -> str:
    """The input as modelled (every joint at 0, its own scale; an MJCF or USD file as it is read into the asset
    model) beside the output at its initial state, :data:`COMPARED_VIEWS` each; ``side``: :func:`read_input`;
    ``after``: the output's renders (view -> (H, W, 3) uint8), each drawn as a captioned figure. A
    one-line note naming the input's file (never a temporary path) when it cannot be drawn."""
    figs = []
    size = next(((a.shape[1], a.shape[0]) for a in (after or {}).values()), (256, 256))
    try:
        if side.urdf is None:
            raise ValueError(side.error or "not read")
        src = render_views(side.urdf, {}, views=COMPARED_VIEWS, size=size)
        figs += [figure(src[v], f"input ({side.name}), {v}") for v in COMPARED_VIEWS]
    except Exception as exc:
        why = side.error or f"{type(exc).__name__}: {one_line(exc)}".replace(str(side.urdf), side.name)
        figs.append(f"<p class='small'>the input could not be drawn: {esc(why)}</p>")
    figs += [figure(after[v], f"output, {v}") for v in COMPARED_VIEWS if after and v in after]
    return "<div class='views'>" + "".join(figs) + "</div>"


def changes_section(report: dict[str, Any] | None, overlay: dict[str, Any] | None, joint_types: dict[str, str],
                    after: dict[str, np.ndarray] | None) -> str:
    """The report's "What asset2sim changed" section (HTML): the input (as its own file declares it, URDF, MJCF or
    USD alike) drawn beside the output, the table of changes; empty without a ``report.json``."""
    if not report:
        return ""
    side = read_input(report.get("source"))
    try:
        return ("<h2>What asset2sim changed</h2>" + before_after(side, after)
                + table(("what", f"input ({side.name})", "output", "why"), change_rows(report, overlay or {}, joint_types, side))
                + understood(report.get("request")))
    finally:
        side.close()


def _source_of(source: str, quantity: str) -> str:
    """The part of a joint's overlay ``source`` text that speaks of ``quantity`` (``"; damping 2 from the request
    ('...')"``), else the whole text: why the output has its value."""
    parts = [p.strip() for p in source.split(";") if p.strip()]
    named = [p for p in parts if quantity in p]
    return "; ".join(named or parts)


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
        asked = "-" if q.get("asked") is None else quantity_text(q["asked"], unit) + (
            "" if q.get("asked_high") is None else f" to {quantity_text(q['asked_high'], unit)}") + frame
        rows.append(_row(f"{q.get('what')} ('{q.get('phrase', '')}')", asked, got,
                         ("within tolerance" if q.get("within_tolerance") else "MISSED") + (f": {q['why']}" if q.get("why") else "")))
    if found.get("ignored"):
        rows.append(_row("words not used", "", "", "; ".join(found["ignored"])))
    return "<h3>The request as understood</h3>" + table(("what", "asked", "output", "note"), rows) if rows else ""
