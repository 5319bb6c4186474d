"""Wall time per phase of a run (assembly, solve, estimate, refine, output), and of the solver.

The phases are timed on the main thread. The sparse factorisations also run in a worker thread
(:mod:`ngat.pardiso`), behind the estimators, the crack band and the assembly: the time during
which a linear solver runs on either thread (:data:`linear_solver`) is more than the main
thread's ``solve`` phase, and the rest of the wall is the time no linear solve is under way.
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager, nullcontext

__all__ = ["BusyClock", "PhaseTimer", "linear_solver", "SOLVER_KEY"]

SOLVER_KEY = "linear_solver"
"""Key of :meth:`PhaseTimer.summary` for the wall seconds with a linear solver under way on any
thread; it overlaps the phases and is not one of them."""


class BusyClock:
    """Wall-clock seconds during which at least one span runs, on any thread.

    Spans that overlap, on one thread (nested) or on several, count once: the clock runs from
    the moment the first of them begins until the last of them ends.

    Examples
    --------
    >>> clock = BusyClock()
    >>> with clock():
    ...     pass
    >>> clock.seconds() >= 0.0
    True

    Parameters
    ----------
    now
        The time source, seconds (``time.perf_counter``).
    """

    def __init__(self, now: Callable[[], float] = time.perf_counter) -> None:
        self.now = now
        self._lock = threading.Lock()
        self._open = 0
        self._since = 0.0
        self._total = 0.0

    @contextmanager
    def __call__(self) -> Iterator[None]:
        """Count the enclosed block as busy."""
        with self._lock:
            if self._open == 0:
                self._since = self.now()
            self._open += 1
        try:
            yield
        finally:
            with self._lock:
                self._open -= 1
                if self._open == 0:
                    self._total += self.now() - self._since

    def seconds(self) -> float:
        """Busy seconds so far, a span under way counted up to now."""
        with self._lock:
            return self._total + (self.now() - self._since if self._open else 0.0)


linear_solver = BusyClock()
"""The process's clock of linear-solver work: the ``solve`` phase of every :class:`PhaseTimer`
and every PARDISO phase (:class:`ngat.pardiso.Pardiso`), in whichever thread it runs."""


class PhaseTimer:
    """Accumulate wall-clock seconds per named phase.

    The ``solve`` phase also runs :data:`linear_solver`, whose seconds since the timer began
    :meth:`summary` reports under :data:`SOLVER_KEY`.

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
        self.solver_offset = earlier.pop(SOLVER_KEY, 0.0)
        earlier.pop("other", None)
        self.totals: dict[str, float] = defaultdict(float, earlier)
        self.start = time.perf_counter()
        self.solver_start = linear_solver.seconds()

    @contextmanager
    def __call__(self, phase: str) -> Iterator[None]:
        """Time the enclosed block and add it to ``phase``."""
        begin = time.perf_counter()
        try:
            with linear_solver() if phase == "solve" else nullcontext():
                yield
        finally:
            self.totals[phase] += time.perf_counter() - begin

    def elapsed(self) -> float:
        """Seconds since the timer was created, plus those of the earlier part."""
        return self.offset + time.perf_counter() - self.start

    def solver_seconds(self) -> float:
        """Wall seconds with a linear solver under way on any thread, since the timer began."""
        return self.solver_offset + linear_solver.seconds() - self.solver_start

    def summary(self) -> dict[str, float]:
        """Return the totals per phase, ``other`` (the rest), ``wall`` and :data:`SOLVER_KEY`."""
        wall = self.elapsed()
        result = {k: round(v, 4) for k, v in self.totals.items()}
        result["other"] = round(wall - sum(self.totals.values()), 4)
        result["wall"] = round(wall, 4)
        result[SOLVER_KEY] = round(self.solver_seconds(), 4)
        return result
