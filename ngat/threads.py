"""Thread pools fixed by ngat, so that a run's results do not depend on its environment.

Floating-point addition is not associative, so a computation split over threads sums in an order
that depends on the thread count — and, for NGSolve's TaskManager, on the scheduling. Two pools
take part in a run: NGSolve's own threads (the sparse Cholesky factorisation) and OpenBLAS, which
NGSolve, numpy and scipy each load. OpenBLAS starts with one thread per core unless
``OPENBLAS_NUM_THREADS`` or ``OMP_NUM_THREADS`` say otherwise, and a Dask worker sets them to 1,
so the same run gave different element counts from load step 25 on under ``ngat run`` and
``ngat sweep``. :class:`FixedThreads` therefore sets both pools to counts ngat chooses, for the
duration of a run (threadpoolctl for the BLAS and OpenMP libraries loaded in the process), and
reports them for ``summary.json``. One thread each is also the fastest on two cores
(``README.md``).

MKL PARDISO's factorisations of indefinite matrices (Newton's Hessian) are the exception:
with MKL's conditional numerical reproducibility on (:data:`ngat.pardiso.MKL_CBWR_AUTO`) they
gave the same bits with one thread and with two in every comparison made
(``tests/test_pardiso.py``, and the quick two-slits run's ``energies.csv``), and two threads
are faster on the example's meshes (the half-steps' definite matrices and METIS's orderings
run on one thread whatever the count: :data:`ngat.pardiso.TWO_LEVEL`).
MKL therefore gets :func:`factorisation_threads`, the cores the process may use unless
``MKL_NUM_THREADS`` says otherwise (a Dask worker sets it to 1); :class:`CoreUse`
warns when other work keeps those cores busy. Between factorisations their OpenMP threads
sleep after 5 ms instead of spinning for Intel's default 200 ms (:data:`SPIN_MS`; in the teams of
the main thread and of the background worker, :func:`ngat.pardiso.in_background`), so that the
cores are free for the rest of the run, and Netgen's bisection (``mesh.Refine()``) runs on
NGSolve's TaskManager with as many threads (:func:`refinement_threads`): it gave the same
meshes, vertex numbers and prolongated fields with one thread and with two (the paper's break
step: 1.6 against 2.9 s of refinement, the same 189 iterations to the last bit).
"""

from __future__ import annotations

import ctypes
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import ngsolve
import psutil
from threadpoolctl import threadpool_info, threadpool_limits

from ngat.pardiso import in_background

__all__ = [
    "FixedThreads",
    "NGSOLVE_THREADS",
    "BLAS_THREADS",
    "factorisation_threads",
    "CoreUse",
    "refinement_threads",
    "SPIN_MS",
]

NGSOLVE_THREADS = 1
"""NGSolve's threads: with more, the sparse Cholesky factorisation sums in an order that
varies from run to run."""
BLAS_THREADS = 1
"""Threads of every BLAS and OpenMP library loaded (OpenBLAS of NGSolve, numpy and scipy) but
MKL."""


SPIN_MS = 5
"""Milliseconds the OpenMP threads of MKL wait, spinning, for the next parallel region before
they sleep (``KMP_BLOCKTIME``; Intel's default is 200) while a run has several factorisation
threads, unless ``KMP_BLOCKTIME`` is set. A thread spinning for 200 ms after each solve holds
the core that the refinement's threads (:func:`refinement_threads`) and the rest of the
iteration could use: the paper's break step spent 4.0 s in ``mesh.Refine()`` on two threads
beside it, against 2.9 s on one thread and 1.6 s on two with threads that sleep at once.
Sleeping at once costs a wake-up of about 0.4 ms per back-substitution (4.7 against 4.3 ms at
73k DOFs); after 5 ms they do not (4.2 ms), and factorisations take the same time. The
setting belongs to the thread that sets it and the teams it starts: the background worker,
whose METIS orderings run on MKL's threads, gets it too (:meth:`FixedThreads.spin`). With
Intel's 200 ms there, the paper's example spent 7 s of kernel time in the spinning thread's
yields and 300–500 thousand involuntary context switches."""


def factorisation_threads() -> int:
    """Return the threads of MKL PARDISO: ``MKL_NUM_THREADS``, or the cores this process may use.

    Raises
    ------
    ValueError
        If ``MKL_NUM_THREADS`` is set to something other than a positive integer.
    """
    setting = os.environ.get("MKL_NUM_THREADS")
    if setting is None:
        return len(os.sched_getaffinity(0))
    if not setting.strip().isdigit() or int(setting) < 1:
        raise ValueError(f"MKL_NUM_THREADS={setting!r}: expected a positive integer")
    return int(setting)


MIN_INTERVAL = 0.1
"""Seconds :class:`CoreUse` samples at least (the kernel counts processor time in 10 ms ticks)."""


def _busy(times: Any) -> float:
    """Return a core's busy seconds from its ``psutil.cpu_times`` (not idle, stolen included).

    Guest time is already counted in user time, as psutil's ``cpu_percent`` counts it.
    """
    guest = getattr(times, "guest", 0.0) + getattr(times, "guest_nice", 0.0)
    return sum(times) - guest - times.idle - getattr(times, "iowait", 0.0)


class CoreUse:
    """How busy other work keeps the cores of this process, from now until :meth:`warning`.

    Threads of one factorisation wait for each other at every step of it: two quick runs side
    by side with two threads each took 58 s each, against 24 s with one. The sample runs
    while the run sets up (its mesh and operators) instead of pausing it: the cores' busy time
    (psutil) less this process's own processor time, over the wall time between.

    Parameters
    ----------
    min_interval
        Shortest sample [s]: :meth:`other_work` waits for the rest if asked sooner.
    """

    def __init__(self, min_interval: float = MIN_INTERVAL):
        self.cores = sorted(os.sched_getaffinity(0))
        self.min_interval = min_interval
        self._start = self._sample()

    def _sample(self) -> tuple[float, float, float]:
        """Return the wall clock, the cores' busy seconds and this process's processor seconds."""
        per_core = psutil.cpu_times(percpu=True)
        busy = sum(_busy(per_core[core]) for core in self.cores if core < len(per_core))
        own = psutil.Process().cpu_times()
        return time.perf_counter(), busy, own.user + own.system

    def other_work(self) -> float:
        """Return the cores other work kept busy on average since the sample began."""
        if (rest := self.min_interval - (time.perf_counter() - self._start[0])) > 0:
            time.sleep(rest)
        (begin, busy_before, own_before), (end, busy, own) = self._start, self._sample()
        return max(0.0, (busy - busy_before) - (own - own_before)) / (end - begin)

    def warning(self, factorisation: int) -> str | None:
        """Return a warning if other work keeps busy the cores the factorisation's threads need.

        Returns
        -------
        str or None
            The warning, naming the remedy, or ``None`` if the cores are free (or one thread).
        """
        if factorisation < 2:
            return None
        busy = self.other_work()
        if busy <= len(self.cores) - factorisation + 0.5:
            return None
        return (
            f"{busy:.1f} of {len(self.cores)} cores are busy with other work, and the "
            f"factorisation runs on {factorisation} threads that wait for each other: runs side "
            "by side take several times longer each. Set MKL_NUM_THREADS=1 for runs side by "
            "side (ngat sweep does)."
        )


@contextmanager
def refinement_threads(count: int) -> Iterator[None]:
    """Run the block in NGSolve's TaskManager with ``count`` threads (none if ``count`` < 2).

    For ``mesh.Refine()``: Netgen's bisection and topology update run in parallel there, 1.6
    times faster on two threads, with the same mesh and numbering as on one (see the module's
    docstring); NGSolve's thread count is set back afterwards.
    """
    if count < 2:
        yield
        return
    previous = ngsolve.GetNumThreads()
    ngsolve.SetNumThreads(count)
    try:
        with ngsolve.TaskManager():
            yield
    finally:
        ngsolve.SetNumThreads(previous)


def _intel_openmp() -> ctypes.CDLL | None:
    """Return Intel's OpenMP library as loaded for MKL, or ``None`` if it is not loaded."""
    for pool in threadpool_info():
        if pool["internal_api"] == "openmp" and pool["prefix"] == "libiomp":
            return ctypes.CDLL(pool["filepath"])
    return None


class FixedThreads:
    """Set NGSolve's and the BLAS libraries' thread counts until :meth:`restore`.

    Examples
    --------
    >>> threads = FixedThreads()
    >>> threads.summary()["blas"]
    1
    >>> threads.restore()
    """

    def __init__(self) -> None:
        self.factorisation = factorisation_threads()
        self._ngsolve = ngsolve.GetNumThreads()
        ngsolve.SetNumThreads(NGSOLVE_THREADS)
        limits = {
            pool["prefix"]: self.factorisation if pool["internal_api"] == "mkl" else BLAS_THREADS
            for pool in threadpool_info()
        }
        self._limits = threadpool_limits(limits=limits)
        self._openmp = None
        if self.factorisation > 1 and "KMP_BLOCKTIME" not in os.environ:
            self._openmp = _intel_openmp()
        if self._openmp is not None:
            self._spin = self._openmp.kmp_get_blocktime()
            self.spin(SPIN_MS)

    def spin(self, milliseconds: int) -> None:
        """Set the OpenMP spin (:data:`SPIN_MS`) of the main thread's and the worker's teams."""
        self._openmp.kmp_set_blocktime(milliseconds)
        in_background(self._openmp.kmp_set_blocktime, milliseconds).result()

    def summary(self) -> dict[str, Any]:
        """Return the thread counts in force, per pool and per library loaded."""
        return {
            "ngsolve": ngsolve.GetNumThreads(),
            "blas": BLAS_THREADS,
            "factorisation": self.factorisation,
            "libraries": [
                {
                    "library": pool["prefix"],
                    "api": pool["internal_api"],
                    "version": pool["version"],
                    "threads": pool["num_threads"],
                }
                for pool in threadpool_info()
            ],
        }

    def restore(self) -> None:
        """Give every pool back the thread count it had before."""
        self._limits.restore_original_limits()
        ngsolve.SetNumThreads(self._ngsolve)
        if self._openmp is not None:
            self.spin(self._spin)
