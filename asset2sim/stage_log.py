"""Progress messages and wall time per stage of one refine: what the stages say (``progress(stage,
message)``, the library never prints) and how long each took (s, summed over repeats)."""

from __future__ import annotations

import time
from typing import Callable

Progress = Callable[[str, str], None]
"""progress(stage, message)"""


class StageLog:
    """Progress messages (``say(stage, message)``) and wall time per stage (``times``: stage -> s, summed
    over repeats; :meth:`lap` charges the time since the previous lap), and this process's CPU time likewise
    (``cpu``: stage -> s, every thread's: what a stage costs on a machine other work shares)."""

    def __init__(self, progress: Progress | None):
        self.say: Progress = progress or (lambda stage, msg: None)
        self.times: dict[str, float] = {}
        self.cpu: dict[str, float] = {}
        self._t, self._c = time.perf_counter(), time.process_time()

    def lap(self, stage: str) -> None:
        """Charge the time since the previous lap to ``stage``."""
        now, cpu = time.perf_counter(), time.process_time()
        self.times[stage] = self.times.get(stage, 0.0) + (now - self._t)
        self.cpu[stage] = self.cpu.get(stage, 0.0) + (cpu - self._c)
        self._t, self._c = now, cpu
