"""Model-backed overlay synthesis: the ``llm`` estimator (any litellm model
string, ``base_url=`` for a local server) and ``openai`` (an OpenAI-compatible
server, model ``openai/<name>``), registered with the estimator registry; both
check credentials when created. The reply is a prior, not the answer
(:func:`overlay_from_reply`). What is sent, how the reply becomes the overlay
and the direct / IVW baselines: ``docs/design/model_backends.md``.
"""

from __future__ import annotations

from asset2sim.models.client import LLMClient, make_client, model_string
from asset2sim.models.errors import ModelCallError, ReplyError, ReplyInvalid
from asset2sim.models.usage import Usage
from asset2sim.schemas.model_reply import PROPOSAL_SCHEMA_NAME, REPLY_SCHEMA_NAME, JointProposalReply, ModelReply, reply_json_schema
from asset2sim.tasks.synthesize import estimator
from asset2sim.engines.base import SimSession
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.llm_baselines import IVW_TEMPERATURE, direct_overlay, ivw_overlay
from asset2sim.tasks.synthesize.llm_overlay import MASS_AGREEMENT, estimator_info, overlay_from_reply
from asset2sim.tasks.synthesize.llm_prompt import (DESCRIPTION_MARK, PROPOSAL_MARK, VIEWS, build_messages, describe, proposal_messages,
                                                   render_closed_views)

#: The estimators' own names and the pieces' names callers import from here.
__all__ = ["DESCRIPTION_MARK", "IVW_TEMPERATURE", "MASS_AGREEMENT", "PROPOSAL_MARK", "VIEWS", "LLMEstimator", "OpenAICompatibleEstimator",
           "describe", "direct_overlay", "ivw_overlay", "make_client", "model_string", "overlay_from_reply"]


class LLMEstimator:
    """Overlay from a vision-language model. ``model``: litellm model string (``openai``: the server's
    name); ``base_url``: a local server; ``client`` replaces both; ``max_reasks`` after an unusable reply.

    Raises:
        ValueError, LLMUnavailable, MissingCredentials: see :func:`make_client`, at construction.
    """

    name = "llm"

    #: Replies remembered per asset and request: a second ``estimate`` (another resting pose) makes no call.
    MEMO_SIZE = 16

    def __init__(self, model: str | None = None, base_url: str | None = None, *, client: LLMClient | None = None, max_reasks: int = 2):
        self.client = client or make_client(self.name, model, base_url)
        self.max_reasks = max_reasks
        self._memo: dict[tuple, tuple[ModelReply, Usage, list[list[str]], list[str]]] = {}

    def joint_proposer(self, ctx: EstimationContext):
        """``proposer(state, pairs, intervals) -> (list of {joint: value}, model calls)`` for the state
        search when it stalls: the model proposes candidate states (one call, at most two re-asks)."""
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

    def estimate(self, ctx: EstimationContext, kin: SimSession) -> estimator.Estimate:
        """Ask the model (once per asset and request; a repeat rebuilds the overlay from the remembered
        reply) and build the overlay with the model's band per movable joint (``kin``: the input's kinematics
        session, for the description and the joints' loads).

        Raises:
            ModelCallError: the network failed after the retries.
            ReplyError: no usable reply after the re-asks.
            ReplyInvalid: a remembered reply no longer validates for this context.
        """
        cfg = self.client.config
        key = (ctx.asset.asset_id, ctx.asset.input_hash, str(ctx.asset.urdf_path), ctx.request.text, ctx.category)
        memo = self._memo.get(key)
        if memo is None:
            schema = reply_json_schema()
            images, render_notes = render_closed_views(ctx, VIEWS, cfg.render_size)
            answer = self.client.ask(build_messages(describe(ctx, kin), images, schema), ModelReply, schema=schema,
                                     schema_name=REPLY_SCHEMA_NAME,
                                     accept=lambda r: overlay_from_reply(ctx, kin, r, name=self.name, model=cfg.model),
                                     max_reasks=self.max_reasks)
            est = answer.value
            memo = (answer.reply, answer.usage, answer.history, render_notes)
            while len(self._memo) >= self.MEMO_SIZE:
                self._memo.pop(next(iter(self._memo)))
            self._memo[key] = memo
        else:
            est = overlay_from_reply(ctx, kin, memo[0], name=self.name, model=cfg.model)
        _, usage, history, render_notes = memo
        overlay = est.overlay
        other = [*overlay.notes.other, *render_notes, f"model {cfg.model}: {usage.summary()}",
                 *(f"model reply {i + 1} rejected and re-asked: " + "; ".join(errs[:5]) for i, errs in enumerate(history))]
        overlay = overlay.model_copy(update={"estimator": estimator_info(self.name, cfg.model, usage), "notes": overlay.notes.model_copy(update={"other": other})})
        return estimator.Estimate(overlay=overlay, bands=dict(est.bands), notes=list(est.notes))


class OpenAICompatibleEstimator(LLMEstimator):
    """An OpenAI-compatible server (model string ``openai/M``)."""

    name = "openai"


estimator.register_estimator("llm", LLMEstimator)
estimator.register_estimator("openai", OpenAICompatibleEstimator)
