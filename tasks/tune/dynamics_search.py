"""The friction and damping of a joint bracketed between robust rest (wants them high) and the task
(wants them low): :class:`DynamicsSearch` turns the proposals of relief
(:func:`relieve`) and escalation
(:func:`asset2sim.tasks.tune.escalation.escalate`) into a bracketed search over the post-check rounds
(``docs/design/metrics.md``, "Interaction under manipulation"; the rules of :meth:`DynamicsSearch.settle`:
``docs/design/core.md``). Settings are ordered by the operating cost f + c w (w the gripper's top speed
at the grasp point; 1 without a budget).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.tune import operating

#: Settings whose operating costs differ by less than this share are the same
#: setting (dimensionless): a bracket this narrow is not split again.
SAME_SHARE = 0.02
#: Smallest measured headroom worth a round, as a share of the joint's friction (dimensionless).
HEADROOM_MIN_SHARE = 0.01
#: Raises in a row after which a joint whose drift did not answer is raised no more ...
UNANSWERED_RAISES = 2
#: ... each raising its friction at least this many times (dimensionless) ...
UNANSWERED_RATIO = 2.0
#: ... while its largest drift shrank by less than this share (dimensionless): friction from its tilt floor on
#: (its weight held at robust rest's tilt with a margin) that leaves a part moving as much is not what stops it (a
#: contact pushes it), so more friction would only cost the hand. Below the floor a part may slide onto a stop,
#: the same drift at any friction until it holds: no stop there.
UNANSWERED_SHARE = 0.1

#: Smallest share of its friction a joint keeps in one relief round (:func:`relieve`).
RELIEF_MIN_SHARE = 0.5


@dataclass(frozen=True, slots=True)
class Retuning:
    """One step on the joints' friction and damping (:func:`relieve`, :meth:`DynamicsSearch.settle`,
    :func:`asset2sim.tasks.tune.escalation.escalate`): ``overlay`` after it, ``changes`` joint ->
    {"friction" (N m or N), "damping" (N m s/rad or N s/m)} changed (empty: nothing changed), ``reason`` (why,
    one line; "" when nothing changed) and ``notes`` (one line per joint the bracketing moved or held back)."""

    overlay: Overlay
    changes: dict[str, dict[str, float]]
    reason: str = ""
    notes: list[str] = field(default_factory=list)

@dataclass(frozen=True)
class Setting:
    """Friction (N m or N) and damping (N m s/rad or N s/m) of one joint."""

    friction: float
    damping: float

    def cost(self, speed: float) -> float:
        """Resistance at ``speed`` (rad/s or m/s): friction + damping x speed (N m or N)."""
        return self.friction + self.damping * speed

    def midpoint(self, other: Setting) -> Setting:
        """The setting halfway between ``self`` and ``other``, per component."""
        return Setting(0.5 * (self.friction + other.friction), 0.5 * (self.damping + other.damping))


@dataclass
class JointRecord:
    """What the rounds measured for one joint: ``weak`` the strongest setting robust rest did not hold,
    ``strong`` the weakest at which the task failed by force, ``good`` the latest at which both passed."""

    weak: Setting | None = None
    strong: Setting | None = None
    good: Setting | None = None
    drifts: list[tuple[Setting, float]] = field(default_factory=list)
    """(setting, largest drift in rad or m: robust rest's trials and the rest test) of each round it was not held"""


@dataclass
class RoundOutcome:
    """Per-joint outcome of one post-check round, read from its metrics."""

    not_held: set[str] = field(default_factory=set)
    """joints a robust-rest trial found leaving their state"""
    held: set[str] = field(default_factory=set)
    """joints robust rest ran on and found held in every trial"""
    task_bad: set[str] = field(default_factory=set)
    """joints whose task needed more than a real force (range exceeded, or the free object slid / tipped)"""
    task_ok: set[str] = field(default_factory=set)
    """joints with task attempts, every one a success and inside the force range"""
    peak_force: dict[str, float] = field(default_factory=dict)
    """joint -> largest peak operating force of its attempts, N"""
    task_ran: bool = False
    drift: dict[str, float] = field(default_factory=dict)
    """joint -> largest drift from its state (rad or m) over robust rest's trials and the rest test's state hold"""


def round_outcome(metrics: list[MetricResult], budgets: dict[str, operating.OperatingBudget]) -> RoundOutcome:
    """The per-joint outcome of a post-check round's ``metrics``; a task counts
    against a joint as relief counts it (:func:`force_excess`)."""
    out = RoundOutcome()
    seen: set[str] = set()
    drifts = []  # joint -> drift, per robust-rest trial and rest test
    tried: dict[str, bool] = {}
    for m in metrics:
        if m.name == "robust_rest":
            for trial in (m.details.get("trials") or {}).values():
                out.not_held.update(trial.get("failing_joints") or [])
                drifts.append(trial.get("joint_drift") or {})
                seen.update(drifts[-1])
        elif m.name == "state_hold":
            drifts.append(m.details.get("drift") or {})
        elif m.name == "task_execution" and m.passed is not None:
            out.task_ran = True
            for a in m.details.get("attempts") or []:
                j = a["joint"]
                tried[j] = tried.get(j, True) and bool(a.get("success"))
                out.peak_force[j] = max(out.peak_force.get(j, 0.0), float(a.get("peak_operating_force_n") or 0.0))
    for j, d in (jd for drift in drifts for jd in drift.items()):
        out.drift[j] = max(out.drift.get(j, 0.0), float(d))
    out.held = seen - out.not_held
    out.task_bad = set(force_excess(metrics, budgets)[0])
    out.task_ok = {j for j, ok in tried.items() if ok and j not in out.task_bad}
    return out


class DynamicsSearch:
    """Bracketed search of each joint's friction and damping over the post-check
    rounds (module docstring); ``budgets``: joint -> the task gripper's
    operating budget (joints without one get no measured-headroom step); ``hand_caps``: joint -> the friction
    (N m or N) a headroom step never passes; ``floors``: joint -> its tilt floor (N m or N), from which on a drift
    that does not answer raises stops them (joints without one are never stopped so)."""

    def __init__(self, budgets: dict[str, operating.OperatingBudget] | None = None,
                 hand_caps: dict[str, float] | None = None, floors: dict[str, float] | None = None):
        self.budgets = dict(budgets or {})
        self.floors = dict(floors or {})
        """joint -> friction (N m or N) that holds its part's weight at robust rest's tilt
        (:func:`~asset2sim.tasks.tune.operating.tilt_floors`); a drift that does not answer raises from at least it
        is not its weight's (:meth:`_unanswered`)"""
        self.hand_caps = dict(hand_caps or {})
        """joint -> friction (N m or N) no headroom step goes above (a hand still moves the part both ways)"""
        self.joints: dict[str, JointRecord] = {}
        self._last: RoundOutcome | None = None

    def _cost(self, joint: str, s: Setting) -> float:
        b = self.budgets.get(joint)
        return s.cost(float(b.speed) if b is not None and b.speed > 0 else 1.0)

    def record(self, overlay: Overlay, metrics: list[MetricResult]) -> RoundOutcome:
        """Record what a round measured at ``overlay``'s settings; returns the round's outcome."""
        out = round_outcome(metrics, self.budgets)
        for name, d in overlay.joints.items():
            s = Setting(float(d.friction), float(d.damping))
            rec = self.joints.setdefault(name, JointRecord())
            if name in out.not_held and (rec.weak is None or self._cost(name, s) > self._cost(name, rec.weak)):
                rec.weak = s
            if name in out.task_bad and (rec.strong is None or self._cost(name, s) < self._cost(name, rec.strong)):
                rec.strong = s
            if out.task_ran and name in out.held and name not in out.task_bad and (
                    name in out.task_ok or name not in out.peak_force):
                rec.good = s
            if name in out.not_held and name in out.drift:
                rec.drifts.append((s, out.drift[name]))
        self._last = out
        return out

    def _same(self, joint: str, a: Setting, b: Setting) -> bool:
        ca, cb = self._cost(joint, a), self._cost(joint, b)
        return abs(ca - cb) <= SAME_SHARE * max(ca, cb, 1e-12)

    def _headroom(self, joint: str) -> float:
        """Friction (N m or N) the task's measured peak force leaves under the budget's allowed force."""
        b = self.budgets.get(joint)
        out = self._last
        if b is None or out is None or joint not in out.task_ok or joint not in out.peak_force or b.force_n == float("inf"):
            return 0.0
        return max(0.0, (operating.BUDGET_SHARE * float(b.force_n) - out.peak_force[joint]) * float(b.lever or 1.0))

    def settle(self, before: Overlay, proposal: Overlay, changes: dict[str, dict[str, float]],
               caps: dict[str, float] | None = None) -> Retuning:
        """Apply the bracketing rules (``docs/design/core.md``) to a round's ``proposal`` (made
        from ``before``, the round just recorded, with its ``changes``);
        ``caps``: joint -> friction cap (N m or N), raised in place by a headroom step.

        Returns:
            the overlay, its changes from ``before`` and the notes (no reason).
        """
        out = self._last or RoundOutcome()
        ov = proposal.model_copy(deep=True)
        notes: list[str] = []
        for name in list(dict.fromkeys([*changes, *sorted(out.not_held)])):
            d0, d1 = before.joints.get(name), ov.joints.get(name)
            if d0 is None or d1 is None:
                continue
            rec = self.joints.get(name, JointRecord())
            cur, prop = Setting(float(d0.friction), float(d0.damping)), Setting(float(d1.friction), float(d1.damping))
            new, why = prop, ""
            c_prop, c_cur = self._cost(name, prop), self._cost(name, cur)
            up, down = c_prop > c_cur, c_prop < c_cur
            to_strong = up and rec.strong is not None and c_prop >= self._cost(name, rec.strong)
            to_weak = down and rec.weak is not None and c_prop <= self._cost(name, rec.weak)
            stuck = not up and not down and name in out.not_held
            empty = rec.strong is not None and rec.weak is not None and self._cost(name, rec.weak) >= self._cost(name, rec.strong)
            if (to_strong or to_weak or (stuck and rec.strong is not None)) and rec.good is not None \
                    and not self._same(name, rec.good, cur):
                new, why = rec.good, "back to the last setting where robust rest held it and its task passed"
            elif empty:
                pass  # robust rest failed where the task already failed by force: no bracket, the models decide
            elif to_strong:
                new, why = self._inside(name, rec, cur, rec.strong, "the task needed more than a real force at")
            elif to_weak:
                new, why = self._inside(name, rec, cur, rec.weak, "robust rest did not hold it at")
            elif stuck:
                if rec.strong is not None:
                    new, why = self._inside(name, rec, cur, rec.strong, "not held at its caps; the task needed more than a real force at")
                else:
                    h = min(self._headroom(name), self.hand_caps.get(name, float("inf")) - cur.friction)
                    if h > HEADROOM_MIN_SHARE * max(cur.friction, 1e-9):
                        new = Setting(cur.friction + h, cur.damping)
                        why = (f"not held at its caps; the task's measured operating force leaves {h:.3g} "
                               f"{self.budgets[name].unit} of the real range: friction raised by it")
                        if caps is not None:
                            caps[name] = max(caps.get(name, 0.0), new.friction)
            if up and new == prop and (why := self._unanswered(name)):
                new = cur
                notes.append(f"{name}: {why}")
            if new == cur:
                ov.joints[name] = d0
                changes.pop(name, None)
                continue
            if new != prop:
                ov.joints[name] = d1.model_copy(update={"friction": new.friction, "damping": new.damping,
                                                        "source": d0.source + f"; {why}: friction {new.friction:.3g}, damping {new.damping:.3g}"})
                notes.append(f"{name}: {why}")
            changes[name] = {"damping": new.damping, "friction": new.friction}
        return Retuning(ov, {k: v for k, v in changes.items() if k in ov.joints}, notes=notes)

    def _unanswered(self, joint: str) -> str:
        """Why ``joint`` is raised no more ("" when it may be): its last :data:`UNANSWERED_RAISES` raises, each at
        least :data:`UNANSWERED_RATIO` times the friction and the first from at least its tilt floor, left its largest
        drift within :data:`UNANSWERED_SHARE` of where it was."""
        seen = self.joints.get(joint, JointRecord()).drifts[-(UNANSWERED_RAISES + 1):]
        floor = self.floors.get(joint)
        if len(seen) < UNANSWERED_RAISES + 1 or floor is None or seen[0][0].friction < floor:
            return ""  # below the tilt floor, a part may slide onto a stop whatever its friction, until it holds
        for (a, da), (b, db) in zip(seen, seen[1:]):
            if b.friction < UNANSWERED_RATIO * a.friction or db < (1.0 - UNANSWERED_SHARE) * da:
                return ""
        (first, d0), (last, d1) = seen[0], seen[-1]
        return (f"friction {first.friction:.3g} -> {last.friction:.3g} left its drift at {d0:.3g} -> {d1:.3g}: not what "
                f"holds it (a contact moves it), raised no more")

    def _inside(self, joint: str, rec: JointRecord, cur: Setting, bound: Setting, what: str) -> tuple[Setting, str]:
        """The bisection of ``weak`` and ``strong`` when both are known, else halfway from ``cur`` to ``bound``."""
        b = f"{what} friction {bound.friction:.3g}, damping {bound.damping:.3g}"
        if rec.weak is not None and rec.strong is not None:
            if self._same(joint, rec.weak, rec.strong):
                return cur, ""
            return rec.weak.midpoint(rec.strong), f"{b}; bisecting between robust rest's and the task's bounds"
        if self._same(joint, cur, bound):
            return cur, ""
        return cur.midpoint(bound), f"{b}; halfway to it"


def failing_tiers(metrics: list[MetricResult]) -> int:
    """Number of metrics of a post-check round that fail (``passed`` False)."""
    return sum(m.passed is False for m in metrics)


def fewest_failures(rounds: list[list[MetricResult]]) -> int:
    """Index of the round (its metrics) with the fewest failing metrics, the latest of equals."""
    return min(range(len(rounds)), key=lambda i: (failing_tiers(rounds[i]), -i))


def force_excess(metrics: list[MetricResult], budgets: dict[str, operating.OperatingBudget]) -> tuple[dict[str, float], dict[str, str]]:
    """Joints whose task needed more than a real operating force -> the measured excess (N m or N), and why:
    an ``operating_force`` attempt outside its range, or a moved part under which the free object slid or
    tipped at a peak operating force above the budget's allowed force."""
    excess: dict[str, float] = {}
    why: dict[str, str] = {}
    for m in metrics:
        if m.name == "operating_force" and m.passed is False:
            for row in m.details.get("attempts") or []:
                if row.get("passed") is not False:
                    continue
                b = budgets.get(row["joint"])
                e = 0.0
                if row.get("force_range_n"):
                    e = max(e, float(row["peak_operating_force_n"]) - float(row["force_range_n"][1]))
                    if b is not None and b.lever:
                        e *= b.lever
                if row.get("torque_range_nm") and row.get("peak_torque_nm") is not None:
                    e = max(e, float(row["peak_torque_nm"]) - float(row["torque_range_nm"][1]))
                if e > 0:
                    excess[row["joint"]] = max(excess.get(row["joint"], 0.0), e)
                    why[row["joint"]] = "operating force above the real range"
        if m.name == "task_execution" and m.passed is False:
            for a in m.details.get("attempts") or []:
                b = budgets.get(a["joint"])
                if not (a.get("slid") or a.get("tipped")) or b is None or not a.get("moved"):
                    continue
                e = (float(a["peak_operating_force_n"]) - b.force_n) * (b.lever or 1.0)
                if e > 0:
                    excess[a["joint"]] = max(excess.get(a["joint"], 0.0), e)
                    why.setdefault(a["joint"], "the free object slid under the gripper's push")
    return excess, why


def relieve(overlay: Overlay, metrics: list[MetricResult], limits: operating.OperatingLimits) -> Retuning:
    """Lower the friction (then the damping at top speed) of joints whose task
    needed more than a real operating force by the excess (:func:`force_excess`)
    / ``BUDGET_SHARE``, at most down to :data:`RELIEF_MIN_SHARE` of the friction
    per round and never below the hold floor; ``limits``' caps are lowered with them.

    Returns:
        the new overlay, its changes and the reason; no changes when nothing
        failed on force.
    """
    excess, why = force_excess(metrics, limits.budgets)
    ov = overlay.model_copy(deep=True)
    changes: dict[str, dict[str, float]] = {}
    for name, e in excess.items():
        d = ov.joints.get(name)
        b = limits.budgets.get(name)
        if d is None or b is None:
            continue
        need = e / operating.BUDGET_SHARE
        fr = max(d.friction - need, RELIEF_MIN_SHARE * d.friction, min(b.hold_floor, d.friction))
        left = need - (d.friction - fr)
        dm = max(d.damping - left / b.speed, 0.0) if left > 0 else d.damping
        if fr == d.friction and dm == d.damping:
            continue
        ov.joints[name] = d.model_copy(update={"friction": fr, "damping": dm, "source": d.source + (
            f"; task needed {e:.3g} {b.unit} more than a real operating force: friction {d.friction:.3g} -> {fr:.3g}, "
            f"damping {d.damping:.3g} -> {dm:.3g}")})
        limits.friction_caps[name] = fr
        limits.damping_caps[name] = dm
        changes[name] = {"damping": dm, "friction": fr}
    return Retuning(ov, changes, "; ".join(f"{j}: {w}" for j, w in why.items() if j in changes))
