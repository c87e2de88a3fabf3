"""Child-process stage runner: results, errors, hard time limit, crashes."""

from __future__ import annotations

import os
import time

import pytest

from asset2sim.flows.isolation import call_target, import_target, run_isolated

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)


class Boom(RuntimeError):
    failure_mode = "invalid_overlay"


def add(a: int, b: int) -> dict:
    return {"sum": a + b, "pid": os.getpid()}


def fail() -> dict:
    raise Boom("overlay has a negative mass on link_0")


def sleep_forever() -> dict:
    time.sleep(3600)
    return {}


def abort() -> dict:
    os.abort()


def test_ok_runs_in_another_process(tmp_path):
    res = run_isolated(f"{__name__}:add", {"a": 2, "b": 3}, timeout=60, workdir=tmp_path)
    assert res.status == "ok" and res.value["sum"] == 5
    assert res.value["pid"] != os.getpid()


def test_error_is_recorded_with_failure_mode(tmp_path):
    res = run_isolated(f"{__name__}:fail", {}, timeout=60, workdir=tmp_path)
    assert res.status == "error"
    assert res.failure_mode == "invalid_overlay"
    assert "negative mass" in res.error and res.error_type.endswith("Boom")
    assert "Traceback" in res.traceback


def test_time_limit_kills_the_child(tmp_path):
    t0 = time.perf_counter()
    res = run_isolated(f"{__name__}:sleep_forever", {}, timeout=3, workdir=tmp_path)
    assert res.status == "timeout" and res.failure_mode == "timeout"
    assert time.perf_counter() - t0 < 20
    assert res.returncode is not None and res.returncode < 0  # killed


def test_native_crash_becomes_a_crash_record(tmp_path):
    res = run_isolated(f"{__name__}:abort", {}, timeout=60, workdir=tmp_path)
    assert res.status == "crash" and res.failure_mode == "crash"
    assert "signal 6" in res.error


def test_in_process_call_and_bad_targets(tmp_path):
    assert call_target(f"{__name__}:add", {"a": 1, "b": 1})["value"]["sum"] == 2
    rec = call_target(f"{__name__}:fail", {})
    assert rec["ok"] is False and rec["failure_mode"] == "invalid_overlay"
    with pytest.raises(ValueError):
        import_target("no_colon_here")
    with pytest.raises(ValueError):
        run_isolated(f"{__name__}:add", {}, timeout=0, workdir=tmp_path)
    res = run_isolated("asset2sim.no_such_module:f", {}, timeout=60, workdir=tmp_path)
    assert res.status == "error" and "ModuleNotFoundError" in res.error_type


def allocate(mb: int) -> dict:
    import numpy as np

    block = np.ones(mb * 1024 * 1024 // 8)  # touches every page
    return {"sum": float(block.sum())}


def test_memory_limit_fails_the_child_alone(tmp_path):
    """An allocation beyond the child's address-space limit is a MemoryError
    in that child (status error), not the machine's memory; the same call
    under no limit succeeds."""
    res = run_isolated(f"{__name__}:allocate", {"mb": 2048}, timeout=120, workdir=tmp_path / "limited", memory_limit_mb=1024)
    assert res.status == "error" and res.error_type.endswith("MemoryError"), (res.status, res.error, res.log_tail)
    ok = run_isolated(f"{__name__}:allocate", {"mb": 64}, timeout=120, workdir=tmp_path / "small", memory_limit_mb=1024)
    assert ok.status == "ok" and ok.value["sum"] == 64 * 1024 * 1024 // 8
