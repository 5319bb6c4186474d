"""The phase timer and the clock of linear-solver work on any thread."""

import threading

import pytest

from ngat.timing import SOLVER_KEY, BusyClock, PhaseTimer, linear_solver


class Now:
    """A time source the test moves by hand."""

    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_overlapping_spans_count_once_and_gaps_not_at_all():
    now = Now()
    clock = BusyClock(now)
    first, second = clock(), clock()
    first.__enter__()  # busy from 0
    now.t = 1.0
    second.__enter__()
    now.t = 2.0
    first.__exit__(None, None, None)
    assert clock.seconds() == pytest.approx(2.0)  # one span still open, counted up to now
    now.t = 3.0
    second.__exit__(None, None, None)  # idle from 3
    now.t = 5.0
    with clock():
        now.t = 6.0
    assert clock.seconds() == pytest.approx(4.0)  # [0, 3] and [5, 6], not 1 + 2 + 1


def test_spans_on_two_threads_share_the_clock():
    now = Now()
    clock = BusyClock(now)
    inside, leave = threading.Event(), threading.Event()

    def worker():
        with clock():
            inside.set()
            leave.wait()

    thread = threading.Thread(target=worker)
    thread.start()
    inside.wait()
    with clock():  # the main thread's span lies within the worker's
        now.t = 2.0
    now.t = 3.0
    leave.set()
    thread.join()
    assert clock.seconds() == pytest.approx(3.0)


def test_the_solve_phase_runs_the_solver_clock_and_the_summary_reports_it():
    timer = PhaseTimer()
    with timer("estimate"):
        pass
    with timer("solve"), linear_solver():  # a PARDISO call inside the phase counts once
        busy = linear_solver.seconds()
    summary = timer.summary()
    assert summary[SOLVER_KEY] >= summary["solve"] - 1e-4
    assert summary[SOLVER_KEY] <= summary["wall"] + 1e-4
    assert busy <= linear_solver.seconds()
    assert set(summary) == {"estimate", "solve", "other", "wall", SOLVER_KEY}


def test_a_resumed_timer_counts_on_from_the_earlier_part_and_keeps_no_phase_of_it():
    earlier = {"solve": 2.0, "other": 1.0, "wall": 5.0, SOLVER_KEY: 3.0}
    summary = PhaseTimer(earlier).summary()
    assert summary[SOLVER_KEY] >= 3.0 and summary["wall"] >= 5.0
    assert set(summary) == {"solve", "other", "wall", SOLVER_KEY}
