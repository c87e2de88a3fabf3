"""Progress messages and wall time per stage of one refine: what the stages say (``progress(stage,
message)``, the library never prints) and how long each took (s, summed over repeats)."""

from __future__ import annotations

import time
from typing import Callable

Progress = Callable[[str, str], None]
"""progress(stage, message)"""


class StageLog:
    """Progress messages (``say(stage, message)``) and wall time per stage (``times``: stage -> s, summed
    over repeats; :meth:`lap` charges the time since the previous lap)."""

    def __init__(self, progress: Progress | None):
        self.say: Progress = progress or (lambda stage, msg: None)
        self.times: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Charge the time since the previous lap to ``stage``."""
        now = time.perf_counter()
        self.times[stage] = self.times.get(stage, 0.0) + (now - self._t)
        self._t = now
