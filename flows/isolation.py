"""Run one function call in a child process with a hard wall-time limit.

The refine flow runs each asset's stages through :func:`run_isolated` so that a
native crash (a segmentation fault in a simulator or mesh library) or a hang
costs only that asset: the child is killed at the time limit and the Dask
worker that waited for it carries on with the next asset.

Protocol: the parent writes ``spec.json`` (``target`` = ``module:function``,
``kwargs`` JSON, ``result`` path) into a work folder and starts
``python -m asset2sim.flows.isolation spec.json`` in a new session with the
parent's ``sys.path`` prepended to ``PYTHONPATH`` (same imports as the
parent). The child calls ``target(**kwargs)``, which must return a JSON-able
dict, and writes ``{"ok": true, "value": ...}`` or ``{"ok": false, "error":
..., "error_type": ..., "failure_mode": ..., "traceback": ...}`` atomically to
the result path. Its stdout/stderr go to ``child.log`` in the work folder.

The child ends with the process that started it, killed or not: its first
act is to ask for SIGKILL when that parent (pid ``parent`` of the spec) ends
(:func:`asset2sim.flows.lifeline.set_parent_death_signal`), so a Dask worker
that dies (with the flow's driver) leaves no stage process behind.

Nothing here imports Prefect, Dask or MLflow.
"""

from __future__ import annotations

import importlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from asset2sim import allocator, atomic
from asset2sim.flows.lifeline import set_parent_death_signal

Status = Literal["ok", "error", "timeout", "crash"]


@dataclass
class IsolatedResult:
    """Outcome of :func:`run_isolated`.

    ``status``: ``ok`` (``value`` holds the return value), ``error`` (the
    function raised: ``error``, ``error_type``, ``failure_mode`` when the
    exception had one, ``traceback``), ``timeout`` (killed at the limit) or
    ``crash`` (the child died without a result: ``returncode`` < 0 is the
    signal). ``seconds``: wall time of the child (s). ``log_tail``: the last
    lines of its output.
    """

    status: Status
    value: Any = None
    error: str = ""
    error_type: str = ""
    failure_mode: str | None = None
    traceback: str = ""
    returncode: int | None = None
    seconds: float = 0.0
    log_tail: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def import_target(target: str):
    """The callable named ``module:function``.

    Raises:
        ValueError: ``target`` is not of that form.
        ImportError / AttributeError: the module or function does not exist.
    """
    if ":" not in target:
        raise ValueError(f"target must be 'module:function', got {target!r}")
    module, name = target.split(":", 1)
    obj = importlib.import_module(module)
    for part in name.split("."):
        obj = getattr(obj, part)
    if not callable(obj):
        raise TypeError(f"{target} is not callable")
    return obj


def call_target(target: str, kwargs: dict[str, Any]) -> dict[str, Any]:
    """Call ``target(**kwargs)`` in this process, with the same result record
    as the child writes (never raises for errors of the function itself)."""
    try:
        value = import_target(target)(**kwargs)
        json.dumps(value, allow_nan=True)  # must be JSON-able
        return {"ok": True, "value": value}
    except Exception as exc:  # recorded, not raised: the caller decides
        return {
            "ok": False,
            "error": str(exc) or type(exc).__name__,
            "error_type": f"{type(exc).__module__}.{type(exc).__qualname__}",
            "failure_mode": getattr(exc, "failure_mode", None),
            "traceback": traceback.format_exc(limit=20),
        }


def _tail(path: Path, n: int = 30) -> str:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join(lines[-n:])


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    paths = [p for p in sys.path if p and os.path.isdir(p)]
    if env.get("PYTHONPATH"):
        paths.append(env["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    return env


def run_isolated(target: str, kwargs: dict[str, Any], *, timeout: float, workdir: Path | str,
                 memory_limit_mb: int | None = None) -> IsolatedResult:
    """Call ``target(**kwargs)`` in a child Python process, killing it (and its
    process group) after ``timeout`` seconds.

    Args:
        target: ``module:function`` importable by the child (the parent's
            ``sys.path`` is passed on).
        kwargs: JSON-able keyword arguments.
        timeout: wall-time limit, s (> 0).
        workdir: folder for ``spec.json``, ``result.json`` and ``child.log``
            (created; kept for inspection).
        memory_limit_mb: address-space limit of the child, MiB
            (``RLIMIT_AS``), None for none. An allocation beyond it fails in
            the child (a ``MemoryError``: status ``error``; a native
            ``std::bad_alloc``: status ``crash``) and costs only this call.

    Returns:
        :class:`IsolatedResult` (errors of the function are in it, not raised).

    Raises:
        ValueError: ``timeout`` <= 0 or ``kwargs`` not JSON-able.
        OSError: the work folder cannot be written or Python cannot start.
    """
    if not timeout > 0:
        raise ValueError(f"timeout must be > 0 s, got {timeout}")
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    result_path = workdir / "result.json"
    if result_path.exists():
        result_path.unlink()
    spec = workdir / "spec.json"
    atomic.write_json(spec, {"target": target, "kwargs": kwargs, "result": str(result_path), "parent": os.getpid(),
                             "memory_limit_mb": memory_limit_mb})
    log = workdir / "child.log"
    t0 = time.perf_counter()
    with open(log, "wb") as fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "asset2sim.flows.isolation", str(spec)],
            stdout=fh,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=_child_env(),
            start_new_session=True,
        )
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            return IsolatedResult(
                status="timeout",
                error=f"time limit of {timeout:.0f} s exceeded; child process killed",
                failure_mode="timeout",
                returncode=proc.returncode,
                seconds=time.perf_counter() - t0,
                log_tail=_tail(log),
            )
        except BaseException:
            _kill_group(proc)
            raise
    seconds = time.perf_counter() - t0
    try:
        data = json.loads(result_path.read_text())
    except (OSError, ValueError):
        sig = -rc if rc is not None and rc < 0 else None
        what = f"killed by signal {sig} ({signal.Signals(sig).name})" if sig else f"exited with code {rc}"
        return IsolatedResult(
            status="crash",
            error=f"child process {what} without a result",
            failure_mode="crash",
            returncode=rc,
            seconds=seconds,
            log_tail=_tail(log),
        )
    if data.get("ok"):
        return IsolatedResult(status="ok", value=data.get("value"), returncode=rc, seconds=seconds)
    return IsolatedResult(
        status="error",
        error=data.get("error", ""),
        error_type=data.get("error_type", ""),
        failure_mode=data.get("failure_mode"),
        traceback=data.get("traceback", ""),
        returncode=rc,
        seconds=seconds,
        log_tail=_tail(log),
    )


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        try:
            proc.kill()
        except ProcessLookupError:
            pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass


def _child_main(argv: list[str]) -> int:
    spec = json.loads(Path(argv[0]).read_text())
    if spec.get("parent") is not None:  # end with the process that waits for this one
        set_parent_death_signal(signal.SIGKILL, expected_parent=int(spec["parent"]))
    run_child_spec(spec)
    return 0


def run_child_spec(spec: dict[str, Any]) -> None:
    """The body of an isolated call in its child process (a spawned one here,
    a forked one in :mod:`asset2sim.flows.forkserver`): set the address-space
    limit ``spec["memory_limit_mb"]`` (MiB; RLIMIT_AS), run
    :func:`call_target` on ``spec["target"]`` and ``spec["kwargs"]``, write its
    record atomically as JSON to ``spec["result"]`` (a record that is not
    JSON-able is written as a ``TypeError`` failure).

    Raises:
        OSError: the result file cannot be written.
    """
    allocator.keep_freed_memory()  # a stage process lives for one call: freed arrays are reused, not faulted in again
    if spec.get("memory_limit_mb"):
        limit = int(spec["memory_limit_mb"]) * 1024 * 1024
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    record = call_target(spec["target"], spec.get("kwargs") or {})
    try:
        atomic.write_text(spec["result"], json.dumps(record, allow_nan=True))
    except (TypeError, ValueError) as exc:
        atomic.write_json(spec["result"], {"ok": False, "error": f"result not JSON-able: {exc}", "error_type": "TypeError"})


if __name__ == "__main__":  # the child process
    sys.exit(_child_main(sys.argv[1:]))
