"""Whether a self-closing part shuts on its own: the metric ``shuts_on_its_own``, by which the as-asked tier grades
a request's self-closing word ("swings shut on its own", "closes by itself").

Each part the word applies to is released from fully open in the reference engine, gravity on, its object held still
(root fixed, as a hand steadies a cabinet whose door it lets go of) and its other parts where they are, and must come
back within its robust-rest band of its closed end (max(0.02 rad or 2 mm, 5 % of its joint's range between its
limits), the band the SPEC grades a part's rest in) within :data:`CLOSE_SECONDS`. A closer sized for the part's
weight near its closed end only (a drop-down door whose weight opens it further the further it is open) stops part
way: the word is then not met, and the report says where the part stopped.
"""

from __future__ import annotations

from typing import Any

from asset2sim.engines.source import SimObject
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.synthesize import set_down

#: Time (s) a released self-closing part has to come back shut: twice the least time ADA 404.2.8 (2010 ADA Standards,
#: door closers) lets a closer take from 90 degrees open to 12 degrees (5 s), since a closer may be set that slow.
CLOSE_SECONDS = 10.0


def shuts_on_its_own(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]],
                     joints: list[str]) -> MetricResult:
    """The metric ``shuts_on_its_own`` of ``joints`` of ``obj``: each released at rest from fully open (``closed``:
    joint -> (q_closed rad or m, opening direction +1 / -1, open range rad or m)), graded as the module docstring says.

    ``value``: the largest distance from shut at the end, as a fraction of the range; ``details["joints"]``: joint ->
    ``ended_at`` (fraction of its open range from shut after :data:`CLOSE_SECONDS`), ``band`` (the same, as that fraction),
    ``seconds`` (when it first came within its band; None: never), ``shut`` (bool). Joints not in ``closed`` are
    left out.

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading ``obj.source`` raises.
    """
    steps = max(1, round(0.5 / obj.conventions.timestep))
    rows: dict[str, dict[str, Any]] = {}
    for name in (n for n in joints if n in closed):
        q_closed, direction, rng = closed[name]
        with obj.open(engine, fixed_base=True, ground=False) as session:
            span = max(float(rng), 1e-12)
            lower, upper = session.joint_limits.get(name, (0.0, span))
            band = set_down.joint_band(lower, upper, session.joint_types.get(name) == "prismatic") / span
            session.set_joint_positions({**obj.state, name: q_closed + direction * rng})
            session.release_joint(name)
            seconds, t, frac = None, 0.0, 1.0
            while t < CLOSE_SECONDS - 1e-9:
                session.step(steps)
                t += steps * obj.conventions.timestep
                frac = (session.joint_state(name)[0] - q_closed) * direction / span
                if seconds is None and abs(frac) <= band:
                    seconds = round(t, 3)
        rows[name] = {"ended_at": round(float(frac), 4), "band": round(float(band), 4), "seconds": seconds,
                      "shut": bool(abs(frac) <= band)}
    failing = [n for n, r in rows.items() if not r["shut"]]
    return MetricResult(name="shuts_on_its_own", value=max((abs(r["ended_at"]) for r in rows.values()), default=0.0),
                        unit=unit("shuts_on_its_own"), passed=not failing if rows else None,
                        threshold=f"released fully open, back within its robust-rest band of shut in {CLOSE_SECONDS:g} s",
                        details={"joints": rows, "failing": failing, "seconds": CLOSE_SECONDS}, engine=engine)
