"""The live progress of ``asset2sim flow``: a rich progress bar (counts,
elapsed time, ETA), or one line per asset when the output is not a terminal.
While the bar is drawn, console log handlers show warnings and errors only
(their INFO lines would be written across the bar)."""

from __future__ import annotations

import logging
import sys
import time
from typing import Any

from asset2sim.commands._output import raw
from asset2sim.flow_progress import ProgressEvent
from asset2sim.inert import markup


def eta_seconds(elapsed: float, finished: int, total: int, worked: int | None = None) -> float | None:
    """Seconds left at the average rate so far; None before the first asset.
    With ``worked`` (assets done or failed) the rate is over those (skipped
    assets take moments)."""
    if finished <= 0 or finished >= total:
        return 0.0 if finished >= total else None
    return elapsed / (worked or finished) * (total - finished)


#: Shown until the first asset finishes (a temporary Prefect server, a Dask cluster and the stage servers start first).
STARTING = "starting Prefect, Dask and the workers (up to a minute) ..."
#: Shown instead when every asset finished before: nothing is started, each finished result is reused.
NOTHING_TO_START = "every one finished before: reused, nothing to start"


def starting(ev: ProgressEvent) -> str:
    """What a run is doing before its first asset finishes: :data:`STARTING`, or :data:`NOTHING_TO_START` when no asset
    goes to the workers (``ev.pending`` 0)."""
    return NOTHING_TO_START if ev.pending == 0 else STARTING


class FlowProgress:
    """A listener of :mod:`asset2sim.flow_progress`: a bar when ``live``
    (default: stdout is a terminal), else one line per asset."""

    def __init__(self, live: bool | None = None, stream: Any = None):
        self.stream = stream or sys.stdout
        self.live = raw(self.stream).isatty() if live is None else live  # the terminal beneath the commands' inert stream
        self.counts = {"done": 0, "skipped": 0, "failed": 0}
        self.total = 0
        self.started = time.perf_counter()
        self._progress = None
        self._task = None
        self._quieted: list[tuple[logging.Handler, int]] = []

    def __call__(self, ev: ProgressEvent) -> None:
        if ev.kind == "run_started":
            self.total, self.started = ev.total, time.perf_counter()
            self.counts = {"done": 0, "skipped": 0, "failed": 0}
            if self.live:
                self._start_bar(ev)
            else:
                print(f"run {ev.run} of dataset {ev.dataset}: {ev.total} assets; {starting(ev)}", file=self.stream, flush=True)
        elif ev.kind == "asset_finished":
            self.counts[ev.status if ev.status in self.counts else "failed"] += 1
            if self._progress is not None:
                self._progress.update(self._task, advance=1, description=markup(ev.dataset), **self.counts)
            elif not self.live:
                print(self._line(ev), file=self.stream, flush=True)
        elif ev.kind == "run_finished":
            self.close()

    def _line(self, ev: ProgressEvent) -> str:
        c = self.counts
        n = sum(c.values())
        elapsed = time.perf_counter() - self.started
        eta = eta_seconds(elapsed, n, self.total, c["done"] + c["failed"])
        mode = f" ({ev.failure_mode})" if ev.failure_mode and ev.failure_mode != "none" else ""
        secs = f" {ev.seconds:.1f} s" if ev.seconds is not None else ""
        return (f"[{n}/{self.total}] {ev.asset_id}: {ev.status}{mode}{secs} | done {c['done']}, skipped {c['skipped']}, "
                f"failed {c['failed']} | elapsed {elapsed:.0f} s" + ("" if eta is None else f", ETA {eta:.0f} s"))

    def _start_bar(self, ev: ProgressEvent) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        self.close()
        counts = TextColumn("[green]done {task.fields[done]}[/] [cyan]skipped {task.fields[skipped]}[/] "
                            "[red]failed {task.fields[failed]}[/]")
        self._progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), counts, TimeElapsedColumn(),
                                  TextColumn("ETA"), TimeRemainingColumn(), console=Console(file=raw(self.stream)))
        # every terminal log handler raised to WARNING (its level remembered)
        loggers = [logging.getLogger()] + [lg for lg in logging.root.manager.loggerDict.values() if isinstance(lg, logging.Logger)]
        for lg in loggers:
            for h in lg.handlers:
                stream = getattr(h, "stream", None) or getattr(getattr(h, "console", None), "file", None)
                if stream in (sys.stderr, sys.stdout, sys.__stderr__, sys.__stdout__) or type(h).__name__ == "PrefectConsoleHandler":
                    if h.level < logging.WARNING and all(h is not q for q, _ in self._quieted):
                        self._quieted.append((h, h.level))
                        h.setLevel(logging.WARNING)
        self._progress.start()
        self._task = self._progress.add_task(f"{markup(ev.dataset)}: {starting(ev)}", total=max(1, ev.total), **self.counts)

    def close(self) -> None:
        """Stop drawing the bar and restore the log handlers (idempotent)."""
        if self._progress is not None:
            self._progress.stop()
            self._progress = None
        for h, level in self._quieted:
            h.setLevel(level)
        self._quieted = []
