"""Wall time per phase of a run (assembly, solve, estimate, refine, output)."""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

__all__ = ["PhaseTimer"]


class PhaseTimer:
    """Accumulate wall-clock seconds per named phase.

    Examples
    --------
    >>> timer = PhaseTimer()
    >>> with timer("solve"):
    ...     pass
    >>> sorted(timer.totals)
    ['solve']

    Parameters
    ----------
    previous
        The :meth:`summary` of an earlier part of the same run (a resumed run counts on from it).
    """

    def __init__(self, previous: Mapping[str, float] | None = None) -> None:
        earlier = dict(previous or {})
        self.offset = earlier.pop("wall", 0.0)
        earlier.pop("other", None)
        self.totals: dict[str, float] = defaultdict(float, earlier)
        self.start = time.perf_counter()

    @contextmanager
    def __call__(self, phase: str) -> Iterator[None]:
        """Time the enclosed block and add it to ``phase``."""
        begin = time.perf_counter()
        try:
            yield
        finally:
            self.totals[phase] += time.perf_counter() - begin

    def elapsed(self) -> float:
        """Seconds since the timer was created, plus those of the earlier part."""
        return self.offset + time.perf_counter() - self.start

    def summary(self) -> dict[str, float]:
        """Return the totals per phase, ``other`` (the rest) and ``wall``."""
        wall = self.elapsed()
        result = {k: round(v, 4) for k, v in self.totals.items()}
        result["other"] = round(wall - sum(self.totals.values()), 4)
        result["wall"] = round(wall, 4)
        return result
