"""Model-backed overlay synthesis (SPEC stage 2 with a vision-language model).

Registers two estimators with :mod:`asset2sim.tasks.synthesize.estimate`:

- ``llm``: ``get_estimator("llm", model="gemini/gemini-2.5-flash")`` (any
  litellm model string; ``base_url=`` for a local vLLM / Ollama / llama.cpp
  server);
- ``openai``: ``get_estimator("openai", model="m", base_url="http://host/v1")``,
  shorthand for an OpenAI-compatible server (the model becomes ``openai/m``).

Both check credentials when created (a missing key fails before any work).

**Request.** Five renders of the input asset at its geometric closed state
(front, back, left, right, perspective; :func:`asset2sim.tasks.publish.render.render_views`,
PNG data URLs) and the structured description of the analysis stage
(:func:`describe`: links with semantic labels, volumes, areas and extents at
scale 1, joints with types, limits and closed ends, the category, the request
text and what the request parser understood). The reply must follow
:class:`~asset2sim.schemas.model_reply.ModelReply`, whose JSON schema is sent
as the structured-output constraint; replies are parsed strictly and checked
by :func:`overlay_from_reply` with the same validator as the offline
estimator (:func:`asset2sim.tasks.synthesize.validate_overlay.validate_overlay`), and
re-asked at most twice with the problems (:meth:`LLMClient.ask`).

**The reply is a prior, not the answer** (:func:`overlay_from_reply`): the
model picks the scale, a material (density, shell or solid, wall thickness)
per link, and per joint a state band and qualitative dynamics (damping level,
holds position, spring, stiff, free moving). Mass then follows the geometry
(m = v rho s^3 eta, or A s^2 t rho for open shells; :func:`physics.link_physics`),
kept within a factor :data:`MASS_AGREEMENT` of the model's own mass estimate;
inertia comes from the scaled geometry; damping and friction from the joint
loads (:func:`physics.joint_dynamics`); the state from the band through the
geometric closed ends (:func:`estimate.state_from_bands`), and the refine
pipeline still refines it in the simulator. The chosen bands are returned with
the overlay (:class:`asset2sim.tasks.synthesize.estimate.Estimate`) for the
refine stage.

**Baselines** (SPEC): :func:`direct_overlay` (one call, five views, the
model's numbers applied as they are) and :func:`ivw_overlay` (each of 5 views
asked 5 times, numbers fused per parameter by inverse-variance weighting,
:mod:`asset2sim.tasks.synthesize.ivw`).
"""

from __future__ import annotations

import base64
import io
import json
from typing import Any

import numpy as np

from asset2sim import __version__
from asset2sim.schemas.model_reply import (
    PROPOSAL_SCHEMA_NAME,
    REPLY_SCHEMA_NAME,
    JointProposalReply,
    ModelReply,
    reply_json_schema,
)
from asset2sim.schemas.overlay import (
    ContactMaterial,
    EstimatorInfo,
    Inertia,
    JointDynamics,
    LinkPhysics,
    Overlay,
    ValidationNotes,
)
from asset2sim.schemas.request import BAND_TARGET
from asset2sim.tasks.interpret import priors
from asset2sim.tasks.publish import render
from asset2sim.tasks.synthesize import estimate, ivw, physics, validate_overlay
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.llm_client import (
    ClientConfig,
    LLMClient,
    LLMError,
    ModelCallError,
    ReplyError,
    ReplyInvalid,
    Usage,
)

DESCRIPTION_MARK = "ASSET DESCRIPTION (JSON):"
PROPOSAL_MARK = "STALLED STATE SEARCH (JSON):"
"""Line that precedes the state-search summary in a joint-proposal request."""
"""Line preceding the structured description in the user message."""

VIEWS: tuple[str, ...] = ("front", "back", "left", "right", "perspective")
"""Views sent with a request (the SPEC's five)."""

MASS_AGREEMENT = 3.0
"""Largest factor between the geometric total mass and the model's own
estimate before the links are rescaled to the nearer bound (dimensionless)."""

IVW_TEMPERATURE = 1.0
"""Sampling temperature of the IVW baseline's repeated queries (independent samples)."""


# ------------------------------------------------------------------ the request
def _r(x: float, n: int = 5) -> float:
    return float(f"{float(x):.{n}g}")


def describe(ctx: EstimationContext) -> dict[str, Any]:
    """The structured description sent to the model (JSON-able; lengths in m
    and angles in rad, all at scale 1 in the input asset's frames; prismatic
    values in the input's units, which the scale multiplies).

    Contents: category (and why), the request text and what the request parser
    understood, the closed object's extents, the typical real dimensions and
    mass range of the category for this request (priors), every link (semantic
    label, joint kind, volume, area, extents, the offline prior's material)
    and every movable joint (type, parent, child and its label, axis, limits,
    closed end, opening direction and range, whether tasks act on it, the band
    the parser read for it).
    """
    asset = ctx.asset
    req = ctx.request
    target = priors.target_size(ctx.category, req)
    bands, band_notes = estimate.requested_bands(ctx)
    relevant = set(estimate.task_relevant_joints(ctx))
    links = []
    for ln in asset.links:
        g = ctx.geometry.get(ln.name)
        pj = asset.parent_joint(ln.name)
        entry: dict[str, Any] = {
            "name": ln.name,
            "semantic_label": ln.semantic_label,
            "semantic_joint": ln.semantic_joint,
            "parent_joint": pj.name if pj else None,
            "has_geometry": g is not None,
        }
        if g is not None:
            mat = priors.material_for(ctx.category, ln.semantic_label)
            entry.update(
                {
                    "volume_m3": _r(g.volume),
                    "volume_method": g.volume_method,
                    "watertight": g.watertight,
                    "area_m2": _r(g.area),
                    "extents_m": [_r(e) for e in g.extents],
                    "typical_material": {"name": mat.name, "density": mat.density, "shell": mat.shell, "wall_thickness": mat.wall_thickness},
                }
            )
        links.append(entry)
    joints = []
    for j in asset.movable_joints():
        cs = ctx.closed.get(j.name)
        entry = {
            "name": j.name,
            "type": j.type,
            "parent": j.parent,
            "child": j.child,
            "child_label": asset.link(j.child).semantic_label,
            "axis": [_r(a) for a in j.axis],
            "lower": None if j.lower is None else _r(j.lower),
            "upper": None if j.upper is None else _r(j.upper),
            "unit": "m at scale 1 (multiply by the scale)" if j.type == "prismatic" else "rad",
            "task_relevant": j.name in relevant,
            "requested_band": bands.get(j.name, "closed"),
            "height_m": _r(ctx.joint_heights.get(j.name, 0.0)),
        }
        if cs is not None:
            entry.update(
                {
                    "closed_position": _r(cs.q_closed),
                    "opening_direction": int(cs.direction),
                    "opening_range": _r(cs.open_range),
                }
            )
        joints.append(entry)
    return {
        "asset_id": asset.asset_id,
        "category": ctx.category,
        "category_reason": ctx.category_reason,
        "request": req.text,
        "request_parse": {
            "size_class": req.size_class,
            "size_factor": req.size_factor,
            "joint_states": [js.model_dump() for js in req.joint_states],
            "damping": req.damping,
            "holds_position": req.holds_position,
            "spring": req.spring,
            "stiff": req.stiff,
            "free_moving": req.free_moving,
            "pose": req.pose_hint,
            "notes": band_notes,
        },
        "closed_extents_m": [_r(e) for e in np.asarray(ctx.closed_extents, float)],
        "typical_dims_m": [_r(d) for d in target.dims],
        "typical_mass_range_kg": [_r(m) for m in target.mass_range],
        "typical_size_note": target.note,
        "links": links,
        "joints": joints,
        "band_fractions": dict(BAND_TARGET),
    }


SYSTEM_PROMPT = """You turn an articulated 3D asset into an interaction-ready simulation asset.
You get renders of the object in its closed state (views named before each image; the render scale is arbitrary) and a
structured description (JSON) from mesh analysis at scale 1. Answer with exactly ONE JSON object that follows the JSON
schema below: every field present, no other fields, no prose, no Markdown.

How your answer is used and what each field means (SI units, angles in radians):
- scale: the uniform factor s that gives the object the real-world size the request asks for
  (real dimensions = closed_extents_m * s; typical_dims_m is the usual size of such an object for this request).
- links: one entry per link that has geometry, names exactly as given. material, density (kg/m^3), shell (true for hollow
  molded / sheet / panel parts), wall_thickness (m). The mass will be computed from the geometry:
  solid m = volume_m3 * density * s^3, shell m = area_m2 * s^2 * wall_thickness * density. mass: your own estimate (kg) of
  that link at the requested size.
- joints: one entry per movable joint, names exactly as given. band: the state the request asks for (fraction of the
  opening range from the closed end: closed 0, slightly_open 0.2, quarter 0.25, halfway 0.5, mostly 0.75, fully 1);
  joints the request does not address stay closed. position: that state's joint value
  q = closed_position + opening_direction * fraction * opening_range (prismatic: times s, in metres).
  damping_level low / moderate / high; holds_position (friction must hold the state against gravity); spring (a return
  spring is intended); stiff; free_moving. damping, friction, stiffness: numbers for the scaled object
  (revolute N*m*s/rad, N*m, N*m/rad; prismatic N*s/m, N, N/m); stiffness 0 unless a spring is intended.
- Every number with a std is your estimate and its 1-sigma uncertainty in the same unit (std > 0).
- lateral_friction and restitution: the object's contact material.
- notes: size reasoning, material reasoning, mass arithmetic.
"""


def system_prompt(schema: dict[str, Any]) -> str:
    """The system message: instructions plus the JSON schema (also sent as
    ``response_format``, repeated here for servers that ignore it)."""
    return SYSTEM_PROMPT + "\nJSON schema:\n" + json.dumps(schema, separators=(",", ":"))


def png_data_url(image: np.ndarray) -> str:
    """``data:image/png;base64,...`` of an RGB(A) uint8 (H, W, 3|4) image."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG", optimize=False)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def render_closed_views(ctx: EstimationContext, views: tuple[str, ...] = VIEWS, size: tuple[int, int] = (384, 384)) -> tuple[dict[str, str], list[str]]:
    """Render ``views`` of the input asset at its geometric closed state.

    Returns:
        (view -> PNG data URL, notes). A render failure is not fatal: the
        request then carries the description only and the note says why.
    """
    q = {n: float(cs.q_closed) for n, cs in ctx.closed.items()}
    try:
        images = render.render_views(ctx.asset.urdf_path, q, views=views, size=size)
    except Exception as exc:  # renders are evidence, not a requirement
        return {}, [f"renders failed ({type(exc).__name__}: {exc}); the model got the description only"]
    return {v: png_data_url(img) for v, img in images.items()}, []


def build_messages(description: dict[str, Any], images: dict[str, str], schema: dict[str, Any], *, extra: str = "") -> list[dict[str, Any]]:
    """OpenAI-format chat messages: the system prompt (with the schema) and one
    user message with the description and each view (name, then image)."""
    parts: list[dict[str, Any]] = [
        {
            "type": "text",
            "text": (
                f"Request: {description.get('request') or '(no request: a generic interaction-ready asset)'}\n"
                + (extra + "\n" if extra else "")
                + f"{DESCRIPTION_MARK}\n{json.dumps(description, separators=(',', ':'))}"
            ),
        }
    ]
    for view, url in images.items():
        parts.append({"type": "text", "text": f"view: {view} (closed state)"})
        parts.append({"type": "image_url", "image_url": {"url": url}})
    return [{"role": "system", "content": system_prompt(schema)}, {"role": "user", "content": parts}]


# ------------------------------------------------------------ reply -> overlay
def check_reply_names(ctx: EstimationContext, reply: ModelReply) -> list[str]:
    """Problems with the names in a reply: unknown or duplicated links and joints."""
    errors = []
    links = {ln.name for ln in ctx.asset.links}
    movable = {j.name for j in ctx.asset.movable_joints()}
    seen: set[str] = set()
    for i, lr in enumerate(reply.links):
        if lr.link not in links:
            errors.append(f"links.{i}.link: {lr.link!r} is not a link of the asset; links are {sorted(ctx.geometry)}")
        elif lr.link in seen:
            errors.append(f"links.{i}.link: {lr.link!r} appears twice")
        seen.add(lr.link)
    seen = set()
    for i, jr in enumerate(reply.joints):
        if jr.joint not in movable:
            errors.append(f"joints.{i}.joint: {jr.joint!r} is not a movable joint of the asset; movable joints are {sorted(movable)}")
        elif jr.joint in seen:
            errors.append(f"joints.{i}.joint: {jr.joint!r} appears twice")
        seen.add(jr.joint)
    return errors


def _prior_material(ctx: EstimationContext, label: str | None) -> physics.MaterialChoice:
    m = priors.material_for(ctx.category, label)
    return physics.MaterialChoice(name=m.name, density=float(m.density), shell=bool(m.shell), wall_thickness=float(m.wall_thickness), source=m.source)


def _scaled_link(lp: LinkPhysics, f: float, why: str) -> LinkPhysics:
    return lp.model_copy(
        update={
            "mass": lp.mass * f,
            "inertia": lp.inertia.model_copy(update={k: getattr(lp.inertia, k) * f for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}),
            "source": lp.source + why,
        }
    )


def overlay_from_reply(ctx: EstimationContext, reply: ModelReply, *, name: str = "llm", model: str | None = None) -> tuple[Overlay, dict[str, str], list[str]]:
    """The asset2sim overlay from a model reply (the reply is a prior; see the
    module docstring), validated with :func:`validate_overlay.validate_overlay`.

    Links without a reply entry get the offline prior's material, joints
    without one the request parser's band and dynamics words (both noted).

    Returns:
        (overlay, band per movable joint, notes). ``overlay.estimator`` has no
        usage yet (the caller fills it).

    Raises:
        ReplyInvalid: unknown or duplicated names, a link whose mass cannot be
            computed, or an overlay the validator rejects (messages name them).
    """
    errors = check_reply_names(ctx, reply)
    if errors:
        raise ReplyInvalid(errors)
    s = float(reply.scale.value)
    notes: list[str] = []
    # ---- links: material from the model, mass and inertia from the geometry
    by_link = {lr.link: lr for lr in reply.links}
    links: dict[str, LinkPhysics] = {}
    mat_notes, missing = [], []
    for ln in ctx.asset.links:
        geom = ctx.geometry.get(ln.name)
        if geom is None:
            continue
        lr = by_link.get(ln.name)
        if lr is None:
            mat = _prior_material(ctx, ln.semantic_label)
            missing.append(ln.name)
            src = f"geometry + {mat.name} (offline prior; no model entry)"
        else:
            mat = physics.MaterialChoice(name=lr.material, density=lr.density, shell=lr.shell, wall_thickness=lr.wall_thickness, source="model")
            src = f"geometry + {mat.name} (model)"
        try:
            links[ln.name] = physics.link_physics(geom, s, mat, source=src)
        except ValueError as exc:
            errors.append(f"links: {exc}")
            continue
        mat_notes.append(f"{ln.name}: {mat.name}, {mat.density:g} kg/m^3, {'shell t=' + format(mat.wall_thickness, 'g') + ' m' if mat.shell else 'solid'}")
    if errors:
        raise ReplyInvalid(errors)
    if missing:
        notes.append(f"the model gave no material for {missing}; offline priors used")
    geo_total = sum(lp.mass for lp in links.values())
    model_total = sum(by_link[n].mass.value for n in links if n in by_link)
    geo_known = sum(links[n].mass for n in links if n in by_link)
    mass_note = " + ".join(f"{lp.mass:.4g}" for lp in links.values()) + f" = {geo_total:.4g} kg from the geometry (m = v*rho*s^3*eta)"
    if model_total > 0 and geo_known > 0:
        ratio = geo_known / model_total
        mass_note += f"; the model estimated {model_total:.4g} kg for those links (ratio {ratio:.3g})"
        if ratio > MASS_AGREEMENT or ratio < 1.0 / MASS_AGREEMENT:
            target = model_total * (MASS_AGREEMENT if ratio > MASS_AGREEMENT else 1.0 / MASS_AGREEMENT)
            f = target / geo_known
            links = {n: _scaled_link(lp, f, f"; x{f:.3g} to within {MASS_AGREEMENT:g}x of the model's mass estimate") for n, lp in links.items()}
            mass_note += f"; more than {MASS_AGREEMENT:g}x apart: every link scaled by {f:.3g}"
    # ---- state: the model's band per joint through the geometric closed ends
    parsed, _ = estimate.requested_bands(ctx)
    by_joint = {jr.joint: jr for jr in reply.joints}
    movable = ctx.asset.movable_joints()
    prismatic = {j.name for j in movable if j.type == "prismatic"}
    bands: dict[str, str] = {}
    for j in movable:
        jr = by_joint.get(j.name)
        bands[j.name] = jr.band if jr is not None else parsed.get(j.name, "closed")
        if jr is None:
            notes.append(f"{j.name}: no model entry; the request parser's band {bands[j.name]!r} and dynamics words used")
        elif jr.band != parsed.get(j.name, "closed"):
            notes.append(f"{j.name}: the model chose band {jr.band!r}, the request parser read {parsed.get(j.name, 'closed')!r}; the model's band used")
    state = estimate.state_from_bands(ctx.closed, bands, s, prismatic)
    # ---- dynamics from the loads, with the model's qualitative choices
    relevant = set(estimate.task_relevant_joints(ctx))
    choices: dict[str, estimate.JointChoice] = {}
    for j in movable:
        jr = by_joint.get(j.name)
        rq = ctx.request
        is_rel = j.name in relevant
        if jr is not None:
            choices[j.name] = estimate.JointChoice(jr.damping_level, jr.holds_position, jr.spring, jr.stiff, jr.free_moving)
        else:
            choices[j.name] = estimate.JointChoice(
                rq.damping if is_rel else "moderate",
                rq.holds_position and is_rel,
                rq.spring and is_rel,
                rq.stiff and is_rel,
                rq.free_moving and is_rel,
            )
    joints = estimate.joint_dynamics_for(ctx, links, state, s, choices, source=f"{name} physics (model choices)")
    asked_state = bool(ctx.request.joint_states) or any(b != "closed" for b in bands.values())
    if reply.category.strip().lower() != str(ctx.category).lower():
        notes.append(f"the model calls it {reply.category!r}; the pipeline's category {ctx.category!r} is kept")
    overlay = Overlay(
        estimator=EstimatorInfo(name=name, model=model, version=__version__),
        scale=s,
        category=ctx.category,
        contact_material=ContactMaterial(lateral_friction=reply.lateral_friction, restitution=reply.restitution, note=f"model ({name})"),
        links=links,
        joints=joints,
        initial_joint_positions=state if asked_state else None,
        notes=ValidationNotes(
            size=f"model: s = {s:.4g} +- {reply.scale.std:.3g}; {reply.notes.size}",
            material="; ".join(mat_notes) + (f" | model: {reply.notes.material}" if reply.notes.material else ""),
            mass_arithmetic=mass_note + (f" | model: {reply.notes.mass_arithmetic}" if reply.notes.mass_arithmetic else ""),
            other=[f"category: {ctx.category} ({ctx.category_reason})", "bands (model): " + ", ".join(f"{k}={v}" for k, v in bands.items())] + notes,
        ),
    )
    try:
        validate_overlay.validate_overlay(overlay, ctx.asset, ctx.geometry)
    except validate_overlay.OverlayInvalid as exc:
        raise ReplyInvalid([f"{i.code} at {i.where}: {i.message}" for i in exc.issues if i.severity == "error" and not i.fixed]) from None
    return overlay, bands, notes


def _info(name: str, model: str, usage: Usage) -> EstimatorInfo:
    return EstimatorInfo(
        name=name,
        model=model,
        version=__version__,
        queries=usage.calls,
        tokens=usage.total_tokens,
        cost_usd=usage.cost_usd,
        seconds=round(usage.seconds, 3),
    )


# ------------------------------------------------------------------- estimator
def model_string(estimator: str, model: str | None) -> str:
    """litellm model string for an estimator name: ``openai`` prefixes
    ``openai/`` when missing; ``llm`` takes it as given.

    Raises:
        ValueError: no model given.
    """
    if not model:
        raise ValueError(f"--estimator {estimator} needs --model (a litellm model string, e.g. gemini/gemini-2.5-flash)")
    if estimator == "openai" and not model.startswith("openai/"):
        return "openai/" + model
    return model


def make_client(estimator: str = "llm", model: str | None = None, base_url: str | None = None, *, check: bool = True, **overrides) -> LLMClient:
    """A client for ``estimator`` (``llm`` or ``openai``) with knobs from the
    environment (:meth:`ClientConfig.from_env`) and ``overrides``.

    Raises:
        ValueError: no model.
        LLMUnavailable: litellm missing.
        MissingCredentials: ``check`` and the provider's key is not set.
    """
    client = LLMClient(ClientConfig.from_env(model_string(estimator, model), base_url, **overrides))
    if check:
        client.check_credentials()
    return client


class LLMEstimator:
    """Overlay from a vision-language model (see the module docstring).

    Args:
        model: litellm model string (``openai`` estimator: the server's model name).
        base_url: OpenAI-compatible / local server base URL (no key needed).
        client: an existing :class:`LLMClient` (then ``model``/``base_url`` are ignored).
        max_reasks: re-asks after an unusable reply (default 2).

    Raises:
        ValueError, LLMUnavailable, MissingCredentials: see :func:`make_client`
            (at construction, before any work).
    """

    name = "llm"

    #: Replies remembered per asset and request (bounded), so that a second
    #: ``estimate`` of the same context (the refine stage retries with another
    #: resting pose) rebuilds the overlay from the same reply without a call.
    MEMO_SIZE = 16

    def __init__(self, model: str | None = None, base_url: str | None = None, *, client: LLMClient | None = None, max_reasks: int = 2, **settings):
        self.client = client or make_client(self.name, model, base_url)
        self.max_reasks = max_reasks
        self.settings = settings
        self._memo: dict[tuple, tuple[ModelReply, Usage, list[list[str]], list[str]]] = {}

    @staticmethod
    def _memo_key(ctx: EstimationContext) -> tuple:
        return (ctx.asset.asset_id, ctx.asset.input_hash, str(ctx.asset.urdf_path), ctx.request.text, ctx.category)

    def joint_proposer(self, ctx: EstimationContext):
        """A proposer for :func:`asset2sim.tasks.state.refine_state.refine_initial_state`:
        when the simulator's local search stalls, the model sees the current
        state, the allowed interval of every joint and the worst colliding link
        pairs, and proposes up to a few candidate states (one call, re-asked at
        most twice on malformed replies). The simulator keeps a candidate only
        if it lowers the objective. Returns ``proposer(state, pairs, intervals)
        -> (list of {joint: value}, model calls)``."""
        client = self.client
        labels = {j.name: ctx.asset.link(j.child).semantic_label for j in ctx.asset.movable_joints()}
        types = {j.name: j.type for j in ctx.asset.movable_joints()}

        def propose(state, pairs, intervals):
            schema = reply_json_schema(JointProposalReply)
            text = (
                "The physics simulator could not remove all self-penetration of this articulated object "
                "by searching joint positions near the requested state. Propose up to 4 alternative "
                "initial states (joint positions; radians for revolute, metres for prismatic; each inside "
                "its allowed interval) that might separate the colliding parts. Reply with JSON only, "
                "following this schema:\n" + json.dumps(schema)
            )
            info = {
                "category": ctx.category,
                "request": ctx.request.text,
                "joints": [
                    {"name": n, "type": types.get(n), "part": labels.get(n), "current": round(float(q), 6),
                     "allowed": [round(float(intervals[n][0]), 6), round(float(intervals[n][1]), 6)]}
                    for n, q in state.items() if n in intervals
                ],
                "colliding_link_pairs": [
                    {"link_a": p_["link_a"], "link_b": p_["link_b"], "penetration_m": round(float(p_["depth_m"]), 6)}
                    for p_ in pairs
                ],
            }
            messages = [
                {"role": "system", "content": text},
                {"role": "user", "content": f"{PROPOSAL_MARK}\n{json.dumps(info, separators=(',', ':'))}"},
            ]

            def accept(reply: JointProposalReply):
                unknown = sorted({jv.name for p_ in reply.proposals for jv in p_.joints} - set(intervals))
                if unknown:
                    raise ReplyInvalid([f"unknown joint names {unknown}; use only {sorted(intervals)}"])
                return [{jv.name: jv.value for jv in p_.joints} for p_ in reply.proposals]

            try:
                answer = client.ask(messages, JointProposalReply, schema=schema, schema_name=PROPOSAL_SCHEMA_NAME, accept=accept, max_reasks=2)
            except ReplyError as exc:  # unusable replies: no proposals, but the calls were made
                return [], len(exc.history)
            except ModelCallError:
                return [], 0
            return answer.value, answer.usage.calls

        return propose

    def estimate(self, ctx: EstimationContext) -> estimate.Estimate:
        """Ask the model (once per asset and request) and build the overlay;
        the bands are the model's choice per movable joint.

        A repeated call for the same asset and request reuses the remembered
        reply (the physics is recomputed for the context, e.g. another resting
        pose); its ``estimator`` info repeats the calls the reply cost.

        Raises:
            ModelCallError: the network failed after the retries.
            ReplyError: no usable reply after the re-asks.
            ReplyInvalid: a remembered reply no longer validates for this context.
        """
        cfg = self.client.config
        key = self._memo_key(ctx)
        memo = self._memo.get(key)
        if memo is None:
            schema = reply_json_schema()
            desc = describe(ctx)
            images, render_notes = render_closed_views(ctx, VIEWS, cfg.render_size)
            messages = build_messages(desc, images, schema)
            answer = self.client.ask(
                messages,
                ModelReply,
                schema=schema,
                schema_name=REPLY_SCHEMA_NAME,
                accept=lambda r: overlay_from_reply(ctx, r, name=self.name, model=cfg.model),
                max_reasks=self.max_reasks,
            )
            overlay, bands, notes = answer.value
            memo = (answer.reply, answer.usage, answer.history, render_notes)
            while len(self._memo) >= self.MEMO_SIZE:
                self._memo.pop(next(iter(self._memo)))
            self._memo[key] = memo
        else:
            overlay, bands, notes = overlay_from_reply(ctx, memo[0], name=self.name, model=cfg.model)
        reply, usage, history, render_notes = memo
        other = list(overlay.notes.other) + render_notes
        other.append(f"model {cfg.model}: {usage.summary()}")
        for i, errs in enumerate(history):
            other.append(f"model reply {i + 1} rejected and re-asked: " + "; ".join(errs[:5]))
        overlay = overlay.model_copy(update={"estimator": _info(self.name, cfg.model, usage), "notes": overlay.notes.model_copy(update={"other": other})})
        return estimate.Estimate(overlay=overlay, bands=dict(bands), notes=list(notes))


class OpenAICompatibleEstimator(LLMEstimator):
    """``--estimator openai --base-url URL --model M``: an OpenAI-compatible
    server (model string ``openai/M``)."""

    name = "openai"


estimate.register_estimator("llm", LLMEstimator)
estimate.register_estimator("openai", OpenAICompatibleEstimator)


# -------------------------------------------------------------------- baselines
def _numeric_overlay(
    ctx: EstimationContext,
    name: str,
    model: str,
    usage: Usage,
    scale: float,
    link_mass: dict[str, tuple[float, bool]],
    joint_values: dict[str, dict[str, float]],
    contact: tuple[float, float],
    notes: list[str],
) -> Overlay:
    """An overlay from the model's numbers as they are (no validation): masses
    and dynamics as given, inertia of the scaled geometry at that mass (shell
    or solid tensor as the model said; URDF needs a tensor and the reply has
    none), COM of the scaled geometry; links the reply misses stay missing."""
    links = {}
    for ln, (mass, shell) in link_mass.items():
        g = ctx.geometry.get(ln)
        if g is None:
            continue
        links[ln] = LinkPhysics(
            mass=float(mass),
            inertia=Inertia.from_matrix(validate_overlay.geometry_inertia(g, float(mass), scale, shell)),
            com=tuple(float(c) * scale for c in g.com),
            source=f"{name}: model mass, geometry inertia",
        )
    joints = {}
    state = {}
    for jn, v in joint_values.items():
        joints[jn] = JointDynamics(
            damping=float(v["damping"]),
            friction=float(v["friction"]),
            stiffness=float(v["stiffness"]),
            spring_reference=float(v["position"]) if v["stiffness"] > 0 else None,
            source=f"{name}: model values",
        )
        state[jn] = float(v["position"])
    return Overlay(
        estimator=_info(name, model, usage),
        scale=float(scale),
        category=ctx.category,
        contact_material=ContactMaterial(lateral_friction=max(0.0, contact[0]), restitution=min(1.0, max(0.0, contact[1])), note=f"model ({name})"),
        links=links,
        joints=joints,
        initial_joint_positions=state or None,
        notes=ValidationNotes(size=f"{name}: s = {scale:.4g}", other=notes + [f"model {model}: {usage.summary()}"]),
    )


def direct_overlay(ctx: EstimationContext, client: LLMClient) -> Overlay:
    """``direct`` baseline: one call with the five views; the reply's numbers
    (scale, link masses, damping, friction, stiffness, joint positions) applied
    as they are: no re-ask, no validation, no physics, no state refinement.

    Raises:
        ModelCallError: the call failed.
        ReplyError: the single reply is unusable (does not parse into the schema).
    """
    cfg = client.config
    schema = reply_json_schema()
    images, render_notes = render_closed_views(ctx, VIEWS, cfg.render_size)
    answer = client.ask(build_messages(describe(ctx), images, schema), ModelReply, schema=schema, schema_name=REPLY_SCHEMA_NAME, max_reasks=0)
    r = answer.reply
    return _numeric_overlay(
        ctx,
        "direct",
        cfg.model,
        answer.usage,
        r.scale.value,
        {lr.link: (lr.mass.value, lr.shell) for lr in r.links},
        {jr.joint: {k: getattr(jr, k).value for k in ("damping", "friction", "stiffness", "position")} for jr in r.joints},
        (r.lateral_friction, r.restitution),
        render_notes + ["direct: one model call applied as is (no validation, no refinement)"],
    )


def ivw_overlay(ctx: EstimationContext, client: LLMClient, n_views: int = 5, n_calls: int = 5) -> Overlay:
    """``ivw`` baseline: ``n_calls`` independent calls for each of the first
    ``n_views`` views (one image per call, temperature :data:`IVW_TEMPERATURE`),
    each reply's numbers with their reported std fused per parameter by
    inverse-variance weighting (:func:`asset2sim.tasks.synthesize.ivw.fuse`): scale, link
    masses, joint damping, friction, stiffness and positions. Unusable replies
    and failed calls are skipped (noted); no re-asks, no validation, no physics.

    Raises:
        ValueError: ``n_views`` not in 1..5 or ``n_calls`` < 1.
        ReplyError: no call gave a usable reply (the last error is chained).
    """
    if not (1 <= n_views <= len(VIEWS)) or n_calls < 1:
        raise ValueError(f"n_views must be in 1..{len(VIEWS)} and n_calls >= 1, got {n_views}, {n_calls}")
    cfg = client.config
    schema = reply_json_schema()
    desc = describe(ctx)
    views = VIEWS[:n_views]
    images, render_notes = render_closed_views(ctx, views, cfg.render_size)
    before = client.usage.snapshot()
    replies: list[ModelReply] = []
    failures: list[str] = []
    last_exc: Exception | None = None
    for v in views:
        one = {v: images[v]} if v in images else {}
        for k in range(n_calls):
            msgs = build_messages(desc, one, schema, extra=f"Independent estimate {k + 1} of {n_calls} from the {v} view.")
            try:
                ans = client.ask(msgs, ModelReply, schema=schema, schema_name=REPLY_SCHEMA_NAME, max_reasks=0, temperature=IVW_TEMPERATURE)
            except LLMError as exc:
                failures.append(f"{v} #{k + 1}: {exc}")
                last_exc = exc
                continue
            if check_reply_names(ctx, ans.reply):
                failures.append(f"{v} #{k + 1}: names not in the asset")
                continue
            replies.append(ans.reply)
    usage = client.usage.since(before)
    if not replies:
        raise ReplyError(f"ivw: no usable reply from {len(views) * n_calls} calls ({failures[-1] if failures else 'no calls'})", [failures]) from last_exc
    scale = ivw.fuse([(r.scale.value, r.scale.std) for r in replies])
    masses: dict[str, list[tuple[float, float]]] = {}
    shells: dict[str, list[bool]] = {}
    for r in replies:
        for lr in r.links:
            masses.setdefault(lr.link, []).append((lr.mass.value, lr.mass.std))
            shells.setdefault(lr.link, []).append(lr.shell)
    fused_mass = ivw.fuse_all(masses)
    jvals: dict[str, dict[str, list[tuple[float, float]]]] = {}
    for r in replies:
        for jr in r.joints:
            d = jvals.setdefault(jr.joint, {})
            for k in ("damping", "friction", "stiffness", "position"):
                e = getattr(jr, k)
                d.setdefault(k, []).append((e.value, e.std))
    joint_values = {jn: {k: f.value for k, f in ivw.fuse_all(d).items()} for jn, d in jvals.items()}
    for jn, d in joint_values.items():  # IVW of non-negative values stays non-negative; keep it explicit
        for k in ("damping", "friction", "stiffness"):
            d[k] = max(0.0, d[k])
    contact = (float(np.mean([r.lateral_friction for r in replies])), float(np.mean([r.restitution for r in replies])))
    return _numeric_overlay(
        ctx,
        "ivw",
        cfg.model,
        usage,
        scale.value,
        {ln: (f.value, sum(shells[ln]) * 2 > len(shells[ln])) for ln, f in fused_mass.items()},
        joint_values,
        contact,
        render_notes
        + [f"ivw: {len(replies)} usable replies of {len(views) * n_calls} calls ({n_views} views x {n_calls}); scale {scale.value:.4g} +- {scale.std:.3g}"]
        + [f"skipped: {f}" for f in failures[:10]],
    )
