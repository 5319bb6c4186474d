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

MKL PARDISO's factorisations are the exception: they gave the same bits with one thread and
with two in every comparison made (``tests/test_pardiso.py``, and the quick two-slits run's
``energies.csv``), and two threads factorise about 1.5 times faster on the example's meshes.
MKL therefore gets :func:`factorisation_threads`, the cores the process may use unless
``MKL_NUM_THREADS`` says otherwise (a Dask worker sets it to 1); :func:`oversubscription`
warns when other work keeps those cores busy.
"""

from __future__ import annotations

import os
from typing import Any

import ngsolve
import psutil
from threadpoolctl import threadpool_info, threadpool_limits

__all__ = [
    "FixedThreads",
    "NGSOLVE_THREADS",
    "BLAS_THREADS",
    "factorisation_threads",
    "oversubscription",
]

NGSOLVE_THREADS = 1
"""NGSolve's threads: with more, the sparse Cholesky factorisation sums in an order that
varies from run to run."""
BLAS_THREADS = 1
"""Threads of every BLAS and OpenMP library loaded (OpenBLAS of NGSolve, numpy and scipy) but
MKL."""


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


def oversubscription(factorisation: int, interval: float = 0.1) -> str | None:
    """Return a warning if other work keeps busy the cores the factorisation's threads need.

    The processors' use is sampled over ``interval`` seconds (psutil), before the run computes
    anything. Threads of one factorisation wait for each other at every step of it: two quick
    runs side by side with two threads each took 58 s each, against 24 s with one.

    Returns
    -------
    str or None
        The warning, naming the remedy, or ``None`` if the cores are free (or one thread).
    """
    if factorisation < 2:
        return None
    cores = sorted(os.sched_getaffinity(0))
    usage = psutil.cpu_percent(interval=interval, percpu=True)
    busy = sum(usage[core] for core in cores if core < len(usage)) / 100
    if busy <= len(cores) - factorisation + 0.5:
        return None
    return (
        f"{busy:.1f} of {len(cores)} cores are busy with other work, and the factorisation runs "
        f"on {factorisation} threads that wait for each other: runs side by side take several "
        "times longer each. Set MKL_NUM_THREADS=1 for runs side by side (ngat sweep does)."
    )


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
