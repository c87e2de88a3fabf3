"""The flow tests' project: a project folder with generated assets and its own catalog.yaml
(:func:`make_project`), its manifest (:func:`write_manifest`), the fake refine function's name
(:data:`FAKE_REFINE`) and the file it logs its calls to (:data:`CALLS_PATH`). Imported by the flow tests and
their ``conftest.py`` as ``flowproject``; a test outside tests/flows imports it as ``tests.flows.flowproject``, a
second module object that keeps the first one's call log (:data:`CALLS_PATH`, set once per process tree)."""

from __future__ import annotations

import atexit
import csv
import os
import shutil
import tempfile
from pathlib import Path

import yaml

# Prefect reads its settings when first imported: keep its state out of ~/.prefect, in a folder removed when the
# process that made it exits (a child process importing this module makes and removes its own, unused one).
_PREFECT_HOME = tempfile.mkdtemp(prefix="a2s-test-prefect-")
atexit.register(shutil.rmtree, _PREFECT_HOME, True)
os.environ.setdefault("PREFECT_HOME", _PREFECT_HOME)
os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("DO_NOT_TRACK", "1")
os.environ.setdefault("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", "180")
os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")
# Every process the flows start (Dask workers, isolated stage processes)
# inherits this: the fake refine function logs its calls there. Set once per process tree: a second import of this
# file under another module name (``tests.flows.flowproject`` from a test outside tests/flows) reads the same file
# rather than moving the log under the tests that hold the first name's CALLS_PATH.
os.environ.setdefault("FLOWFAKES_CALLS", str(Path(_PREFECT_HOME) / "fake_refine_calls.jsonl"))
CALLS_PATH = Path(os.environ["FLOWFAKES_CALLS"])

try:  # package layout (tests/flows/__init__.py) or rootdir-on-sys.path layout
    from . import flowfakes  # type: ignore[no-redef]
except ImportError:
    import flowfakes  # type: ignore[no-redef]

FAKE_REFINE = f"{flowfakes.__name__}:refine_fake"


def write_manifest(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        fields = ["id", "category", "prompt", "time_limit_seconds"]
        w = csv.DictWriter(fh, fieldnames=fields, lineterminator="\n", extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow(r)


def make_project(
    root: Path, assets: dict[str, str], *, catalog_extra: dict | None = None, time_limits: dict | None = None
) -> Path:
    """A project folder with ``raw/`` assets built by the demo generator.

    ``assets``: id -> demo object it is a copy of (``broken`` ones lose a
    mesh); ``time_limits``: id -> per-asset limit (s) in the manifest.
    Returns the path of its catalog.yaml.
    """
    from asset2sim import demo_assets

    raw = root / "raw"
    raw.mkdir(parents=True, exist_ok=True)
    rows = []
    prompts = {o.asset_id: (o.category, o.prompt) for o in demo_assets.DEMO_OBJECTS}
    for aid, source in assets.items():
        kind = "box_lid" if source == "broken" else source
        demo_assets._write_folder(raw / aid, demo_assets.demo_files(kind))
        if source == "broken":
            victim = sorted((raw / aid / "textured_objs").glob("*.obj"))[0]
            victim.unlink()
        cat, prompt = prompts[kind]
        rows.append({"id": aid, "category": cat, "prompt": prompt, "time_limit_seconds": (time_limits or {}).get(aid, "")})
    write_manifest(raw / "manifest.csv", rows)
    config = {
        "version": 1,
        "default_dataset": "gen",
        "output_root": "refined",
        "catalog_root": "catalog",
        "datasets": {"gen": {"root": "raw", "manifest": "raw/manifest.csv"}},
        "estimator": {"name": "offline", "retries": 2, "retry_delay_seconds": 0},
        "run": {
            "workers": 2,
            "time_limit_seconds": 40,
            "isolation": "process",
            "evaluate": True,
            "extras": False,
            "refine_function": FAKE_REFINE,
        },
        "schedule": {"cron": "0 2 * * *", "timezone": "UTC", "dataset": "gen"},
        "tracking": {"enabled": True, "uri": f"sqlite:///{root / 'mlflow.db'}", "experiment": "flowtest"},
    }
    for k, v in (catalog_extra or {}).items():
        if isinstance(v, dict) and isinstance(config.get(k), dict):
            config[k] = {**config[k], **v}
        else:
            config[k] = v
    path = root / "catalog.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path




