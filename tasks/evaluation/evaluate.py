"""Evaluate any URDF asset: the interaction-readiness protocol as one task.

:func:`evaluate_asset` loads a URDF (with ``initial_state.json`` beside it when
present), runs every registered metric under the SPEC's conventions
(``asset2sim.engines.base``) and returns an :class:`Evaluation`; it writes
``evaluation.json`` and a self-contained ``report.html`` when asked.

Metrics are registered with :func:`register_metric`; each returns
:class:`~asset2sim.schemas.report.MetricResult` objects (value, unit,
pass/fail, threshold, details). The registry holds, in order:

physical robustness (per engine)
    ``penetration`` (Phi at the initial state, mm, link pairs; from
    :mod:`asset2sim.tasks.check.metrics`), ``ground_penetration`` (mm),
    ``rest_stability`` and ``oscillation`` (:mod:`asset2sim.tasks.check.metrics`),
    ``divergence`` (NaN or explosion), ``joint_hold`` (a requested state that
    sags, a lid that snaps shut).
semantic accuracy
    ``scale_deviation``, ``initial_joint_deviation``, ``total_mass``
    (:mod:`asset2sim.tasks.evaluation.semantic_metrics`), ``prompt_alignment``.
behaviour
    ``probes`` (:mod:`asset2sim.tasks.check.probes`, PyBullet only).

Definitions, conventions and thresholds are in ``docs/metrics.md``. The
SPEC's rest test is run once per engine and shared by the rest-test metrics.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr

from asset2sim.atomic import write_json
from asset2sim.engines.base import EngineUnavailable, SessionOptions, Spring, open_session
from asset2sim.schemas.config import RefineConfig, SimConventions
from asset2sim.schemas.metrics import METRIC_INFO, REST_TEST_METRICS
from asset2sim.schemas.report import MetricResult, RefineReport
from asset2sim.tasks.check import metrics as spec_metrics
from asset2sim.tasks.check.postcheck import RestRecording, measure_rest_test, record_rest_test
from asset2sim.tasks.evaluation import semantic_metrics as sem
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.publish.report_html import write_report
from asset2sim.urdf import UrdfError, read_urdf

EVALUATION_VERSION = "1"

#: Largest ground penetration during the rest test that passes, m.
GROUND_PENETRATION_TOL = 0.005
#: Explosion thresholds (divergence): root speed m/s, revolute rad/s, prismatic m/s.
EXPLOSION_ROOT_SPEED = 10.0
EXPLOSION_JOINT_SPEED_REVOLUTE = 100.0
EXPLOSION_JOINT_SPEED_PRISMATIC = 10.0
#: Root travel that counts as an explosion: max(1 m, 5 x largest extent).
EXPLOSION_TRAVEL_MIN = 1.0
EXPLOSION_TRAVEL_FACTOR = 5.0

_MOVABLE = ("revolute", "continuous", "prismatic")


class EvaluationError(ValueError):
    """The asset cannot be evaluated (message names the file and why)."""


# ------------------------------------------------------------------ results
class Evaluation(BaseModel):
    """Contents of ``evaluation.json``.

    ``metrics``: every metric result (one per engine for the simulator metrics).
    ``passed``: every metric that has a verdict passed. ``failures``: names of
    the failed metrics (``name@engine``). ``scale`` dimensionless (relative to
    the raw input); ``initial_state`` rad/m; ``seconds`` wall time of the
    evaluation without report writing.
    """

    model_config = ConfigDict(extra="forbid")
    version: str = EVALUATION_VERSION
    asset_id: str
    urdf: str
    method: str | None = None
    prompt: str | None = None
    reference: str | None = None
    category: str | None = None
    scale: float | None = None
    scale_source: str = ""
    engines: list[str] = Field(default_factory=list)
    seed: int = 0
    initial_state: dict[str, float] = Field(default_factory=dict)
    initial_state_source: str = ""
    task_joints: list[str] = Field(default_factory=list)
    closed_positions: dict[str, dict[str, float]] = Field(default_factory=dict)
    metrics: list[MetricResult] = Field(default_factory=list)
    passed: bool = False
    failures: list[str] = Field(default_factory=list)
    notes: list[str] = Field(default_factory=list)
    seconds: float = 0.0
    _runs: dict[str, "EngineRun"] = PrivateAttr(default_factory=dict)
    _context: Any = PrivateAttr(default=None)

    def metric(self, name: str, engine: str | None = None) -> MetricResult | None:
        """The first metric called ``name`` (of ``engine`` when given)."""
        for m in self.metrics:
            if m.name == name and (engine is None or m.engine in (engine, "none")):
                return m
        return None


# ------------------------------------------------------------------ context
@dataclass
class JointInfo:
    """A joint as written in the URDF (limits rad/m, dynamics SI or None)."""

    name: str
    type: str
    parent: str
    child: str
    lower: float | None
    upper: float | None
    damping: float | None
    friction: float | None


@dataclass
class LinkInfo:
    """A link as written in the URDF (mass kg or None without ``<inertial>``)."""

    name: str
    mass: float | None
    has_collision: bool
    has_visual: bool


@dataclass
class ClosedEnd:
    """Closed end of a joint: q_closed (rad/m), opening direction +-1, the
    largest opening from q_closed (rad/m) and where it came from."""

    q_closed: float
    direction: float
    open_range: float
    source: str

    def fraction(self, q: float) -> float:
        if self.open_range <= 0:
            return 0.0
        return float(self.direction * (q - self.q_closed) / self.open_range)


@dataclass
class Context:
    """Everything the metrics need besides the simulator runs."""

    urdf: Path
    folder: Path
    asset_id: str
    links: dict[str, LinkInfo]
    joints: dict[str, JointInfo]
    initial_state: dict[str, float]
    initial_state_source: str
    overlay: dict[str, Any] | None
    report: dict[str, Any] | None
    baseline: dict[str, Any] | None
    semantics: dict[str, tuple[str, str]]
    category: str | None
    prompt: str | None
    request: Any  # schemas.request.RequestSpec | None
    request_error: str | None
    reference_dir: Path | None
    reference_scale: float | None
    reference_state: dict[str, float]
    reference_rule: str
    scale: float | None
    scale_source: str
    task_joints: list[str]
    closed: dict[str, ClosedEnd]
    springs: dict[str, Spring]
    prior: dict[str, Any]
    conventions: SimConventions
    sag_tol_revolute: float
    sag_tol_prismatic: float
    notes: list[str] = field(default_factory=list)
    closed_extents: np.ndarray | None = None
    """(3,) m: AABB of the object with every joint at its closed end (file frame)."""

    @property
    def movable(self) -> list[str]:
        return [n for n, j in self.joints.items() if j.type in _MOVABLE]


@dataclass
class EngineRun:
    """Raw measurements in one engine (shared by the metrics)."""

    engine: str
    error: str | None = None
    penetration: MetricResult | None = None
    trace: spec_metrics.RestTrace | None = None
    ground_series: np.ndarray | None = None
    """(K,) m: deepest ground penetration after each recorded step (settle + test)."""
    root_series: np.ndarray | None = None
    """(K, 3) m: root position after each step (settle + test)."""
    joint_series: dict[str, np.ndarray] = field(default_factory=dict)
    extents: np.ndarray | None = None
    """(3,) m: AABB of every link with collision at the initial state."""
    link_centres: dict[str, np.ndarray] = field(default_factory=dict)
    masses: dict[str, dict[str, Any]] = field(default_factory=dict)
    probes: list[Any] = field(default_factory=list)
    point_cloud: dict[str, np.ndarray] = field(default_factory=dict)
    """link -> (N, 3) m collision vertices in the world at the initial state (report)."""
    seconds: float = 0.0


# ------------------------------------------------------------------ registry
MetricFn = Callable[[Context, dict[str, EngineRun]], list[MetricResult]]


@dataclass
class MetricSpec:
    """A registered metric: ``fn(context, runs) -> [MetricResult]``; ``group``
    ``physical`` / ``semantic`` / ``behaviour``; ``description`` one line."""

    name: str
    group: str
    fn: MetricFn
    description: str


METRICS: dict[str, MetricSpec] = {}


def register_metric(name: str, group: str | None = None, description: str | None = None) -> Callable[[MetricFn], MetricFn]:
    """Decorator registering ``fn(context, runs) -> list[MetricResult]`` for
    metric ``name``; ``group`` and ``description`` default to the registry
    table's (:data:`asset2sim.schemas.metrics.METRIC_INFO`)."""
    info = METRIC_INFO.get(name)

    def deco(fn: MetricFn) -> MetricFn:
        METRICS[name] = MetricSpec(name, group or (info.group if info else "physical"), fn,
                                   description or (info.description if info else ""))
        return fn

    return deco


def metric_names() -> list[str]:
    """Registered metric names in evaluation order."""
    return list(METRICS)


# ------------------------------------------------------------------ reading
def find_urdf(path: Path | str) -> Path:
    """The URDF of ``path`` (:func:`asset2sim.tasks.ingest.partnet_mobility.find_urdf`: the file
    itself, else ``mobility.urdf``, else the only ``*.urdf`` not named
    ``reference_*``).

    Raises:
        EvaluationError: nothing (or several candidates) found.
    """
    try:
        return partnet_mobility.find_urdf(path)
    except AssetError as exc:
        raise EvaluationError(str(exc)) from exc


def parse_urdf(urdf: Path) -> tuple[dict[str, LinkInfo], dict[str, JointInfo]]:
    """Links and joints of a URDF as written, read by :func:`asset2sim.urdf.read_urdf`
    in lenient mode (raw PartNet-Mobility and GenSim2 reference files are graded too).

    Raises:
        EvaluationError: unreadable XML or a malformed number (names the file,
            line and link or joint).
    """
    try:
        model = read_urdf(urdf, mode="lenient")
    except UrdfError as exc:
        raise EvaluationError(f"unreadable URDF: {exc}") from exc
    links = {
        name: LinkInfo(name, None if ln.inertial is None else ln.inertial.mass, bool(ln.collisions), bool(ln.visuals))
        for name, ln in model.links.items()
    }
    joints = {}
    for jt in model.joints:
        lim, dyn = jt.limit, jt.dynamics
        joints[jt.name] = JointInfo(
            name=jt.name,
            type=jt.type,
            parent=jt.parent,
            child=jt.child,
            lower=None if lim is None else lim.lower,
            upper=None if lim is None else lim.upper,
            damping=None if dyn is None else dyn.damping,
            friction=None if dyn is None else dyn.friction,
        )
    return links, joints


def _read_json(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, OSError) as exc:
        raise EvaluationError(f"{path}: unreadable JSON: {exc}") from exc
    return data if isinstance(data, dict) else None


def _read_semantics(folder: Path) -> dict[str, tuple[str, str]]:
    """``semantics.txt`` (:func:`asset2sim.tasks.ingest.partnet_mobility.read_semantics`);
    malformed files read as empty (evaluation works on any URDF)."""
    try:
        return partnet_mobility.read_semantics(folder)
    except AssetError:
        return {}


def _read_category(folder: Path) -> str | None:
    return partnet_mobility.read_category(folder)


def _clip(q: float, lo: float | None, hi: float | None) -> float:
    if lo is not None and math.isfinite(lo):
        q = max(q, lo)
    if hi is not None and math.isfinite(hi):
        q = min(q, hi)
    return float(q)


# ------------------------------------------------------------------ lazily provided parts
def parse_prompt(prompt: str | None) -> tuple[Any, str | None]:
    """RequestSpec of ``prompt`` via :func:`asset2sim.tasks.interpret.request.parse_request`.

    Returns (spec or None, error message or None).
    """
    if not prompt:
        return None, None
    try:
        from asset2sim.tasks.interpret.request import parse_request
    except ImportError as exc:
        return None, f"request parser not available ({exc})"
    try:
        return parse_request(prompt), None
    except Exception as exc:  # a parser failure must not stop the evaluation
        return None, f"request parser failed: {type(exc).__name__}: {exc}"


def category_prior(category: str | None, spec=None) -> dict[str, Any]:
    """Size target and mass prior of a category from :mod:`asset2sim.tasks.interpret.priors`.

    Args:
        category: category name (canonical, model_cat or synonym).
        spec: the parsed request (size words, variants such as "mini fridge").

    Returns:
        {} when the priors are unavailable or no category is known, else
        {"category", "target_dims" (m, largest first, size words applied),
        "base_dims" (m, regular or the variant's), "factor", "variant",
        "base_mass_range" (kg, for ``base_dims``), "note", "source"}.
    """
    if not category:
        return {}
    try:
        from asset2sim.tasks.interpret import priors
    except ImportError:
        return {}
    try:
        t = priors.target_size(category, spec)
        cat = priors.category_prior(category)
        base_mass = cat.mass_range
        if t.variant:
            var = next((v for v in cat.variants if v.name == t.variant), None)
            if var is not None:
                base_mass = var.mass_range
    except Exception:
        return {}
    return {
        "category": t.category,
        "target_dims": [float(x) for x in t.dims],
        "base_dims": [float(x) for x in t.base_dims],
        "factor": float(t.factor),
        "variant": t.variant,
        "base_mass_range": (float(base_mass[0]), float(base_mass[1])),
        "note": t.note,
        "source": f"asset2sim/priors/categories.yaml: {cat.dims_source}; {cat.mass_source}",
    }


def scaled_mass_range(prior: dict[str, Any], extents: Any) -> tuple[tuple[float, float] | None, float]:
    """Plausible mass range (kg) for an object of the prior's category with
    closed-state ``extents`` (3,) m: the base range scaled by
    :func:`asset2sim.tasks.interpret.priors.scale_mass_range` (solid f^3 to thin-walled
    f^2) with f the geometric mean of (extent / base dimension) over the two
    largest dimensions, both sorted — the same size factor the refine stage
    uses (``tasks.estimate.plausible_mass_range``). Returns (range or None, f)."""
    if not prior or not prior.get("base_mass_range"):
        return None, 1.0
    lo, hi = prior["base_mass_range"]
    f = 1.0
    ext = None if extents is None else np.sort(np.asarray(extents, float).ravel())[::-1]
    if ext is not None and len(ext) >= 2 and prior.get("base_dims") and float(ext[0]) > 0:
        base = np.sort(np.asarray(prior["base_dims"], float))[::-1]
        f = float(np.exp(np.mean(np.log(np.maximum(ext[:2], 1e-9) / base[:2]))))
    try:
        from asset2sim.tasks.interpret.priors import scale_mass_range

        return scale_mass_range(lo, hi, f), f
    except Exception:
        return (lo * f**3, hi * f**3), f


def recognize_category(prompt: str | None, model_cat: str | None = None, labels: list[str] | None = None) -> str | None:
    """Category from the request, ``model_cat`` and semantic labels via
    :func:`asset2sim.tasks.interpret.priors.recognize_category`; None when unavailable."""
    if not prompt and not model_cat:
        return None
    try:
        from asset2sim.tasks.interpret.priors import recognize_category as rc
    except ImportError:
        return model_cat
    try:
        m = rc(model_cat, labels or [], prompt or "")
    except Exception:
        return model_cat
    return getattr(m, "name", None) or model_cat


# ------------------------------------------------------------------ scale
def infer_scale_from_geometry(urdf: Path, raw_urdf: Path) -> float | None:
    """Uniform scale of ``urdf`` relative to ``raw_urdf`` from geometry.

    Both are loaded in PyBullet (fixed base, no gravity, joints at 0 clipped to
    their limits); s = largest extent of the box bounding the evaluated
    asset's collision hull vertices / that of the raw asset
    (:func:`_geometry_extents`). Used only when no ``overlay.json``,
    ``report.json`` or ``baseline.json`` states the scale. Returns None when
    either cannot be measured.
    """
    exts = []
    for path in (urdf, raw_urdf):
        try:
            s = open_session("pybullet", path, SessionOptions(fixed_base=True, gravity=False, ground=False))
        except Exception:
            return None
        try:
            try:
                from asset2sim.tasks.ingest.extract import extract_asset

                desc = extract_asset(path)
                hull = _hull_points(desc)
            except Exception:
                desc, hull = None, None
            q0 = {n: _clip(0.0, *s.joint_limits[n]) for n in s.joint_names}
            exts.append(_geometry_extents(s, desc, q0, hull))
        finally:
            s.close()
    a, b = float(np.max(exts[0])), float(np.max(exts[1]))
    return a / b if a > 0 and b > 0 else None


def _hull_points(desc) -> dict[str, np.ndarray] | None:
    """Convex-hull vertices per link (link frame) via
    :func:`asset2sim.tasks.geometry.closed_state.link_hull_points`, or None."""
    try:
        from asset2sim.tasks.geometry.closed_state import link_hull_points

        return link_hull_points(desc)
    except Exception:
        return None


def _geometry_extents(session, desc, state: dict[str, float], hull: dict[str, np.ndarray] | None) -> np.ndarray:
    """Extents (3,) m of the box bounding the links' collision hull vertices at
    ``state`` (:func:`asset2sim.tasks.geometry.closed_state.object_extents`). Bullet's
    own AABBs are loose for a link whose inertia tensor has off-diagonal terms
    (the shape sits rotated in the principal-axes frame and its box is
    re-bounded: 0.67 m instead of 0.39 m for a refined toilet), so they are
    only the fallback."""
    try:
        from asset2sim.tasks.geometry.closed_state import object_extents

        if hull is not None:
            return np.asarray(object_extents(session, state, desc, hull), float)
    except Exception:
        pass
    session.set_joint_positions(state)
    return _extents(session)


def _extents(session) -> np.ndarray:
    """Extents (3,) m of the union of Bullet's link AABBs (loose; see
    :func:`_geometry_extents`)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for name in session.link_names:
        if not session.link_has_collision(name):
            continue
        a, b = session.link_aabb(name)
        lo, hi = np.minimum(lo, a), np.maximum(hi, b)
    if not np.all(np.isfinite(lo)):
        return np.zeros(3)
    return np.maximum(hi - lo, 0.0)


# ------------------------------------------------------------------ context building
def _task_joints(ctx_joints: dict[str, JointInfo], reference_dir: Path | None, requested: list[str]) -> tuple[list[str], str]:
    movable = [n for n, j in ctx_joints.items() if j.type in _MOVABLE]
    if reference_dir is not None:
        ref = partnet_mobility.read_reference(reference_dir)
        tj = [j for j in ref.task_joints if j in movable]
        if tj:
            return tj, "movable joints of reference_gensim2.urdf"
    if requested:
        return [j for j in movable if j in requested], "joints the request names"
    return movable, "every movable joint"


def _match_label(label: str | None, wanted: str | None, category: str | None = None) -> bool:
    """Whether the request's part word ``wanted`` names a link labelled
    ``label``: :func:`asset2sim.tasks.interpret.priors.request_label_matches` (canonical
    labels and the category's synonyms, e.g. a laptop's "lid" is its
    ``screen``); without the priors, equal labels or ``wanted`` as one of the
    ``_``-separated words of ``label``."""
    if not label or not wanted:
        return False
    try:
        from asset2sim.tasks.interpret.priors import request_label_matches
    except ImportError:
        request_label_matches = None
    if request_label_matches is not None:
        try:
            return bool(request_label_matches(category or "Generic", wanted, label))
        except Exception:
            pass
    label, wanted = label.lower(), wanted.lower()
    return wanted == label or wanted in label.split("_")


def requested_joints(spec, joints: dict[str, JointInfo], semantics: dict[str, tuple[str, str]],
                     centres: dict[str, np.ndarray], task_joints: list[str],
                     category: str | None = None) -> tuple[list[tuple[str, str, str | None, str]], list[str]]:
    """Map a RequestSpec's joint states to joints.

    ``selector == "all"``: every task-relevant joint. ``label``: movable joints
    whose child link's semantic label the request's word names
    (:func:`_match_label`), ordered top to bottom by the height of the child
    link's AABB centre (then by x); ``ordinal`` picks one. A label that names
    no part falls back to the task-relevant joints (the pipeline's convention,
    :func:`asset2sim.tasks.interpret.priors.request_label_matches`); a phrase that still
    maps to nothing is returned as unmatched. A later phrase overrides an
    earlier one for the same joint.

    Returns:
        ([(joint, band, label, phrase)], [phrases that matched no joint]).
    """
    out, unmatched = [], []
    if spec is None:
        return out, unmatched
    movable = [n for n, j in joints.items() if j.type in _MOVABLE]
    zero = np.zeros(3)
    for js in spec.joint_states:
        if js.selector == "all":
            names = list(task_joints)
        else:
            names = [n for n in movable if _match_label(semantics.get(joints[n].child, (None, None))[1], js.label, category)]
            if not names:
                names = [n for n in task_joints if n in movable]
            names.sort(key=lambda n: (-float(centres.get(joints[n].child, zero)[2]), float(centres.get(joints[n].child, zero)[0])))
            if js.ordinal is not None:
                names = [names[js.ordinal]] if 0 <= js.ordinal < len(names) else []
        if not names:
            unmatched.append(js.phrase or f"{js.label or 'all'} {js.band}")
        for n in names:
            out.append((n, js.band, semantics.get(joints[n].child, (None, None))[1], js.phrase))
    dedup: dict[str, tuple[str, str, str | None, str]] = {}
    for item in out:
        dedup[item[0]] = item
    return list(dedup.values()), unmatched


def _closed_fallback(j: JointInfo) -> ClosedEnd:
    """Closed end without geometry: the limit nearest 0 (continuous: 0, range pi)."""
    lo, hi = j.lower, j.upper
    if j.type == "continuous" or lo is None or hi is None or lo > hi:
        return ClosedEnd(0.0, 1.0, math.pi, "fallback: continuous joint, 0 taken as closed")
    qc = lo if abs(lo) <= abs(hi) else hi
    d = 1.0 if qc == lo else -1.0
    return ClosedEnd(float(qc), d, float(hi - lo), "fallback: the limit nearest 0")


def compute_closed(urdf: Path, joints: dict[str, JointInfo], names: list[str],
                   extents_out: list | None = None) -> tuple[dict[str, ClosedEnd], list[str]]:
    """Closed end of each joint in ``names`` (rad or m, the URDF's units).

    Source: :func:`asset2sim.tasks.geometry.closed_state.closed_positions` (geometric,
    computed here for every method alike, so no method grades itself) in a
    fresh fixed-base, gravity-free PyBullet session; else (module missing or
    failing) the limit nearest 0, opening towards the other limit.

    Args:
        urdf: the evaluated URDF.
        joints: its joints (:func:`parse_urdf`).
        names: joints to report.
        extents_out: when given, the (3,) m AABB extents of the object with
            every joint at its closed end are appended to it.

    Returns:
        (joint -> :class:`ClosedEnd`, notes).
    """
    notes: list[str] = []
    out: dict[str, ClosedEnd] = {}
    if not names:
        return out, notes
    try:
        from asset2sim.tasks.geometry.closed_state import closed_positions
        from asset2sim.tasks.ingest.extract import extract_asset
    except ImportError as exc:
        notes.append(f"closed_state not available ({exc}); closed end = limit nearest 0")
        return {n: _closed_fallback(joints[n]) for n in names}, notes
    try:
        desc = extract_asset(urdf)
        s = open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False))
        try:
            hull = _hull_points(desc)
            cs = closed_positions(s, desc, **({"hull_points": hull} if hull is not None else {}))
            if extents_out is not None:
                extents_out.append(_geometry_extents(s, desc, {n: c.q_closed for n, c in cs.items()}, hull))
        finally:
            s.close()
        for n in names:
            c = cs.get(n)
            if c is None or not c.open_range > 0:
                out[n] = _closed_fallback(joints[n])
            else:
                out[n] = ClosedEnd(float(c.q_closed), float(c.direction), float(c.open_range), "geometry (closed_state)")
    except Exception as exc:
        notes.append(f"closed_positions failed ({type(exc).__name__}: {exc}); closed end = limit nearest 0")
        out = {n: _closed_fallback(joints[n]) for n in names}
    return out, notes


def build_context(
    asset: Path | str,
    *,
    reference: Path | str | None = None,
    prompt: str | None = None,
    category: str | None = None,
    conventions: SimConventions | None = None,
) -> Context:
    """Read the asset and its sidecars, the reference and the request.

    Raises:
        EvaluationError: no URDF, unreadable URDF/JSON, a reference folder that
            does not exist.
    """
    urdf = find_urdf(asset).resolve()
    folder = urdf.parent
    links, joints = parse_urdf(urdf)
    notes: list[str] = []
    overlay = _read_json(folder / "overlay.json")
    report = _read_json(folder / "report.json")
    baseline = _read_json(folder / "baseline.json")
    st = _read_json(folder / "initial_state.json")
    movable = [n for n, j in joints.items() if j.type in _MOVABLE]
    if st is not None:
        raw = st.get("initial_joint_positions", st)
        initial = {k: float(v) for k, v in raw.items() if k in joints}
        src = "initial_state.json"
    else:
        initial, src = {}, "none: 0 clipped to the limits"
    for n in movable:
        if n not in initial:
            initial[n] = _clip(0.0, joints[n].lower, joints[n].upper)
    ref_dir = Path(reference).resolve() if reference is not None else None
    if ref_dir is not None and not ref_dir.is_dir():
        raise EvaluationError(f"reference {ref_dir}: no such folder")
    semantics = _read_semantics(folder) or (_read_semantics(ref_dir) if ref_dir else {})
    cat = (
        category
        or (overlay or {}).get("category")
        or (report or {}).get("category")
        or (baseline or {}).get("category")
        or recognize_category(prompt, _read_category(folder) or (_read_category(ref_dir) if ref_dir else None),
                              [lab for _, lab in semantics.values()])
    )
    spec, req_err = parse_prompt(prompt)
    if req_err:
        notes.append(req_err)
    # reference
    ref_scale = None
    ref_state: dict[str, float] = {}
    rule = ""
    ref_info = None
    if ref_dir is not None:
        from asset2sim.tasks.evaluation.baselines import urdf_joints

        ref_info = partnet_mobility.read_reference(ref_dir)
        ref_scale = ref_info.scale
    # scale of the evaluated asset
    scale, scale_src = None, "unknown"
    if overlay is not None and isinstance(overlay.get("scale"), (int, float)):
        scale, scale_src = float(overlay["scale"]), "overlay.json"
    elif report is not None and isinstance(report.get("scale"), (int, float)):
        scale, scale_src = float(report["scale"]), "report.json"
    elif baseline is not None and isinstance(baseline.get("scale"), (int, float)):
        scale, scale_src = float(baseline["scale"]), "baseline.json"
    elif ref_dir is not None and (ref_dir / "mobility.urdf").is_file():
        inferred = infer_scale_from_geometry(urdf, ref_dir / "mobility.urdf")
        if inferred is not None:
            scale, scale_src = inferred, "geometry: largest AABB extent vs the raw mobility.urdf at q = 0"
    conv = conventions or SimConventions()
    # springs
    springs: dict[str, Spring] = {}
    for jn, jd in ((overlay or {}).get("joints") or {}).items():
        k = float(jd.get("stiffness") or 0.0)
        if k > 0 and jn in joints:
            ref_q = jd.get("spring_reference")
            springs[jn] = Spring(k, float(ref_q) if ref_q is not None else initial.get(jn, 0.0))
    ctx = Context(
        urdf=urdf,
        folder=folder,
        asset_id=(report or {}).get("asset_id") or (baseline or {}).get("asset_id") or folder.name,
        links=links,
        joints=joints,
        initial_state=initial,
        initial_state_source=src,
        overlay=overlay,
        report=report,
        baseline=baseline,
        semantics=semantics,
        category=cat,
        prompt=prompt,
        request=spec,
        request_error=req_err,
        reference_dir=ref_dir,
        reference_scale=ref_scale,
        reference_state=ref_state,
        reference_rule=rule,
        scale=scale,
        scale_source=scale_src,
        task_joints=[],
        closed={},
        springs=springs,
        prior=category_prior(cat, spec),
        conventions=conv,
        sag_tol_revolute=RefineConfig().sag_tolerance_revolute,
        sag_tol_prismatic=RefineConfig().sag_tolerance_prismatic,
        notes=notes,
    )
    # reference state (output units of the evaluated asset)
    if ref_info is not None and ref_info.urdf is not None:
        rj = urdf_joints(ref_info.urdf)
        rng = ref_info.joint_position_range
        for n in ref_info.task_joints:
            if n not in joints:
                continue
            jr = rj[n]
            q = rng[0] if rng is not None else 0.0
            q = _clip(q, jr["lower"], jr["upper"])
            if jr["type"] == "prismatic":
                q *= scale if scale is not None else (ref_scale or 1.0)
            ref_state[n] = q
        ctx.reference_rule = (
            "lower end of joint_position_range" if rng is not None else "0"
        ) + " clipped to reference_gensim2.urdf's limits (prismatic x the evaluated scale)"
    return ctx


# ------------------------------------------------------------------ simulation
def _link_centres(session) -> dict[str, np.ndarray]:
    out = {}
    for name in session.link_names:
        a, b = session.link_aabb(name)
        out[name] = 0.5 * (a + b)
    return out


def _masses(session, links: dict[str, LinkInfo]) -> dict[str, dict[str, Any]]:
    out = {}
    for name, m in session.link_masses().items():
        li = links.get(name)
        out[name] = {"mass": m, "source": "file <inertial>" if li is not None and li.mass is not None else "engine default (no <inertial>)"}
    return out


def _point_cloud(session, max_points: int = 1500) -> dict[str, np.ndarray]:
    out = {}
    for name in session.link_names:
        v = session.link_collision_vertices(name)
        if not len(v):
            continue
        pos, R = session.link_frame(name)
        w = v @ R.T + pos
        if len(w) > max_points:
            w = w[np.linspace(0, len(w) - 1, max_points).astype(int)]
        out[name] = w
    return out


def run_engine(ctx: Context, engine: str, *, probes: bool = True, keep_geometry: bool = False,
               closed_for: list[str] | None = None, rest_test: bool = True,
               recording: RestRecording | None = None) -> EngineRun:
    """Open ``engine`` on the asset and take every raw measurement once:
    penetration at the initial state, extents, masses, the SPEC rest test with
    per-step root/ground recording, and (PyBullet) the probes from the initial
    state. ``closed_for``: joints whose closed end is computed in this
    (PyBullet) session into ``ctx.closed`` before anything is stepped.
    ``rest_test=False``: no rest test (its measurement was taken elsewhere,
    e.g. by the post-check); ``trace`` and the series stay None.
    ``recording``: the post-check's step-by-step rest test
    (:class:`~asset2sim.tasks.check.postcheck.RestRecording`); when it
    :meth:`~asset2sim.tasks.check.postcheck.RestRecording.matches` this
    engine, URDF, initial state, springs and conventions, its trace and
    series are recorded and the rest test is not simulated again. With
    probes, a rest test still to be simulated runs in a session of its own
    (:func:`~asset2sim.tasks.check.postcheck.measure_rest_test`, as in the
    post-check), so the probes start from a session that was never stepped
    whether or not the rest test was reused: Bullet's ``restoreState`` puts
    back poses and velocities but not everything a rest test leaves behind
    (the probes measured after a rest test and a restore differed by up to
    ~1e-3 relative from those measured without one). Errors are caught into
    ``EngineRun.error``."""
    t0 = time.perf_counter()
    run = EngineRun(engine)
    try:
        session = open_session(engine, ctx.urdf, SessionOptions(initial_state=dict(ctx.initial_state), springs=dict(ctx.springs), conventions=ctx.conventions))
    except EngineUnavailable as exc:
        run.error = f"engine unavailable: {exc}"
        return run
    except Exception as exc:
        run.error = f"could not load: {type(exc).__name__}: {exc}"
        return run
    try:
        pyb = session.engine == "pybullet"  # the reference engine takes the extra measurements
        # Phi first, in the fresh session: Bullet keeps contact manifolds (up to 4
        # cached points per pair) across later queries and restoreState, so Phi
        # "at the initial state" is only history-free at the first query.
        run.penetration = spec_metrics.penetration(session)
        saved = None
        if pyb:
            run.extents = _extents(session)
            run.link_centres = _link_centres(session)
            run.masses = _masses(session, ctx.links)
            if keep_geometry:
                run.point_cloud = _point_cloud(session)
            saved = session.save_state()
        if rest_test:
            if recording is None or not recording.matches(engine, ctx.urdf, ctx.initial_state, ctx.springs, ctx.conventions):
                if pyb and probes:  # in a session of its own, as the post-check does: the probes start unstepped
                    _, recording = measure_rest_test(engine, ctx.urdf, ctx.initial_state, ctx.springs, ctx.conventions)
                else:
                    recording = record_rest_test(session, ctx.conventions, ctx.urdf, ctx.initial_state, ctx.springs)
            run.trace = recording.trace
            run.root_series = recording.root_series
            run.ground_series = recording.ground_series
            run.joint_series = recording.joint_series
        if pyb and closed_for is not None:
            # In a fresh fixed-base session: contact manifolds cached here would
            # change the closed ends' penetration tie-breaks.
            ext: list = []
            ctx.closed, cnotes = compute_closed(ctx.urdf, ctx.joints, closed_for, extents_out=ext)
            ctx.closed_extents = ext[0] if ext else None
            ctx.notes += cnotes
        if pyb and probes and saved is not None:
            from asset2sim.tasks.check.probes import run_probes

            session.restore_state(saved)
            targets = {
                n: (c.q_closed, c.direction, c.open_range)
                for n, c in ctx.closed.items()
                if n in ctx.task_joints and c.open_range > 0
            }
            holds = bool(getattr(ctx.request, "holds_position", False))
            run.probes = run_probes(session, targets, holds_position=holds)
    except Exception as exc:
        run.error = f"{type(exc).__name__}: {exc}"
    finally:
        session.close()
    run.seconds = time.perf_counter() - t0
    return run


# ------------------------------------------------------------------ metrics
def _skip(name: str, unit: str, engine: str, reason: str) -> MetricResult:
    return MetricResult(name=name, value=None, unit=unit, passed=None, threshold="", details={"skipped": reason}, engine=engine)


@register_metric("penetration")
def _m_penetration(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return [r.penetration if r.penetration is not None else _skip("penetration", "mm", e, r.error or "not measured") for e, r in runs.items()]


@register_metric("ground_penetration")
def _m_ground(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    out = []
    for e, r in runs.items():
        if r.ground_series is None:
            out.append(_skip("ground_penetration", "mm", e, r.error or "not measured"))
            continue
        g = r.ground_series
        finite = g[np.isfinite(g)]
        worst = float(np.max(finite)) if len(finite) else 0.0
        at = int(np.argmax(finite)) if len(finite) else 0
        out.append(
            MetricResult(
                name="ground_penetration",
                value=worst * 1000.0,
                unit="mm",
                passed=bool(worst <= GROUND_PENETRATION_TOL and len(finite) == len(g)),
                threshold=f"<= {GROUND_PENETRATION_TOL * 1000:g} mm at every step of the rest test",
                details={"worst_step": at, "worst_time_s": (at + 1) * ctx.conventions.timestep, "steps": int(len(g))},
                engine=e,
            )
        )
    return out


@register_metric("rest_stability")
def _m_rest(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    out = []
    for e, r in runs.items():
        if r.trace is None:
            out.append(_skip("rest_stability", "m", e, r.error or "not measured"))
        else:
            out.append(spec_metrics.rest_stability(r.trace, ctx.conventions, engine=e))
    return out


@register_metric("oscillation")
def _m_osc(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    out = []
    for e, r in runs.items():
        if r.trace is None:
            out.append(_skip("oscillation", "joints", e, r.error or "not measured"))
        else:
            out.append(spec_metrics.oscillation(r.trace, ctx.conventions, engine=e))
    return out


def divergence_check(root: np.ndarray, joints: dict[str, np.ndarray], joint_types: dict[str, str],
                     dt: float, largest_extent: float) -> dict[str, Any]:
    """Divergence of one run: non-finite values or an explosion.

    Args:
        root: (K, 3) m root positions per step (settle + test); the first row
            is compared with the rest for travel.
        joints: joint -> (K,) positions per step.
        joint_types: joint -> type.
        dt: timestep s; largest_extent: m.

    Returns:
        {diverged, nan, reasons, peak_root_speed (m/s), root_travel (m),
        peak_joint_speed {joint: rad/s or m/s}}.
    """
    reasons = []
    nan = not (np.all(np.isfinite(root)) and all(np.all(np.isfinite(v)) for v in joints.values()))
    if nan:
        reasons.append("non-finite pose or joint position")
    r = root[np.all(np.isfinite(root), axis=1)] if len(root) else root
    speed = float(np.max(np.linalg.norm(np.diff(r, axis=0), axis=1)) / dt) if len(r) > 1 else 0.0
    travel = float(np.max(np.linalg.norm(r - r[0], axis=1))) if len(r) else 0.0
    travel_lim = max(EXPLOSION_TRAVEL_MIN, EXPLOSION_TRAVEL_FACTOR * largest_extent)
    if speed > EXPLOSION_ROOT_SPEED:
        reasons.append(f"root speed {speed:.3g} m/s > {EXPLOSION_ROOT_SPEED} m/s")
    if travel > travel_lim:
        reasons.append(f"root travelled {travel:.3g} m > {travel_lim:.3g} m")
    peak = {}
    for n, q in joints.items():
        q = q[np.isfinite(q)]
        v = float(np.max(np.abs(np.diff(q))) / dt) if len(q) > 1 else 0.0
        peak[n] = v
        lim = EXPLOSION_JOINT_SPEED_PRISMATIC if joint_types.get(n) == "prismatic" else EXPLOSION_JOINT_SPEED_REVOLUTE
        if v > lim:
            reasons.append(f"joint {n} speed {v:.3g} > {lim}")
    return {
        "diverged": bool(reasons),
        "nan": bool(nan),
        "reasons": reasons,
        "peak_root_speed": speed,
        "root_travel": travel,
        "travel_limit": travel_lim,
        "peak_joint_speed": peak,
    }


@register_metric("divergence")
def _m_div(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    out = []
    for e, r in runs.items():
        if r.trace is None or r.root_series is None:
            out.append(_skip("divergence", "", e, r.error or "not measured"))
            continue
        largest = float(np.max(r.extents)) if r.extents is not None else 0.0
        d = divergence_check(r.root_series, r.joint_series, r.trace.joint_types, ctx.conventions.timestep, largest)
        d["nan"] = d["nan"] or r.trace.diverged
        d["diverged"] = d["diverged"] or r.trace.diverged
        out.append(
            MetricResult(
                name="divergence",
                value=float(d["diverged"]),
                unit="flag",
                passed=not d["diverged"],
                threshold=(
                    f"finite, root speed <= {EXPLOSION_ROOT_SPEED} m/s, joint speed <= {EXPLOSION_JOINT_SPEED_REVOLUTE} rad/s "
                    f"({EXPLOSION_JOINT_SPEED_PRISMATIC} m/s), root travel <= max({EXPLOSION_TRAVEL_MIN} m, "
                    f"{EXPLOSION_TRAVEL_FACTOR} x largest extent)"
                ),
                details=d,
                engine=e,
            )
        )
    return out


@register_metric("joint_hold")
def _m_hold(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    out = []
    for e, r in runs.items():
        if r.trace is None:
            out.append(_skip("joint_hold", "rad", e, r.error or "not measured"))
            continue
        drift = spec_metrics.joint_drift(r.trace)
        per, failing = {}, []
        for n in ctx.task_joints:
            if n not in drift:
                continue
            pri = ctx.joints[n].type == "prismatic"
            tol = ctx.sag_tol_prismatic if pri else ctx.sag_tol_revolute
            q_end = float(r.trace.joints[n][-1])
            c = ctx.closed.get(n)
            per[n] = {
                "drift": drift[n],
                "unit": "m" if pri else "rad",
                "tolerance": tol,
                "q_initial": ctx.initial_state.get(n),
                "q_end": q_end,
                "fraction_initial": c.fraction(ctx.initial_state.get(n, 0.0)) if c else None,
                "fraction_end": c.fraction(q_end) if c else None,
                "failed": drift[n] > tol,
            }
            if drift[n] > tol:
                failing.append(n)
        out.append(
            MetricResult(
                name="joint_hold",
                value=float(max([v["drift"] for v in per.values()], default=0.0)),
                unit="rad/m",
                passed=(not failing) if per else None,
                threshold=f"largest |q(t) - q_initial| <= {ctx.sag_tol_revolute} rad / {ctx.sag_tol_prismatic} m over settle + test",
                details={"joints": per, "failing": failing},
                engine=e,
            )
        )
    return out


@register_metric("scale_deviation")
def _m_scale(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return [sem.scale_deviation(ctx.scale, ctx.reference_scale, scale_source=ctx.scale_source)]


@register_metric("initial_joint_deviation")
def _m_initdev(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    if ctx.reference_dir is None:
        return [MetricResult(name="initial_joint_deviation", value=None, unit="rad", passed=None,
                             details={"reason": "no reference given"}, engine="none")]
    m = sem.initial_joint_deviation(ctx.initial_state, ctx.reference_state, ctx.task_joints,
                                    {n: j.type for n, j in ctx.joints.items()})
    m.details["reference_rule"] = ctx.reference_rule
    return [m]


def _first_run(runs: dict[str, EngineRun]) -> EngineRun | None:
    for r in runs.values():
        if r.extents is not None:
            return r
    return None


def _largest_extent(ctx: Context, runs: dict[str, EngineRun]) -> tuple[float | None, str]:
    """Largest extent (m) of the object: closed state when known, else initial."""
    if ctx.closed_extents is not None and float(np.max(ctx.closed_extents)) > 0:
        return float(np.max(ctx.closed_extents)), "closed state"
    r = _first_run(runs)
    if r is not None and r.extents is not None and float(np.max(r.extents)) > 0:
        return float(np.max(r.extents)), "initial state"
    return None, "unknown"


@register_metric("total_mass")
def _m_mass(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    r = _first_run(runs)
    if r is None:
        total = sum((li.mass if li.mass is not None else 1.0) for li in ctx.links.values())
        per = {n: {"mass": li.mass if li.mass is not None else 1.0, "source": "file" if li.mass is not None else "default 1 kg"} for n, li in ctx.links.items()}
    else:
        total = sum(v["mass"] for v in r.masses.values())
        per = r.masses
    largest, where = _largest_extent(ctx, runs)
    rfirst = _first_run(runs)
    extents = ctx.closed_extents if ctx.closed_extents is not None else (rfirst.extents if rfirst is not None else None)
    rng, f = scaled_mass_range(ctx.prior, extents)
    m = sem.mass_plausibility(total, rng, per_link=per, category=ctx.category)
    m.details.update({"size_factor_vs_prior": f, "largest_extent_m": largest, "extent_state": where,
                      "base_mass_range_kg": ctx.prior.get("base_mass_range"), "prior_source": ctx.prior.get("source")})
    if rng is not None:
        m.threshold = f"{rng[0]:.3g} kg <= m <= {rng[1]:.3g} kg (category range scaled to the asset's size, f = {f:.3g})"
    return [m]


@register_metric("prompt_alignment")
def _m_prompt(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    if not ctx.prompt:
        return [MetricResult(name="prompt_alignment", value=None, unit="fraction", details={"reason": "no prompt"}, engine="none")]
    spec = ctx.request
    if spec is None:
        return [MetricResult(name="prompt_alignment", value=None, unit="fraction",
                             details={"reason": ctx.request_error or "request not parsed"}, engine="none")]
    r = _first_run(runs)
    centres = r.link_centres if r is not None else {}
    largest, where = _largest_extent(ctx, runs)
    req, unmatched = requested_joints(spec, ctx.joints, ctx.semantics, centres, ctx.task_joints, ctx.category)
    checks = []
    for name, band, label, phrase in req:
        c = ctx.closed.get(name)
        checks.append(sem.JointStateCheck(name, band, c.fraction(ctx.initial_state[name]) if c else None, label, phrase))
    dims = ctx.prior.get("base_dims")
    m = sem.prompt_alignment(
        size_requested=spec.size_class is not None,
        largest_extent=largest,
        typical_largest=dims[0] if dims else None,
        size_factor=float(ctx.prior.get("factor", 1.0)),
        joint_checks=checks,
        state_requested=bool(spec.joint_states),
        unmatched_requests=unmatched,
        text=ctx.prompt,
    )
    m.details["size_class"] = spec.size_class
    m.details["category"] = ctx.category
    m.details["variant"] = ctx.prior.get("variant")
    m.details["extent_state"] = where
    m.details["prior_note"] = ctx.prior.get("note")
    return [m]


@register_metric("probes")
def _m_probes(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    from asset2sim.tasks.check.probes import probes_metric

    r = runs.get("pybullet")
    if r is None:
        return [_skip("probes", "failed probes", "pybullet", "probes run in PyBullet only; pybullet not among the engines")]
    if r.error and not r.probes:
        return [_skip("probes", "failed probes", "pybullet", r.error)]
    return [probes_metric(r.probes)]


# ------------------------------------------------------------------ entry point
def evaluate_asset(
    urdf_dir_or_path: Path | str,
    *,
    reference: Path | str | None = None,
    prompt: str | None = None,
    engines: tuple[str, ...] | list[str] = ("pybullet",),
    seed: int = 0,
    category: str | None = None,
    method: str | None = None,
    out_dir: Path | str | None = None,
    write_report: bool = False,
    probes: bool = True,
    conventions: SimConventions | None = None,
    measured: list[MetricResult] | None = None,
    recording: RestRecording | None = None,
    views: dict[str, np.ndarray] | None = None,
    views_state: dict[str, float] | None = None,
) -> Evaluation:
    """Evaluate one asset with every registered metric.

    Args:
        urdf_dir_or_path: asset folder (``mobility.urdf`` or one ``*.urdf``) or
            a URDF file; ``initial_state.json``, ``overlay.json``,
            ``report.json``, ``baseline.json``, ``semantics.txt`` beside it are
            used when present.
        reference: PartNet-Mobility folder with ``reference_gensim2.json`` /
            ``reference_gensim2.urdf`` (reference scale, task joint, reference
            state); None skips the reference metrics.
        prompt: the request; None skips prompt alignment.
        engines: engine names (``asset2sim.engines``); unavailable ones are
            recorded as skipped metrics.
        seed: recorded for reproducibility; every measurement here is
            deterministic (PyBullet DIRECT mode, fixed step), so it changes
            nothing today.
        category: overrides the category found in the sidecars.
        method: name recorded in the evaluation (benchmark).
        out_dir: where ``evaluation.json`` (always, when given) and
            ``report.html`` (when ``write_report``) go.
        write_report: write ``report.html`` into ``out_dir``.
        probes: run the passive probes.
        conventions: SPEC conventions (default :class:`SimConventions`).
        measured: results of the rest-test metrics
            (:data:`asset2sim.schemas.metrics.REST_TEST_METRICS`) already
            measured in the first engine under the same conventions and
            initial state (the refine post-check): recorded as they are, and
            that engine's rest test is not run again (the probes start from
            the unstepped initial state either way, :func:`run_engine`); the
            metrics that need its per-step trace (ground penetration,
            divergence, joint hold) are then recorded as skipped.
        recording: the post-check's rest test of this asset, step by step
            (:class:`~asset2sim.tasks.check.postcheck.RestRecording`): when it
            matches an engine's simulation (engine, URDF, initial state,
            springs, conventions) every rest-test metric of that engine
            (ground penetration, divergence and joint hold included) is
            computed from it and the rest test is not simulated again; the
            result equals a fresh rest test's (the simulation is
            deterministic). Otherwise it is ignored.
        views, views_state: renders of the object already taken
            (:func:`asset2sim.tasks.publish.render.render_views`, view name ->
            (H, W, 3) uint8) at the joint positions ``views_state`` (rad/m):
            ``report.html`` shows them when that is the evaluated initial
            state, else it renders its own.

    Returns:
        The :class:`Evaluation`.

    Raises:
        EvaluationError: the asset or reference cannot be read.
        ValueError: ``write_report`` without ``out_dir``; no engine given.
    """
    if write_report and out_dir is None:
        raise ValueError("write_report needs out_dir")
    if not engines:
        raise ValueError("at least one engine is needed")
    t0 = time.perf_counter()
    ctx = build_context(urdf_dir_or_path, reference=reference, prompt=prompt, category=category, conventions=conventions)
    # joints that matter: the task's, plus those the request names
    pre_req: list[str] = []
    if ctx.request is not None:
        for js in ctx.request.joint_states:
            if js.selector == "label":
                pre_req += [n for n in ctx.movable if _match_label(ctx.semantics.get(ctx.joints[n].child, (None, None))[1], js.label, ctx.category)]
    ctx.task_joints, tj_rule = _task_joints(ctx.joints, ctx.reference_dir, pre_req)
    ctx.notes.append(f"task-relevant joints: {', '.join(ctx.task_joints) or 'none'} ({tj_rule})")
    need_closed = list(dict.fromkeys(ctx.task_joints + pre_req))
    if ctx.request is not None and any(js.selector == "all" for js in ctx.request.joint_states):
        need_closed = list(dict.fromkeys(need_closed + ctx.task_joints))
    runs: dict[str, EngineRun] = {}
    order = sorted(engines, key=lambda e: e != "pybullet")  # PyBullet first: it computes the closed ends
    reuse_engine = engines[0] if measured is not None else None
    for e in order:
        pending = need_closed if (e == "pybullet" and not ctx.closed) else None
        runs[e] = run_engine(ctx, e, probes=probes and e == "pybullet", keep_geometry=write_report, closed_for=pending,
                             rest_test=e != reuse_engine, recording=recording)
        if runs[e].error:
            ctx.notes.append(f"{e}: {runs[e].error}")
    if need_closed and not ctx.closed:
        ext: list = []
        ctx.closed, cnotes = compute_closed(ctx.urdf, ctx.joints, need_closed, extents_out=ext)
        ctx.closed_extents = ext[0] if ext else None
        ctx.notes += cnotes
    runs = {e: runs[e] for e in engines}
    results: list[MetricResult] = []
    for spec in METRICS.values():
        if spec.name == "probes" and not probes:
            continue
        if reuse_engine is not None and spec.name in REST_TEST_METRICS:
            results += [m for m in measured if m.name == spec.name and m.engine == reuse_engine]
            others = {e: r for e, r in runs.items() if e != reuse_engine}
            try:
                results += spec.fn(ctx, others) if others else []
            except Exception as exc:
                results.append(MetricResult(name=spec.name, value=None, unit="", passed=False,
                                            details={"error": f"{type(exc).__name__}: {exc}"}, engine="none"))
            continue
        try:
            results += spec.fn(ctx, runs)
        except Exception as exc:  # one broken metric must not hide the others
            results.append(MetricResult(name=spec.name, value=None, unit="", passed=False,
                                        details={"error": f"{type(exc).__name__}: {exc}"}, engine="none"))
    failures = [f"{m.name}@{m.engine}" for m in results if m.passed is False]
    ev = Evaluation(
        asset_id=ctx.asset_id,
        urdf=str(ctx.urdf),
        method=method or (ctx.baseline or {}).get("method") or ("asset2sim" if ctx.overlay else None),
        prompt=prompt,
        reference=str(ctx.reference_dir) if ctx.reference_dir else None,
        category=ctx.category,
        scale=ctx.scale,
        scale_source=ctx.scale_source,
        engines=list(engines),
        seed=seed,
        initial_state=ctx.initial_state,
        initial_state_source=ctx.initial_state_source,
        task_joints=ctx.task_joints,
        closed_positions={n: {"q_closed": c.q_closed, "direction": c.direction, "open_range": c.open_range} for n, c in ctx.closed.items()},
        metrics=results,
        passed=not failures and all(r.error is None for r in runs.values()),
        failures=failures + [f"engine@{e}" for e, r in runs.items() if r.error],
        notes=ctx.notes,
        seconds=time.perf_counter() - t0,
    )
    ev._runs = runs
    ev._context = ctx
    if out_dir is not None:
        same_state = views is not None and views_state is not None and dict(views_state) == dict(ev.initial_state)
        write_evaluation(ev, out_dir, report=write_report, views=views if same_state else None)
    return ev


def evaluate_refined(
    out_dir: Path | str,
    report: RefineReport,
    *,
    recording: RestRecording | None = None,
    reference: Path | str | None = None,
    views: dict[str, np.ndarray] | None = None,
    views_state: dict[str, float] | None = None,
) -> dict[str, Path]:
    """Evaluate a refined output folder (PyBullet, SPEC conventions, probes)
    and write ``evaluation.json`` and ``report.html`` beside its
    ``report.json`` (refine's extras).

    Args:
        out_dir: the refined output folder.
        report: its :class:`~asset2sim.schemas.report.RefineReport` (the
            run's ``prompt`` and ``category`` are used).
        recording: the final post-check's rest test
            (:class:`~asset2sim.tasks.check.postcheck.RestRecording`), reused
            when it matches (see :func:`evaluate_asset`).
        reference: the reference folder (GenSim2), None for none.
        views: the renders refine wrote (view -> (H, W, 3) uint8), taken at
            ``views_state`` (rad/m); used in ``report.html`` when that is the
            evaluated initial state, else the report renders its own.

    Returns:
        {"evaluation": path, "report": path}.

    Raises:
        EvaluationError: the folder cannot be read.
    """
    out_dir = Path(out_dir)
    evaluate_asset(out_dir, reference=reference, prompt=report.prompt or None, category=report.category,
                   method="asset2sim", out_dir=out_dir, write_report=True, recording=recording,
                   views=views, views_state=views_state)
    return {"evaluation": out_dir / "evaluation.json", "report": out_dir / "report.html"}


def write_evaluation(ev: Evaluation, out_dir: Path | str, *, report: bool = True,
                     views: dict[str, np.ndarray] | None = None) -> dict[str, Path]:
    """Write ``evaluation.json`` (and ``report.html``, rendering ``ev``:
    :func:`asset2sim.tasks.publish.report_html.write_report`, with ``views``
    the renders at ``ev.initial_state`` when already taken) into ``out_dir``
    atomically.

    Returns:
        {"evaluation": path, "report": path (when written)}.
    """
    out_dir = Path(out_dir)
    paths = {"evaluation": write_json(out_dir / "evaluation.json", _jsonable(ev.model_dump(mode="json")))}
    if report:
        paths["report"] = write_report(ev, out_dir / "report.html", views=views)
    return paths


def _jsonable(obj: Any) -> Any:
    """Replace non-finite floats by None (strict JSON)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating,)):
        return _jsonable(float(obj))
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj
