"""Wall time per phase of a run (assembly, solve, estimate, refine, output), and of the solver.

The phases are timed on the main thread. The sparse factorisations also run in a worker thread
(:mod:`ngat.pardiso`), behind the estimators, the crack band and the assembly: the time during
which a linear solver runs on either thread (:data:`linear_solver`) is more than the main
thread's ``solve`` phase, and the rest of the wall is the time no linear solve is under way.
:meth:`PhaseTimer.without_solver` splits that rest by phase: the work that no solve hides.
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager, nullcontext

__all__ = ["BusyClock", "PhaseTimer", "linear_solver", "SOLVER_KEY", "WITHOUT_SOLVER_KEY"]

SOLVER_KEY = "linear_solver"
"""Key of :meth:`PhaseTimer.summary` for the wall seconds with a linear solver under way on any
thread; it overlaps the phases and is not one of them."""
WITHOUT_SOLVER_KEY = "timing_without_solver"
"""Key of a run's ``summary.json`` for :meth:`PhaseTimer.without_solver`, next to ``timing``."""


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

    @property
    def busy(self) -> bool:
        """Whether a span is under way now."""
        return self._open > 0

    def seconds(self) -> float:
        """Busy seconds so far, a span under way counted up to now."""
        with self._lock:
            return self._total + (self.now() - self._since if self._open else 0.0)


linear_solver = BusyClock()
"""The process's clock of linear-solver work: the ``solve`` phase of every :class:`PhaseTimer`
and every PARDISO phase (:class:`ngat.pardiso.Pardiso`), in whichever thread it runs."""


class PhaseTimer:
    """Accumulate wall-clock seconds per named phase, with and without a linear solver under way.

    A phase timed inside another counts for itself alone (the re-meshing's bisections are
    ``refine``, not ``remesh``), so the phases and ``other`` add up to the wall. The ``solve``
    phase also runs the solver clock (:data:`linear_solver`), whose seconds since the timer
    began :meth:`summary` reports under :data:`SOLVER_KEY`; :meth:`without_solver` reports
    each phase's seconds during which no linear solver ran on any thread.

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
    previous_without_solver
        The :meth:`without_solver` of that part.
    clock
        The solver clock, whose time source the timer uses too (:data:`linear_solver`).
    """

    def __init__(
        self,
        previous: Mapping[str, float] | None = None,
        previous_without_solver: Mapping[str, float] | None = None,
        clock: BusyClock = linear_solver,
    ) -> None:
        earlier = dict(previous or {})
        self.clock = clock
        self.offset = earlier.pop("wall", 0.0)
        self.solver_offset = earlier.pop(SOLVER_KEY, 0.0)
        earlier.pop("other", None)
        self.totals: dict[str, float] = defaultdict(float, earlier)
        alone = dict(previous_without_solver or {})
        alone.pop("other", None)
        self.alone: dict[str, float] = defaultdict(float, alone)
        self.start = clock.now()
        self.solver_start = clock.seconds()
        self._open: list[str] = []  # the phases under way, innermost last
        self._mark = (self.start, self.solver_start)  # when the innermost phase last began to count

    def _count(self) -> None:
        """Add the time since the last mark to the innermost open phase; mark now."""
        now, busy = self.clock.now(), self.clock.seconds()
        if self._open:
            phase, (then, busy_then) = self._open[-1], self._mark
            self.totals[phase] += now - then
            self.alone[phase] += (now - then) - (busy - busy_then)
        self._mark = (now, busy)

    @contextmanager
    def __call__(self, phase: str) -> Iterator[None]:
        """Time the enclosed block and add it to ``phase``, less the phases timed inside it."""
        self._count()
        self._open.append(phase)
        try:
            with self.clock() if phase == "solve" else nullcontext():
                yield
        finally:
            self._count()
            self._open.pop()

    @property
    def phase(self) -> str:
        """The innermost phase under way, ``"other"`` between phases (read from any thread)."""
        innermost = self._open[-1:]  # one slice: the list may change on the timer's thread
        return innermost[0] if innermost else "other"

    def elapsed(self) -> float:
        """Seconds since the timer was created, plus those of the earlier part."""
        return self.offset + self.clock.now() - self.start

    def solver_seconds(self) -> float:
        """Wall seconds with a linear solver under way on any thread, since the timer began."""
        return self.solver_offset + self.clock.seconds() - self.solver_start

    def summary(self) -> dict[str, float]:
        """Return the totals per phase, ``other`` (the rest), ``wall`` and :data:`SOLVER_KEY`."""
        wall = self.elapsed()
        result = {k: round(v, 4) for k, v in self.totals.items()}
        result["other"] = round(wall - sum(self.totals.values()), 4)
        result["wall"] = round(wall, 4)
        result[SOLVER_KEY] = round(self.solver_seconds(), 4)
        return result

    def without_solver(self) -> dict[str, float]:
        """Return each phase's seconds with no linear solver under way, and ``other``'s.

        They add up to the wall less :data:`SOLVER_KEY`: the time in which the run does work
        that no solve hides (the ``solve`` phase has none, its clock runs all through it).
        """
        rest = self.elapsed() - self.solver_seconds()
        phases = {k: v for k, v in self.alone.items() if k != "solve"}
        result = {k: round(v, 4) for k, v in phases.items()}
        result["other"] = round(rest - sum(phases.values()), 4)
        return result
