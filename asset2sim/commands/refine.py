"""``asset2sim refine ASSET --prompt P --out OUT``: refine one asset.

Exit status: 0 written and interaction-ready, 1 invalid input, 2 invalid
request, estimator failure or invalid overlay, 3 written but not
interaction-ready or not as asked (``request_not_met``), 4 output location problem.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
from pathlib import Path

from asset2sim.commands._status import (INVALID_INPUT, INVALID_REQUEST, NOT_READY, CommandError, add_allow_outside,
                                        add_mjcf_reading, failure, join_codes, outside_paths, parse_engines)
from asset2sim.api import load_config, merge_overrides
from asset2sim.schemas.config import RefineConfig, default_engines
from asset2sim.tasks import refine as refine_stage
from asset2sim.tasks.interpret.overrides import OverrideError
from asset2sim.tasks.interpret.request import RequestTooLong
from asset2sim.output_folder import OutputError
from asset2sim.refined_asset import RefinedAsset
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.extract import MESSAGE_FINDINGS
from asset2sim.tasks.check.as_asked import as_asked_lines, quantity_text
from asset2sim.tasks.check.failure_reasons import why_it_failed
from asset2sim.tasks.check.verdict import TIERS, penetration_measures, readiness, verdict_line
from asset2sim.tasks.evaluation.report_changes import from_closed_text, opening_text, state_moves
from asset2sim.tasks.evaluation.report_html import host_notes
from asset2sim.tasks.ingest.partnet_mobility import read_semantics
from asset2sim.tasks.refine import RefineError
from asset2sim.tasks.synthesize.validate_overlay import OverlayInvalid

NAME = "refine"
HELP = "Refine one asset for a natural-language request into an interaction-ready asset (an output folder: docs/guide/outputs.md)."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {
    0: "written and interaction-ready",
    1: "invalid input",
    2: "invalid request, estimator failure or invalid overlay",
    3: "written but not interaction-ready or not as asked",
    4: "output location problem",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("asset", type=Path, help="asset folder (mobility.urdf + meshes), a URDF file, or an MJCF (.xml) or OpenUSD (.usd, .usda, .usdc, .usdz) file")
    parser.add_argument("--prompt", "-p", default="", help='the request, e.g. "I want a slightly open stapler."')
    parser.add_argument("--out", "-o", type=Path, required=True, help="output folder (must not be inside the input)")
    parser.add_argument("--category", help="override the asset's category (meta.json model_cat)")
    parser.add_argument("--task", help=(
        'the manipulation task, e.g. "close the microwave door": the post-check executes it with a force- and '
        "speed-limited gripper (tiers task and force) and friction and damping are kept to what a real operating "
        "force overcomes in its direction (docs/guide/metrics.md)"))
    parser.add_argument("--estimator", help=(
        "overlay estimator: offline (the default, no network); llm (any litellm model, e.g. --model gemini/gemini-2.5-flash, "
        "key from the provider's environment variable); openai (an OpenAI-compatible server: --base-url URL --model M). "
        "See docs/guide/model_backends.md"))
    parser.add_argument("--model", help="model for llm/openai: a litellm model string (provider/name) or the server's model name")
    parser.add_argument("--base-url", help="base URL of an OpenAI-compatible or local server (vLLM, Ollama, llama.cpp); needs no key")
    parser.add_argument("--request-parser", choices=("offline", "model"), help=(
        "who parses the request into its typed intent: offline (the default) or model (the --estimator llm/openai model, "
        "with the intent's JSON schema; the offline parse is kept, with a note, when the model's parse is invalid or the "
        "call fails; docs/guide/requests.md)"))
    parser.add_argument("--engines", help=(
        "comma-separated engines the asset must pass in (pybullet,physx,mujoco,newton); missing ones are skipped and "
        "reported (default: pybullet, and physx where SAPIEN is installed)"))
    over = parser.add_argument_group("overrides", "typed values that win over the request's words (strings carry units)")
    over.add_argument("--mass", help="total mass, e.g. 12kg or 500g")
    over.add_argument("--size", help="largest extent of the closed object, e.g. 0.5m or 30cm")
    over.add_argument("--scale", type=float, help="uniform scale of the input (wins over --size)")
    over.add_argument("--state", action="append", default=[], metavar="NAME=VALUE",
                      help="a joint (by joint name or part label) at an angle (30deg, 0.5rad), a distance (2cm), an opening "
                           "fraction (0.4) or a band (closed, slightly_open, quarter, halfway, mostly, fully); repeatable")
    over.add_argument("--mount", choices=("fixed", "free"), help="root fixed where the file puts it, or free on the ground")
    over.add_argument("--material", help="material of the whole object (a materials.yaml key, e.g. steel_sheet)")
    add_mjcf_reading(parser)
    parser.add_argument("--config", type=Path,
                        help="YAML file of refine options (estimator, model, engines, sim, overrides: {mass: 12kg, state: {lid: 30deg}} ...); "
                             "flags given on the command line win over it")
    add_allow_outside(parser)
    parser.add_argument("--keep-declared", action="store_true", help=(
        "keep the physics the asset declares where asset2sim audit finds it plausible (masses, inertia, damping, "
        "friction, springs, size) and refine around it (docs/guide/audit.md)"))
    parser.add_argument("--force", action="store_true", help="redo even when the output is complete for this input and configuration")
    parser.add_argument("--overwrite", action="store_true", help=(
        "write into an output folder that holds files asset2sim did not write (they are kept unless a written file has the same path)"))
    parser.add_argument("--no-extras", action="store_true", help="skip MJCF export, renders and the HTML report")
    parser.add_argument("--no-clips", action="store_true", help="skip the clips of each task-relevant joint's sweep (clips/)")
    parser.add_argument("--defer-media", action="store_true",
                        help="write the verdict's files and exports only; `asset2sim report OUT` makes the renders, clips and "
                             "report.html later")
    parser.add_argument("--open-containers", action="store_true", help=(
        "give a container modelled as one mesh group (a bucket, a trash can's body, a dishwasher tub) a convex "
        "decomposition that leaves its inside open, so things can be put into it (needs the [coacd] extra; "
        "docs/guide/outputs.md)"))
    parser.add_argument("--quiet", "-q", action="store_true", help="print only warnings and the summary")
    parser.add_argument("--json", action="store_true", help=(
        "for scripts: print one JSON object instead of the progress and the summary (the output folder, the verdict, "
        "each tier, why it failed, the files written); warnings still go to stderr"))


def _joint_words(out_dir) -> tuple[dict[str, str], dict[str, str]]:
    """Joint name -> type of the output's URDF ({} when it cannot be read), and joint name -> its moving part's label
    in the output's ``semantics.txt`` ({} when either cannot be read)."""
    types, labels = {}, {}
    with contextlib.suppress(Exception):
        joints = RefinedAsset(Path(out_dir)).model.joints
        types = {j.name: j.type for j in joints}
        sem = read_semantics(Path(out_dir))
        labels = {j.name: sem[j.child].label for j in joints if j.child in sem}
    return types, labels


#: How a joint's asked state reads beside it: the asked number's unit -> (its number in the shown unit, that unit).
_ASKED_UNITS = {"rad": (math.degrees, "deg"), "m": (lambda v: 1000.0 * v, "mm"),
                "opening fraction": (lambda v: 100.0 * v, "% open")}


def _state_text(name: str, q: float, report, types: dict[str, str], labels: dict[str, str], moves: dict[str, str]) -> str:
    """One joint's initial state in the one frame of every amount: "joint_2 (lid) = 30.0 deg from closed (asked 30 deg),
    25 % open", the number asked (``report.request.quantities``) beside what it has, and why it stands elsewhere than
    its request put it when something moved it (``moves``: :func:`~asset2sim.tasks.evaluation.report_changes.state_moves`)."""
    asked = next((x for x in (report.request.quantities if report.request else []) if x.kind == "state" and x.asked is not None
                  and x.what.rsplit(" ", 1)[0] == name), None)
    ask = ""
    if asked is not None and asked.what.endswith(" end"):
        ask = f" (asked '{asked.phrase}')"
    elif asked is not None and asked.unit in _ASKED_UNITS:
        scale, unit = _ASKED_UNITS[asked.unit]
        ask = f" (asked {scale(asked.asked):.4g} {unit})"
    who = f"{name} ({labels[name]})" if labels.get(name) else name
    return (f"{who} = {from_closed_text(q, report.closed_positions.get(name), types.get(name, 'revolute'))}{ask}"
            + (f", {opening_text(report.opening_fractions[name])}" if name in report.opening_fractions else "")
            + (f" ({moves[name]})" if name in moves else ""))


def summary_lines(result) -> list[str]:
    """Human-readable summary of a RefineResult."""
    r = result.report
    osc = r.metric("oscillation")
    types, labels = _joint_words(result.out_dir)
    moves = state_moves(r.model_dump(mode="json"))
    state = ", ".join(_state_text(k, v, r, types, labels, moves) for k, v in r.initial_joint_positions.items()) or "(no movable joints)"
    lines = [
        f"asset        {r.asset_id} ({r.category or 'no category'})",
        f"output       {result.out_dir}",
        f"scale        {r.scale:.4g}",
        f"total mass   {r.total_mass:.4g} kg",
        f"initial state {state}",
    ] + ([f"task         {r.task}"] if r.task else []) + [
        "penetration  " + ("; ".join(penetration_measures(r.metrics)) or "n/a"),
        stability_line(r.metrics),
        f"oscillation  {'PASS' if osc and osc.passed else 'FAIL'}",
        _manipulation_line(r),
        _operability_line(r),
        f"verdict      {verdict_line(r.failure_mode, r.readiness, readiness(r.metrics).failures)}",
    ] + [f"why it failed {why}" for why in (why_it_failed(r.metrics) if r.failure_mode != "none" else [])] + as_asked_lines(r)
    # an export or check skipped for a missing optional dependency, with the extra that would do it
    lines += [f"skipped      {n.replace(' skipped: ', ': ', 1)}" for n in r.notes if " skipped: " in n and "asset2sim[" in n]
    lines += engine_lines(r) + request_lines(r.request) + [f"host         {n}" for n in host_notes(r.notes)]
    lines.append("wall time    " + wall_time_text(r.stage_seconds))
    return once(lines) + [report_line(r, result.out_dir)]


#: Where a summary line's message starts (after its label column, ``"request      "``).
LABEL_WIDTH = 13
#: Messages shorter than this are never dropped as repeats (``PASS``, an engine's numbers).
REPEAT_MIN_CHARS = 30


def once(lines: list[str]) -> list[str]:
    """``lines`` with every ``NOT AS ASKED`` and ``request`` line whose message (after its label; a ``WARNING: ``
    prefix aside) an earlier line already says dropped: one missing part is said once per summary (in "why it failed"), not again as ``NOT AS
    ASKED``, a request line and a warning."""
    kept: list[str] = []
    for line in lines:
        message = line[LABEL_WIDTH:].strip().removeprefix("WARNING: ")
        restating = line.startswith(("NOT AS ASKED ", "request      "))
        if restating and len(message) >= REPEAT_MIN_CHARS and any(message in k for k in kept):
            continue
        kept.append(line)
    return kept


def report_line(report, out_dir) -> str:
    """The summary's last line: where to read why each check passed or failed (``report.html``, its plots and
    frames), or how to make it when it was not (``--no-extras``, ``--defer-media``)."""
    html = Path(out_dir) / "report.html"
    if report.media == "done" and html.is_file():
        return f"report       {html} (every check with its evidence; open it in a browser)"
    if report.media == "deferred":
        return f"report       deferred: `asset2sim report {out_dir}` makes views/, clips/ and {html}"
    return f"report       {Path(out_dir) / 'report.json'} (no report.html with --no-extras: `asset2sim report {out_dir}` makes it)"


def stability_line(metrics) -> str:
    """The rest tier in one line, as the verdict reads it: the root's drift at rest (``rest_stability``) and every
    other rest-tier measure that fails (a joint leaving its state, ``state_hold``): never ``PASS`` beside a verdict
    whose rest tier fails."""
    stab = next((m for m in metrics if m.name == "rest_stability"), None)
    if stab is None:
        return "stability    n/a"
    failing = [f for f in readiness(metrics).failures if f.split("@")[0] in TIERS["rest"][0] and not f.startswith("rest_stability@")]
    return (f"stability    {'PASS' if stab.passed and not failing else 'FAIL'} (D_pos "
            f"{stab.details.get('D_pos_m', float('nan')):.2e} m, D_ori {stab.details.get('D_ori_rad', float('nan')):.2e} rad"
            + (f"; failing: {', '.join(failing)}" if failing else "") + ")")


def engine_lines(report) -> list[str]:
    """One line per engine the checks ran in (``report.parity``): whether it ran, its rest test and self-contact Phi
    in the verdict's words, and the checks that fail in it (the verdict's ``metric@engine``), so no engine line reads
    as a pass beside the verdict's failure."""
    failing = readiness(report.metrics).failures
    out = []
    words = {True: "pass", False: "FAIL", None: "n/a"}
    for row in report.parity:
        if row["status"] != "ok":  # skipped (its extra missing) or an error: said with its reason
            out.append(f"engine {row['engine']:<8} {row['status']}" + (f": {row['reason']}" if row["reason"] else ""))
            continue
        here = [f.split("@")[0] for f in failing if f.endswith(f"@{row['engine']}")]
        rest = False if set(here) & set(TIERS["rest"][0]) else row["rest_stability"]  # the rest tier, as the verdict reads it
        out.append(f"engine {row['engine']:<8} rest {words.get(rest, rest)}, oscillation "
                   f"{words.get(row['oscillation'], row['oscillation'])}, self-contact "
                   f"{'-' if row['penetration_mm'] is None else format(float(row['penetration_mm']), '.3f')} mm"
                   + (f"; failing here: {', '.join(here)}" if here else "") + (f" ({row['reason']})" if row["reason"] else ""))
    return out


def request_lines(found) -> list[str]:
    """The request's lines of the summary: each state phrase with the parts it set (or why not), numbers asked vs
    achieved, warnings, words no rule used."""
    if found is None:
        return []
    out = [f"request      {p}" for p in (*found.phrases, *found.asked)]
    for q in found.quantities:
        if q.asked is None or q.achieved is None:
            continue
        frame = " from the closed end" if q.kind == "state" and q.unit in ("rad", "m") else ""
        asked = quantity_text(q.asked, q.unit) + ("" if q.asked_high is None else f" to {quantity_text(q.asked_high, q.unit)}")
        out.append(f"request      {q.what}: asked {asked}, got {quantity_text(q.achieved, q.unit)}{frame}"
                   + ("" if q.within_tolerance else f"  (MISSED, gap {quantity_text(abs(q.achieved - q.asked), q.unit)}: {q.why})"))
    out += [f"request      {w}" for w in found.warnings]
    if found.ignored:
        out.append("request      not understood: " + "; ".join(f"'{g}'" for g in found.ignored))
    return out


def _manipulation_line(report) -> str:
    """Joint sweep, robust rest, task execution and operating force of the post-check, one line."""
    parts = [f"{label} {'n/a' if m.passed is None else 'PASS' if m.passed else 'FAIL'}{_failures_text(m)}"
             for name, label in (("joint_sweep", "sweep"), ("robust_rest", "robust rest"), ("task_execution", "task"),
                                 ("operating_force", "force")) if (m := report.metric(name)) is not None]
    return "manipulation " + (", ".join(parts) if parts else "n/a")


def _operability_line(report) -> str:
    """The operability tier, one line: each handled part's peak operating force (and torque) against the top
    of its real range, and what fails."""
    m = report.metric("operability")
    if m is None or m.passed is None:
        return "operability  n/a" + (f" ({m.details['not_run']})" if m is not None and m.details.get("not_run") else "")
    parts = []
    for joint, e in (m.details.get("efforts") or {}).items():
        top = (e.get("force_range_n") or [None, None])[1]
        torque = "" if e.get("peak_torque_nm") is None else f", {e['peak_torque_nm']:.2f} N m"
        parts.append(f"{joint} ({e.get('label') or 'unlabelled'}) {e['peak_force_n']:.1f} N{torque}"
                     + (f" of {top:g} N" if top is not None else ""))
    return f"operability  {'PASS' if m.passed else 'FAIL'}: " + ", ".join(parts) + _failures_text(m)


def _failures_text(metric) -> str:
    """`` (F1; F2; F3)``: the first three failures a metric's details name ("" when none)."""
    fails = metric.details.get("failures") or []
    return f" ({'; '.join(fails[:3])})" if fails else ""


def _refine_failure(exc: RefineError, args: argparse.Namespace) -> CommandError:
    """The one-line failure of a refine run: status, code(s) (validation,
    fatal ``OVL_*``, ``ESTIMATOR_*``, ``OUTPUT_*`` ...) and path; the failure
    mode starts the message."""
    cause = exc.__cause__
    if isinstance(cause, OutputError):
        return failure(cause, NAME, args)
    codes = list(exc.codes)
    if isinstance(cause, OverlayInvalid) and not codes:
        codes = [i.code for i in cause.issues if i.severity == "error" and not i.fixed]
    mode = exc.failure_mode
    code = join_codes(codes) or mode.upper()
    status = INVALID_INPUT if mode == "invalid_input" and not isinstance(cause, (RequestTooLong, OverrideError)) else INVALID_REQUEST
    msg = str(exc).removeprefix(f"{args.asset}: ")
    if isinstance(cause, OverrideError) or "ESTIMATOR_UNAVAILABLE" in codes:  # an option's error: one sentence naming it
        return CommandError(status, code, None, msg)
    return CommandError(status, code, args.asset, f"{mode.replace('_', ' ')}: {msg}",
                        problems=finding_problems(cause, args.asset) if isinstance(cause, AssetError) else ())


def finding_problems(exc: AssetError, asset) -> list[tuple[str, str, str]]:
    """``(code, path, message)`` of each validation error of a refused asset, one problem each: the asset's path
    once, the file inside it (and line) and the link or joint in the message; ``... and N more`` past
    :data:`MESSAGE_FINDINGS`."""
    errors = [f for f in exc.findings if f.severity == "error"]
    out = []
    for f in errors[:MESSAGE_FINDINGS]:
        same = os.path.abspath(f.file) == os.path.abspath(asset) or (os.path.isfile(asset) and f.file == os.path.basename(asset))
        inside = f"line {f.line}: " if same and f.line else "" if same else (f"{f.file}:{f.line}: " if f.line else f"{f.file}: ")
        text = f.message.removeprefix(f"{f.file}: ").removeprefix(f"{asset}: ")
        where = "" if f.where == "global" or text.startswith(f.where) else f"{f.where}: "
        out.append((f.code, str(asset), f"invalid input: {inside}{where}{text}"))
    if len(errors) > MESSAGE_FINDINGS:
        out.append((join_codes(f.code for f in errors[MESSAGE_FINDINGS:]), str(asset),
                    f"invalid input: ... and {len(errors) - MESSAGE_FINDINGS} more (asset2sim validate lists them all)"))
    return out


def option_error(message: str, given: dict, state: dict) -> str:
    """An override's error as one sentence naming the option as typed: ``overrides: mass: unit missing in '30'; ...``
    -> ``--mass 30: unit missing in '30'; ...``, ``overrides: state: state lid: ...`` -> ``--state lid=5kg: ...``;
    a message about a field not given on the command line (``--config``'s) as it is."""
    text = message.removeprefix("overrides: ")
    field, _, rest = text.partition(": ")
    if field in given:
        return f"--{field} {given[field]}: {rest.removeprefix(f'{field}: ')}"
    if field == "state":
        name, _, why = rest.removeprefix("state ").partition(": ")
        if name in state:
            return f"--state {name}={state[name]}: {why}"
    return text


def options(args: argparse.Namespace) -> RefineConfig:
    """The run's :class:`RefineConfig`: ``--config``'s file, then the flags
    given (CommandError status 2 ``CONFIG_INVALID`` / ``OVERRIDE_INVALID``, or the code of a file refused unread:
    ``INPUT_NOT_REGULAR_FILE``, ``INPUT_TOO_LARGE``, ``YAML_ALIAS_LIMIT`` ...)."""
    try:
        base = load_config(args.config) if args.config else RefineConfig()
    except (OSError, ValueError) as exc:
        raise CommandError(INVALID_REQUEST, getattr(exc, "code", None) or "CONFIG_INVALID", args.config, str(exc)) from exc
    fields = {k: v for k in ("estimator", "model", "base_url", "request_parser") if (v := getattr(args, k)) is not None}
    fields |= {k: v for k in ("keep_declared", "open_containers", "body") if (v := getattr(args, k))}
    if args.no_clips:
        fields["clips"] = False
    if args.mjcf_angle:
        fields["mjcf"] = base.mjcf.model_copy(update={"angle": args.mjcf_angle})
    if args.engines or not args.config:
        listed = parse_engines(args.engines or ",".join(default_engines()))
        fields["engines"] = ["pybullet"] + [e for e in listed if e != "pybullet"]
    given = {k: v for k in ("mass", "size", "scale", "mount", "material") if (v := getattr(args, k)) is not None}
    state = {}
    for item in args.state or []:
        name, eq, value = item.partition("=")
        if not eq or not name.strip() or not value.strip():
            raise CommandError.invalid("OVERRIDE_INVALID", f"--state {item!r}: write NAME=VALUE, e.g. lid=30deg")
        state[name.strip()] = value.strip()
    try:
        overrides = merge_overrides(base.overrides, {**given, **({"state": state} if state else {})})
    except ValueError as exc:
        raise CommandError.invalid("OVERRIDE_INVALID", option_error(str(exc), given, state)) from exc
    return base.model_copy(update={**fields, "overrides": overrides})


#: The stages as the progress lines name them (``report.json``'s ``stage_seconds`` keeps the stages' own names).
STAGE_WORDS = {"extract": "read", "analyze": "geometry", "closed_state": "closed ends", "synthesize": "physics",
               "refine_state": "state", "post_check": "checks", "shut_repair": "repair", "sweep_repair": "repair",
               "skip": "kept"}


def wall_time_text(stage_seconds: dict[str, float]) -> str:
    """The wall time per stage in the progress lines' words (:data:`STAGE_WORDS`: ``shut_repair`` and ``sweep_repair``
    are one ``repair``), in stage order, each word once."""
    words: dict[str, float] = {}
    for k, v in stage_seconds.items():
        word = STAGE_WORDS.get(k, k.replace("_", " "))
        words[word] = words.get(word, 0.0) + float(v)
    return ", ".join(f"{k} {v:.2f}s" for k, v in words.items())


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()

    def progress(stage: str, message: str) -> None:
        line = f"[{time.perf_counter() - t0:6.2f}s] {STAGE_WORDS.get(stage, stage.replace('_', ' ')):<12} {message}"
        if message.startswith("WARNING"):  # warnings are printed with --quiet too, on stderr
            print(line, file=sys.stderr, flush=True)
        elif not (args.quiet or args.json):
            print(line, flush=True)

    config = options(args)
    try:
        with outside_paths(args):
            result = refine_stage.refine_asset(args.asset, args.prompt, args.out, config, category=args.category,
                                               task=args.task or None, progress=progress,
                                               skip_if_complete=not args.force, extras=not args.no_extras,
                                               overwrite=args.overwrite, media=not args.defer_media)
    except RefineError as exc:
        raise _refine_failure(exc, args) from exc
    print(json.dumps(json_summary(result), indent=2) if args.json else "\n".join(summary_lines(result)))
    return 0 if result.report.failure_mode == "none" else NOT_READY


def json_summary(result) -> dict:
    """``refine --json``: what a script needs of a refine, in one object: the output folder, the verdict (``ready``,
    ``failure_mode``, each tier), why it failed (the terminal's sentences), the report and the extra files written."""
    r = result.report
    return {"out_dir": str(result.out_dir), "ready": r.failure_mode == "none", "failure_mode": r.failure_mode,
            "readiness": dict(r.readiness), "why_it_failed": why_it_failed(r.metrics) if r.failure_mode != "none" else [],
            "report": str(Path(result.out_dir) / "report.json"), "files": dict(result.extras)}
