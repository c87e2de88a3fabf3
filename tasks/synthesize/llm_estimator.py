"""Model-backed overlay synthesis (SPEC stage 2 with a vision-language model).

Registers two estimators with :mod:`asset2sim.tasks.synthesize.estimate`:

- ``llm``: ``get_estimator("llm", model="gemini/gemini-2.5-flash")`` (any
  litellm model string; ``base_url=`` for a local vLLM / Ollama / llama.cpp
  server);
- ``openai``: ``get_estimator("openai", model="m", base_url="http://host/v1")``,
  shorthand for an OpenAI-compatible server (the model becomes ``openai/m``).

Both check credentials when created (a missing key fails before any work).

**Request.** Five renders of the input asset at its geometric closed state
(front, back, left, right, perspective; :func:`asset2sim.tasks.geometry.render.render_views`,
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
the overlay (:class:`asset2sim.tasks.synthesize.estimator.Estimate`) for the
refine stage.

**Baselines** (SPEC): :func:`direct_overlay` (one call, five views, the
model's numbers applied as they are) and :func:`ivw_overlay` (each of 5 views
asked 5 times, numbers fused per parameter by inverse-variance weighting,
:mod:`asset2sim.tasks.synthesize.ivw`).

This module holds the estimators and their client; the pieces live beside it
and their public names are importable from here too: what is sent
(:mod:`~asset2sim.tasks.synthesize.llm_prompt`), the reply turned into an
overlay (:mod:`~asset2sim.tasks.synthesize.llm_overlay`), the baselines
(:mod:`~asset2sim.tasks.synthesize.llm_baselines`), the network
(:mod:`~asset2sim.tasks.synthesize.llm_client`).
"""

from __future__ import annotations

from asset2sim.schemas.model_reply import (
    PROPOSAL_SCHEMA_NAME,
    REPLY_SCHEMA_NAME,
    JointProposalReply,
    ModelReply,
    reply_json_schema,
)
from asset2sim.tasks.synthesize import estimator
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.llm_baselines import IVW_TEMPERATURE, direct_overlay, ivw_overlay
from asset2sim.tasks.synthesize.llm_client import ClientConfig, LLMClient
from asset2sim.tasks.synthesize.llm_errors import ModelCallError, ReplyError, ReplyInvalid
from asset2sim.tasks.synthesize.llm_overlay import MASS_AGREEMENT, check_reply_names, estimator_info, overlay_from_reply
from asset2sim.tasks.synthesize.llm_prompt import (
    DESCRIPTION_MARK,
    PROPOSAL_MARK,
    SYSTEM_PROMPT,
    VIEWS,
    build_messages,
    describe,
    png_data_url,
    proposal_messages,
    render_closed_views,
    system_prompt,
)
from asset2sim.tasks.synthesize.llm_usage import Usage

__all__ = [
    "DESCRIPTION_MARK",
    "IVW_TEMPERATURE",
    "MASS_AGREEMENT",
    "PROPOSAL_MARK",
    "SYSTEM_PROMPT",
    "VIEWS",
    "LLMEstimator",
    "OpenAICompatibleEstimator",
    "build_messages",
    "check_reply_names",
    "describe",
    "direct_overlay",
    "estimator_info",
    "ivw_overlay",
    "make_client",
    "model_string",
    "overlay_from_reply",
    "png_data_url",
    "proposal_messages",
    "render_closed_views",
    "system_prompt",
]


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

        def propose(state, pairs, intervals):
            schema = reply_json_schema(JointProposalReply)
            messages = proposal_messages(ctx, state, pairs, intervals, schema)

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

    def estimate(self, ctx: EstimationContext) -> estimator.Estimate:
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
        overlay = overlay.model_copy(update={"estimator": estimator_info(self.name, cfg.model, usage), "notes": overlay.notes.model_copy(update={"other": other})})
        return estimator.Estimate(overlay=overlay, bands=dict(bands), notes=list(notes))


class OpenAICompatibleEstimator(LLMEstimator):
    """``--estimator openai --base-url URL --model M``: an OpenAI-compatible
    server (model string ``openai/M``)."""

    name = "openai"


estimator.register_estimator("llm", LLMEstimator)
estimator.register_estimator("openai", OpenAICompatibleEstimator)
