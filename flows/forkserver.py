"""Per-worker stage servers: a child Python that imports the refine pipeline
once and forks a child per call, with :func:`asset2sim.flows.isolation.run_isolated`'s contract.

Protocol, one JSON object per line: the worker writes ``{"spec": path}``; the
server answers ``{"pid": n}`` when the child runs and ``{"rc": n, "cpu": s}``
when it ended (``rc`` < 0: killed by signal ``-rc``; ``cpu``: user + system s).
"""

from __future__ import annotations

import contextlib
import functools
import gc
import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from asset2sim import allocator
from asset2sim.engines.quiet import startup_quiet
from asset2sim.flows.isolation import IsolatedResult, _child_env, _read_result, _tail, _timed_out, _write_spec, run_child_spec
from asset2sim.flows.lifeline import set_parent_death_signal

#: Heavy third-party modules the server imports before it forks (missing ones skipped).
WARM_MODULES = (
    "numpy",
    "scipy.spatial",
    "scipy.sparse.csgraph",
    "scipy.ndimage",
    "trimesh",
    "pybullet",
    "mujoco",
    "matplotlib",
    "matplotlib.figure",
    "matplotlib.ticker",
    "PIL.Image",
    "PIL.ImageDraw",
    "sapien",
    "sapien.physx",
    "pxr.Gf",
    "pxr.Sdf",
    "pxr.Tf",
    "pxr.Usd",
    "pxr.UsdGeom",
    "pxr.UsdPhysics",
    "pxr.Vt",
    "requests",
)
#: Project modules the server imports (the stage functions come as ``preload``).
PROJECT_MODULES = (
    "asset2sim.tasks.refine",
    "asset2sim.tasks.evaluation.evaluate",
    "asset2sim.engines.pybullet_engine",
    "asset2sim.engines.physx_engine",
    "asset2sim.priors",
    "asset2sim.formats.usd.export",
)


def warm_tables() -> list[str]:
    """Call every argument-less ``lru_cache(maxsize=1)`` function of the loaded ``asset2sim.tasks`` modules and
    :mod:`asset2sim.prior_tables` (one that raises is skipped); returns the names called."""
    import inspect

    done = []
    for name, mod in sorted(sys.modules.items()):
        if not (name.startswith("asset2sim.tasks.") or name == "asset2sim.prior_tables") or mod is None:
            continue
        for attr, fn in sorted(vars(mod).items()):
            if not isinstance(fn, functools._lru_cache_wrapper) or getattr(fn, "__module__", None) != name:
                continue
            try:
                if fn.cache_parameters().get("maxsize") != 1 or inspect.signature(fn).parameters:
                    continue
                fn()
                done.append(f"{name}:{attr}")
            except Exception:  # noqa: BLE001 - a warm-up only
                continue
    return done


class StageServer:
    """One pre-imported stage server (a child process); ``preload``: further modules it imports (besides
    :data:`WARM_MODULES` and :data:`PROJECT_MODULES`; one that fails to import is skipped); ``niceness``: the ``nice``
    increment of the server, which its children inherit (0: this process's priority)."""

    def __init__(self, preload: tuple[str, ...] = (), niceness: int = 0):
        self.preload = tuple(dict.fromkeys((*PROJECT_MODULES, *preload)))
        self.niceness = int(niceness)
        self.proc: subprocess.Popen | None = None
        self.starts = 0
        self._buf = b""
        self._lock = threading.Lock()

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def start(self) -> None:
        """Start the server and wait until its imports are done; RuntimeError when it exited before."""
        self.close()
        env = _child_env()
        env.setdefault("MPLBACKEND", "Agg")
        # started by one thread living as long as this process (PR_SET_PDEATHSIG fires when the forking *thread* ends)
        with _OWNER_LOCK:
            owner = _OWNER.get(os.getpid())
            if owner is None:
                owner = _OWNER[os.getpid()] = ThreadPoolExecutor(1, thread_name_prefix="asset2sim-stage-server-owner")
        self.proc = owner.submit(
            subprocess.Popen,
            [sys.executable, "-m", "asset2sim.flows.forkserver", str(os.getpid()), *self.preload],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
            start_new_session=True,
            **({"preexec_fn": functools.partial(os.nice, self.niceness)} if self.niceness else {}),
        ).result()
        self.starts += 1
        self._buf = b""
        msg = self._read(timeout=600.0)
        if msg is None or not msg.get("ready"):
            self.close()
            raise RuntimeError("the stage server exited before it was ready")

    def start_soon(self) -> None:
        """Start the server in a background thread unless it runs (a call made meanwhile waits for it)."""
        if self.alive():
            return

        def run() -> None:
            with contextlib.suppress(RuntimeError):  # the next call starts it again and reports the failure
                self.ensure_started()

        threading.Thread(target=run, name="asset2sim-stage-server-start", daemon=True).start()

    def ensure_started(self) -> float:
        """Start the server unless it runs (or wait for :meth:`start_soon`'s start); returns the seconds waited.
        RuntimeError: it exited before it was ready."""
        t0 = time.perf_counter()
        with self._lock:
            if not self.alive():
                self.start()
        return time.perf_counter() - t0

    def close(self) -> None:
        """Stop the server (SIGKILL of its process group; children end with it)."""
        if self.proc is None:
            return
        _kill_group(self.proc.pid)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(timeout=10)
        for fh in (self.proc.stdin, self.proc.stdout):
            with contextlib.suppress(OSError, AttributeError):
                fh.close()
        self.proc = None

    def _send(self, obj: dict[str, Any]) -> bool:
        try:
            self.proc.stdin.write((json.dumps(obj) + "\n").encode())
            self.proc.stdin.flush()
            return True
        except (BrokenPipeError, OSError, ValueError):
            return False

    def _read(self, timeout: float | None) -> dict[str, Any] | None:
        """The next message, None at end of file; raises TimeoutError after ``timeout`` s."""
        fd = self.proc.stdout.fileno()
        deadline = None if timeout is None else time.monotonic() + timeout
        while b"\n" not in self._buf:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                raise TimeoutError
            chunk = os.read(fd, 65536)
            if not chunk:
                return None
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return json.loads(line)

    def _read_in_time(self, timeout: float) -> dict[str, Any] | None:
        """The next message, None at end of file or after ``timeout`` s."""
        try:
            return self._read(timeout)
        except TimeoutError:
            return None

    def call(self, target: str, kwargs: dict[str, Any], *, timeout: float, workdir: Path | str,
             memory_limit_mb: int | None = None) -> IsolatedResult:
        """:func:`asset2sim.flows.isolation.run_isolated`'s contract, in a child forked from this server (started
        when needed). Raises ValueError (``timeout`` <= 0, ``kwargs`` not JSON-able), OSError, RuntimeError (no server)."""
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {timeout}")
        t_start = time.perf_counter()
        with self._lock:
            waited = time.perf_counter() - t_start  # a start begun by start_soon()
            spec, result_path, log = _write_spec(workdir, target, kwargs, memory_limit_mb=memory_limit_mb,
                                                 log=str(Path(workdir) / "child.log"))
            started = not self.alive()
            if started:
                self.start()
            t0 = time.perf_counter()
            if not self._send({"spec": str(spec)}):
                self.start()
                started = True
                if not self._send({"spec": str(spec)}):
                    raise RuntimeError("the stage server does not take calls")
            res = self._wait(t0, timeout, result_path, log)
            if started or waited > 0.05:  # paid once per worker (and after a lost server), not by the call
                res.extra["server_start_seconds"] = t0 - t_start
            return res

    def _wait(self, t0: float, timeout: float, result_path: Path, log: Path) -> IsolatedResult:
        def lost() -> IsolatedResult:
            self.close()
            return IsolatedResult(status="crash", error="the stage server died during the call",
                                  failure_mode="crash", seconds=time.perf_counter() - t0, log_tail=_tail(log))

        msg = self._read_in_time(timeout)
        if msg is None or "pid" not in msg:
            return lost()
        pid = int(msg["pid"])
        try:
            msg = self._read(max(0.0, timeout - (time.perf_counter() - t0)))
        except TimeoutError:
            _kill_group(pid)
            rc_msg = self._read_in_time(10.0)
            if rc_msg is None:
                self.close()
            return _timed_out(timeout, None if rc_msg is None else rc_msg.get("rc"), time.perf_counter() - t0, log)
        if msg is None or "rc" not in msg:
            return lost()
        extra = {} if msg.get("cpu") is None else {"cpu_seconds": float(msg["cpu"])}
        return _read_result(result_path, int(msg["rc"]), time.perf_counter() - t0, log, extra)


def _kill_group(pid: int) -> None:
    """SIGKILL the process group ``pid`` (gone already: nothing to do)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGKILL)


#: Per process, the one-thread executor that starts its stage servers (:meth:`StageServer.start`).
_OWNER: dict[int, ThreadPoolExecutor] = {}
_OWNER_LOCK = threading.Lock()


_SERVERS: dict[int, StageServer] = {}
_SERVERS_LOCK = threading.Lock()


def worker_server(preload: tuple[str, ...] = ()) -> StageServer:
    """This process's stage server (one per process id)."""
    with _SERVERS_LOCK:
        return _SERVERS.setdefault(os.getpid(), StageServer(preload))


def _server_with(preload: tuple[str, ...]) -> StageServer:
    """This process's stage server, restarted on its next start when it lacks a module of ``preload``."""
    srv = worker_server(preload)
    for mod in preload:
        if mod not in srv.preload:
            srv.preload = (*srv.preload, mod)
            srv.close()
    return srv


def start_soon(preload: tuple[str, ...] = ()) -> None:
    """Start this process's stage server (:func:`worker_server`) in the background unless it runs."""
    _server_with(preload).start_soon()


def ready_server(preload: tuple[str, ...] = ()) -> float:
    """Start this process's stage server with ``preload`` imported and wait until it is ready; returns the seconds
    waited. RuntimeError: the server exited before it was ready."""
    return _server_with(tuple(preload)).ensure_started()


def run_forked(target: str, kwargs: dict[str, Any], *, timeout: float, workdir: Path | str,
               memory_limit_mb: int | None = None, preload: tuple[str, ...] = ()) -> IsolatedResult:
    """``target(**kwargs)`` in a child forked from this process's stage server (:meth:`StageServer.call`);
    ``preload``: modules the server should import."""
    return _server_with(preload).call(target, kwargs, timeout=timeout, workdir=workdir, memory_limit_mb=memory_limit_mb)


def _server_main(argv: list[str]) -> int:
    set_parent_death_signal(expected_parent=int(argv[0]))
    out_fd = os.dup(1)  # the protocol pipe; fd 1 goes to stderr so prints cannot break it
    os.dup2(2, 1)
    allocator.keep_freed_memory()  # the children inherit it (Dask gives its workers a 64 KiB trim threshold)
    import importlib

    with startup_quiet():  # PyBullet's build line, SAPIEN's libvulkan warning (shown with asset2sim --verbose)
        for mod in (*WARM_MODULES, *argv[1:]):
            with contextlib.suppress(Exception):  # a missing optional package: the call that needs it fails in its child
                importlib.import_module(mod)
    warm_tables()
    gc.collect()
    gc.freeze()  # what the imports made is never collected, so a child's collections do not copy its pages
    out = os.fdopen(out_fd, "w", buffering=1)

    def say(obj: dict[str, Any]) -> None:
        out.write(json.dumps(obj) + "\n")
        out.flush()

    say({"ready": True, "pid": os.getpid()})
    for line in sys.stdin:
        line = line.strip()
        if not line:
            continue
        spec = json.loads(line)["spec"]
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        # the child: its own process group, output to the log, the call; never returns into this loop
        if pid == 0:
            code = 0
            try:
                os.close(out_fd)
                os.setpgid(0, 0)
                set_parent_death_signal()
                spec = json.loads(Path(spec).read_text())
                fd = os.open(spec["log"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                os.dup2(fd, 1)
                os.dup2(fd, 2)
                os.close(fd)
                run_child_spec(spec)
                sys.stdout.flush()
                sys.stderr.flush()
            except BaseException:  # noqa: BLE001 - the child must never return into the server loop
                code = 1
            os._exit(code)
        say({"pid": pid})
        _, status, usage = os.wait4(pid, 0)
        rc = -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)
        say({"rc": rc, "cpu": round(usage.ru_utime + usage.ru_stime, 4)})  # the child's CPU time (user + system, s)
    return 0


if __name__ == "__main__":  # the stage server
    sys.exit(_server_main(sys.argv[1:]))
