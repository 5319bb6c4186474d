"""Alternating minimisation in (u, v) for one load step, on a fixed or adaptive mesh.

Algorithm 1 of the paper minimises I_j in u with v frozen, then in v with u frozen, until
‖v^n − v^{n−1}‖_∞ < ``am_tol``; I_j never increases from one half-step to the next (proof of
Proposition 2). By default the test is on the distance to the fixed point estimated from the
contraction of the last two changes (``am_stop="contraction"``,
:func:`ngat.strategies.estimated_error`): where a crack front creeps, each change is a small
fraction of the way still to go, and the paper's test on the change itself stops the step with
the crack short of its equilibrium. It measures the change where the material still bears load
(:func:`load_bearing_change`): inside a crack, v drifts slowly towards 0 as the crack opens, with
no effect on the energies, and would hold later steps for tens of iterations. Algorithm 2
refines inside each half-step: solve, estimate (μ for the u-step, ν for the v-step,
Proposition 4), mark, refine, until the estimator is ≤ TOL.
The variant ``"after"`` runs Algorithm 1 to convergence first and refines only then. The
default ``"band"`` is Algorithm 2 with the crack band resolved after every v-step
(:class:`ngat.band.CrackBand`): an iteration that refined the band does not count as converged.
With ``band_search`` > 1 the band is coarser until the iteration first converges
(:meth:`ngat.band.CrackBand.search`), then resolved to its target, and the iteration goes on to
convergence on that mesh.

The loop is the same for every ``nonlinear`` solver, all with the same stopping test on an
alternating-minimisation iteration; what a solver adds between the half-steps (acceleration,
Newton steps) is a strategy of :mod:`ngat.strategies`, taken from
:func:`ngat.strategies.nonlinear_strategy`, and the half-steps themselves are solved by
:class:`ngat.halfsteps.HalfStepSolvers`. The step's :class:`StepResult` gathers the statistics
that both report.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ngat.band import CrackBand
from ngat.estimators import mu_estimator, nu_estimator
from ngat.extension import CrackExtension
from ngat.halfsteps import HalfStepSolvers
from ngat.parameters import AdaptivityParameters, SolverParameters
from ngat.refinement import mark, refinable, refine
from ngat.state import ATState
from ngat.strategies import NonlinearStrategy, estimated_error, nonlinear_strategy

__all__ = [
    "StepResult",
    "alternating_minimization",
    "estimate",
    "ConvergenceError",
    "iteration_limit",
    "load_bearing_change",
    "predict_v",
    "predicted_v",
    "PREDICTOR_MAX",
    "tolerance",
]

log = logging.getLogger(__name__)

HalfStepMonitor = Callable[[str, ATState], None]

ROUND_OFF_TOL = 1e-6
"""Smallest TOL of the relative form: estimators of fields that are round-off are not refined."""
CRACKED = 0.25
"""v below which a vertex is crack for the stopping test ``am_stop="contraction"``: its
stiffness v² is below 1/16 (:func:`load_bearing_change`)."""
PROGRESS_EVERY = 50
"""Iterations between the progress lines of one load step (log level INFO): a step in which a
crack runs through the body can take hundreds of iterations and tens of minutes, and a log or
console without a line for that long cannot be told from a hung run."""


ITERATIONS_PER_EPS = 10
"""Iterations of one load step allowed per ε of the body's diameter (:func:`iteration_limit`)."""
LEAST_ITERATIONS = 1000
"""The smallest default iteration limit of a load step."""


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
        Whether the stopping test (``am_stop``) fell below the tolerance.
    change
        The last ‖v^n − v^{n−1}‖_∞.
    refinements
        Number of mesh refinements during the step.
    band_refinements
        Those of them that resolved the crack band (:class:`ngat.band.CrackBand`).
    mu
        μ_j(u^n, v^{n−1}) of the last u-step, the value Algorithm 2 tests against TOL (``None``
        if the iteration did not estimate it: ``adapt`` ``fixed`` or ``after``).
    history
        One entry per refinement: iteration, half-step, elements, estimator before refining.
    energies
        I_j after every iteration.
    energy_increases
        Iterations on an unchanged mesh that increased I_j (should be 0: each half-step is a
        minimisation).
    bound_active
        DOFs of v held at a bound by the last v-step (0 if the mesh changed since).
    fallbacks
        Accelerated iterates rejected by the energy safeguard, and rejected Newton steps.
    newton_steps
        Accepted Newton steps (``nonlinear="newton"``).
    escapes
        Steps along a direction of negative curvature of I_j (away from a saddle) instead of
        a Newton step.
    extensions
        Accepted jumps of running cracks (:class:`ngat.extension.CrackExtension`).
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
    mu: float | None = None
    history: list[dict] = field(default_factory=list)
    energies: list[float] = field(default_factory=list)
    energy_increases: int = 0
    bound_active: int = 0
    fallbacks: int = 0
    newton_steps: int = 0
    escapes: int = 0
    extensions: int = 0
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
    with G_c = 1 (the paper) both are Proposition 4's. Computed once per mesh and values of u,
    v and CR (:meth:`ngat.state.ATState.of_values`): a step's record takes the ν of its last
    v-step; the result is read-only.
    """
    with state.timer("estimate"):
        inputs = (state.u_values, state.v_values) + ((crack,) if stage == "v" else ())
        return state.of_values(("estimate", stage), inputs, lambda: _estimate(state, stage, crack))


def _estimate(state: ATState, stage: str, crack: np.ndarray) -> np.ndarray:
    """:func:`estimate`, computed."""
    model = state.model
    if stage == "u":
        indicators = mu_estimator(
            state.arrays, state.edges, state.u_values, state.v_values, model.eta,
            state.dirichlet_vertices, state.elasticity, state.dirichlet,
        ) / state.elasticity.modulus  # fmt: skip
    else:
        indicators = nu_estimator(
            state.arrays, state.edges, state.u_values, state.v_values, model.surface, crack,
            state.elasticity, model.gc,
        ) * model.gc  # fmt: skip
    indicators.flags.writeable = False
    return indicators


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
    state: ATState,
    half_steps: HalfStepSolvers,
    stage: str,
    adaptivity: AdaptivityParameters,
    result: StepResult,
) -> None:
    """Solve one half-step; with Algorithm 2, refine and re-solve until the estimator ≤ TOL."""
    while True:
        crack = state.crack_set()
        if stage == "u":
            half_steps.solve_u()
            half_steps.prepare_v(crack)  # b_j(u^n) factorises while μ is computed
        else:
            half_steps.solve_v(crack)
            half_steps.prepare_u()  # a_j(v^n) factorises while ν and the rest are computed
        if adaptivity.adapt not in ("paper", "band"):
            return
        indicators = estimate(state, stage, crack)
        if stage == "u":
            result.mu = float(np.sqrt(indicators.sum()))
        if not _refine_by(state, [indicators], adaptivity, result, stage):
            return


def _refine_after(state: ATState, adaptivity: AdaptivityParameters, result: StepResult) -> bool:
    """Refine by μ and ν of the converged pair; return whether the mesh changed."""
    crack = state.crack_set()
    indicators = [estimate(state, "u", crack), estimate(state, "v", crack)]
    return _refine_by(state, indicators, adaptivity, result, "after")


def iteration_limit(state: ATState, solver: SolverParameters) -> int:
    """Return the iteration limit of a load step: ``am_max_iter``, or scaled with ε if 0.

    Where a load step is unstable a crack runs through the body before the iteration settles,
    and alternating minimisation moves its tip by 0.1–0.15ε per iteration (measured on the
    paper's example: its break step took 150 iterations at ε = 0.05, 500 at 0.025 and more
    than 1000 at 0.0125). The default limit is :data:`ITERATIONS_PER_EPS` iterations per ε of
    the diameter of the body's bounding box, at least :data:`LEAST_ITERATIONS`, so that a
    crack may cross the whole body in one step whatever ε is (1,844 on the paper's example,
    7,376 at ε = 0.0125).
    """
    if solver.am_max_iter:
        return solver.am_max_iter
    diameter = state.arrays.bounding_diameter
    return max(LEAST_ITERATIONS, int(np.ceil(ITERATIONS_PER_EPS * diameter / state.model.eps)))


def load_bearing_change(v: np.ndarray, v_old: np.ndarray) -> float:
    """Return the change of v outside the crack, ‖(v − v_old) min(1, v̄ / CRACKED)‖_∞.

    v̄ = (v + v_old)/2.

    Where v̄ ≥ :data:`CRACKED` this is the change itself; inside a crack (stiffness v² < 1/16)
    it is scaled down with v̄. As a crack opens, the jump of u across its band grows and v in
    the band drifts towards 0, by about 1e−3 per iteration at v ≈ 0.005 and with a contraction
    rate near 1, while I_j moves by 1e−5 of itself (measured on the paper's example after the
    body broke, t = 1.5: 29 iterations and 32 s with ‖Δv‖_∞, 1 with this). The crack's flanks
    settle the same way once a crack has run: in the paper's example's break step the last 17
    iterations moved v by up to 1e−3 per iteration only at v = 0.05–0.1, and I_j by less than
    1e−5 of itself (132 instead of 149 iterations with the threshold at 0.25 instead of 0.1,
    the final I_j 4e−5 higher). A crack front creeping through intact material is measured in
    full.

    Parameters
    ----------
    v, v_old
        Nodal values of v after and before the iteration.
    """
    weight = np.minimum(1.0, (v + v_old) / (2 * CRACKED))
    return float(np.max(np.abs(v - v_old) * weight))


def _stopping_error(change: float, previous: float, moved: float, am_stop: str) -> float:
    """Return what the loop compares with ``am_tol``.

    ``am_stop="change"``: ``change`` = ‖v^n − v^{n−1}‖_∞ (the paper). ``"contraction"``: the
    distance to the fixed point estimated from the last two changes, ``change`` =
    :func:`load_bearing_change` (:func:`ngat.strategies.estimated_error`),
    and at least the strategy's own step (a Newton step) since the last iteration: an iteration
    is not converged while Newton still moves v further than the tolerance.
    """
    if am_stop == "change":
        return change
    return max(estimated_error(change, previous), moved)


PREDICTOR_MAX = 0.025
"""Largest change of v in the last load step, ‖v(t_{k−1}) − v(t_{k−2})‖_∞, after which the
next step is still started from the extrapolation (:func:`predict_v`): a larger one is a crack
that grew or jumped, not a trend to follow. On the paper's example (Δt = 0.01) the change is
0.003–0.02 per step up to t = 1.25, 0.03–0.11 once the cracks leave their slits."""


def predicted_v(
    v: np.ndarray, change: np.ndarray, ratio: float, upper: np.ndarray | float = 1.0
) -> np.ndarray | None:
    """Return v(t_{k−1}) + ratio · (v(t_{k−1}) − v(t_{k−2})), clipped; ``None`` if no prediction.

    Alternating minimisation (Algorithm 1) starts from v(t_{k−1}); while v follows the load
    smoothly, its linear extrapolation is O(Δt²) from the step's solution instead of O(Δt), and
    the first iteration's change already passes the stopping test (measured on the paper's
    example: its 139 steps before the break in 500 linear solves instead of 848, fracture time
    and E(1.0) unchanged). The prediction is clipped to the admissible set (0 ≤ v ≤ 1,
    or ≤ v(t_{k−1}) with pointwise irreversibility); v = 0 on CR(t_k) is set by the loop.
    There is none after a step whose change exceeded :data:`PREDICTOR_MAX`.

    Parameters
    ----------
    v, change
        Nodal values of v(t_{k−1}) and of v(t_{k−1}) − v(t_{k−2}).
    ratio
        (t_k − t_{k−1}) / (t_{k−1} − t_{k−2}).
    upper
        The upper bound of v: 1, or v(t_{k−1}) with pointwise irreversibility.
    """
    largest = float(np.abs(change).max()) if len(change) else 0.0
    if largest == 0.0 or largest > PREDICTOR_MAX:
        return None
    predicted = v + ratio * change
    np.clip(predicted, 0.0, upper, out=predicted)
    return predicted


def predict_v(state: ATState, ratio: float) -> bool:
    """Start the load step from :func:`predicted_v`; return whether there was a prediction.

    ``state`` holds ``v`` = ``v_prev`` = v(t_{k−1}) and ``v_change`` = v(t_{k−1}) − v(t_{k−2})
    on the current mesh, prolongated with them.
    """
    upper = state.v_prev.vec.FV().NumPy() if state.model.irreversibility == "pointwise" else 1.0
    v = predicted_v(state.v_values, state.v_change.vec.FV().NumPy(), ratio, upper)
    if v is None:
        return False
    state.v_values[:] = v
    return True


def alternating_minimization(
    state: ATState,
    solver: SolverParameters,
    adaptivity: AdaptivityParameters,
    monitor: HalfStepMonitor | None = None,
    band: CrackBand | None = None,
    half_steps: HalfStepSolvers | None = None,
    strategy: NonlinearStrategy | None = None,
    extension: CrackExtension | None = None,
) -> StepResult:
    """Run Algorithm 1 or 2 from the current (u, v), with v = 0 on CR(t_k).

    Parameters
    ----------
    state
        Fields and operators; u already carries the Dirichlet data g(t_k) and ``v_prev`` is
        v(t_{k−1}), which defines CR(t_k) on every mesh of the step.
    solver
        Stopping tolerance and iteration limit, the linear and the nonlinear solvers.
    adaptivity
        Refinement variant (``paper``, ``after``, ``fixed``), TOL, marking, element floor.
    monitor
        Called as ``monitor("u", state)`` and ``monitor("v", state)`` after each half-step.
    band
        With ``adapt="band"``: the crack band, resolved after every v-step.
    half_steps, strategy
        The solvers of the half-steps (:mod:`ngat.halfsteps`) and the nonlinear solver
        (:mod:`ngat.strategies`), kept by the caller so that their factorisations serve every
        load step; default new ones as ``solver`` sets them.
    extension
        Jumps of running cracks (:class:`ngat.extension.CrackExtension`), tried after each
        iteration that did not converge, before the strategy's own step.

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
    half_steps = half_steps or HalfStepSolvers.from_parameters(state, solver)
    strategy = strategy or nonlinear_strategy(solver)
    state.v_values[state.crack_set()] = 0.0
    half_steps.start()
    strategy.start(state, half_steps)
    if extension:
        extension.start()
    if band:
        band.search()
    previous, moved = np.inf, 0.0  # the last iteration's change, the strategy's step after it
    limit = iteration_limit(state, solver)
    while result.iterations < limit:
        result.iterations += 1
        state.v_iter.vec.data = state.v.vec
        elements = state.arrays.ne
        _half_step(state, half_steps, "u", adaptivity, result)
        if not strategy.accept_u_step(state):
            _half_step(state, half_steps, "u", adaptivity, result)
        if monitor:
            monitor("u", state)
        _half_step(state, half_steps, "v", adaptivity, result)
        if monitor:
            monitor("v", state)
        band_rounds = _resolve_band(state, band, result) if band else 0
        energy = state.energies()["total"]
        strategy.next_iterate(state)
        if result.energies and elements == state.arrays.ne:
            if energy > result.energies[-1] * (1 + 1e-10) + 1e-14:
                result.energy_increases += 1
        result.energies.append(energy)
        v_old = state.v_iter.vec.FV().NumPy()
        change = float(np.max(np.abs(state.v_values - v_old)))
        result.change = change
        if not np.isfinite(change) or not np.isfinite(energy):
            raise ConvergenceError(
                f"the alternating minimisation produced NaN/Inf at iteration {result.iterations}"
            )
        if solver.am_stop == "contraction":
            measured = load_bearing_change(state.v_values, v_old)
        else:
            measured = change
        error = _stopping_error(measured, previous, moved, solver.am_stop)
        previous = measured
        if result.iterations % PROGRESS_EVERY == 0:
            _log_progress(state, result)
        if error < solver.am_tol and not band_rounds and band and band.end_search():
            band_rounds = _resolve_band(state, band, result)
        if error < solver.am_tol and not band_rounds:
            if adaptivity.adapt == "after" and _refine_after(state, adaptivity, result):
                continue
            result.converged = True
            result.reason = "converged"
            break
        moved = 0.0
        if extension and extension.advance(state, half_steps, energy):
            moved = 1.0  # v fell from about 1 to 0 where the crack jumped
            result.energies.append(state.energies()["total"])
            continue
        before = state.v_values.copy()
        if strategy.after_iteration(state, change):
            moved = float(np.max(np.abs(state.v_values - before)))
            result.energies.append(state.energies()["total"])
    else:
        result.reason = "iteration limit"
        log.warning(
            "alternating minimisation stopped at the iteration limit %d with ‖Δv‖∞ = %.3g",
            limit,
            result.change,
        )
    if band:
        band.end_search()
    _record_statistics(result, half_steps, strategy)
    if extension:
        result.extensions = extension.jumps
        result.band_refinements += extension.band_rounds
        result.refinements += extension.band_rounds
    return result


def _resolve_band(state: ATState, band: CrackBand, result: StepResult) -> int:
    """Resolve the crack band after a v-step (:meth:`ngat.band.CrackBand.refine`).

    Returns the bisection rounds (0: the mesh is unchanged) and records them in ``result``.
    """
    elements = state.arrays.ne
    rounds = band.refine(state)
    if rounds:
        result.band_refinements += rounds
        result.refinements += rounds
        result.history.append(
            {"iteration": result.iterations, "stage": "band", "elements": elements,
             "estimate": 0.0, "new_elements": state.arrays.ne}
        )  # fmt: skip
    return rounds


def _log_progress(state: ATState, result: StepResult) -> None:
    """Log where a long load step stands: iteration, ‖v^n − v^{n−1}‖_∞, I_j, elements."""
    log.info(
        "t=%g: iteration %d, ‖Δv‖∞ = %.3g, total %.6g, %d elements",
        state.t.Get(), result.iterations, result.change, result.energies[-1], state.arrays.ne,
    )  # fmt: skip


def _record_statistics(
    result: StepResult, half_steps: HalfStepSolvers, strategy: NonlinearStrategy
) -> None:
    """Copy what the half-step solvers and the nonlinear strategy report into ``result``."""
    linear, nonlinear = half_steps.statistics, strategy.statistics
    result.bound_active = half_steps.bound_active
    result.linear_solves = linear.solves + nonlinear.linear_solves
    result.cg_iterations = sum(linear.cg_iterations)
    result.cg_max_iterations = max(linear.cg_iterations, default=0)
    result.cg_not_converged = linear.cg_not_converged
    result.fallbacks = nonlinear.fallbacks
    result.newton_steps = nonlinear.newton_steps
    result.escapes = nonlinear.escapes
    result.curvature_solves = nonlinear.curvature_solves
