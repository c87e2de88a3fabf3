"""What a model-backed estimator sends: the structured description, the five
closed-state views as PNG data URLs, the chat messages, and the request for
alternative joint states when the state search stalls. Lengths in m, angles in
rad, at scale 1 in the input asset's frames (``docs/design/model_backends.md``).
"""

from __future__ import annotations

import base64
import json
from typing import Any

import numpy as np

from asset2sim.schemas.request import BAND_TARGET
from asset2sim.tasks.synthesize import request_apply
from asset2sim.tasks.interpret.part_priors import material_for
from asset2sim.tasks.interpret.size_priors import target_size
from asset2sim.tasks.geometry import render
from asset2sim.tasks.geometry.render_images import png_bytes
from asset2sim.tasks.synthesize import estimate
from asset2sim.engines.base import SimSession
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.inert import one_line
from asset2sim.package_data import package_text

DESCRIPTION_MARK = "ASSET DESCRIPTION (JSON):"
"""Line preceding the structured description in the user message."""

PROPOSAL_MARK = "STALLED STATE SEARCH (JSON):"
"""Line that precedes the state-search summary in a joint-proposal request."""

VIEWS: tuple[str, ...] = ("front", "back", "left", "right", "perspective")
"""Views sent with a request (the SPEC's five)."""


def _r(x: float | None) -> float | None:
    return None if x is None else float(f"{float(x):.5g}")


def describe(ctx: EstimationContext, kin: SimSession) -> dict[str, Any]:
    """The structured description sent to the model (JSON-able; m and rad at scale 1; prismatic values in
    the input's units): category, request and its parse, extents, typical size and mass, links, movable joints
    (``kin``, the input's kinematics session, moved for the request's ordinals and ends)."""
    asset = ctx.asset
    req = ctx.request
    target = target_size(ctx.category, req)
    resolved = request_apply.resolve_states(ctx, kin, estimate.choose_scale(ctx)[0])
    relevant = set(request_apply.task_relevant_joints(ctx))
    links = []
    for ln in asset.links:
        g = ctx.geometry.get(ln.name)
        pj = asset.parent_joint(ln.name)
        entry: dict[str, Any] = {
            **ln.model_dump(include={"name", "semantic_label", "semantic_joint"}),
            "parent_joint": pj.name if pj else None,
            "has_geometry": g is not None,
        }
        if g is not None:
            mat = material_for(ctx.category, ln.semantic_label)
            entry.update({"volume_m3": _r(g.volume), "volume_method": g.volume_method, "watertight": g.watertight, "area_m2": _r(g.area),
                          "extents_m": [_r(e) for e in g.extents],
                          "typical_material": mat.model_dump(include={"name", "density", "shell", "wall_thickness"})})
        links.append(entry)
    joints = []
    for j in asset.movable_joints():
        cs = ctx.closed.get(j.name)
        entry = {
            **j.model_dump(include={"name", "type", "parent", "child"}),
            "child_label": asset.link(j.child).semantic_label,
            "axis": [_r(a) for a in j.axis],
            "lower": _r(j.lower),
            "upper": _r(j.upper),
            "unit": "m at scale 1 (multiply by the scale)" if j.type == "prismatic" else "rad",
            "task_relevant": j.name in relevant,
            "requested_band": resolved.bands.get(j.name, "closed"),
            "requested_opening_fraction": None if j.name not in resolved.targets else _r(resolved.targets[j.name].fraction),
            "height_m": _r(ctx.joint_heights.get(j.name, 0.0)),
        }
        if cs is not None:
            entry.update({"closed_position": _r(cs.q_closed), "opening_direction": int(cs.direction), "opening_range": _r(cs.open_range)})
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
            **{k: getattr(req, k) for k in ("damping", "holds_position", "spring", "stiff", "free_moving")},
            "pose": req.pose_hint,
            **request_apply.prompt_fields(req),
            "notes": resolved.warnings + resolved.notes,
        },
        "closed_extents_m": [_r(e) for e in np.asarray(ctx.closed_extents, float)],
        "typical_dims_m": [_r(d) for d in target.dims],
        "typical_mass_range_kg": [_r(m) for m in target.mass_range],
        "typical_size_note": target.note,
        "links": links,
        "joints": joints,
        "band_fractions": dict(BAND_TARGET),
    }


#: The system prompt of an overlay request (the reply format and how each field is used).
SYSTEM_PROMPT = package_text(__package__, "overlay_prompt.txt")


def png_data_url(image: np.ndarray) -> str:
    """``data:image/png;base64,...`` of an RGB(A) uint8 (H, W, 3|4) image."""
    return "data:image/png;base64," + base64.b64encode(png_bytes(image)).decode("ascii")


def render_closed_views(ctx: EstimationContext, views: tuple[str, ...],
                        size: tuple[int, int]) -> tuple[dict[str, str], list[str]]:
    """(view -> PNG data URL, notes) of ``views`` (of :data:`VIEWS`) of the input asset at its geometric closed state,
    ``size`` (width, height) pixels; a render failure
    leaves the views out and the note says why."""
    try:
        images = render.render_views(ctx.asset.urdf_path, {n: float(cs.q_closed) for n, cs in ctx.closed.items()}, views=views,
                                     size=size)
    except Exception as exc:  # renders are evidence, not a requirement
        return {}, [f"renders failed ({type(exc).__name__}: {one_line(exc)}); the model got the description only"]
    return {v: png_data_url(img) for v, img in images.items()}, []


def build_messages(description: dict[str, Any], images: dict[str, str], schema: dict[str, Any], *, extra: str = "") -> list[dict[str, Any]]:
    """OpenAI-format messages: the system prompt and one user message with the description and each view."""
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
    system = SYSTEM_PROMPT + "\nJSON schema:\n" + json.dumps(schema, separators=(",", ":"))  # for servers ignoring response_format
    return [{"role": "system", "content": system}, {"role": "user", "content": parts}]


def proposal_messages(ctx: EstimationContext, state: dict[str, float], pairs: list[dict[str, Any]],
                      intervals: dict[str, tuple[float, float]], schema: dict[str, Any]) -> list[dict[str, Any]]:
    """OpenAI-format messages asking for alternative initial states: instructions with ``schema``, then
    :data:`PROPOSAL_MARK` and a summary of every joint of ``state`` with an interval in ``intervals`` (rad or
    m) and the colliding link ``pairs`` (``depth_m`` in m), values rounded to 1e-6."""
    labels = {j.name: ctx.asset.link(j.child).semantic_label for j in ctx.asset.movable_joints()}
    types = {j.name: j.type for j in ctx.asset.movable_joints()}
    text = package_text(__package__, "proposal_prompt.txt") + json.dumps(schema)
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
    return [
        {"role": "system", "content": text},
        {"role": "user", "content": f"{PROPOSAL_MARK}\n{json.dumps(info, separators=(',', ':'))}"},
    ]
