"""A refine's wall time against its two bounds (``schemas/config.py``: ``MAX_REFINE_STEPS`` steps and
``MAX_REFINE_SECONDS`` of wall time; ``docs/design/trust.md``, "Bounded work"), on the case that showed the step cap
alone is no time bound: a base with N revolute links (each a 10 cm cube on a z hinge, 12 cm apart on a plate; N = 32,
the joint cap) refined with ``sim: {timestep: 1.0e-4, settle_time: 10, test_time: 10}`` (exactly the 200,000-step
cap of one measurement).

Prints PyBullet's steps a second at that time step on the N-link object and on the demo box with a lid (two links),
the time the step cap alone allows each (the cap over the rate: before the deadline), then refines the N-link object
under a deadline (``--seconds``, default the product's) and prints how the refine ended and after how long.

    .venv/bin/python benchmarks/bench_refine_deadline.py --seconds 60        # the deadline's end, in a minute
    .venv/bin/python benchmarks/bench_refine_deadline.py                     # the product's deadline (15 min)
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from asset2sim import demo_assets
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.config import MAX_REFINE_SECONDS, MAX_REFINE_STEPS, RefineConfig, SimConventions
from asset2sim.tasks import refine
from tests.helpers import write_hinge_bank

#: The configuration of the case: 10 s settle + 10 s test at 1e-4 s, the 200,000-step cap of one measurement.
SIM = {"timestep": 1.0e-4, "settle_time": 10.0, "test_time": 10.0}

def steps_per_second(urdf: Path, steps: int) -> float:
    """PyBullet steps a second of ``urdf`` at :data:`SIM`'s time step, free on the ground (the rest test's set-up)."""
    options = SessionOptions(conventions=SimConventions(**SIM))
    with open_session("pybullet", urdf, options) as s:
        s.step(10)
        t0 = time.perf_counter()
        s.step(steps)
        return steps / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--links", type=int, default=32, help="revolute links of the object (default 32, the joint cap)")
    ap.add_argument("--seconds", type=float, default=MAX_REFINE_SECONDS, help="the refine's deadline, s (default the product's)")
    ap.add_argument("--steps", type=int, default=3000, help="steps timed for the rate (default 3000)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-deadline-") as tmp:
        big = write_hinge_bank(Path(tmp) / f"links_{args.links}", args.links)
        box = demo_assets.build_object("box_lid", Path(tmp) / "box_lid")
        for name, folder in ((f"{args.links} revolute links", big), ("box with a lid (2 links)", box)):
            rate = steps_per_second(folder / "mobility.urdf", args.steps)
            print(f"{name:<26} {rate:8.0f} steps/s at 1e-4 s; the step cap ({MAX_REFINE_STEPS:,} steps) alone allows "
                  f"{MAX_REFINE_STEPS / rate / 60:6.1f} min")
        config = RefineConfig(sim=SIM, engines=["pybullet"])
        refine.MAX_REFINE_SECONDS = args.seconds  # the deadline this run is given
        t0 = time.perf_counter()
        try:
            result = refine.refine_asset(big, "", Path(tmp) / "out", config, extras=False)
            ended = f"finished: {result.report.failure_mode}"
        except refine.RefineError as exc:
            ended = f"failed: {exc.failure_mode} {','.join(exc.codes)}"
        print(f"refine of {args.links} links, deadline {args.seconds:g} s: {ended} after {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
