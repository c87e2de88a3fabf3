"""The per-worker pre-imported stage server: one server for many calls, each
call isolated in its own forked child (errors, time limit, memory limit,
native crashes), and a server killed from outside replaced on the next call."""

from __future__ import annotations

import os
import signal
import time

import psutil
import pytest

from asset2sim.flows.forkserver import StageServer

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from . import test_isolation as iso  # type: ignore[no-redef]
except ImportError:
    import test_isolation as iso  # type: ignore[no-redef]

MOD = iso.__name__


def hog() -> dict:
    blocks = [bytearray(64 * 1024 * 1024) for _ in range(64)]  # 4 GiB
    return {"n": len(blocks)}


def test_one_server_many_isolated_calls(tmp_path):
    srv = StageServer(preload=(MOD,))
    try:
        a = srv.call(f"{MOD}:add", {"a": 2, "b": 3}, timeout=120, workdir=tmp_path / "a")
        assert a.status == "ok" and a.value["sum"] == 5
        assert a.extra["server_start_seconds"] > 0  # the first call started the server ...
        server_pid = srv.proc.pid
        b = srv.call(f"{MOD}:add", {"a": 1, "b": 1}, timeout=60, workdir=tmp_path / "b")
        assert b.status == "ok" and b.value["sum"] == 2
        assert "server_start_seconds" not in b.extra  # ... the next did not pay for it
        assert a.extra["cpu_seconds"] >= 0 and b.extra["cpu_seconds"] >= 0  # the child's CPU time (wait4)
        assert srv.proc.pid == server_pid  # the same server ...
        assert len({a.value["pid"], b.value["pid"], server_pid, os.getpid()}) == 4  # ... a new child per call

        err = srv.call(f"{MOD}:fail", {}, timeout=60, workdir=tmp_path / "err")
        assert err.status == "error" and err.failure_mode == "invalid_overlay" and "negative mass" in err.error

        t0 = time.perf_counter()
        slow = srv.call(f"{MOD}:sleep_forever", {}, timeout=2, workdir=tmp_path / "slow")
        assert slow.status == "timeout" and slow.failure_mode == "timeout"
        assert time.perf_counter() - t0 < 30

        crash = srv.call(f"{MOD}:abort", {}, timeout=60, workdir=tmp_path / "crash")
        assert crash.status == "crash" and crash.returncode == -signal.SIGABRT and "SIGABRT" in crash.error

        mem = srv.call(f"{__name__}:hog", {}, timeout=60, workdir=tmp_path / "mem", memory_limit_mb=1024)
        assert mem.status in ("error", "crash") and mem.status != "ok"
        assert srv.proc.pid == server_pid  # none of these took the server down
        again = srv.call(f"{MOD}:add", {"a": 4, "b": 4}, timeout=60, workdir=tmp_path / "again")
        assert again.status == "ok" and again.value["sum"] == 8
    finally:
        srv.close()


def test_a_killed_server_is_replaced_and_takes_its_children_along(tmp_path):
    srv = StageServer(preload=(MOD,))
    try:
        srv.start()
        first = srv.proc.pid
        os.kill(first, signal.SIGKILL)
        srv.proc.wait(timeout=10)
        res = srv.call(f"{MOD}:add", {"a": 1, "b": 2}, timeout=120, workdir=tmp_path / "x")
        assert res.status == "ok" and srv.proc.pid != first
        # a child forked for a call ends when its server is killed mid-call
        import threading

        out = {}
        t = threading.Thread(target=lambda: out.update(r=srv.call(f"{MOD}:sleep_forever", {}, timeout=60,
                                                                     workdir=tmp_path / "y")))
        t.start()
        deadline = time.time() + 30
        kids = []
        while time.time() < deadline and not kids:
            kids = psutil.Process(srv.proc.pid).children()
            time.sleep(0.1)
        assert kids
        os.kill(srv.proc.pid, signal.SIGKILL)
        t.join(timeout=30)
        assert out["r"].status == "crash"
        psutil.wait_procs(kids, timeout=10)
        assert not any(k.is_running() and k.status() != psutil.STATUS_ZOMBIE for k in kids)
    finally:
        srv.close()


def test_the_server_outlives_the_thread_that_started_it(tmp_path):
    """A Dask worker runs tasks on pool threads that may end; the server
    (whose parent-death signal follows the forking thread) must not end with one."""
    import threading

    srv = StageServer(preload=(MOD,))
    try:
        t = threading.Thread(target=lambda: srv.call(f"{MOD}:add", {"a": 1, "b": 1}, timeout=120, workdir=tmp_path / "t"))
        t.start()
        t.join(timeout=180)
        first = srv.proc.pid
        time.sleep(1.0)
        assert psutil.pid_exists(first) and psutil.Process(first).status() != psutil.STATUS_ZOMBIE
        res = srv.call(f"{MOD}:add", {"a": 2, "b": 2}, timeout=60, workdir=tmp_path / "m")
        assert res.status == "ok" and srv.proc.pid == first and srv.starts == 1
    finally:
        srv.close()


def test_start_soon_starts_the_server_in_the_background(tmp_path):
    srv = StageServer(preload=(MOD,))
    try:
        srv.start_soon()
        res = srv.call(f"{MOD}:add", {"a": 2, "b": 2}, timeout=120, workdir=tmp_path / "a")
        assert res.status == "ok" and res.value["sum"] == 4 and srv.starts == 1  # one server, started once
        assert res.extra["server_start_seconds"] > 0  # the call waited for that start
        srv.start_soon()  # running: nothing happens
        assert srv.call(f"{MOD}:add", {"a": 1, "b": 2}, timeout=60, workdir=tmp_path / "b").value["sum"] == 3
        assert srv.starts == 1
    finally:
        srv.close()


def test_ready_server_waits_for_a_started_server_and_keeps_it(tmp_path):
    """What the flow runs on every Dask worker before the first asset: the
    server is up when it returns, and the next call pays no start."""
    from asset2sim.flows import forkserver

    waited = forkserver.ready_server((MOD,))
    srv = forkserver.worker_server((MOD,))
    try:
        assert waited > 0 and srv.alive() and MOD in srv.preload and srv.starts == 1
        assert forkserver.ready_server((MOD,)) < waited  # running: returns at once, no second start
        res = srv.call(f"{MOD}:add", {"a": 2, "b": 5}, timeout=60, workdir=tmp_path / "a")
        assert res.status == "ok" and res.value["sum"] == 7
        assert "server_start_seconds" not in res.extra and srv.starts == 1
    finally:
        srv.close()


def niceness() -> dict:
    return {"nice": os.nice(0), "pid": os.getpid()}


def test_a_niced_server_runs_its_calls_at_its_lower_priority(tmp_path):
    """The media phase's servers (``niceness``): the server and every child it forks run that much nicer than the
    process that started them; a server without it runs at this process's priority."""
    base = os.nice(0)
    plain, niced = StageServer(preload=(__name__,)), StageServer(preload=(__name__,), niceness=7)
    try:
        a = plain.call(f"{__name__}:niceness", {}, timeout=120, workdir=tmp_path / "a")
        b = niced.call(f"{__name__}:niceness", {}, timeout=120, workdir=tmp_path / "b")
        assert a.status == "ok" and b.status == "ok", (a.error, b.error)
        assert a.value["nice"] == base and b.value["nice"] == min(19, base + 7)
        assert psutil.Process(niced.proc.pid).nice() == min(19, base + 7)
        assert b.value["pid"] != niced.proc.pid  # measured in the forked child
    finally:
        plain.close()
        niced.close()
