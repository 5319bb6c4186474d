"""Nonlinear solvers of one load step: strategies around the alternating-minimisation iteration.

Every solver of ``SolverParameters.nonlinear`` iterates Algorithm 1 of the paper — a u-step, a
v-step, until ‖v^n − v^{n−1}‖_∞ < ``am_tol`` — and they differ only in what happens between the
half-steps: plain alternating minimisation does nothing (:class:`AlternatingMinimization`);
over-relaxation and Anderson acceleration replace the plain iterate by an extrapolated one and
check it against the energy after the next u-step (:class:`OverRelaxed`, :class:`Anderson`);
the Newton switch tries a Newton step on the coupled system once the iteration slows down
(:class:`NewtonSwitch`, around either of them). A strategy is therefore the set of hooks that
the loop of :func:`ngat.minimization.alternating_minimization` calls (:class:`NonlinearStrategy`),
each given the state — the fields, I_j and the load step's CR(t_k) and v(t_{k−1}) — and each
strategy counts what it did in its own :class:`NonlinearStatistics`. :func:`nonlinear_strategy`
makes the strategy named by ``nonlinear``. A strategy may serve every load step of a run: the
Newton solver's graph and factorisation then outlive a load step.

A module of its own rather than a part of :mod:`ngat.minimization`: that module is the loop and
the refinement of Algorithm 2, the same for every solver; this one what a solver adds to it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from ngsolve import GridFunction

from ngat.halfsteps import HalfStepSolvers
from ngat.newton import NewtonSolver
from ngat.parameters import SolverParameters
from ngat.state import ATState

__all__ = [
    "NonlinearStrategy",
    "NonlinearStatistics",
    "AlternatingMinimization",
    "Accelerated",
    "OverRelaxed",
    "Anderson",
    "NewtonSwitch",
    "STRATEGIES",
    "nonlinear_strategy",
    "remaining_iterations",
    "estimated_error",
    "error_factor",
    "RATE_MAX",
    "NEWTON_COST",
    "NEWTON_WAIT",
]

NEWTON_COST = 2
"""Alternating-minimisation iterations that a Newton attempt costs: its factorisation of the
coupled 2n × 2n system is about three half-step factorisations (1.5 iterations), and the up to
ten back-solves of the search for negative curvature cost about an eighth of a factorisation
each (0.13 s against 1.05 s at 122k vertices). Newton is tried only where more alternating
minimisation iterations than this remain."""

NEWTON_WAIT = 2
"""Eligible iterations without a Newton attempt after a rejected step, or an accepted one that
lowered I_j by less than the plain iteration before it; doubled after each further such step
(:class:`NewtonSwitch`). In the paper's example, once its cracks have linked, steps along
negative curvature lower I_j by 0–30 % of a plain iteration's decrease and cost about two
iterations each (27 of them, 5 s of the 38 s break step); while the cracks run, most steps
lower it 2–10 times more than an iteration does, and the wait ends with the first such step."""


@dataclass
class NonlinearStatistics:
    """What a nonlinear strategy did in one load step.

    Attributes
    ----------
    fallbacks
        Accelerated iterates rejected by the energy safeguard, and rejected Newton steps.
    newton_steps
        Accepted Newton steps.
    escapes
        Steps along a direction of negative curvature of I_j (away from a saddle) instead of
        a Newton step.
    linear_solves
        Linear systems the strategy solved itself (the Newton systems; the half-steps count
        theirs in :class:`ngat.halfsteps.LinearStatistics`).
    curvature_solves
        Solves with a Newton factorisation already computed, in the search for negative
        curvature (Lanczos steps).
    """

    fallbacks: int = 0
    newton_steps: int = 0
    escapes: int = 0
    linear_solves: int = 0
    curvature_solves: int = 0


class NonlinearStrategy(Protocol):
    """The hooks of the alternating-minimisation loop, in the order it calls them.

    Attributes
    ----------
    statistics : NonlinearStatistics
        What the strategy did since the last :meth:`start`.
    """

    statistics: NonlinearStatistics

    def start(self, state: ATState, half_steps: HalfStepSolvers) -> None:
        """Begin a load step: forget the last step's iterates, count from zero.

        ``half_steps`` are the loop's solvers of the half-steps on ``state``, with the
        operators of its current mesh.
        """

    def accept_u_step(self, state: ATState) -> bool:
        """After a u-step: return ``False`` if the strategy restored the plain iterate.

        The loop then repeats the u-step from the restored v.
        """

    def next_iterate(self, state: ATState) -> None:
        """After the v-step and its energy: replace the plain iterate in ``state.v`` or keep it."""

    def after_iteration(self, state: ATState, change: float) -> bool:
        """After an iteration that did not converge: return whether the state was moved.

        ``change`` is the iteration's ‖v^n − v^{n−1}‖_∞; the loop records the energy of a
        moved state.
        """


class AlternatingMinimization:
    """Plain alternating minimisation (paper, Algorithm 1): every hook keeps the iterate.

    I_j never increases from one half-step to the next (proof of Proposition 2). The base of
    the accelerated strategies, and what :class:`NewtonSwitch` needs of the iteration it
    interrupts: :meth:`ceiling` and :meth:`restart`.
    """

    def __init__(self) -> None:
        self.statistics = NonlinearStatistics()

    def start(self, state: ATState, half_steps: HalfStepSolvers) -> None:
        """Begin a load step: the statistics count from zero."""
        self.statistics = NonlinearStatistics()

    def accept_u_step(self, state: ATState) -> bool:
        """Accept every u-step."""
        return True

    def next_iterate(self, state: ATState) -> None:
        """Keep the plain iterate."""

    def after_iteration(self, state: ATState, change: float) -> bool:
        """Leave the state as the iteration left it."""
        return False

    def ceiling(self) -> float:
        """Return the energy that a step of another method must not exceed (∞: none)."""
        return np.inf

    def restart(self) -> None:
        """Forget the iterates so far (another method changed the iterate)."""


class Accelerated(AlternatingMinimization):
    """Extrapolation of the alternating-minimisation map v ↦ G(v), with an energy safeguard.

    G is one u-step followed by one v-step. After the v-step, :meth:`next_iterate` replaces the
    plain iterate G(v) by the extrapolation of a subclass, projected to 0 ≤ v ≤ 1 (≤ v(t_{k−1})
    for pointwise irreversibility) and v = 0 on CR. The v-step minimises I_j(u^n, ·) exactly, so
    the accelerated v cannot be judged before the next u-step: :meth:`accept_u_step` compares
    I_j(u^{n+1}, v_acc) with I_j(u^n, G(v)) and, if the energy went up, restores the plain
    iterate (the loop repeats the u-step) and clears the history. The plain iterate is kept
    in a GridFunction that ``mesh.Refine()`` prolongates, so the comparison also holds when the
    u-step refined the mesh (bisection with the vertex rule does not raise I_j). The sequence of
    accepted energies therefore never increases, as for plain alternating minimisation.
    """

    def __init__(self) -> None:
        super().__init__()
        self.plain: GridFunction | None = None
        self.has_plain = False
        self.plain_energy = np.inf

    def start(self, state: ATState, half_steps: HalfStepSolvers) -> None:
        """Begin a load step without history."""
        super().start(state, half_steps)
        self.plain, self.plain_energy = None, np.inf
        self.restart()

    def restart(self) -> None:
        """Forget the history (the iterate was changed by another method)."""
        self.has_plain = False

    def ceiling(self) -> float:
        """Return I_j of the last plain iterate: an accelerated one may lie above it."""
        return self.plain_energy if self.has_plain else np.inf

    def extrapolate(self, v: np.ndarray, v_old: np.ndarray) -> np.ndarray | None:
        """Return the accelerated iterate from G(v_old) = ``v``, or ``None`` to keep ``v``."""
        raise NotImplementedError

    def next_iterate(self, state: ATState) -> None:
        """Replace the plain iterate in ``state.v`` by the accelerated one."""
        v = state.v_values
        v_old = state.v_iter.vec.FV().NumPy()
        if self.plain is None:
            self.plain = GridFunction(state.fes, autoupdate=True)
        self.plain.vec.data = state.v.vec
        self.has_plain = True
        self.plain_energy = state.energies()["total"]
        candidate = self.extrapolate(v, v_old)
        if candidate is None:
            return
        upper = state.v_prev.vec.FV().NumPy() if state.model.irreversibility == "pointwise" else 1.0
        np.clip(candidate, 0.0, upper, out=candidate)
        candidate[state.crack_set()] = 0.0
        v[:] = candidate

    def accept_u_step(self, state: ATState) -> bool:
        """Keep the accelerated v if I_j did not increase; else restore the plain iterate."""
        if not self.has_plain or state.energies()["total"] <= self.plain_energy:
            return True
        state.v.vec.data = self.plain.vec
        state.v_iter.vec.data = self.plain.vec
        self.restart()
        self.statistics.fallbacks += 1
        return False


class OverRelaxed(Accelerated):
    """Over-relaxation v_old + ω(G(v_old) − v_old) of alternating minimisation.

    Parameters
    ----------
    omega
        Over-relaxation factor ω in (0, 2).
    """

    def __init__(self, omega: float) -> None:
        super().__init__()
        self.omega = omega

    def extrapolate(self, v: np.ndarray, v_old: np.ndarray) -> np.ndarray:
        """Return v_old + ω(v − v_old)."""
        return v_old + self.omega * (v - v_old)


class Anderson(Accelerated):
    """Anderson acceleration of alternating minimisation.

    The new iterate is G(x_k) − Σ_i γ_i ΔG_i, with γ the least-squares fit of the last
    residual G(x_k) − x_k by the differences of the last ``depth`` residuals.

    Parameters
    ----------
    depth
        Number of previous iterates combined.
    """

    def __init__(self, depth: int) -> None:
        super().__init__()
        self.depth = depth
        self.iterates: list[np.ndarray] = []  # G(x_k)
        self.residuals: list[np.ndarray] = []  # G(x_k) − x_k

    def restart(self) -> None:
        """Forget the history."""
        super().restart()
        self.iterates, self.residuals = [], []

    def next_iterate(self, state: ATState) -> None:
        """Replace the plain iterate by the Anderson combination (none after a refinement)."""
        if self.iterates and len(self.iterates[0]) != len(state.v_values):
            self.restart()  # the history lives on the mesh before the refinement
            return
        super().next_iterate(state)

    def extrapolate(self, v: np.ndarray, v_old: np.ndarray) -> np.ndarray | None:
        """Return the Anderson combination, or ``None`` while the history has one iterate."""
        self.iterates.append(v.copy())
        self.residuals.append(v - v_old)
        self.iterates = self.iterates[-(self.depth + 1) :]
        self.residuals = self.residuals[-(self.depth + 1) :]
        if len(self.residuals) < 2:
            return None
        d_res = np.diff(np.array(self.residuals), axis=0)
        d_it = np.diff(np.array(self.iterates), axis=0)
        gamma = np.linalg.lstsq(d_res.T, self.residuals[-1], rcond=None)[0]
        return v - d_it.T @ gamma


class NewtonSwitch:
    """Alternating minimisation (plain or accelerated) with Newton steps once it slows down.

    After an iteration with ‖v^n − v^{n−1}‖_∞ below ``switch`` whose rate predicts more than
    :data:`NEWTON_COST` further iterations (:func:`remaining_iterations`), a Newton step on the
    coupled system (:class:`ngat.newton.NewtonSolver`), or a step along negative curvature, is
    tried from the iterate. An accepted step restarts the acceleration's history. An accepted
    step pays if it lowered I_j by at least as much as the plain iteration before it: after a
    rejected step or one that does not pay, the next attempts wait 2, 4, 8, … eligible
    iterations (doubling with every such step, none after one that pays; :data:`NEWTON_WAIT`).
    A rejection used to lower the threshold to half the current change instead, which where
    the cracks then run (the change grows) ended Newton for the rest of the load step: the
    paper's example's break step, from the state at t = 1.39 that Newton's escapes of 0.3
    (``escape_size``) lead to, rejected one step early on and took 270 iterations that way,
    118 with the wait (with escapes of 0.5: 159 and 127). The Newton solver is kept across
    load steps as long as the half-steps' solvers (and so the state) are the same.

    Parameters
    ----------
    iteration
        The iteration Newton interrupts: :class:`AlternatingMinimization` or an accelerated one.
    switch
        ``newton_switch``: the change below which Newton steps are tried.
    am_tol
        The loop's stopping tolerance.
    contraction
        Whether the loop's test is on the estimated error (``am_stop="contraction"``,
        :func:`estimated_error`) or on the change itself.
    """

    def __init__(
        self,
        iteration: AlternatingMinimization,
        switch: float,
        am_tol: float,
        contraction: bool = True,
    ) -> None:
        self.iteration = iteration
        self.switch = switch
        self.am_tol = am_tol
        self.contraction = contraction
        self.newton: NewtonSolver | None = None
        self._reset()

    def _reset(self) -> None:
        """Forget the load step's threshold, counts, last I_j and mesh, and Newton's wait."""
        self.previous = np.inf
        self.newton_steps = self.escapes = self.rejected = 0
        self.energy, self.elements = np.inf, 0  # I_j and mesh after the last iteration
        self.wait = self.waiting = 0

    @property
    def statistics(self) -> NonlinearStatistics:
        """The iteration's statistics with the Newton steps, rejections and solves added."""
        iteration, newton = self.iteration.statistics, self.newton
        solves = newton.solves if newton else 0
        curvature = newton.curvature_solves if newton else 0
        return NonlinearStatistics(
            fallbacks=iteration.fallbacks + self.rejected,
            newton_steps=iteration.newton_steps + self.newton_steps,
            escapes=iteration.escapes + self.escapes,
            linear_solves=iteration.linear_solves + solves,
            curvature_solves=iteration.curvature_solves + curvature,
        )

    def start(self, state: ATState, half_steps: HalfStepSolvers) -> None:
        """Begin a load step: the iteration's, and Newton's on the state's current mesh."""
        self.iteration.start(state, half_steps)
        if self.newton is None or self.newton.half_steps is not half_steps:
            self.newton = NewtonSolver(state, half_steps)
        self.newton.restart()
        self._reset()

    def accept_u_step(self, state: ATState) -> bool:
        """Apply the iteration's safeguard."""
        return self.iteration.accept_u_step(state)

    def next_iterate(self, state: ATState) -> None:
        """Form the iteration's next iterate."""
        self.iteration.next_iterate(state)

    def after_iteration(self, state: ATState, change: float) -> bool:
        """Try a Newton step where the iteration is slow; return whether the state moved."""
        remaining = remaining_iterations(change, self.previous, self.am_tol, self.contraction)
        self.previous = change
        energy, elements = state.energies()["total"], state.arrays.ne
        descent = self.energy - energy if elements == self.elements else np.nan
        self.energy, self.elements = energy, elements
        if not (change < self.switch and remaining > NEWTON_COST):
            return False
        if self.waiting:
            self.waiting -= 1
            return False
        self.previous = np.inf  # the next ratio would measure the Newton step
        outcome = self.newton.step(state.crack_set(), self.iteration.ceiling())
        if not outcome:
            self.rejected += 1
            self._wait_longer()
            return False
        self.energy = state.energies()["total"]
        self._judge(energy - self.energy, descent)
        self.iteration.restart()
        self.newton_steps += outcome == "newton"
        self.escapes += outcome == "escape"
        return True

    def _judge(self, gain: float, descent: float) -> None:
        """Set the wait before the next attempt from what the accepted step gained.

        ``gain`` is the decrease of I_j by the step, ``descent`` that by the plain iteration
        before it (NaN if the mesh changed in between: no judgement).
        """
        if not np.isfinite(descent):
            return
        if gain < descent:
            self._wait_longer()
        else:
            self.wait = 0

    def _wait_longer(self) -> None:
        """Skip the next :data:`NEWTON_WAIT` eligible iterations, or twice as many as last time."""
        self.wait = max(NEWTON_WAIT, 2 * self.wait)
        self.waiting = self.wait


RATE_MAX = 0.99
"""Contraction rate assumed where successive changes do not shrink (ρ ≥ 1): an iteration that
does not contract is taken as one creeping at this rate, so its change must be 99 times
smaller than the tolerance before it stops."""


def error_factor(change: float, previous: float) -> float:
    """Return max(1, ρ/(1 − ρ)), ρ = change / previous capped at :data:`RATE_MAX`.

    For an iteration converging linearly with rate ρ, v* − v^n = Σ_{m>n} (v^m − v^{m−1}) is at
    most ‖v^n − v^{n−1}‖ ρ/(1 − ρ); where ρ ≤ 1/2 the change itself bounds it. Without a
    previous change (``previous = inf``) the factor is 1.
    """
    if not np.isfinite(previous) or previous <= 0:
        return 1.0
    rate = min(change / previous, RATE_MAX)
    return max(1.0, rate / (1.0 - rate))


def estimated_error(change: float, previous: float) -> float:
    """Return the distance ‖v* − v^n‖_∞ to the fixed point estimated from the last two changes.

    The alternating minimisation (Algorithm 1) converges linearly near a minimiser; while a
    crack front creeps, its changes shrink by a rate ρ close to 1 and each is far smaller than
    the way still to go (measured on ``surfing``: ρ = 0.9–0.98 at changes just above 1e−3,
    with the crack 1.3ε short of where the step ends). The estimate is the change times
    :func:`error_factor`.
    """
    return change * error_factor(change, previous)


def remaining_iterations(
    change: float, previous: float, tol: float, contraction: bool = True
) -> float:
    """Estimate the iterations until the loop's stopping test holds, from the last contraction.

    Alternating minimisation converges linearly near a minimiser, with the ratio of successive
    changes as its rate ρ: the test ``change · f < tol`` (f = :func:`error_factor`, or 1 with
    ``contraction=False``, the plain test on the change) holds after about
    log(tol / (change f)) / log ρ more iterations; infinitely many if the change did not
    shrink; 0 without a previous change (``previous = inf``), which is not yet evidence of
    slow convergence.
    """
    if not np.isfinite(previous):
        return 0.0
    ratio = change / previous
    if ratio >= 1:
        return np.inf
    factor = error_factor(change, previous) if contraction else 1.0
    if change * factor <= tol:
        return 0.0
    return float(np.log(tol / (change * factor)) / np.log(ratio))


def _newton_switch(iteration: AlternatingMinimization, solver: SolverParameters) -> NewtonSwitch:
    """Return Newton steps around ``iteration``, aimed at the loop's stopping test."""
    return NewtonSwitch(
        iteration, solver.newton_switch, solver.am_tol, solver.am_stop == "contraction"
    )


STRATEGIES: dict[str, Callable[[SolverParameters], NonlinearStrategy]] = {
    "am": lambda solver: AlternatingMinimization(),
    "overrelaxed": lambda solver: OverRelaxed(solver.omega),
    "anderson": lambda solver: Anderson(solver.anderson_depth),
    "newton": lambda solver: _newton_switch(AlternatingMinimization(), solver),
    "anderson-newton": lambda solver: _newton_switch(Anderson(solver.anderson_depth), solver),
}
"""The strategy of each name of :data:`ngat.parameters.NONLINEAR_SOLVERS`, made from the
solver parameters."""


def nonlinear_strategy(solver: SolverParameters) -> NonlinearStrategy:
    """Return a new strategy for ``solver.nonlinear`` (:data:`STRATEGIES`)."""
    return STRATEGIES[solver.nonlinear](solver)
