"""Alternating minimisation in (u, v) for one load step, on a fixed or adaptive mesh.

Algorithm 1 of the paper minimises I_j in u with v frozen, then in v with u frozen, until
‖v^n − v^{n−1}‖_∞ < ``am_tol``; I_j never increases from one half-step to the next (proof of
Proposition 2). Algorithm 2 refines inside each half-step: solve, estimate (μ for the u-step,
ν for the v-step, Proposition 4), mark, refine, until the estimator is ≤ TOL. The variant
``"after"`` runs Algorithm 1 to convergence first and refines only then. The default ``"band"``
is Algorithm 2 with the crack band resolved after every v-step (:class:`ngat.band.CrackBand`):
an iteration that refined the band does not count as converged.

``nonlinear`` selects how the iterates are formed, all with the same stopping test on an
alternating-minimisation iteration: plain (the paper), over-relaxed or Anderson-accelerated
(:class:`Accelerator`, with an energy safeguard), and with ``newton``/``anderson-newton`` a
Newton step on the coupled system (:class:`ngat.newton.NewtonSolver`, or a step along negative
curvature) after an iteration with ‖v^n − v^{n−1}‖_∞ < ``newton_switch`` whose rate predicts
more than ``NEWTON_COST`` further iterations (:func:`remaining_iterations`).
"""

from __future__ import annotations

import logging
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from ngsolve import GridFunction

from ngat.band import CrackBand
from ngat.estimators import mu_estimator, nu_estimator
from ngat.newton import NewtonSolver
from ngat.parameters import AdaptivityParameters, SolverParameters
from ngat.refinement import mark, refinable, refine
from ngat.state import ATState

__all__ = [
    "StepResult",
    "alternating_minimization",
    "Accelerator",
    "estimate",
    "ConvergenceError",
    "remaining_iterations",
    "tolerance",
]

log = logging.getLogger(__name__)

HalfStepMonitor = Callable[[str, ATState], None]

_newton_solvers: weakref.WeakKeyDictionary[ATState, NewtonSolver] = weakref.WeakKeyDictionary()
"""One Newton solver per state, so that its graph and factorisation outlive a load step."""

NEWTON_COST = 2
"""Alternating-minimisation iterations that a Newton attempt costs: its factorisation of the
coupled 2n × 2n system is about three half-step factorisations (1.5 iterations), and the up to
ten back-solves of the search for negative curvature cost about an eighth of a factorisation
each (0.13 s against 1.05 s at 122k vertices). Newton is tried only where more alternating
minimisation iterations than this remain."""


ROUND_OFF_TOL = 1e-6
"""Smallest TOL of the relative form: estimators of fields that are round-off are not refined."""


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
    band_refinements
        Those of them that resolved the crack band (:class:`ngat.band.CrackBand`).
    history
        One entry per refinement: iteration, half-step, elements, estimator before refining.
    energies
        I_j after every iteration.
    energy_increases
        Iterations on an unchanged mesh that increased I_j (should be 0: each half-step is a
        minimisation).
    fallbacks
        Accelerated iterates rejected by the energy safeguard, and rejected Newton steps.
    newton_steps
        Accepted Newton steps (``nonlinear="newton"``).
    escapes
        Steps along a direction of negative curvature of I_j (away from a saddle) instead of
        a Newton step.
    linear_solves
        Linear systems solved during the step.
    curvature_solves
        Solves with a Newton factorisation already computed, in the search for negative
        curvature (Lanczos steps).
    cg_iterations
        CG iterations of the step's solves (``linear_solver="cg-h1amg"``; 0 with ``direct``).
    cg_max_iterations
        Most CG iterations of one solve in the step.
    cg_not_converged
        Solves of the step that stopped at the CG iteration cap above the tolerance.
    reason
        Why the iteration stopped: ``converged`` or ``iteration limit``.
    """

    iterations: int = 0
    converged: bool = False
    change: float = np.inf
    refinements: int = 0
    band_refinements: int = 0
    history: list[dict] = field(default_factory=list)
    energies: list[float] = field(default_factory=list)
    energy_increases: int = 0
    fallbacks: int = 0
    newton_steps: int = 0
    escapes: int = 0
    linear_solves: int = 0
    curvature_solves: int = 0
    cg_iterations: int = 0
    cg_max_iterations: int = 0
    cg_not_converged: int = 0
    reason: str = ""


def estimate(state: ATState, stage: str, crack: np.ndarray) -> np.ndarray:
    """Return the squared element indicators of μ (``stage="u"``) or ν (``stage="v"``).

    Both are measured in the dual of the energy norm of their half-step, so that they compare
    with I_j^{1/2} (:func:`tolerance`) whatever the material's units: μ² is divided by the
    stiffness scale of the model (:attr:`ngat.elasticity.Elasticity.modulus`) and ν², the
    indicator of the v-equation divided by G_c, is multiplied by G_c. For the anti-plane model
    with G_c = 1 (the paper) both are Proposition 4's.
    """
    with state.timer("estimate"):
        model = state.model
        if stage == "u":
            return mu_estimator(
                state.arrays, state.edges, state.u_values, state.v_values, model.eta,
                state.dirichlet_vertices, state.elasticity, state.dirichlet,
            ) / state.elasticity.modulus  # fmt: skip
        return nu_estimator(
            state.arrays, state.edges, state.u_values, state.v_values, model.surface, crack,
            state.elasticity, model.gc,
        ) * model.gc  # fmt: skip


def tolerance(state: ATState, adaptivity: AdaptivityParameters) -> float:
    """Return TOL_n for μ and ν: ``tol`` (Algorithm 2), or ``tol_rel`` · I_j(u, v)^{1/2} (band).

    μ and ν bound the residuals in the dual of the energy norm, and I_j^{1/2} is the size of
    (u, v) in that norm: the relative form means the same when the load, the domain or ε
    change (the absolute TOL = 0.3 of the paper is 0.18 I_j^{1/2} at t = 1 of its example).
    Without load, I_j is round-off and so are μ and ν: TOL is never below ``ROUND_OFF_TOL``.
    """
    if adaptivity.adapt != "band":
        return adaptivity.tol
    return max(adaptivity.tol_rel * float(np.sqrt(state.energies()["total"])), ROUND_OFF_TOL)


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
    allowed = refinable(state, adaptivity.floor * state.model.eps)
    tol = tolerance(state, adaptivity)
    marked = np.zeros(state.arrays.ne, dtype=bool)
    values = []
    for eta_sq in indicators:
        values.append(float(np.sqrt(eta_sq.sum())))
        if values[-1] > tol and np.sqrt(eta_sq[allowed].sum()) > tol:
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
        if adaptivity.adapt not in ("paper", "band"):
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
    band: CrackBand | None = None,
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
    band
        With ``adapt="band"``: the crack band, resolved after every v-step.

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
    solves_before = state.linear_solves, state.curvature_solves
    cg_before = (len(state.cg_iterations), state.cg_not_converged)
    state.v_values[state.crack_set()] = 0.0
    accelerator = None
    if solver.nonlinear in ("overrelaxed", "anderson", "anderson-newton"):
        accelerator = Accelerator(solver)
    newton = None
    if solver.nonlinear in ("newton", "anderson-newton"):
        newton = _newton_solvers.setdefault(state, NewtonSolver(state))
        newton.restart()
    newton_below, previous_change = solver.newton_switch, np.inf
    while result.iterations < solver.am_max_iter:
        result.iterations += 1
        state.v_iter.vec.data = state.v.vec
        elements = state.arrays.ne
        _half_step(state, "u", adaptivity, result)
        if accelerator and not accelerator.safeguard(state, result):
            _half_step(state, "u", adaptivity, result)
        if monitor:
            monitor("u", state)
        _half_step(state, "v", adaptivity, result)
        if monitor:
            monitor("v", state)
        band_rounds = band.refine(state) if band else 0
        if band_rounds:
            result.band_refinements += band_rounds
            result.refinements += band_rounds
            result.history.append(
                {"iteration": result.iterations, "stage": "band", "elements": elements,
                 "estimate": 0.0, "new_elements": state.arrays.ne}
            )  # fmt: skip
        energy = state.energies()["total"]
        if accelerator:
            accelerator.step(state)
        if result.energies and elements == state.arrays.ne:
            if energy > result.energies[-1] * (1 + 1e-10) + 1e-14:
                result.energy_increases += 1
        result.energies.append(energy)
        change = np.max(np.abs(state.v_values - state.v_iter.vec.FV().NumPy()))
        result.change = float(change)
        if not np.isfinite(change) or not np.isfinite(energy):
            raise ConvergenceError(
                f"the alternating minimisation produced NaN/Inf at iteration {result.iterations}"
            )
        if change < solver.am_tol and not band_rounds:
            if adaptivity.adapt == "after" and _refine_after(state, adaptivity, result):
                continue
            result.converged = True
            result.reason = "converged"
            break
        remaining = remaining_iterations(change, previous_change, solver.am_tol)
        previous_change = change
        if newton and change < newton_below and remaining > NEWTON_COST:
            previous_change = np.inf  # the next ratio would measure the Newton step
            ceiling = accelerator.plain_energy if accelerator and accelerator.has_plain else np.inf
            outcome = newton.step(state.crack_set(), ceiling)
            if outcome:
                result.energies.append(state.energies()["total"])
                if accelerator:
                    accelerator.restart()
                result.newton_steps += outcome == "newton"
                result.escapes += outcome == "escape"
            else:
                # Too far from a minimiser for Newton: wait until the iteration has halved.
                result.fallbacks += 1
                newton_below = change / 2
    else:
        result.reason = "iteration limit"
        log.warning(
            "alternating minimisation stopped at the iteration limit %d with ‖Δv‖∞ = %.3g",
            solver.am_max_iter,
            result.change,
        )
    result.linear_solves = state.linear_solves - solves_before[0]
    result.curvature_solves = state.curvature_solves - solves_before[1]
    cg_counts = state.cg_iterations[cg_before[0] :]
    result.cg_iterations = sum(cg_counts)
    result.cg_max_iterations = max(cg_counts, default=0)
    result.cg_not_converged = state.cg_not_converged - cg_before[1]
    return result


def remaining_iterations(change: float, previous: float, tol: float) -> float:
    """Estimate the iterations until ‖v^n − v^{n−1}‖_∞ < tol from the last contraction.

    Alternating minimisation converges linearly near a minimiser, with the ratio of successive
    changes as its rate ρ: about log(tol / change) / log ρ more iterations; infinitely many if
    the change did not shrink; 0 without a previous change (``previous = inf``), which is not
    yet evidence of slow convergence.
    """
    if not np.isfinite(previous):
        return 0.0
    ratio = change / previous
    if ratio >= 1:
        return np.inf
    if change <= tol:
        return 0.0
    return float(np.log(tol / change) / np.log(ratio))


class Accelerator:
    """Over-relaxation or Anderson acceleration of the alternating-minimisation map v ↦ G(v).

    G is one u-step followed by one v-step. After the v-step, :meth:`step` replaces the plain
    iterate G(v) by v_old + ω(G(v) − v_old) (over-relaxation) or by the Anderson combination
    of the last ``depth`` iterates, projected to 0 ≤ v ≤ 1 (≤ v(t_{k−1}) for pointwise
    irreversibility) and v = 0 on CR. The v-step minimises I_j(u^n, ·) exactly, so the
    accelerated v cannot be judged before the next u-step: :meth:`safeguard` compares
    I_j(u^{n+1}, v_acc) with I_j(u^n, G(v)) and, if the energy went up, restores the plain
    iterate (the caller repeats the u-step) and clears the history. The plain iterate is kept
    in a GridFunction that ``mesh.Refine()`` prolongates, so the comparison also holds when the
    u-step refined the mesh (bisection with the vertex rule does not raise I_j). The sequence of
    accepted energies therefore never increases, as for plain alternating minimisation.
    """

    def __init__(self, solver: SolverParameters):
        self.kind = "anderson" if solver.nonlinear == "anderson-newton" else solver.nonlinear
        self.omega = solver.omega
        self.depth = solver.anderson_depth
        self.iterates: list[np.ndarray] = []  # G(x_k)
        self.residuals: list[np.ndarray] = []  # G(x_k) − x_k
        self.plain: GridFunction | None = None
        self.has_plain = False
        self.plain_energy = np.inf

    def restart(self) -> None:
        """Forget the history (the iterate was changed by another method)."""
        self.iterates, self.residuals, self.has_plain = [], [], False

    def step(self, state: ATState) -> None:
        """Replace the plain iterate in ``state.v`` by the accelerated one."""
        v = state.v_values
        v_old = state.v_iter.vec.FV().NumPy()
        if len(v_old) != len(v) or (self.iterates and len(self.iterates[0]) != len(v)):
            self.restart()
            return
        if self.plain is None:
            self.plain = GridFunction(state.fes, autoupdate=True)
        self.plain.vec.data = state.v.vec
        self.has_plain = True
        self.plain_energy = state.energies()["total"]
        if self.kind == "overrelaxed":
            candidate = v_old + self.omega * (v - v_old)
        else:
            self.iterates.append(v.copy())
            self.residuals.append(v - v_old)
            self.iterates = self.iterates[-(self.depth + 1) :]
            self.residuals = self.residuals[-(self.depth + 1) :]
            if len(self.residuals) < 2:
                return
            d_res = np.diff(np.array(self.residuals), axis=0)
            d_it = np.diff(np.array(self.iterates), axis=0)
            gamma = np.linalg.lstsq(d_res.T, self.residuals[-1], rcond=None)[0]
            candidate = v - d_it.T @ gamma
        upper = state.v_prev.vec.FV().NumPy() if state.model.irreversibility == "pointwise" else 1.0
        np.clip(candidate, 0.0, upper, out=candidate)
        candidate[state.crack_set()] = 0.0
        v[:] = candidate

    def safeguard(self, state: ATState, result: StepResult) -> bool:
        """After the u-step: keep the accelerated v if I_j did not increase; else restore.

        Returns ``False`` when the plain iterate was restored (the u-step must be repeated).
        """
        if not self.has_plain or state.energies()["total"] <= self.plain_energy:
            return True
        state.v.vec.data = self.plain.vec
        state.v_iter.vec.data = self.plain.vec
        self.restart()
        result.fallbacks += 1
        return False
