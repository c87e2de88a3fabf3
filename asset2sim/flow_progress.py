"""Progress events of a flow run (start, each asset's row, end) for the
listeners of this process (``asset2sim flow``'s progress bar); a listener
that raises never disturbs the run.
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
    pending: int | None = None
    """``run_started``: how many assets go to the workers (0: every one finished before; nothing starts)."""


Listener = Callable[[ProgressEvent], None]
_listeners: list[Listener] = []
_lock = threading.Lock()


@contextlib.contextmanager
def listening(listener: Listener) -> Iterator[None]:
    """Receive events while the block runs."""
    with _lock:
        _listeners.append(listener)
    try:
        yield
    finally:
        with _lock:
            _listeners.remove(listener)


def emit(event: ProgressEvent) -> None:
    """Hand ``event`` to every listener; a listener's exception is swallowed."""
    with _lock:
        targets = list(_listeners)
    for fn in targets:
        with contextlib.suppress(Exception):  # a display problem is not the run's
            fn(event)
