"""When the refine flow's subflow records an asset's row (asset2sim.flows.subflow._run_assets): as soon as its
chain (or, for an asset its input stage ends, its prepare batch) ends, whatever the other assets' prepares are
doing. The futures are Prefect's interface (``add_done_callback``, ``result``) driven by the test, so the order
of completions is the test's."""

from __future__ import annotations

import threading
from types import SimpleNamespace

from asset2sim.flows import subflow
from asset2sim.flows.job_records import Prepared
from asset2sim.flows.stages import AssetJob

WAIT_S = 10.0


class _Future:
    """A future the test ends: ``add_done_callback`` and ``result`` as Prefect's futures have them."""

    def __init__(self, label: str):
        self.label, self._value, self._done, self._callbacks = label, None, False, []
        self._lock = threading.Lock()

    def add_done_callback(self, fn) -> None:
        with self._lock:
            if not self._done:
                self._callbacks.append(fn)
                return
        fn(self)

    def end(self, value) -> None:
        with self._lock:
            self._value, self._done, callbacks = value, True, list(self._callbacks)
        for fn in callbacks:
            fn(self)

    def result(self, raise_on_failure: bool = True):
        if isinstance(self._value, BaseException):
            raise self._value
        return self._value


class _ChainTask:
    """``chain_task.with_options(...).submit(job, prepared)``: a new future per asset, kept by asset id, with an event
    per asset of ``ids`` set when its chain is submitted."""

    def __init__(self, ids: list[str]):
        self.submitted: dict[str, _Future] = {}
        self.was_submitted = {a: threading.Event() for a in ids}

    def with_options(self, **_options) -> "_ChainTask":
        return self

    def submit(self, job, prepared) -> _Future:
        fut = _Future(job.value.asset_id)
        self.submitted[job.value.asset_id] = fut
        self.was_submitted[job.value.asset_id].set()
        return fut


class _Recorder:
    """What :class:`asset2sim.flows.subflow._AssetRecorder` is asked: each row, in order, with an event per asset."""

    def __init__(self, ids: list[str]):
        self.inputs: dict = {}
        self.order: list[tuple[str, str | None]] = []
        self.recorded = {a: threading.Event() for a in ids}

    def record(self, job, prepared, refined, measured, exc, published=None) -> None:
        self.order.append((job.asset_id, None if exc is None else type(exc).__name__))
        self.recorded[job.asset_id].set()


def _job(asset_id: str) -> AssetJob:
    return AssetJob(dataset="dev", run_id="r", asset_id=asset_id, prompt="A box.", asset_dir="/nonexistent",
                    out_dir="/nonexistent/out", work_dir="/nonexistent/work", metrics_dir="/nonexistent/metrics")


def _run(prep: dict, chains: _ChainTask, rec: _Recorder) -> threading.Thread:
    t = threading.Thread(target=subflow._run_assets, args=(prep, chains, rec, {}), daemon=True)
    t.start()
    return t


def _chain_result() -> SimpleNamespace:
    return SimpleNamespace(refined=None, measured=None, error=None, published=None)


def test_an_assets_row_is_recorded_when_its_chain_ends_while_another_prepare_still_runs():
    a, b = _job("a"), _job("b")
    prep_a, prep_b = _Future("prepare a"), _Future("prepare b")
    chains, rec = _ChainTask(["a", "b"]), _Recorder(["a", "b"])
    worker = _run({prep_a: [a], prep_b: [b]}, chains, rec)
    prep_a.end([Prepared(ok=True)])
    assert chains.was_submitted["a"].wait(WAIT_S), "a's chain was not submitted when its prepare ended"
    chains.submitted["a"].end(_chain_result())
    assert rec.recorded["a"].wait(WAIT_S), "a's row waited for b's prepare"
    assert not rec.recorded["b"].is_set()
    prep_b.end([Prepared(ok=True)])
    assert chains.was_submitted["b"].wait(WAIT_S)
    chains.submitted["b"].end(_chain_result())
    worker.join(WAIT_S)
    assert not worker.is_alive()
    assert rec.order == [("a", None), ("b", None)]


def test_a_failed_prepare_and_a_failed_chain_are_recorded_with_their_errors_in_the_order_they_end():
    a, b, c = _job("a"), _job("b"), _job("c")
    prep_ab, prep_c = _Future("prepare a, b"), _Future("prepare c")
    chains, rec = _ChainTask(["a", "b", "c"]), _Recorder(["a", "b", "c"])
    worker = _run({prep_ab: [a, b], prep_c: [c]}, chains, rec)
    prep_ab.end([Prepared(ok=True), Prepared(ok=False, failure_mode="invalid_input", error="unreadable")])
    assert rec.recorded["b"].wait(WAIT_S), "b's row (its input stage ended it) waited"
    assert chains.was_submitted["a"].wait(WAIT_S)
    prep_c.end(OSError("worker lost"))
    assert rec.recorded["c"].wait(WAIT_S)
    chains.submitted["a"].end(RuntimeError("refine crashed"))
    worker.join(WAIT_S)
    assert not worker.is_alive()
    assert rec.order == [("b", None), ("c", "OSError"), ("a", "RuntimeError")]
    assert set(chains.submitted) == {"a"}
