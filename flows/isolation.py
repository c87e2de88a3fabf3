"""Run one function call in a child process with a hard wall-time limit, so that a native crash or a hang
costs only that asset: the parent writes ``spec.json`` into a work folder and starts ``python -m
asset2sim.flows.isolation spec.json`` in a new session; the child, killed when that parent ends
(:mod:`asset2sim.flows.lifeline`), writes :func:`call_target`'s record atomically to the result path.
"""

from __future__ import annotations

import contextlib
import functools
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
    """Outcome of :func:`run_isolated`: ``status`` ``ok`` (``value``), ``error``
    (the function raised), ``timeout`` or ``crash`` (no result; ``returncode``
    < 0: the signal); ``seconds``: wall time (s); ``log_tail``: its last output lines."""

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
        target: ``module:function`` importable by the child.
        kwargs: JSON-able keyword arguments.
        timeout: wall-time limit, s (> 0).
        workdir: folder for ``spec.json``, ``result.json`` and ``child.log`` (created, kept).
        memory_limit_mb: address-space limit of the child, MiB (``RLIMIT_AS``), None for none.

    Returns:
        :class:`IsolatedResult` (errors of the function are in it, not raised).

    Raises:
        ValueError: ``timeout`` <= 0 or ``kwargs`` not JSON-able.
        OSError: the work folder cannot be written or Python cannot start.
    """
    if not timeout > 0:
        raise ValueError(f"timeout must be > 0 s, got {timeout}")
    spec, result_path, log = _write_spec(workdir, target, kwargs, parent=os.getpid(), memory_limit_mb=memory_limit_mb)
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
            return _timed_out(timeout, proc.returncode, time.perf_counter() - t0, log)
        except BaseException:
            _kill_group(proc)
            raise
    return _read_result(result_path, rc, time.perf_counter() - t0, log)


def _write_spec(workdir: Path | str, target: str, kwargs: dict[str, Any], **more: Any) -> tuple[Path, Path, Path]:
    """``workdir`` made, its old result removed and ``spec.json`` written (``target``, ``kwargs``, result path,
    ``more``); returns the paths of the spec, the result and the child's log."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    result_path = workdir / "result.json"
    result_path.unlink(missing_ok=True)
    spec = workdir / "spec.json"
    atomic.write_json(spec, {"target": target, "kwargs": kwargs, "result": str(result_path), **more})
    return spec, result_path, workdir / "child.log"


def _timed_out(timeout: float, rc: int | None, seconds: float, log: Path) -> IsolatedResult:
    """The record of a child killed at its time limit of ``timeout`` s."""
    return IsolatedResult(status="timeout", error=f"time limit of {timeout:.0f} s exceeded; child process killed",
                          failure_mode="timeout", returncode=rc, seconds=seconds, log_tail=_tail(log))


def _read_result(result_path: Path, rc: int | None, seconds: float, log: Path, extra: dict[str, Any] | None = None) -> IsolatedResult:
    """The record of a child that ended with ``rc`` after ``seconds`` s, from its result file (``crash`` without one)."""
    ended = functools.partial(IsolatedResult, returncode=rc, seconds=seconds, extra={} if extra is None else extra)
    try:
        data = json.loads(result_path.read_text())
    except (OSError, ValueError):
        sig = -rc if rc is not None and rc < 0 else None
        what = f"killed by signal {sig} ({signal.Signals(sig).name})" if sig else f"exited with code {rc}"
        return ended(status="crash", error=f"child process {what} without a result", failure_mode="crash", log_tail=_tail(log))
    if data.get("ok"):
        return ended(status="ok", value=data.get("value"))
    return ended(status="error", error=data.get("error", ""), error_type=data.get("error_type", ""),
                 failure_mode=data.get("failure_mode"), traceback=data.get("traceback", ""), log_tail=_tail(log))


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        with contextlib.suppress(ProcessLookupError):
            proc.kill()
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=10)


def run_child_spec(spec: dict[str, Any]) -> None:
    """The body of an isolated call in its (spawned or forked) child: :func:`call_target` under the address-space
    limit ``spec["memory_limit_mb"]`` (MiB), its record written atomically as JSON to ``spec["result"]``.
    Raises OSError: the result file cannot be written."""
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
    _spec = json.loads(Path(sys.argv[1]).read_text())
    if _spec.get("parent") is not None:  # end with the process that waits for this one
        set_parent_death_signal(expected_parent=int(_spec["parent"]))
    run_child_spec(_spec)
