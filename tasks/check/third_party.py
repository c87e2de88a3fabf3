"""Third-party checkers on an output folder: ``urdf_parser_py`` (PyPI
``urdfdom-py``, ROS's), ``urdf-validator`` (command ``urdf_validate``),
``mjcf-doctor`` (on ``mjcf/mobility.xml``), Drake (``MultibodyPlant``:
inertia validity, damping read back) and, on request only (:data:`OPT_IN`: it
simulates in MuJoCo and PyBullet, up to minutes an object), ``simcheck``
(densities, inertia against geometry, pass-through, drops and sweeps). All are optional (extra ``checkers``);
a missing one raises :class:`CheckerUnavailable`. Findings are reported as
the tool gives them; false alarms are discussed in ``docs/design/simulators.md``.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import logging.handlers
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from asset2sim.engines.loading import read_urdf
from asset2sim.output_folder import URDF_NAME
from asset2sim.refined_asset import read_root

MJCF_PATH = "mjcf/mobility.xml"
#: Wall-clock limit for one run of a checker's command line (s).
COMMAND_TIMEOUT = 300


class CheckerUnavailable(RuntimeError):
    """The checker's package or command is not installed (names it)."""


@dataclass
class CheckerResult:
    """One checker on one file: ``errors`` and ``warnings`` as text, ``details`` tool-specific."""

    tool: str
    file: str
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    details: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return not self.errors


def _need_module(module: str, package: str) -> None:
    if importlib.util.find_spec(module) is None:
        raise CheckerUnavailable(f"{package} is not installed (pip install 'asset2sim[checkers]')")


def _command(name: str) -> str:
    """The checker's console script: next to this Python first, then PATH."""
    local = Path(sys.executable).with_name(name)
    if local.is_file():
        return str(local)
    found = shutil.which(name)
    if not found:
        raise CheckerUnavailable(f"command {name!r} not found (pip install 'asset2sim[checkers]')")
    return found


def _run(args: list[str], cwd: str) -> subprocess.CompletedProcess:
    """A checker's command line run in its scratch folder ``cwd``, output captured, within :data:`COMMAND_TIMEOUT`."""
    return subprocess.run(args, capture_output=True, text=True, timeout=COMMAND_TIMEOUT, cwd=cwd)


def _no_report(res: CheckerResult, proc: subprocess.CompletedProcess, what: str = "no report") -> CheckerResult:
    """``res`` with the error that the command left no report: its exit status and the tail of what it printed."""
    res.errors.append(f"{what} (exit {proc.returncode}): {(proc.stderr or proc.stdout).strip()[-300:]}")
    return res


def check_urdf_parser_py(urdf: Path) -> CheckerResult:
    """Parse ``urdf`` with ``urdf_parser_py``: errors the exception it raises,
    warnings what its ``on_error`` hook receives.

    Raises:
        CheckerUnavailable: urdfdom-py (urdf_parser_py) is not installed.
    """
    _need_module("urdf_parser_py", "urdfdom-py")
    from urdf_parser_py import xml_reflection
    from urdf_parser_py.urdf import URDF

    res = CheckerResult("urdf_parser_py", str(urdf))
    core = xml_reflection.core
    saved = core.on_error
    core.on_error = res.warnings.append
    try:
        robot = URDF.from_xml_string(Path(urdf).read_bytes())
        res.details = {"links": len(robot.links), "joints": len(robot.joints)}
    except Exception as exc:  # the parser's verdict on the file
        res.errors.append(f"{type(exc).__name__}: {' '.join(str(exc).split())}")
    finally:
        core.on_error = saved
    return res


def check_urdf_validator(urdf: Path) -> CheckerResult:
    """Run ``urdf_validate`` and read its JSON report (errors: critical issues,
    a non-PASS schema or a crash).

    Raises:
        CheckerUnavailable: urdf-validator is not installed.
    """
    cmd = _command("urdf_validate")
    res = CheckerResult("urdf-validator", str(urdf))
    with tempfile.TemporaryDirectory() as tmp:
        proc = _run([cmd, "--output-dir", tmp, str(Path(urdf).resolve())], tmp)
        reports = list(Path(tmp).glob("*.json"))
        if not reports:
            return _no_report(res, proc)
        rep = json.loads(reports[0].read_text())
    res.errors += [_text(x) for x in rep.get("critical_issues", [])]
    schema = rep.get("schema") or {}
    if schema.get("status") not in (None, "PASS"):
        res.errors += [f"schema: {_text(x)}" for x in schema.get("critical_issues", [])] or [f"schema {schema.get('status')}"]
    res.warnings += [_text(x) for x in rep.get("warnings", [])] + [f"schema: {_text(x)}" for x in schema.get("warnings", [])]
    res.details = {"overall_status": rep.get("overall_status"), "schema": schema.get("status"),
                   "statics": (rep.get("statics") or {}).get("status"), "links": len(rep.get("links") or [])}
    return res


def check_mjcf_doctor(xml: Path) -> CheckerResult:
    """Run ``mjcf-doctor check --json XML``; its ERROR and WARN findings as ``code subject: message``.

    Raises:
        CheckerUnavailable: mjcf-doctor is not installed.
    """
    cmd = _command("mjcf-doctor")
    res = CheckerResult("mjcf-doctor", str(xml))
    with tempfile.TemporaryDirectory() as tmp:  # MuJoCo appends its warnings to MUJOCO_LOG.TXT in the working directory
        proc = _run([cmd, "check", "--json", str(Path(xml).resolve())], tmp)
    out = proc.stdout
    start = out.find("\n[")
    try:
        reports = json.loads(out[start + 1:] if start >= 0 else out)
    except ValueError:
        return _no_report(res, proc, "no JSON report")
    for rep in reports:
        for f in rep.get("findings", []):
            _add(res, f.get("level"), f"{f.get('code')} {f.get('subject')}: {f.get('message')}", "ERROR", "WARN")
        res.details = {"errors": rep.get("errors"), "warnings": rep.get("warnings")}
    return res


def check_drake(urdf: Path) -> CheckerResult:
    """Parse ``urdf`` into a Drake ``MultibodyPlant``. Errors: the exception, each body
    whose spatial inertia is not physically valid, each joint whose damping Drake
    holds differently; warnings: Drake's parser warnings.

    Raises:
        CheckerUnavailable: drake is not installed.
    """
    _need_module("pydrake", "drake")
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant
    from pydrake.multibody.tree import BodyIndex, JointIndex

    res = CheckerResult("drake", str(urdf))
    handler = logging.handlers.BufferingHandler(sys.maxsize)
    handler.setLevel(logging.WARNING)
    log = logging.getLogger("drake")
    saved = log.handlers[:], log.propagate
    log.handlers, log.propagate = [handler], False  # collected, not printed
    try:
        plant = MultibodyPlant(0.0)
        Parser(plant).AddModels(str(urdf))
        plant.Finalize()
    except Exception as exc:  # Drake refuses the file
        res.errors.append(f"{type(exc).__name__}: {' '.join(str(exc).split())[:400]}")
        return res
    finally:
        log.handlers, log.propagate = saved
    for m in (r.getMessage() for r in handler.buffer):  # Drake's parser only warns about an invalid inertia and goes on
        (res.errors if "PhysicallyValid" in m else res.warnings).append(" ".join(m.split()))
    model = read_urdf(urdf)
    context = plant.CreateDefaultContext()
    world = plant.world_body().index()
    bodies = [b for b in (plant.get_body(BodyIndex(i)) for i in range(plant.num_bodies())) if b.index() != world]
    for body in bodies:
        si = body.CalcSpatialInertiaInBodyFrame(context)
        about_com = si.Shift(si.get_com()).CalcRotationalInertia()
        if not si.IsPhysicallyValid() or not about_com.CouldBePhysicallyValid():
            res.errors.append(f"link {body.name()!r}: spatial inertia not physically valid (mass {si.get_mass()}, "
                              f"principal moments about the COM {sorted(about_com.CalcPrincipalMomentsOfInertia())})")
    movable = {j.name for j in model.movable_joints}
    joints = [j for j in (plant.get_joint(JointIndex(i)) for i in range(plant.num_joints())) if j.name() in movable]
    for joint in joints:
        want = float(model.joint(joint.name()).damping)
        got = [float(x) for x in joint.default_damping_vector()]
        if any(abs(g - want) > 1e-9 * max(abs(want), 1e-12) for g in got):
            res.errors.append(f"joint {joint.name()!r}: Drake holds damping {got}, the URDF says {want}")
    res.details = {"bodies": len(bodies), "joints": len(joints),
                   "friction_ignored": [j.name for j in model.movable_joints if j.friction]}
    return res


def check_simcheck(urdf: Path) -> CheckerResult:
    """Run ``simcheck check --format json URDF`` (the root held as the output folder declares it); its error and
    warning findings as ``check: message``.

    Raises:
        CheckerUnavailable: simcheck is not installed.
    """
    cmd = _command("simcheck")
    res = CheckerResult("simcheck", str(urdf))
    root = "--fixed-base" if read_root(Path(urdf).parent).fixed else "--free-base"
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "simcheck.json"
        proc = _run([cmd, "check", "--object", root, "--no-config", "--no-cache", "--fail-on", "never", "-q",
                     "--json", str(report), str(Path(urdf).resolve())], tmp)
        if not report.is_file():
            return _no_report(res, proc)
        asset = json.loads(report.read_text())  # one object per file (a list for several)
    for check in asset.get("results", []):
        for f in check.get("findings", []):
            _add(res, f.get("severity"), f"{check.get('id')}: {f.get('message')}", "error", "warning")
    res.details = {"verdict": asset.get("verdict"), "score": asset.get("score"), "engines": asset.get("engines")}
    return res


def _add(res: CheckerResult, level: str | None, text: str, error: str, warning: str) -> None:
    """``text`` among ``res``'s errors when ``level`` is the tool's ``error``, its warnings when ``warning``."""
    {error: res.errors, warning: res.warnings}.get(level or "", []).append(text)


def _text(x) -> str:
    if isinstance(x, dict):
        return "; ".join(f"{k}={v}" for k, v in x.items() if v not in (None, "", []))
    return str(x)


#: checker name -> (function, file in the output folder it reads)
CHECKERS = {
    "urdf_parser_py": (check_urdf_parser_py, URDF_NAME),
    "urdf-validator": (check_urdf_validator, URDF_NAME),
    "drake": (check_drake, URDF_NAME),
    "mjcf-doctor": (check_mjcf_doctor, MJCF_PATH),
    "simcheck": (check_simcheck, URDF_NAME),
}
#: Checkers run only when named.
OPT_IN = {"simcheck"}


def run_checkers(out_dir: Path, names: list[str] | None = None) -> dict[str, CheckerResult | str]:
    """Every checker of :data:`CHECKERS` but :data:`OPT_IN` (or ``names``) on an output folder:
    name -> :class:`CheckerResult`, or why it did not run.

    Raises:
        KeyError: an unknown checker name.
    """
    out_dir = Path(out_dir)
    out: dict[str, CheckerResult | str] = {}
    for name in names or [n for n in CHECKERS if n not in OPT_IN]:
        fn, rel = CHECKERS[name]
        path = out_dir / rel
        if not path.is_file():
            out[name] = f"skipped: {rel} not in {out_dir}"
            continue
        try:
            out[name] = fn(path)
        except CheckerUnavailable as exc:
            out[name] = f"skipped: {exc}"
    return out
