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


def test_the_clock_says_whether_a_span_is_under_way():
    clock = BusyClock(Now())
    assert not clock.busy
    with clock():
        with clock():
            assert clock.busy
        assert clock.busy  # the outer span is still open
    assert not clock.busy


def test_the_timer_names_the_innermost_phase_under_way():
    timer = PhaseTimer(clock=BusyClock(Now()))
    seen = [timer.phase]
    with timer("remesh"):
        seen.append(timer.phase)
        with timer("refine"):
            seen.append(timer.phase)
        seen.append(timer.phase)
    seen.append(timer.phase)
    assert seen == ["other", "remesh", "refine", "remesh", "other"]


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


def test_a_phase_inside_another_counts_for_itself_and_the_phases_add_up_to_the_wall():
    now = Now()
    timer = PhaseTimer(clock=BusyClock(now))
    with timer("remesh"):
        now.t = 1.0
        with timer("refine"):
            now.t = 3.0
        now.t = 4.0
    now.t = 6.0
    summary = timer.summary()
    assert summary["remesh"] == pytest.approx(2.0)  # [0, 1] and [3, 4], not the bisection's 2 s
    assert summary["refine"] == pytest.approx(2.0)
    assert summary["other"] == pytest.approx(2.0) and summary["wall"] == pytest.approx(6.0)


def test_without_solver_leaves_out_every_second_a_solve_runs_on_either_thread():
    now = Now()
    clock = BusyClock(now)
    timer = PhaseTimer(clock=clock)
    with timer("assembly"):
        now.t = 1.0
    with timer("estimate"):
        factorisation = clock()  # on the worker from 1 to 3, behind the estimator
        factorisation.__enter__()
        now.t = 3.0
        factorisation.__exit__(None, None, None)
        now.t = 4.0
    with timer("solve"):
        now.t = 5.0
    now.t = 7.0  # outside every phase
    summary, alone = timer.summary(), timer.without_solver()
    assert summary[SOLVER_KEY] == pytest.approx(3.0)  # [1, 3] and [4, 5]
    assert alone == pytest.approx({"assembly": 1.0, "estimate": 1.0, "other": 2.0})
    assert sum(alone.values()) == pytest.approx(summary["wall"] - summary[SOLVER_KEY])


def test_a_resumed_timer_counts_on_the_earlier_part_without_a_solver():
    earlier = {"assembly": 2.0, "solve": 3.0, "other": 1.0, "wall": 6.0, SOLVER_KEY: 3.0}
    timer = PhaseTimer(earlier, {"assembly": 2.0, "other": 1.0}, clock=BusyClock(Now()))
    assert timer.without_solver() == pytest.approx({"assembly": 2.0, "other": 1.0})
