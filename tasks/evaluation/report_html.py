"""Self-contained HTML reports (CSS, PNG renders and SVG figures inline as
``data:`` URIs; text HTML-escaped): one asset's evaluation
(:func:`render_report`, :func:`write_report`) and its sections; the blocks they are made of in
:mod:`.html_blocks`, the parameter table in :mod:`.parameter_table`, the benchmark pages in
:mod:`.benchmark_pages`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable

import numpy as np

from asset2sim.atomic import write_text
from asset2sim.schemas.metrics import METRIC_INFO
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.source import UrdfFile
from asset2sim.tasks.assemble.joint_sweep import reference_state
from asset2sim.tasks.check.failure_reasons import why_it_failed
from asset2sim.tasks.check.verdict import UNRESOLVED_PENETRATION_MM, penetration_measures, readiness
from asset2sim.tasks.evaluation import plots
from asset2sim.tasks.evaluation.failure_evidence import evidence_section
from asset2sim.tasks.evaluation.html_blocks import TEXTS, figure, fmt, page, svg_tag, table, verdict_cell
from asset2sim.tasks.evaluation.parameter_table import parameter_table
from asset2sim.tasks.evaluation.report_changes import changes_section, esc, from_closed_text, opening_text
from asset2sim.tasks.geometry.render import render_views


def _renders(ev, views: dict[str, np.ndarray] | None = None, error: Exception | None = None) -> tuple[str, str]:
    """(HTML of the object views, what they are); ``views``: the renders, None when ``error`` stopped them (then a plot
    of the collision vertices at the initial state)."""
    if views is not None:
        return f"<div class='views'>{''.join(figure(v, k) for k, v in views.items())}</div>", "renders"
    note = f"render failed ({type(error).__name__}: {error}); "
    try:
        svg = plots.plot_object(point_cloud(Path(ev._context.urdf), dict(ev.initial_state)))
    except Exception:  # no engine either: the report says so
        svg = None
    if svg is None:
        return "<p class='small'>no geometry recorded</p>", note + "no plot"
    return svg_tag(svg, "collision geometry"), note + "plot of the collision vertices per link"


def point_cloud(urdf: Path, state: dict[str, float]) -> dict[str, np.ndarray]:
    """Link -> (N, 3) m collision vertices in the world frame of ``urdf`` at ``state`` (rad or m, root fixed), at most
    1500 per link (evenly picked). Raises what loading the URDF raises."""
    out = {}
    with UrdfFile(urdf).open("pybullet", SessionOptions(initial_state=state, fixed_base=True, gravity=False, ground=False)) as session:
        for name in session.link_names:
            v = session.link_collision_vertices(name)
            if not len(v):
                continue
            pos, R = session.link_frame(name)
            w = v @ R.T + pos
            out[name] = w[np.linspace(0, len(w) - 1, 1500).astype(int)] if len(w) > 1500 else w
    return out


#: A metric's note in the verdict table: the first of these details it holds, said so.
_NOTES = (("skipped", "skipped: {}".format), ("reason", str), ("failures", "; ".join),
          ("failing", lambda v: "failing: " + ", ".join(v)), ("reasons", "; ".join))


def _verdict_table(ev) -> str:
    def note(d: dict, name: str) -> str:
        if name == "rest_stability" and "D_ori_rad" in d:
            return f"D_pos {fmt(d['D_pos_m'])} m, D_ori {fmt(d['D_ori_rad'])} rad"
        return next((say(d[k]) for k, say in _NOTES if d.get(k)), "")

    return table(("metric", "engine", "value", "unit", "verdict", "threshold", "notes"), (
        f"<tr><td>{esc(m.name)}</td><td>{esc(m.engine)}</td><td class='num'>{fmt(m.value)}</td><td>{esc(m.unit)}</td>"
        f"{verdict_cell(m.passed)}<td class='small'>{esc(m.threshold)}</td>"
        f"<td class='small'>{esc(note(m.details, m.name))}</td></tr>"
        for m in ev.metrics))


def _penetration_details(ev) -> str:
    """The penetration tier at the initial state: one sentence with its verdict (the readiness rule, the words of the
    terminal's penetration line), then the self-contact pairs and the children inside their parents, each with its
    verdict; never "no penetration" above a failing pair."""
    measures = penetration_measures(ev.metrics)
    verdict = {True: "pass", False: "FAIL", None: "not measured"}[readiness(list(ev.metrics)).tiers.get("penetration")]
    out = [f"<p>penetration tier: <b>{verdict}</b>" + (f" ({esc('; '.join(measures))})" if measures else "") + "</p>"]
    for m in ev.metrics:
        if m.name != "penetration" or m.value is None:
            continue
        if not m.details.get("pairs"):
            out.append(f"<p class='small'>self-contact ({esc(m.engine)}): no two links that are not parent and child overlap</p>")
            continue
        rows = (f"<tr><td>{esc(p['link_a'])}</td><td>{esc(p['link_b'])}</td><td class='num'>{fmt(p['depth_mm'])}</td>"
                f"<td class='num'>{fmt(p['max_depth_mm'])}</td><td class='num'>{p['points']}</td></tr>"
                for p in m.details["pairs"])
        out.append(f"<h3>Self-contact: penetrating link pairs ({esc(m.engine)}; {'pass' if m.passed else 'FAIL'}: {esc(m.threshold)})</h3>"
                   + table(("link a", "link b", "sum of depths (mm)", "deepest point (mm)", "points"), rows))
    for m in ev.metrics:  # the pairs the self-contact Phi skips: a child inside its parent
        pairs = m.details.get("pairs") if m.name == "parent_child_penetration" else None
        if not pairs:
            continue
        modelled = m.details.get("modelled") or {}
        rows = (f"<tr><td>{esc(k.partition('/')[0])}</td><td>{esc(k.partition('/')[2])}</td><td class='num'>{fmt(v)}</td>"
                f"<td class='num'>{fmt(modelled.get(k, 0.0))}</td><td class='num'>{fmt(over)}</td>"
                f"{verdict_cell(over <= UNRESOLVED_PENETRATION_MM)}</tr>"
                for k, v in pairs.items() for over in [max(v - modelled.get(k, 0.0), 0.0)])
        out.append(f"<h3>A child inside its parent ({esc(m.engine)}; {esc(m.threshold)})</h3>" + table(
            ("parent", "child", "depth (mm)", "at its modelled pose (mm)", "deeper than modelled (mm)", "verdict"), rows))
    return "".join(out)


def _listed(items: Iterable[Any]) -> str:
    """The ``<li>`` items (HTML) of ``items``, each escaped."""
    return "".join(f"<li>{esc(x)}</li>" for x in items)


def why_section(ev) -> str:
    """``Why it failed``, at the top of the report: for every failing tier, one sentence per failing measure naming
    the tier, the parts, the measured value against its threshold and what to do, the sentences the terminal prints
    (:func:`~asset2sim.tasks.check.failure_reasons.why_it_failed`); empty when ready. The failing trials' evidence follows
    under the verdicts."""
    why = why_it_failed(ev.metrics)
    return f"<h2>Why it failed</h2><ul class='why'>{_listed(why)}</ul>" if why else ""


def _request_warnings(d: dict) -> str:
    """The request's warnings (what was not understood or not applied) as a visible list; empty without any."""
    items = list(d.get("warnings", []))
    if d.get("not_counted"):
        items.append("not counted in prompt alignment: " + ", ".join(f"'{n['phrase']}'" for n in d["not_counted"]))
    return (f"<div class='warn' style='padding:6px 12px;border-radius:6px'><b>Request warnings</b><ul>{_listed(items)}</ul></div>"
            if items else "")


def _prompt_details(ev) -> str:
    m = ev.metric("prompt_alignment")
    if m is None or m.value is None:
        return (f"<p class='small'>prompt alignment: {esc((m.details.get('reason') if m else None) or 'not scored')}</p>"
                + (_request_warnings(m.details) if m else ""))
    d = m.details
    size = d.get("size") or {}
    rows = [f"<tr><td>size</td><td>{esc(d.get('size_class') or 'regular (not stated)')}</td>"
            f"<td class='num'>{fmt(size.get('score'))}</td><td class='small'>{esc(size.get('reason'))}</td></tr>",
            *(f"<tr><td>joint {esc(j.get('joint'))} ({esc(j.get('label'))})</td><td>{esc(j.get('band'))}</td>"
              f"<td class='num'>{fmt(j.get('score'))}</td><td class='small'>{esc(j.get('reason'))}</td></tr>"
              for j in d.get("joints", [])),
            *([f"<tr><td>joint state</td><td>-</td><td>-</td><td class='small'>{esc(d.get('joint_state_reason'))}</td></tr>"]
              if d.get("joint_state_score") is None else [])]
    return (f"<p>score <b>{fmt(m.value, 3)}</b> for <i>{esc(d.get('request'))}</i></p>" + _request_warnings(d)
            + table(("part", "requested", "score", "reason"), rows))


def _probe_details(ev) -> str:
    m = ev.metric("probes")
    if m is None or not m.details.get("probes"):
        return "<p class='small'>no probes run" + (f": {esc(m.details.get('skipped'))}" if m and m.details.get("skipped") else "") + "</p>"
    rows = (f"<tr><td>{esc(p['joint'])}</td><td>{esc(p['action'])}</td><td class='num'>{fmt(p['start'])} {unit}</td>"
            f"<td class='num'>{fmt(p['target'])} {unit}</td><td>{fmt(p['reached'])}</td>"
            f"<td class='num'>{fmt(p['peak_force'])} N</td><td class='num'>{fmt(p['peak_effort'])} {eff_unit}</td>"
            f"<td class='num'>{fmt(p['root_displacement'] * 1000)} mm / {fmt(p['root_rotation'])} rad</td>"
            f"<td>{fmt(p['rebound'])}</td><td>{fmt(p['kept_moving'])}</td>"
            f"<td class='{'pass' if p['success'] else 'fail'}'>{esc(p['failure'] or 'ok')}</td>"
            f"<td class='small'>{esc('; '.join(p['notes']))}</td></tr>"
            for p in m.details["probes"] for unit, eff_unit in [("m", "N") if p["joint_type"] == "prismatic" else ("rad", "N*m")])
    return table(("joint", "probe", "start", "target", "reached (crossed the line that counts)", "peak force", "peak torque/force",
                  "object moved", "rebound", "kept moving", "verdict", "notes"), rows)


def operability_section(ev) -> str:
    """The operability tier as a table: per engine and handled part, the grasp, the effort each stroke needs
    (force at the grasp point N, torque about the axis N m) against the part's real range and its source,
    how far the hand got, and the verdict."""
    rows: list[str] = []
    cited: dict[str, int] = {}  # each standard quoted once, under the table; a row names its number
    for m in [m for m in ev.metrics if m.name == "operability"]:
        if not m.details.get("parts"):
            why = m.details.get("skipped") or m.details.get("not_run") or "no handled part"
            rows.append(f"<tr><td>{esc(m.engine)}</td><td colspan='8' class='small'>{esc(why)}</td></tr>")
            continue
        for joint, p in m.details["parts"].items():
            rng = p.get("force_range_n")
            trng = p.get("torque_range_nm")
            limit = (f"{fmt(rng[1])} N" if rng else "") + (f", {fmt(trng[1])} N m" if trng else "")
            lever = "" if p.get("lever_m") is None else f", lever {fmt(p['lever_m'], 3)} m"
            for s in p.get("strokes") or []:
                torque = "" if s.get("needed_torque_nm") is None else f" / {fmt(s['needed_torque_nm'])} N m"
                got = f"{fmt(100.0 * s['reached'], 3)} % open" + (f", stopped by {s['stopped_by']}" if s.get("stopped_by") else "")
                rows.append(
                    f"<tr><td>{esc(m.engine)}</td><td>{esc(joint)} ({esc(p.get('label') or 'unlabelled')})</td>"
                    f"<td>{esc(p['rule'])}{lever}</td>"
                    f"<td>{esc(s['action'])}</td><td class='num'>{fmt(s['needed_force_n'])} N{torque}</td>"
                    f"<td class='num'>{esc(limit)} ({esc(p['range_of'])})</td><td>{esc(got)}</td>"
                    f"<td class='{'pass' if s['passed'] else 'fail'}'>{esc(s['failure'] or 'ok')}</td>"
                    f"<td class='small'>{', '.join(f'[{cited.setdefault(src, len(cited) + 1)}]' for src in p.get('sources') or [])}</td></tr>")
    if not rows:
        return "<p class='small'>operability not measured</p>"
    notes = "".join(f"<li>[{n}] {esc(src)}</li>" for src, n in cited.items())
    return (TEXTS["operability"]
            + table(("engine", "part", "grasp", "stroke", "effort needed", "range", "hand got it to", "verdict", "range source"), rows)
            + (f"<ul class='small'>{notes}</ul>" if notes else ""))


def _badge(ev) -> str:
    """The interaction-readiness verdict (:func:`asset2sim.tasks.check.verdict.readiness`)
    with the other failing checks beside it."""
    r = readiness(list(ev.metrics))
    # an engine's error (``engine@<engine>``, in evaluations written before the checks recorded it as their metric's)
    engine_errors = [f for f in ev.failures if f.startswith("engine@")]
    other = [f for f in ev.failures if f not in r.failures and f not in engine_errors]
    text = r.line() if not r.ready or not engine_errors else "NOT READY"
    return (f"<span class='badge {'pass' if r.ready and not engine_errors else 'fail'}'>{esc(text)}"
            + (f"; {esc(', '.join(engine_errors))}" if engine_errors else "") + "</span>"
            + (f" <span class='small'>other checks failing: {esc(', '.join(other))}</span>" if other else ""))


def _joint_state(ev, joint: str, q: float, jtype: str) -> str:
    """A joint's initial state from its closed end (``"20.8 deg from closed (18 % open)"``, the opening where its range
    is known); its own coordinate, labelled so, when the closed end is unknown."""
    c = ev.closed_positions.get(joint)
    return from_closed_text(q, c.get("q_closed") if c else None, jtype) + (
        f" ({opening_text(c['direction'] * (q - c['q_closed']) / c['open_range'])})" if c and c.get("open_range") else "")


def as_asked_block(ev) -> str:
    """The as-asked verdict (``request_met``, :mod:`asset2sim.tasks.check.as_asked`) near the top of the report:
    each unmet phrase with its gap in a visible block; one line when met; empty when not measured."""
    m = ev.metric("request_met")
    if m is None or m.passed is None:
        return ""
    d = m.details
    if m.passed:
        return (f"<p class='small'>As asked: every part and state the request names is applied ({int(d.get('graded') or 0)} "
                "checked; states measured from the closed end).</p>")
    items = _listed(u.get("text") or u.get("phrase") for u in d.get("unmet") or [])
    if d.get("error"):
        items += f"<li>{esc(d['error'])}</li>"
    return ("<div class='fail' style='padding:6px 12px;border-radius:6px'><b>Not as asked</b> (failure mode "
            "<code>request_not_met</code>; states measured from the closed end)<ul>" + items + "</ul></div>")


def host_notes(notes: list[str]) -> list[str]:
    """The notes of an MJCF or USD input's write-back among a report's ``notes`` (``tasks/publish/extra_outputs.py``):
    the files written back into the input's package, the call its code needs to keep the refined values, or why
    nothing was written (for the terminal and :func:`host_section`)."""
    return [n for n in notes if n.startswith(("host MJCF", "host USD"))]


def host_section(report: dict | None) -> str:
    """"Back into its package": the write-back of an MJCF or USD input (:func:`host_notes` of report.json's notes),
    empty for other inputs."""
    notes = host_notes(list((report or {}).get("notes") or []))
    return f"<h2>Back into its package</h2><ul class='host'>{_listed(notes)}</ul>" if notes else ""


def engines_section(report: dict | None) -> str:
    """"What holds in each engine": one row per engine of ``report.parity`` (``refine --engines``): rest stability,
    the joints held at rest over the rest test, each joint's breakaway push over its declared friction (within 20 %
    passes; the SPEC: "each value means the same in every engine"); empty without parity rows."""
    rows = list((report or {}).get("parity") or [])  # report.json as JSON
    if not rows:
        return ""

    def breakaway_cell(b: dict | None) -> str:
        if not b:
            return "-"
        if not b.get("measured"):
            return f"<span class='small'>not measured: {esc(b.get('reason') or '-')}</span>"
        parts = [f"{esc(j)} {fmt(r.get('ratio'), 2)} f" for j, r in b.get("joints", {}).items()]
        return f"{verdict_cell(b.get('passed'))} <span class='small'>{', '.join(parts) or 'no joint with friction'}</span>"

    cells = [f"\n<tr><td>{esc(r.get('engine'))}</td><td>{esc(r.get('status'))} "
             f"<span class='small'>{esc(r.get('reason') or '')}</span></td><td>{verdict_cell(r.get('rest_stability'))}</td>"
             "<td class='small'>"
             + (", ".join(f"{esc(j)}{'' if ok else ' (moves)'}" for j, ok in (r.get("joints_held") or {}).items()) or "-")
             + f"</td><td>{breakaway_cell(r.get('breakaway'))}</td></tr>" for r in rows]
    return f"<h2>What holds in each engine</h2>\n{TEXTS['engines']}\n" + table(("engine", "status", "rest stability", "joints held", "breakaway"),
                                                                      [*cells, "\n"])


def clips_section(clip_set) -> str:
    """HTML playing every clip of ``clip_set`` (a :class:`~asset2sim.schemas.realism.ClipSet`; None or empty:
    nothing), one row per joint and motion, the videos looping muted with their poster frames (in ``clips/`` beside
    the report)."""
    if clip_set is None or not (clip_set.clips or clip_set.skipped):
        return ""
    rows: dict[tuple[str, str], list] = {}
    for c in clip_set.clips:
        rows.setdefault((c.joint, c.motion), []).append(c)
    what = TEXTS["clip_motions"]
    parts = ["<h2>How it moves</h2>", "<p class='small'>Clips played in real time, from two fixed cameras.</p>"]
    for (joint, motion), cs in rows.items():
        parts.append(f"<h3>{esc(joint)}: {esc(what.get(motion, motion))}</h3><div class='clips'>")
        for c in cs:
            src, poster = (esc(f"clips/{p}") for p in (c.video, c.poster))
            parts.append(f"<figure><video src='{src}' poster='{poster}' width='{c.width}' height='{c.height}' autoplay loop muted "
                         f"playsinline controls></video><figcaption>{esc(c.view)} view, {c.duration_s:.1f} s</figcaption></figure>")
        parts.append("</div>")
    if clip_set.skipped:
        parts.append("<p class='small'>no clip: " + "; ".join(f"{esc(k)}: {esc(v)}" for k, v in clip_set.skipped.items()) + "</p>")
    return "\n".join(parts)


def render_report(ev, views: dict[str, np.ndarray] | None = None, command: str = "evaluate", clips=None,
                  folder: Path | str | None = None) -> str:
    """The HTML text of one evaluation's report; ``views``: renders at
    ``ev.initial_state`` (view -> (H, W, 3) uint8) already taken, None to render here;
    ``command``: the command that wrote it (``refine`` or ``evaluate``), in the title;
    ``clips``: the :class:`~asset2sim.schemas.realism.ClipSet` written beside the report (played in it); ``folder``: where the
    report is written (the URDF is named relative to it when it lies there, :func:`portable_urdf`)."""
    # step 1: the time step, the badge and the renders (a plot of the vertices when rendering fails)
    ctx = ev._context
    dt = ctx.conventions.timestep
    settle_n = int(round(ctx.conventions.settle_time / dt))
    error = None
    if views is None:
        try:
            views = render_views(Path(ev.urdf), dict(ev.initial_state))
        except Exception as exc:  # the report falls back to a plot of the collision vertices
            error = exc
    views_html, views_what = _renders(ev, views, error)
    # step 2: the header, the object at its initial state, the verdicts and the evidence
    joint_types = {j.name: j.type for j in ctx.model.joints}
    state_text = ", ".join(f"{k} = {_joint_state(ev, k, v, joint_types.get(k, 'revolute'))}"
                           for k, v in ev.initial_state.items()) or "none"
    # the engines the verdicts were measured in (those of the metrics, then those the evaluation ran): the header names
    # every engine a row of the verdict table comes from
    engines = dict.fromkeys([m.engine for m in ev.metrics if m.engine and m.engine != "none"] + list(ev.engines))
    sections = [
        f"<h1>asset2sim {esc(command)}: {esc(ev.asset_id)}</h1>",
        f"<p class='meta'>method <b>{esc(ev.method or '-')}</b> &middot; category {esc(ev.category or '-')} &middot; "
        f"engines {esc(', '.join(engines))} &middot; scale {fmt(ev.scale)} ({esc(ev.scale_source)})</p>",
        f"<p class='meta'>URDF <code>{esc(portable_urdf(ev, folder) if folder is not None else ev.urdf)}</code>"
        + (f" &middot; input <code>{esc(Path(str(ctx.report['source'])).name)}</code>"
           if ctx.report and ctx.report.get("source") else "") + "<br/>"
        f"request: <i>{esc(ev.prompt or '-')}</i><br/>"
        f"reference: <code>{esc(ev.reference or '-')}</code></p>",
        _request_warnings(pa.details) if (pa := ev.metric("prompt_alignment")) is not None else "",
        f"<p>{_badge(ev)}</p>",
        why_section(ev),
        as_asked_block(ev),
        host_section(ctx.report),
        "<h2>Object at its initial state</h2>",
        f"<p class='small'>{esc(views_what)}; joints: {esc(state_text)} ({esc(ev.initial_state_source)}); "
        f"task-relevant: {esc(', '.join(ev.task_joints) or '-')}</p>",
        views_html,
        clips_section(clips),
        changes_section(ctx.report, ctx.overlay, joint_types, views),
        "<h2>Verdicts</h2>",
        _verdict_table(ev),
        engines_section(ctx.report),
        evidence_section(ev._runs, ctx.urdf, dt, svg_tag, figure, dict(ev.initial_state),
                         getattr(ev.metric("task_execution"), "details", None), ev.closed_positions, list(ev.metrics),
                         reference_state(ctx.model)),
        "<h2>Operability</h2>",
        operability_section(ev),
        "<h2>Penetration at the initial state</h2>",
        _penetration_details(ev),
        "<h2>Rest test</h2>",
    ]
    # step 3: the rest test's plots per engine
    for eng, run in ev._runs.items():
        if run.trace is None:
            sections.append(f"<p class='small'>{esc(eng)}: " + esc(run.error or "its verdicts above; the rest test recorded in "
                                                                  "PyBullet only") + "</p>")
            continue
        closed = {n: c["q_closed"] for n, c in ev.closed_positions.items()}
        sections += [f"<h3>{esc(eng)}</h3>",
                     svg_tag(plots.plot_root_drift(run.root_series, run.trace, dt, settle_n), f"root drift {eng}"),
                     svg_tag(plots.plot_joints(run.joint_series, run.trace.joint_types, dt, settle_n, closed), f"joints {eng}")]
    # step 4: prompt alignment, probes, parameters, notes and what the checks mean
    sections += ["<h2>Prompt alignment</h2>", _prompt_details(ev), "<h2>Passive probes</h2>", _probe_details(ev)]
    pb = ev._runs.get("pybullet")
    if pb is not None and pb.probes:
        sections.append(svg_tag(plots.plot_probes(pb.probes), "probes"))
    sections += ["<h2>Physical parameters</h2>", parameter_table(ev), f"<h2>Notes</h2><ul>{_listed(ev.notes)}</ul>",
                 "<h2>What the checks mean</h2>" + table(("check", "unit", "what it measures"), (
                     f"<tr><td>{esc(i.name)}</td><td>{esc(i.unit)}</td><td class='small'>{esc(i.description)}</td></tr>"
                     for i in METRIC_INFO.values() if ev.metric(i.name) is not None)), TEXTS["simulation"]]
    return page(f"asset2sim {esc(command)} {esc(ev.asset_id)}", "\n".join(sections))


def portable_urdf(ev, out_dir: Path | str) -> str:
    """The evaluated URDF as ``evaluation.json`` and ``report.html`` name it: relative to ``out_dir`` (the folder they
    are written to) when the URDF lies in it, as a refine's output does (``mobility.urdf``), so a moved or copied
    output names no place it is not; else the path as given."""
    folder = Path(out_dir).resolve()
    for candidate in (Path(ev._context.urdf), Path(ev.urdf)):
        try:
            return candidate.resolve().relative_to(folder).as_posix()
        except (ValueError, OSError):
            continue
    return str(ev.urdf)


def write_report(ev, path: Path | str, views: dict[str, np.ndarray] | None = None, clips=None) -> Path:
    """Write ``report.html`` atomically (``views`` as in :func:`render_report`); returns the path. Its
    title names ``refine`` when it lies beside the refine's ``report.json`` it reports on, else ``evaluate``."""
    ctx = ev._context
    by_refine = ctx.report is not None and Path(path).resolve().parent == Path(ctx.urdf).resolve().parent
    return write_text(Path(path), render_report(ev, views, "refine" if by_refine else "evaluate", clips, folder=Path(path).parent))


