"""What a job reports while it runs: the progress callback's type and the clock of seconds
spent per stage. Their own module, so that the quilting loop and the passes it drives
(:mod:`quilting.core.walk_pass`, :mod:`quilting.core.transfer`) share them without importing
each other."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

Progress = Callable[[float, str], object]
"""``progress(fraction, stage)``, called between levels; raising from it stops the job."""


@dataclass
class Clock:
    """Seconds spent per stage of a job."""

    spent: dict[str, float] = field(default_factory=dict)

    def add(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        self.spent[stage] = self.spent.get(stage, 0.0) + now - since
        return now
