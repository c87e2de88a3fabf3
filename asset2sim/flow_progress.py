"""Progress events of a flow run, for whoever shows them.

The flow (:mod:`asset2sim.flows.refine_flow`) announces a run's start (with
the number of assets), each asset's catalog row as soon as it is written
(status done / skipped / failed, failure mode, seconds) and the run's end;
listeners registered in the same process receive them (``asset2sim flow``
draws a live progress bar, :mod:`asset2sim.commands._progress`). With no
listener (the nightly deployment) nothing happens. A listener that raises
is dropped from that event and never disturbs the run; nothing here prints.
"""

from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass
from typing import Callable, Iterator, Literal

EventKind = Literal["run_started", "asset_finished", "run_finished"]


@dataclass(frozen=True)
class ProgressEvent:
    """One event: ``kind``; the run (``dataset``, ``run``); ``total`` assets
    of the run (``run_started``); the asset, its row ``status``,
    ``failure_mode`` and wall time ``seconds`` (``asset_finished``)."""

    kind: EventKind
    dataset: str
    run: str
    total: int = 0
    asset_id: str | None = None
    status: str | None = None
    failure_mode: str | None = None
    seconds: float | None = None


Listener = Callable[[ProgressEvent], None]
_listeners: list[Listener] = []
_lock = threading.Lock()


def add_listener(listener: Listener) -> None:
    """Receive every later event of this process."""
    with _lock:
        _listeners.append(listener)


def remove_listener(listener: Listener) -> None:
    """Stop receiving events (no error when not registered)."""
    with _lock:
        if listener in _listeners:
            _listeners.remove(listener)


@contextlib.contextmanager
def listening(listener: Listener) -> Iterator[None]:
    """Receive events while the block runs."""
    add_listener(listener)
    try:
        yield
    finally:
        remove_listener(listener)


def emit(event: ProgressEvent) -> None:
    """Hand ``event`` to every listener; a listener's exception is swallowed
    (progress display must never fail a run)."""
    with _lock:
        targets = list(_listeners)
    for fn in targets:
        try:
            fn(event)
        except Exception:  # noqa: BLE001 - a display problem is not the run's
            pass
