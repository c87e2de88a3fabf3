"""The output contract's bookkeeping: the code and configuration hashes, the
completion marker (:func:`is_complete`) and the writer of ``report.json`` (its
reader, :func:`read_report_json`, is :class:`asset2sim.refined_asset.RefinedAsset`'s). The flow's job records and catalog rows built on them are
:mod:`asset2sim.flows.job_records`; ``docs/design/pipeline.md`` explains the skip key.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import stat
import subprocess
from pathlib import Path, PurePosixPath
from typing import Any


import asset2sim
from asset2sim import __version__, atomic, output_folder
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.report import RefineReport
from asset2sim.input_files import file_kind
from asset2sim.output_folder import MARKER_NAME, REPORT_NAME, VOLATILE, OwnedFolder, read_record
from asset2sim.output_paths import OutputError, _safe_rel
from asset2sim.refined_asset import read_report_json  # noqa: F401  the contract's reader, named here too

#: Sub-packages of ``asset2sim`` whose sources make up the code (``package-dir`` in pyproject.toml).
CODE_PACKAGES = ("asset2sim", "asset2sim.tasks", "asset2sim.schemas", "asset2sim.apps", "asset2sim.flows")
#: File suffixes of the package source that change results (modules and the data tables shipped with them).
CODE_SUFFIXES = (".py", ".yaml", ".yml", ".json", ".csv", ".txt")


def _package_dirs() -> list[Path]:
    import importlib.util

    specs = [importlib.util.find_spec(name) for name in CODE_PACKAGES]  # imports only the parent packages
    return list(dict.fromkeys(Path(loc).resolve() for s in specs if s is not None for loc in s.submodule_search_locations or []))


@functools.lru_cache(maxsize=1)
def code_hash() -> str:
    """Hash of the code that makes results (hex, 16): SHA-256 over the package version and, in sorted order,
    the relative path and bytes of every :data:`CODE_SUFFIXES` file under the folders of :data:`CODE_PACKAGES`
    (``__pycache__`` left out). Computed once per process."""
    h = hashlib.sha256(__version__.encode())
    dirs = _package_dirs()
    files: list[tuple[str, Path]] = []
    for i, d in enumerate(dirs):
        nested = [o for o in dirs if o != d and d in o.parents]  # each hashed with its own package
        files += [(f"{i}/{p.relative_to(d).as_posix()}", p) for p in d.rglob("*") if p.suffix in CODE_SUFFIXES
                  and "__pycache__" not in p.parts and p.is_file() and not any(o in p.parents for o in nested)]
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


def run_hash(config: RefineConfig, prompt: str, category: str | None) -> str:
    """Configuration hash of one refine run (hex, 16): SHA-256 of the configuration's own hash, the prompt,
    the category override and the package version."""
    return _hash16({"config": config.config_hash(), "prompt": prompt, "category": category, "version": __version__})


def flow_config_hash(refine_hash: str, *, refine_function: str, evaluate: bool, probes: bool, extras: bool,
                     reference: bool, reference_scale: float | None) -> str:
    """Configuration hash of one asset's result in the catalog (hex, 16): :func:`run_hash` plus the flow
    settings that change the result."""
    return _hash16({"refine": refine_hash, "refine_function": refine_function, "evaluate": evaluate, "probes": probes,
                    "extras": extras, "reference": reference, "reference_scale": reference_scale})


def _incomplete(out_dir: Path, why: str, where: Path | None = None) -> OutputError:
    return OutputError(f"{out_dir} is not a complete output as its completion marker records it: {why}; refine it "
                       "again (--force)", "OUTPUT_INCOMPLETE", where or out_dir)


def _regular_inside(out_dir: Path, rel: object) -> Path:
    """``out_dir/rel`` when ``rel`` is a relative path (no ``..``, not absolute) whose every folder and itself lie
    inside ``out_dir`` without a symlink on the way and it is a regular file (``lstat``: nothing opened); else
    ``OUTPUT_INCOMPLETE``."""
    safe = _safe_rel(rel)
    if safe is None or safe != rel:
        raise _incomplete(out_dir, f"the file {rel!r} is not a relative path inside the folder")
    path = out_dir / safe
    if Path(os.path.realpath(path.parent)) != Path(os.path.realpath(out_dir)) / PurePosixPath(safe).parent:
        raise _incomplete(out_dir, f"the file {safe}: a symlink on the way leads out of the folder", path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        raise _incomplete(out_dir, f"the file {safe} is missing", path) from None
    except OSError as exc:
        raise _incomplete(out_dir, f"the file {safe} cannot be inspected ({exc.strerror})", path) from None
    if not stat.S_ISREG(mode):
        raise _incomplete(out_dir, f"the file {safe} is a {file_kind(mode)}, not the regular file asset2sim wrote", path)
    return path


def verify_output(out_dir: Path | str) -> dict[str, Any]:
    """The completion marker of ``out_dir``, after checking the output against it before anything opens a file of it
    (an engine, a renderer): every entry it lists is a relative path inside the folder (no ``..``, no absolute path,
    no symlink on the way), a regular file (``lstat``; a FIFO, a device or a symlink is refused without being
    opened) holding the SHA-256 recorded; the ``unhashed`` files (wall times) present are regular files too.
    Hashing reads each file once (``O_NONBLOCK``, regular files only).

    Returns:
        The marker (``input_hash``, ``config_hash``, ``version``, ``files`` relative path -> sha256 ...).

    Raises:
        OutputError: ``OUTPUT_INCOMPLETE`` naming the file and what is wrong (no marker, not asset2sim's, an entry
            outside, missing, not a regular file, changed since).
    """
    out_dir = Path(out_dir)
    try:
        marker = read_record(out_dir / MARKER_NAME)
    except (OSError, ValueError) as exc:
        raise _incomplete(out_dir, f"no readable completion marker ({exc})") from exc
    if not isinstance(marker, dict) or not isinstance(marker.get("files"), dict) or not isinstance(marker.get("unhashed", []), list):
        raise _incomplete(out_dir, f"{MARKER_NAME} is not a completion marker asset2sim wrote", out_dir / MARKER_NAME)
    for rel, digest in marker["files"].items():
        path = _regular_inside(out_dir, rel)
        try:
            actual = atomic.sha256_file(path)
        except OSError as exc:  # replaced meanwhile
            raise _incomplete(out_dir, f"the file {rel} cannot be read ({exc.strerror or exc})", path) from None
        if actual != digest:
            raise _incomplete(out_dir, f"the file {rel} changed since the run wrote it (SHA-256 {actual[:12]}..., "
                              f"recorded {str(digest)[:12]}...)", path)
    for rel in marker.get("unhashed", []):
        if isinstance(rel, str) and _safe_rel(rel) == rel and not os.path.lexists(out_dir / rel):
            continue
        _regular_inside(out_dir, rel)
    return marker


def is_complete(out_dir: Path | str, input_hash: str, config_hash: str) -> bool:
    """True when ``out_dir`` holds a completion marker for exactly this input, configuration and version,
    and the output verifies against it (:func:`verify_output`)."""
    try:
        data = verify_output(out_dir)
    except OutputError:
        return False
    return data.get("input_hash") == input_hash and data.get("config_hash") == config_hash and data.get("version") == __version__


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
