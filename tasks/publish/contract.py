"""The output contract's bookkeeping: the code and configuration hashes, the
completion marker (:func:`is_complete`) and the one reader and writer of
``report.json``. The flow's job records and catalog rows built on them are
:mod:`asset2sim.flows.job_records`; ``docs/design/pipeline.md`` explains the skip key.
"""

from __future__ import annotations

import functools
import hashlib
import json
import subprocess
from pathlib import Path
from typing import Any


import asset2sim
from asset2sim import __version__, atomic, output_folder
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.report import RefineReport
from asset2sim.output_folder import (MARKER_NAME, REPORT_NAME, TIMINGS_NAME, VOLATILE, OwnedFolder,
                                    read_record)

#: Sub-packages of ``asset2sim`` whose sources make up the code (``package-dir`` in pyproject.toml).
CODE_PACKAGES = ("asset2sim", "asset2sim.tasks", "asset2sim.schemas", "asset2sim.apps", "asset2sim.flows")
#: File suffixes of the package source that change results (modules and the data tables shipped with them).
CODE_SUFFIXES = (".py", ".yaml", ".yml", ".json", ".csv", ".txt")


def _package_dirs() -> list[Path]:
    import importlib.util

    dirs = []
    for name in CODE_PACKAGES:
        spec = importlib.util.find_spec(name)  # imports only the parent package
        for loc in (spec.submodule_search_locations or []) if spec is not None else []:
            p = Path(loc).resolve()
            if p not in dirs:
                dirs.append(p)
    return dirs


@functools.lru_cache(maxsize=1)
def code_hash() -> str:
    """Hash of the code that makes results (hex, 16): SHA-256 over the package version and, in sorted order,
    the relative path and bytes of every :data:`CODE_SUFFIXES` file under the folders of :data:`CODE_PACKAGES`
    (``__pycache__`` left out). Computed once per process."""
    h = hashlib.sha256(__version__.encode())
    dirs = _package_dirs()
    files: list[tuple[str, Path]] = []
    for i, d in enumerate(dirs):
        nested = [o for o in dirs if o != d and d in o.parents]
        for p in d.rglob("*"):
            if p.suffix not in CODE_SUFFIXES or "__pycache__" in p.parts or not p.is_file():
                continue
            if any(o in p.parents for o in nested):  # hashed with its own package
                continue
            files.append((f"{i}/{p.relative_to(d).as_posix()}", p))
    for rel, p in sorted(files):
        h.update(b"\0" + rel.encode() + b"\0")
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """The readable code version (PEP 440 local): ``<version>+g<commit>`` from a clean git checkout,
    ``<version>+g<commit>.dirty.<code hash 8>`` with uncommitted changes, ``<version>+src.<code hash 12>``
    without git."""
    src = Path(asset2sim.__file__).resolve().parent.parent
    try:
        sha = subprocess.run(["git", "-C", str(src), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=10)  # fmt: skip
        if sha.returncode == 0 and sha.stdout.strip():
            dirty = subprocess.run(["git", "-C", str(src), "status", "--porcelain", "--untracked-files=no"],
                                   capture_output=True, text=True, timeout=20)  # fmt: skip
            tail = f".dirty.{code_hash()[:8]}" if dirty.stdout.strip() else ""
            return f"{__version__}+g{sha.stdout.strip()}{tail}"
    except (OSError, subprocess.SubprocessError):
        pass
    return f"{__version__}+src.{code_hash()[:12]}"


def skip_code_hash(code_change: str) -> str | None:
    """The code hash reused results must have under ``results.code_change`` of ``catalog.yaml``:
    :func:`code_hash` for ``rerun``, None (any) for ``keep``. Raises ValueError for another policy."""
    if code_change == "rerun":
        return code_hash()
    if code_change == "keep":
        return None
    raise ValueError(f"results.code_change must be 'rerun' or 'keep', got {code_change!r}")


def _hash16(blob: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(blob, sort_keys=True).encode()).hexdigest()[:16]


def run_hash(input_hash: str, config: RefineConfig, prompt: str, category: str | None) -> str:
    """Configuration hash of one refine run (hex, 16): SHA-256 of the configuration's own hash, the prompt,
    the category override and the package version (``input_hash`` is not part of it)."""
    return _hash16({"config": config.config_hash(), "prompt": prompt, "category": category, "version": __version__})


def flow_config_hash(refine_hash: str, *, refine_function: str, evaluate: bool, probes: bool, extras: bool,
                     reference: bool, reference_scale: float | None) -> str:
    """Configuration hash of one asset's result in the catalog (hex, 16): :func:`run_hash` plus the flow
    settings that change the result."""
    return _hash16({"refine": refine_hash, "refine_function": refine_function, "evaluate": evaluate, "probes": probes,
                    "extras": extras, "reference": reference, "reference_scale": reference_scale})


def is_complete(out_dir: Path | str, input_hash: str, config_hash: str) -> bool:
    """True when ``out_dir`` holds a completion marker for exactly this input, configuration and version,
    and every file it lists has its recorded SHA-256."""
    try:
        data = read_record(Path(out_dir) / MARKER_NAME)
    except (OSError, ValueError):
        return False
    if not isinstance(data, dict) or not isinstance(data.get("files", {}), dict):
        return False
    if data.get("input_hash") != input_hash or data.get("config_hash") != config_hash or data.get("version") != __version__:
        return False
    for rel, digest in data.get("files", {}).items():
        p = Path(out_dir) / rel
        try:
            if not p.is_file() or atomic.sha256_file(p) != digest:
                return False
        except OSError:  # replaced by a FIFO or removed meanwhile
            return False
    return True


def output_files(out_dir: Path | str) -> list[str]:
    """Files of an output folder (relative, sorted) except the marker and temporary files."""
    out_dir = Path(out_dir)
    return sorted(
        str(p.relative_to(out_dir)) for p in out_dir.rglob("*")
        if p.is_file() and p.name != MARKER_NAME and not p.name.endswith(".tmp")
    )  # fmt: skip


def write_completion_marker(out_dir: Path | str, input_hash: str, config_hash: str, owner: OwnedFolder | None = None) -> Path:
    """Write the completion marker: both hashes, the version and the SHA-256 of every file of
    :func:`output_files` or, with ``owner``, of the files the run wrote (:meth:`OwnedFolder.finish`: raises
    ``OutputError`` when one is missing)."""
    out_dir = Path(out_dir)
    head = {"input_hash": input_hash, "config_hash": config_hash, "version": __version__}
    if owner is not None:
        owner.finish(head)
        return out_dir / MARKER_NAME
    return atomic.write_json(out_dir / MARKER_NAME, {**head, "files": {f: atomic.sha256_file(out_dir / f) for f in output_files(out_dir)
                                                                        if f not in VOLATILE}})


def write_report_json(out_dir: Path | str, report: RefineReport) -> Path:
    """Write ``report`` as ``out_dir/report.json`` without its wall times, and those (``stage_seconds`` {stage: s},
    ``state_seconds`` s) as ``out_dir/timings.json`` (:data:`asset2sim.output_folder.VOLATILE`: not hashed), so two
    refines of the same input and code write the same ``report.json``. Returns the report's path."""
    out_dir = Path(out_dir)
    data = report.model_dump(mode="json")
    timings = {"stage_seconds": data.pop("stage_seconds", {}) or {}}
    if isinstance(data.get("state"), dict):
        timings["state_seconds"] = data["state"].pop("seconds", 0.0)
    output_folder.merge_timings(out_dir, timings)
    return atomic.write_json(out_dir / REPORT_NAME, data)


def read_report_json(out_dir: Path | str) -> RefineReport:
    """``out_dir/report.json`` as a :class:`RefineReport`, with the wall times of ``timings.json`` when it is readable
    (:func:`write_report_json`). Raises OSError (missing, not a regular file, too large) or ValueError (invalid)."""
    out_dir = Path(out_dir)
    data = read_record(out_dir / REPORT_NAME)
    if not isinstance(data, dict):
        raise ValueError(f"{out_dir / REPORT_NAME}: not a JSON object")
    try:
        timings = read_record(out_dir / TIMINGS_NAME)
    except (OSError, ValueError):
        timings = {}
    if isinstance(timings, dict):
        if isinstance(timings.get("stage_seconds"), dict) and not data.get("stage_seconds"):
            data["stage_seconds"] = timings["stage_seconds"]
        if isinstance(data.get("state"), dict) and "seconds" not in data["state"] and isinstance(timings.get("state_seconds"), (int, float)):
            data["state"]["seconds"] = timings["state_seconds"]
    return RefineReport.model_validate(data)
