"""A stand-in refine function for flow tests: the real signature and output
contract (files, report, completion marker), without the physics.

It reads the asset with the real extractor (real input hash), writes a real
output folder (the URDF and meshes copied, ``initial_state.json``,
``overlay.json``, ``report.json`` and the completion marker the real refine
writes) and records every call in ``$FLOWFAKES_CALLS`` (one line per call), so
tests can see which assets were really worked on. Special asset ids trigger
failures: ``hang_*`` sleeps past any time limit, ``crash_*`` aborts the
process, ``flaky_*`` fails like a model call on its first attempt,
``modelfail_*`` always fails like a model call, ``unstable_*`` reports an
unstable result; ``$FLOWFAKES_DELAY_S`` makes every call take that long (s).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

from asset2sim import __version__, atomic


class FakeRefineError(RuntimeError):
    def __init__(self, message: str, failure_mode: str):
        super().__init__(message)
        self.failure_mode = failure_mode


def _calls_file() -> Path | None:
    p = os.environ.get("FLOWFAKES_CALLS")
    return Path(p) if p else None


def _log_call(asset_id: str, prompt: str) -> int:
    """Append a call; return how many calls this asset has had (this one included)."""
    f = _calls_file()
    if f is None:
        return 1
    with open(f, "a") as fh:
        fh.write(json.dumps({"asset_id": asset_id, "prompt": prompt, "pid": os.getpid()}) + "\n")
    return sum(1 for line in f.read_text().splitlines() if json.loads(line)["asset_id"] == asset_id)


def calls(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


class FakeResult:
    def __init__(self, out_dir, report):
        self.out_dir = out_dir
        self.report = report
        self.skipped = False


def refine_fake(asset_dir, prompt, out_dir, config=None, *, category=None, asset_id=None, progress=None, extras=True):
    """Same signature and output contract as ``asset2sim.tasks.refine.refine_asset``."""
    from asset2sim.schemas.report import MetricResult, RefineReport
    from asset2sim.tasks.ingest.extract import extract_asset
    from asset2sim.tasks.publish.contract import MARKER_NAME, run_hash

    t0 = time.perf_counter()
    asset_dir, out_dir = Path(asset_dir), Path(out_dir)
    aid = asset_id or asset_dir.name
    n = _log_call(aid, prompt)
    if os.environ.get("FLOWFAKES_DELAY_S"):  # a refine that takes a while (a worker can be killed mid-asset)
        time.sleep(float(os.environ["FLOWFAKES_DELAY_S"]))
    if aid.startswith("hang_"):
        time.sleep(3600)
    if aid.startswith("crash_"):
        os.abort()
    if aid.startswith("flaky_") and n == 1:
        raise FakeRefineError("model endpoint returned 503", "estimator_failure")
    if aid.startswith("modelfail_"):
        raise FakeRefineError("model endpoint returned 503", "estimator_failure")
    asset = extract_asset(asset_dir, asset_id=aid, category=category)
    if progress:
        progress("extract", f"{len(asset.links)} links")
    chash = run_hash(config, prompt, category)
    out_dir.mkdir(parents=True, exist_ok=True)
    shutil.copytree(asset_dir / "textured_objs", out_dir / "textured_objs", dirs_exist_ok=True)
    atomic.copy_file(asset_dir / "mobility.urdf", out_dir / "mobility.urdf")
    state = {j.name: float(j.lower or 0.0) if j.lower is not None and j.lower > 0 else 0.0 for j in asset.movable_joints()}
    atomic.write_json(out_dir / "initial_state.json", {"initial_joint_positions": state})
    atomic.write_json(out_dir / "overlay.json", {"estimator": {"name": config.estimator, "queries": 0}, "scale": 0.5})
    unstable = aid.startswith("unstable_")
    report = RefineReport(
        asset_id=aid,
        source=str(asset_dir),
        prompt=prompt,
        category=category or asset.category,
        version=__version__,
        input_hash=asset.input_hash,
        config_hash=chash,
        estimator=config.estimator,
        model=config.model,
        model_queries=0 if config.estimator == "offline" else n,
        scale=0.5,
        total_mass=1.25,
        initial_joint_positions=state,
        metrics=[
            MetricResult(name="penetration", value=0.5, unit="mm"),
            MetricResult(name="rest_stability", value=1e-5, unit="m", passed=not unstable,
                         details={"D_pos_m": 1e-5, "D_ori_rad": 2e-4}),
            MetricResult(name="oscillation", value=0.0, unit="joints", passed=True),
        ],
        failure_mode="unstable" if unstable else "none",
        stage_seconds={"extract": time.perf_counter() - t0, "write": 0.01},
    )
    atomic.write_json(out_dir / "report.json", report.model_dump(mode="json"))
    # like the real refine: the marker covers every file of the folder
    files = sorted(str(f.relative_to(out_dir)) for f in out_dir.rglob("*") if f.is_file() and f.name != MARKER_NAME)
    atomic.write_json(
        out_dir / MARKER_NAME,
        {
            "input_hash": asset.input_hash,
            "config_hash": chash,
            "version": __version__,
            "files": {f: atomic.sha256_file(out_dir / f) for f in files},
        },
    )
    return FakeResult(out_dir, report)


def sleep_for(seconds: float) -> dict:
    """A stage function that only sleeps (``seconds`` s), for process tests."""
    time.sleep(float(seconds))
    return {"slept": float(seconds)}
