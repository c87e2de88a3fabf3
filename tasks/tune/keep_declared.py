"""``refine --keep-declared``: refine around the values an asset declares that pass the audit, instead of
replacing them. :class:`KeepDeclared` wraps any estimator: the asset keeps its declared size when that size is
plausible (the estimate is made at scale 1), and each link's mass, inertia tensor and center of mass and each
joint's damping, friction and spring that the audit judges plausible (:func:`asset2sim.tasks.check.plausibility.judge`)
replace the estimator's. What the request asks in words or typed overrides (a mass, a material, damping words,
dynamics in numbers) wins over the declared values it concerns. The refine's later stages (state search,
post-check escalation) treat the kept values as any other; the report lists what was kept."""

from __future__ import annotations

import dataclasses

from asset2sim.engines.base import SimSession
from asset2sim.schemas.audit import ValueVerdict
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.check.plausibility import Judgement, judge
from asset2sim.tasks.ingest.declared import DeclaredPhysics
from asset2sim.tasks.interpret import mounting
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.estimator import Estimate, Estimator

__all__ = ["KeepDeclared"]

#: Quantities a kept joint takes from the declared physics.
JOINT_QUANTITIES = ("damping", "friction")


def _verdicts(values: list[ValueVerdict], where: str) -> dict[str, str]:
    return {v.quantity: v.verdict for v in values if v.where == where}


def _mass_asked(ctx: EstimationContext) -> bool:
    r = ctx.request
    return bool(r.mass_level or any(p.mass is not None or p.material for p in r.properties) or "mass" in " ".join(r.overrides)
                or "material" in " ".join(r.overrides))


def _dynamics_asked(ctx: EstimationContext) -> bool:
    r = ctx.request
    return bool(r.dynamics_values or r.damping != "moderate" or r.holds_position or r.stiff or r.free_moving or r.spring)


class KeepDeclared:
    """An estimator (``inner``'s name) that keeps the declared values of ``declared`` the audit finds plausible."""

    def __init__(self, inner: Estimator, declared: DeclaredPhysics):
        self.inner = inner
        self.name = inner.name
        self.declared = declared
        self.judged: Judgement | None = None

    def __getattr__(self, name):  # the inner estimator's extras (joint_proposer ...)
        return getattr(self.inner, name)

    def estimate(self, ctx: EstimationContext, kin: SimSession) -> Estimate:
        """The inner estimate at the declared size when plausible, with the plausible declared values kept
        (``kin``: the input's kinematics session)."""
        if self.judged is None:  # the declared values and the context do not change between a refine's attempts
            self.judged = judge(ctx, kin, self.declared, mounting.category_mounting(ctx.category))
        judged = self.judged
        size_ok = judged.values[0].quantity == "scale" and judged.values[0].verdict == "plausible"
        inner_ctx = ctx
        if size_ok and ctx.request.scale is None and not ctx.request.sizes:
            inner_ctx = dataclasses.replace(ctx, request=ctx.request.model_copy(update={"scale": 1.0}))
        est = self.inner.estimate(inner_ctx, kin)
        kept, notes = self._keep(ctx, est.overlay, judged, size_ok)
        overlay = est.overlay.model_copy(update={**kept, "notes": est.overlay.notes.model_copy(update={
            "other": [*est.overlay.notes.other, *notes]})})
        return dataclasses.replace(est, overlay=overlay, notes=[*est.notes, *notes])

    def _keep(self, ctx: EstimationContext, overlay: Overlay, judged: Judgement,
              size_ok: bool) -> tuple[dict[str, dict], list[str]]:
        """(the overlay's links and joints with the plausible declared values kept, none when nothing is; the notes)."""
        if not size_ok or overlay.scale != 1.0:
            why = "its size is implausible and is rescaled" if not size_ok else f"the request scales it (x{overlay.scale:.4g})"
            return {}, [f"keep declared: nothing kept: {why}; declared values are judged at the declared size"]
        links, joints, kept = dict(overlay.links), dict(overlay.joints), []
        if not _mass_asked(ctx):
            for name, lp in judged.patched.links.items():
                v = _verdicts(judged.values, f"link {name}")
                if name in links and all(v.get(q) == "plausible" for q in ("mass", "inertia", "center_of_mass")) and v.get("density", "plausible") == "plausible":
                    links[name] = lp.model_copy(update={"material": links[name].material, "density": links[name].density,
                                                        "source": "declared, kept: plausible (asset2sim audit)"})
                    kept.append(f"link {name}: mass {lp.mass:.4g} kg, inertia, center of mass")
        if not _dynamics_asked(ctx):  # damping and friction: declared where plausible, else from the kept masses' loads
            for name, jd in judged.patched.joints.items():
                if name not in joints:
                    continue
                v = _verdicts(judged.values, f"joint {name}")
                ok = [q for q in JOINT_QUANTITIES if v.get(q) == "plausible"]
                update = {"damping": jd.damping, "friction": jd.friction}
                if jd.stiffness > 0 and v.get("stiffness") == "plausible":
                    update.update(stiffness=jd.stiffness, spring_reference=jd.spring_reference)
                    ok.append("spring")
                source = joints[name].source + ("; kept as declared: " + ", ".join(ok) if ok else "; from the kept masses' loads")
                joints[name] = joints[name].model_copy(update={**update, "source": source})
                if ok:
                    kept.append(f"joint {name}: " + ", ".join(f"{q} {update[q]:.4g}" for q in ok if q in JOINT_QUANTITIES)
                                + (" and its spring" if "spring" in ok else ""))
        notes = [f"keep declared: {k}" for k in kept] or ["keep declared: no declared value is plausible; the estimates are used"]
        notes.append(f"keep declared: the declared size kept (scale 1; {judged.values[0].reason})")
        return {"links": links, "joints": joints}, notes
