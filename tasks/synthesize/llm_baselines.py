"""The SPEC's model baselines, the model's numbers applied as they are (no re-ask,
validation, physics or state refinement): ``direct`` (one call, five views) and
``ivw`` (5 views x 5 calls, inverse-variance fused)."""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from asset2sim.models.client import LLMClient
from asset2sim.models.errors import LLMError, ReplyError
from asset2sim.models.usage import Usage
from asset2sim.schemas.model_reply import REPLY_SCHEMA_NAME, ModelReply, reply_json_schema
from asset2sim.schemas.overlay import ContactMaterial, Inertia, JointDynamics, LinkPhysics, Overlay, ValidationNotes
from asset2sim.tasks.synthesize import ivw, validate_overlay
from asset2sim.engines.base import SimSession
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.llm_overlay import check_reply_names, estimator_info
from asset2sim.tasks.synthesize.llm_prompt import VIEWS, build_messages, describe, render_closed_views
from asset2sim.inert import one_line

IVW_TEMPERATURE = 1.0
"""Sampling temperature of the IVW baseline's repeated queries (independent samples)."""

#: The numbers of a reply's joint entry the baselines apply.
_JOINT_VALUES = ("damping", "friction", "stiffness", "position")


def _numeric_overlay(ctx: EstimationContext, name: str, model: str, usage: Usage, scale: float, link_mass: dict[str, tuple[float, bool]],
                     joint_values: dict[str, dict[str, float]], contact: tuple[float, float], notes: list[str]) -> Overlay:
    """An overlay from the model's numbers as they are (no validation); inertia and COM of the scaled
    geometry at the given mass (shell or solid tensor as the model said)."""
    links = {ln: LinkPhysics(mass=float(mass),
                             inertia=Inertia.from_matrix(validate_overlay.geometry_inertia(g, float(mass), scale, shell)),
                             com=tuple(float(c) * scale for c in g.com), source=f"{name}: model mass, geometry inertia")
             for ln, (mass, shell) in link_mass.items() if (g := ctx.geometry.get(ln)) is not None}
    joints = {jn: JointDynamics(damping=float(v["damping"]), friction=float(v["friction"]), stiffness=float(v["stiffness"]),
                                spring_reference=float(v["position"]) if v["stiffness"] > 0 else None,
                                source=f"{name}: model values") for jn, v in joint_values.items()}
    state = {jn: float(v["position"]) for jn, v in joint_values.items()}
    return Overlay(
        estimator=estimator_info(name, model, usage), scale=float(scale), category=ctx.category,
        contact_material=ContactMaterial(lateral_friction=max(0.0, contact[0]), restitution=min(1.0, max(0.0, contact[1])), note=f"model ({name})"),
        links=links, joints=joints, initial_joint_positions=state or None,
        notes=ValidationNotes(size=f"{name}: s = {scale:.4g}", other=notes + [f"model {model}: {usage.summary()}"]),
    )


def direct_overlay(ctx: EstimationContext, kin: SimSession, client: LLMClient) -> Overlay:
    """``direct`` baseline: one call with the five views, the reply's numbers applied as they are (``kin``: the
    input's kinematics session, for the description).

    Raises:
        ModelCallError: the call failed.
        ReplyError: the single reply is unusable (does not parse into the schema).
    """
    cfg = client.config
    schema = reply_json_schema()
    images, render_notes = render_closed_views(ctx, VIEWS, cfg.render_size)
    answer = client.ask(build_messages(describe(ctx, kin), images, schema), ModelReply, schema=schema, schema_name=REPLY_SCHEMA_NAME, max_reasks=0)
    r = answer.reply
    return _numeric_overlay(
        ctx, "direct", cfg.model, answer.usage, r.scale.value, {lr.link: (lr.mass.value, lr.shell) for lr in r.links},
        {jr.joint: {k: getattr(jr, k).value for k in _JOINT_VALUES} for jr in r.joints},
        (r.lateral_friction, r.restitution), render_notes + ["direct: one model call applied as is (no validation, no refinement)"])


def ivw_overlay(ctx: EstimationContext, kin: SimSession, client: LLMClient, n_views: int = 5, n_calls: int = 5) -> Overlay:
    """``ivw`` baseline: ``n_calls`` calls for each of the first ``n_views`` views (one image each,
    temperature :data:`IVW_TEMPERATURE`), numbers fused per parameter by inverse-variance weighting;
    unusable replies and failed calls are skipped (noted). ``kin``: the input's kinematics session, for the
    description.

    Raises:
        ValueError: ``n_views`` not in 1..5 or ``n_calls`` < 1.
        ReplyError: no call gave a usable reply (the last error is chained).
    """
    if not (1 <= n_views <= len(VIEWS)) or n_calls < 1:
        raise ValueError(f"n_views must be in 1..{len(VIEWS)} and n_calls >= 1, got {n_views}, {n_calls}")
    cfg = client.config
    schema = reply_json_schema()
    desc = describe(ctx, kin)
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
                failures.append(f"{v} #{k + 1}: {one_line(exc)}")
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
    masses, shells, jvals = defaultdict(list), defaultdict(list), defaultdict(lambda: defaultdict(list))
    for r in replies:
        for lr in r.links:
            masses[lr.link].append((lr.mass.value, lr.mass.std))
            shells[lr.link].append(lr.shell)
        for jr in r.joints:
            for k in _JOINT_VALUES:
                jvals[jr.joint][k].append((getattr(jr, k).value, getattr(jr, k).std))
    fused_mass = ivw.fuse_all(masses)
    # IVW of non-negative values stays non-negative; keep it explicit (all but the position)
    joint_values = {jn: {k: f.value if k == "position" else max(0.0, f.value) for k, f in ivw.fuse_all(d).items()}
                    for jn, d in jvals.items()}
    contact = (float(np.mean([r.lateral_friction for r in replies])), float(np.mean([r.restitution for r in replies])))
    return _numeric_overlay(
        ctx, "ivw", cfg.model, usage, scale.value, {ln: (f.value, sum(shells[ln]) * 2 > len(shells[ln])) for ln, f in fused_mass.items()},
        joint_values, contact, render_notes
        + [f"ivw: {len(replies)} usable replies of {len(views) * n_calls} calls ({n_views} views x {n_calls}); scale {scale.value:.4g} +- {scale.std:.3g}"]
        + [f"skipped: {f}" for f in failures[:10]],
    )
