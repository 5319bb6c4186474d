"""Alternating minimisation in (u, v) for one load step, on a fixed or adaptive mesh.

Algorithm 1 of the paper minimises I_j in u with v frozen, then in v with u frozen, until
‖v^n − v^{n−1}‖_∞ < ``am_tol``; I_j never increases from one half-step to the next (proof of
Proposition 2). Algorithm 2 refines inside each half-step: solve, estimate (μ for the u-step,
ν for the v-step, Proposition 4), mark, refine, until the estimator is ≤ TOL. The variant
``"after"`` runs Algorithm 1 to convergence first and refines only then.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ngat.estimators import mu_estimator, nu_estimator
from ngat.parameters import AdaptivityParameters, SolverParameters
from ngat.refinement import mark, refinable, refine
from ngat.state import ATState

__all__ = ["StepResult", "alternating_minimization", "estimate", "ConvergenceError"]

log = logging.getLogger(__name__)

HalfStepMonitor = Callable[[str, ATState], None]


class ConvergenceError(RuntimeError):
    """The alternating minimisation produced NaN/Inf."""


@dataclass
class StepResult:
    """Outcome of one load step.

    Attributes
    ----------
    iterations
        Number of (u, v) iterations.
    converged
        Whether ‖v^n − v^{n−1}‖_∞ fell below the tolerance.
    change
        The last ‖v^n − v^{n−1}‖_∞.
    refinements
        Number of mesh refinements during the step.
    history
        One entry per refinement: iteration, half-step, elements, estimator before refining.
    """

    iterations: int = 0
    converged: bool = False
    change: float = np.inf
    refinements: int = 0
    history: list[dict] = field(default_factory=list)


def estimate(state: ATState, stage: str, crack: np.ndarray) -> np.ndarray:
    """Return the squared element indicators of μ (``stage="u"``) or ν (``stage="v"``)."""
    with state.timer("estimate"):
        model = state.model
        if stage == "u":
            return mu_estimator(
                state.arrays, state.edges, state.u_values, state.v_values, model.eta,
                state.dirichlet,
            )  # fmt: skip
        return nu_estimator(
            state.arrays, state.edges, state.u_values, state.v_values, model.eps, crack
        )


def _refine_by(
    state: ATState,
    indicators: list[np.ndarray],
    adaptivity: AdaptivityParameters,
    result: StepResult,
    stage: str,
) -> bool:
    """Mark and refine where an estimator exceeds TOL; return whether the mesh changed.

    Marking sees only the elements above the size floor (:func:`ngat.refinement.refinable`),
    and refining stops once the estimator restricted to them is ≤ TOL: the rest of the
    estimate sits at the floor, where refinement cannot reduce it.
    """
    allowed = refinable(state, adaptivity.h_floor)
    marked = np.zeros(state.arrays.ne, dtype=bool)
    values = []
    for eta_sq in indicators:
        values.append(float(np.sqrt(eta_sq.sum())))
        if values[-1] > adaptivity.tol and np.sqrt(eta_sq[allowed].sum()) > adaptivity.tol:
            marked |= mark(np.where(allowed, eta_sq, 0.0), adaptivity.marking, adaptivity.theta)
    elements = state.arrays.ne
    if result.refinements >= adaptivity.max_refinements or not refine(state, marked):
        return False
    result.refinements += 1
    result.history.append(
        {"iteration": result.iterations, "stage": stage, "elements": elements,
         "estimate": max(values), "new_elements": state.arrays.ne}
    )  # fmt: skip
    return True


def _half_step(
    state: ATState, stage: str, adaptivity: AdaptivityParameters, result: StepResult
) -> None:
    """Solve one half-step; with Algorithm 2, refine and re-solve until the estimator ≤ TOL."""
    while True:
        crack = state.crack_set()
        if stage == "u":
            state.solve_u()
        else:
            state.solve_v(crack)
        if adaptivity.adapt != "paper":
            return
        if not _refine_by(state, [estimate(state, stage, crack)], adaptivity, result, stage):
            return


def _refine_after(state: ATState, adaptivity: AdaptivityParameters, result: StepResult) -> bool:
    """Refine by μ and ν of the converged pair; return whether the mesh changed."""
    crack = state.crack_set()
    indicators = [estimate(state, "u", crack), estimate(state, "v", crack)]
    return _refine_by(state, indicators, adaptivity, result, "after")


def alternating_minimization(
    state: ATState,
    solver: SolverParameters,
    adaptivity: AdaptivityParameters,
    monitor: HalfStepMonitor | None = None,
) -> StepResult:
    """Run Algorithm 1 or 2 from the current (u, v), with v = 0 on CR(t_k).

    Parameters
    ----------
    state
        Fields and operators; u already carries the Dirichlet data g(t_k) and ``v_prev`` is
        v(t_{k−1}), which defines CR(t_k) on every mesh of the step.
    solver
        Stopping tolerance and iteration limit.
    adaptivity
        Refinement variant (``paper``, ``after``, ``fixed``), TOL, marking, element floor.
    monitor
        Called as ``monitor("u", state)`` and ``monitor("v", state)`` after each half-step.

    Returns
    -------
    StepResult
        Iterations, convergence, last change, refinements and their history.

    Raises
    ------
    ConvergenceError
        If a half-step produces NaN or Inf.
    """
    result = StepResult()
    state.v_values[state.crack_set()] = 0.0
    while result.iterations < solver.am_max_iter:
        result.iterations += 1
        state.v_iter.vec.data = state.v.vec
        for stage in ("u", "v"):
            _half_step(state, stage, adaptivity, result)
            if monitor:
                monitor(stage, state)
        change = np.max(np.abs(state.v_values - state.v_iter.vec.FV().NumPy()))
        result.change = float(change)
        if not np.isfinite(change):
            raise ConvergenceError(
                f"the alternating minimisation produced NaN/Inf at iteration {result.iterations}"
            )
        if change < solver.am_tol:
            if adaptivity.adapt == "after" and _refine_after(state, adaptivity, result):
                continue
            result.converged = True
            return result
    log.warning(
        "alternating minimisation stopped at the iteration limit %d with ‖Δv‖∞ = %.3g",
        solver.am_max_iter,
        result.change,
    )
    return result
