"""Alternating minimisation in (u, v) for one load step (paper, Algorithm 1).

Each iteration minimises I_j in u with v frozen, then in v with u frozen; I_j never increases
from one half-step to the next (proof of Proposition 2). The iteration stops when
‖v^n − v^{n−1}‖_∞ < ``am_tol``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ngat.parameters import SolverParameters
from ngat.state import ATState

__all__ = ["StepResult", "alternating_minimization", "ConvergenceError"]

log = logging.getLogger(__name__)

HalfStepMonitor = Callable[[str, ATState], None]


class ConvergenceError(RuntimeError):
    """The alternating minimisation produced NaN/Inf or did not converge."""


@dataclass
class StepResult:
    """Outcome of one load step's alternating minimisation.

    Attributes
    ----------
    iterations
        Number of (u, v) iterations.
    converged
        Whether ‖v^n − v^{n−1}‖_∞ fell below the tolerance.
    change
        The last ‖v^n − v^{n−1}‖_∞.
    """

    iterations: int
    converged: bool
    change: float


def alternating_minimization(
    state: ATState,
    crack: np.ndarray,
    solver: SolverParameters,
    monitor: HalfStepMonitor | None = None,
) -> StepResult:
    """Run Algorithm 1 from the current (u, v) with v = 0 on ``crack``.

    Parameters
    ----------
    state
        Fields and operators; u already carries the Dirichlet data g(t_k).
    crack
        Boolean DOF mask of CR(t_k).
    solver
        Stopping tolerance and iteration limit.
    monitor
        Called as ``monitor("u", state)`` and ``monitor("v", state)`` after each half-step.

    Returns
    -------
    StepResult
        Iterations, convergence flag and last change.

    Raises
    ------
    ConvergenceError
        If a half-step produces NaN or Inf.
    """
    v = state.v_values
    v[crack] = 0.0
    change = np.inf
    for n in range(1, solver.am_max_iter + 1):
        v_old = v.copy()
        state.solve_u()
        if monitor:
            monitor("u", state)
        state.solve_v(crack)
        if monitor:
            monitor("v", state)
        v = state.v_values
        change = float(np.max(np.abs(v - v_old)))
        if not np.isfinite(change):
            raise ConvergenceError(
                f"the alternating minimisation produced NaN/Inf at iteration {n}"
            )
        if change < solver.am_tol:
            return StepResult(n, True, change)
    log.warning(
        "alternating minimisation stopped at the iteration limit %d with ‖Δv‖∞ = %.3g",
        solver.am_max_iter,
        change,
    )
    return StepResult(solver.am_max_iter, False, change)
