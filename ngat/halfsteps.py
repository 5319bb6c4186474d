"""The two half-steps of Algorithm 1 on an :class:`ngat.state.ATState`, with their linear solvers.

The u-step minimises I_j(·, v) over g(t_k) + X_{j,D}, the v-step I_j(u, ·) over X_{j,CR} with
0 ≤ v ≤ 1 (paper, Algorithm 1, steps 2.1 and 2.2). :class:`HalfStepSolvers` keeps the matrices
of a_j and b_j of the state's current mesh (:class:`ngat.operators.LumpedOperators`, rewritten in
place at every half-step) and solves with :mod:`ngat.linear`: per mesh, a sparse
Cholesky factorisation refreshed with ``Inverse.Update()``, which keeps the symbolic analysis,
or, with ``linear_solver="cg-h1amg"``, CG with a rebuilt h1amg preconditioner (one per
component of a vector u, :meth:`HalfStepSolvers._amg_forms`). It owns what
outlives a solve — the factorisations, which a checkpoint keeps (:meth:`solver_state`) — and
counts the solves (:class:`LinearStatistics`); the state holds the mesh and the fields only.

A module of its own rather than a part of :mod:`ngat.linear`: that module solves a linear
system whatever it comes from, this one knows the half-steps' minimisation problems — the
semismooth Newton u-step of an energy split and the active set of the bounded v-step.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from ngsolve import H1, BilinearForm

from ngat.forms import a_form, b_form
from ngat.linear import AMGConjugateGradient, HeldCholesky, LaggedCholesky
from ngat.operators import LumpedOperators
from ngat.parameters import SolverParameters
from ngat.state import ATState

__all__ = ["HalfStepSolvers", "LinearStatistics"]

log = logging.getLogger(__name__)

SLOTS = {"u": 1, "v": 2, "held": 3}
"""Slot of each solver in the one symbolic analysis a mesh's solvers share
(:meth:`HalfStepSolvers._shared_analysis`; :data:`ngat.pardiso.SLOTS` of them)."""

SPLIT_STEP_TOL = 1e-10
"""Newton step, relative to max |u|, below which the u-step of a split whose energy is not
piecewise quadratic (``spectral``) has converged: Newton converges quadratically there, and
the step of round-off (1e−16 times the condition of a_j) stays well below it."""


@dataclass
class LinearStatistics:
    """Linear solves of the half-steps since :meth:`HalfStepSolvers.start`.

    Attributes
    ----------
    solves
        Linear systems solved (each with a new matrix or a lagged factorisation).
    cg_iterations
        CG iterations of every ``cg-h1amg`` solve.
    cg_not_converged
        ``cg-h1amg`` solves that stopped at the iteration cap above the tolerance.
    """

    solves: int = 0
    cg_iterations: list[int] = field(default_factory=list)
    cg_not_converged: int = 0


class HalfStepSolvers:
    """The u-step and the v-step of an :class:`~ngat.state.ATState` with their linear solvers.

    Per mesh of the state, the operators, solvers and work vectors are made on first use; a
    refinement (a new ``state.arrays``) drops them.

    Parameters
    ----------
    state
        Mesh and fields.
    max_cg
        CG iterations accepted with a stale Cholesky factor before it is refreshed
        (:class:`ngat.linear.LaggedCholesky`); 0 refactorises at every solve.
    bounded_v
        Minimise the v-step over 0 ≤ v ≤ 1 (see :meth:`solve_v`); ``False`` solves the
        unconstrained linear system only (the paper's v-step, exact under Hypothesis A).
    linear_solver
        ``"direct"``: sparse Cholesky (:class:`ngat.linear.LaggedCholesky`); ``"cg-h1amg"``:
        CG with NGSolve's h1amg preconditioner (:class:`ngat.linear.AMGConjugateGradient`).

    Attributes
    ----------
    statistics : LinearStatistics
        The solves since the last :meth:`start`.
    """

    def __init__(
        self,
        state: ATState,
        max_cg: int = 0,
        bounded_v: bool = True,
        linear_solver: str = "direct",
    ):
        self.state = state
        self.max_cg = max_cg
        self.bounded_v = bounded_v
        self.linear_solver = linear_solver
        self.statistics = LinearStatistics()
        self._arrays = None
        self._on_mesh()

    @classmethod
    def from_parameters(cls, state: ATState, solver: SolverParameters) -> HalfStepSolvers:
        """Return the solvers set by ``solver.max_cg``, ``bounded_v`` and ``linear_solver``."""
        return cls(state, solver.max_cg, solver.bounded_v, solver.linear_solver)

    def start(self) -> None:
        """Begin a load step: the statistics count from zero."""
        self.statistics = LinearStatistics()

    @property
    def bound_active(self) -> int:
        """DOFs held at a bound of v by the last v-step on the current mesh (0 before one)."""
        return self._bound_active if self._arrays is self.state.arrays else 0

    @property
    def operators(self) -> LumpedOperators:
        """The matrices of a_j and b_j on the state's current mesh."""
        self._on_mesh()
        return self._operators

    def _on_mesh(self) -> None:
        """Replace the operators, solvers and work vectors of an earlier mesh of the state."""
        state = self.state
        if self._arrays is state.arrays:
            return
        self._arrays = state.arrays
        self._operators = operators = LumpedOperators(state)
        state.start_edges()  # the estimators' edge topology, in the background after METIS
        self._a_solver: LaggedCholesky | AMGConjugateGradient | None = None
        self._b_solver: LaggedCholesky | AMGConjugateGradient | None = None
        self._residual = operators.a_matrix.CreateColVector()
        self._correction = operators.a_matrix.CreateColVector()
        self._v_residual = operators.b_matrix.CreateColVector()
        self._v_step = operators.b_matrix.CreateColVector()
        self._bound_active = 0
        self._prepared: dict[str, tuple] = {}  # by prepare_u and prepare_v: mesh, inputs

    # -- u-step -----------------------------------------------------------------------------
    def solve_u(self, max_iterations: int = 50) -> None:
        """u-step: minimise I_j(·, v) over g(t_k) + X_{j,D} (Algorithm 1, step 2.1).

        Without an energy split this is one linear solve. With one, I_j(·, v) is convex and
        C¹, and a semismooth Newton method minimises it: solve with the element matrices of
        the current pattern (:meth:`ngat.elasticity.Elasticity.tension`), halve the step while
        the energy would rise. Where the energy is quadratic on each piece of the pattern
        (``voldev``: the volumetric part of an element degrades only in tension) it stops when
        a full step keeps the pattern (the minimiser of that piece is then the minimiser);
        otherwise (``spectral``) when the step is below :data:`SPLIT_STEP_TOL` relative to u.
        """
        state, operators = self.state, self.operators
        u = state.u_values
        prepared = self._claim("u", state.v_values)
        for _ in range(max_iterations):
            tension = state.elasticity.tension(state.arrays, u)
            if not prepared:
                with state.timer("assembly"):
                    operators.assemble_a()
            with state.timer("solve"):
                if not prepared:
                    self._a_solver = self._refreshed(self._a_solver, "u", ~state.dirichlet)
                prepared = False
                self._residual.data = -1 * (operators.a_matrix * state.u.vec)
                self._solve(self._a_solver)
            if tension is None:
                state.u.vec.data += self._correction
                return
            step = self._correction.FV().NumPy().copy()
            if self._split_step(step, tension):
                return
        log.warning("split u-step: not converged after %d Newton iterations", max_iterations)

    def prepare_u(self, v: np.ndarray | None = None) -> None:
        """Assemble the next u-step's a_j(v) and start factorising it; return at once.

        As :meth:`prepare_v`: the factorisation runs on while the caller computes ν, the crack
        band and the energies of the v-step just solved, and :meth:`solve_u` on the same mesh
        and v uses it. ``v``: the v the next u-step will start from if not the current one (the
        next load step's prediction, prepared while the driver writes this step's results).
        Without an energy split only (with one, a_j depends on u's pattern).
        """
        state = self.state
        if (
            self.linear_solver != "direct"
            or state.elasticity.tension(state.arrays, state.u_values) is not None
        ):
            return
        v = state.v_values if v is None else v
        with state.timer("assembly"):
            self.operators.assemble_a(v)
        with state.timer("solve"):
            self._a_solver = self._refreshed(self._a_solver, "u", ~state.dirichlet, True)
            self._a_solver.refresh(background=True)
        self._prepared["u"] = (state.arrays, v.copy())

    def _claim(self, stage: str, *inputs: np.ndarray) -> bool:
        """Return whether the ``stage``'s matrix was prepared on this mesh from these inputs.

        The preparation is forgotten either way: it serves one half-step at most.
        """
        prepared = self._prepared.pop(stage, None)
        if prepared is None or prepared[0] is not self.state.arrays:
            return False
        return all(np.array_equal(a, b) for a, b in zip(prepared[1:], inputs, strict=True))

    def _split_step(self, step: np.ndarray, tension: np.ndarray) -> bool:
        """Move u along a semismooth Newton step; return whether the u-step has converged."""
        state = self.state
        u = state.u_values
        trial = u + step
        elasticity = state.elasticity
        if elasticity.piecewise_quadratic and np.array_equal(
            elasticity.tension(state.arrays, trial), tension
        ):
            # The full step minimises the quadratic piece of the pattern it keeps: it lowers
            # the energy and is the minimiser, no energy evaluation needed.
            u[:] = trial
            return True
        functional, arrays = state.functional, state.arrays
        c = functional.coefficient(arrays, state.v_values)
        start, scale = functional.bulk(arrays, u, c), 1.0
        while functional.bulk(arrays, trial, c) > start and scale > 2.0**-29:
            scale /= 2
            trial = u + scale * step
        u[:] = trial
        tol = 1e-14 if elasticity.piecewise_quadratic else SPLIT_STEP_TOL
        return np.abs(scale * step).max() <= tol * np.abs(u).max()

    # -- v-step -----------------------------------------------------------------------------
    def solve_v(self, crack: np.ndarray) -> None:
        """v-step: minimise I_j(u, ·) over X_{j,CR} with 0 ≤ v ≤ 1 (Algorithm 1, step 2.2).

        Under Hypothesis A (non-positive off-diagonals of the stiffness matrix) the
        unconstrained minimiser already lies in [0, 1] (Proposition 3) and one linear solve is
        all. Bisection refinement creates obtuse angles that violate Hypothesis A, and then the
        unconstrained solution can dip below 0 by up to ~1e−4 next to the crack. The v-step
        therefore minimises over [0, 1] (the domain of I_ε in eq. 2), with a primal-dual
        active set that only runs when the unconstrained solution leaves the bounds;
        :attr:`bound_active` counts the DOFs held at a bound. With pointwise irreversibility
        the upper bound is v(t_{k−1}) (eq. 3) and the active set always runs.

        Parameters
        ----------
        crack
            Boolean DOF mask of CR(t_k), where v is fixed to 0.
        """
        state = self.state
        direct = self.linear_solver == "direct"
        if not self._claim("v", state.u_values, crack):
            self._assemble_v(crack)
            with state.timer("solve"):
                factorised = np.ones_like(crack) if direct else ~crack
                self._b_solver = self._refreshed(self._b_solver, "v", factorised)
        state.v_values[crack] = 0.0
        with state.timer("solve"):
            free = ~crack
            self._v_correction(self._b_solver, crack)
            if state.model.irreversibility == "pointwise":
                upper = state.v_prev.vec.FV().NumPy().copy()
                self._bound_active = self._enforce_bounds(free, upper)
            elif self.bounded_v:
                self._bound_active = self._enforce_bounds(free, 1.0)

    def prepare_v(self, crack: np.ndarray) -> None:
        """Assemble the next v-step's b_j(u) and start factorising it; return at once.

        The factorisation runs in the background (:meth:`ngat.linear.LaggedCholesky.refresh`)
        while the caller computes on — μ of the u-step just solved (Algorithm 2, step 2.1) —
        and :meth:`solve_v` on the same mesh, u and CR uses it; any other v-step assembles
        anew. The direct solver only; the numbers are those of :meth:`solve_v` alone.
        """
        if self.linear_solver != "direct":
            return
        self._assemble_v(crack)
        with self.state.timer("solve"):
            self._b_solver = self._refreshed(self._b_solver, "v", np.ones_like(crack), True)
            self._b_solver.refresh(background=True)
        self._prepared["v"] = (self.state.arrays, self.state.u_values.copy(), crack.copy())

    def _assemble_v(self, crack: np.ndarray) -> None:
        """Write b_j(u)'s values; the direct solver's with CR decoupled (identity-like rows).

        Decoupled, the crack's DOFs stay in the factorisation: its ordering serves every
        v-step on the mesh however CR grows.
        """
        direct = self.linear_solver == "direct"
        with self.state.timer("assembly"):
            self.operators.assemble_b(crack if direct else None)

    def _v_correction(
        self,
        solver: LaggedCholesky | AMGConjugateGradient | HeldCholesky,
        fixed: np.ndarray | None = None,
    ) -> None:
        """Add the solution of B δ = f m − B v on the solver's free DOFs to v (f = α for AT2).

        ``fixed``: DOFs the solver factorised though v stays there (CR, decoupled in B); the
        right-hand side is 0 on them, and so is δ.
        """
        state = self.state
        self._v_residual.FV().NumPy()[:] = state.model.surface.source * state.arrays.mass
        self._v_residual.data -= self._operators.b_matrix * state.v.vec
        if fixed is not None:
            self._v_residual.FV().NumPy()[fixed] = 0.0
        self._solve(solver, "v")
        state.v.vec.data += self._v_step

    def _enforce_bounds(self, free: np.ndarray, upper, max_sweeps: int = 50) -> int:
        """Primal-dual active set for 0 ≤ v ≤ upper on the free DOFs; return the active count.

        Each sweep solves on the DOFs off the active set: with the direct solver, up to
        :attr:`HeldCholesky.MAX_HELD` active DOFs are held by the capacitance matrix of the
        v-step's factorisation, more get a factorisation of their own (of the 69 bounded
        v-steps of the default ``two-slits`` run, 65 start with 3–6 active DOFs, 3 with 13–15).
        """
        state, operators = self.state, self._operators
        v = state.v_values
        round_off = 1e-12
        low = free & (v < -round_off)
        high = free & (v > upper + round_off)
        if not (low.any() or high.any()):
            return 0
        for _ in range(max_sweeps):
            v[low] = 0.0
            v[high] = upper[high] if np.ndim(upper) else upper
            inactive = free & ~low & ~high
            if self.linear_solver == "cg-h1amg":
                self._b_solver = self._refreshed(self._b_solver, "v", inactive)
                self._v_correction(self._b_solver)
            elif (free & ~inactive).sum() <= HeldCholesky.MAX_HELD:
                self._v_correction(HeldCholesky(self._b_solver, inactive, decoupled=~free))
            else:
                held = LaggedCholesky(
                    operators.b_matrix, inactive, 0, ordering=operators.ordering,
                    **self._shared_analysis("held"),
                )  # fmt: skip
                self._v_correction(held)
            self._v_residual.FV().NumPy()[:] = state.model.surface.source * state.arrays.mass
            self._v_residual.data -= operators.b_matrix * state.v.vec
            gradient = -self._v_residual.FV().NumPy()  # ∂I_j/∂v_i up to the factor 2
            new_low = free & ((low & (gradient > 0)) | (~high & (v < -round_off)))
            new_high = free & ((high & (gradient < 0)) | (~low & (v > upper + round_off)))
            if np.array_equal(new_low, low) and np.array_equal(new_high, high):
                break
            low, high = new_low, new_high
        else:
            log.warning("bounded v-step: active set not settled after %d sweeps", max_sweeps)
        return int(low.sum() + high.sum())

    # -- linear solves ----------------------------------------------------------------------
    def _refreshed(
        self,
        solver: LaggedCholesky | AMGConjugateGradient | None,
        stage: str,
        free: np.ndarray,
        background: bool = False,
    ) -> LaggedCholesky | AMGConjugateGradient:
        """Return a solver of the ``stage``'s matrix (``"u"``: a_j, ``"v"``: b_j) on ``free``.

        Call after rewriting the matrix values. A Cholesky factorisation is kept while the free
        DOFs stay the same; the CG solver keeps its form and preconditioner per mesh. A new
        Cholesky solver is analysed and factorised in the ``background`` if asked.
        """
        operators = self._operators
        matrix = operators.a_matrix if stage == "u" else operators.b_matrix
        if self.linear_solver == "cg-h1amg":
            if solver is None:
                return AMGConjugateGradient(self._amg_forms(stage), matrix, free)
            solver.values_changed(free)
            return solver
        if solver is None or not np.array_equal(free, solver.free):
            return LaggedCholesky(
                matrix, free, self.max_cg, ordering=operators.ordering, background=background,
                **self._shared_analysis(stage),
            )  # fmt: skip
        solver.values_changed()
        return solver

    def _shared_analysis(self, stage: str) -> dict:
        """Return the solver whose analysis a new one of ``stage`` shares, and its slot.

        ``stage``: ``"u"`` (a_j), ``"v"`` (b_j) or ``"held"`` (b_j on the bounded v-step's
        inactive DOFs). b_j's graph is a_j's when u is scalar: one symbolic analysis per mesh
        then serves all three, each factorised into a slot of its own
        (:class:`ngat.pardiso.PardisoInverse`); the same bits as an analysis each.
        """
        scalar = self.state.elasticity.components == 1
        candidates = {
            "u": [self._a_solver] + [self._b_solver] * scalar,
            "v": [self._b_solver] + [self._a_solver] * scalar,
            "held": [self._b_solver],
        }[stage]
        analysis = next((c for c in candidates if isinstance(c, LaggedCholesky)), None)
        return {"analysis": analysis, "slot": SLOTS[stage]}

    def _amg_forms(self, stage: str) -> list[BilinearForm]:
        """Return the forms h1amg is built on: b_j, or a_j's block of each component of u.

        Each on a P1 space of its own: the solver overwrites its free DOFs.
        """
        state = self.state
        density = state.elasticity

        def space():
            return H1(state.mesh, order=1, autoupdate=False)

        if stage == "v":
            surface, gc = state.model.surface, state.model.gc
            return [b_form(space(), state.u, surface, bilinear=density.bilinear, gc=gc)]
        blocks = [partial(density.component_bilinear, i) for i in range(density.components)]
        return [a_form(space(), state.v, state.model.eta, bilinear=block) for block in blocks]

    def _solve(self, solver: LaggedCholesky | AMGConjugateGradient, stage: str = "u") -> None:
        """Set the stage's correction to the solution of the system with its residual."""
        if stage == "u":
            solver.solve(self._residual, self._correction)
        else:
            solver.solve(self._v_residual, self._v_step)
        self.statistics.solves += 1
        if isinstance(solver, AMGConjugateGradient):
            self.statistics.cg_iterations.append(solver.iterations)
            self.statistics.cg_not_converged += not solver.converged

    # -- checkpoints ------------------------------------------------------------------------
    def solver_state(self) -> dict[str, np.ndarray]:
        """Return the matrix values behind each lagged factorisation and the v-step's free DOFs.

        With ``max_cg > 0`` a factorisation outlives its load step; a resumed run rebuilds it
        from these values to repeat the uninterrupted run exactly (:mod:`ngat.checkpoint`).
        The ``cg-h1amg`` solver keeps nothing between solves but its per-mesh form.
        """
        self._on_mesh()
        saved = {}
        if self.linear_solver != "direct":
            return saved
        if self._a_solver is not None:
            saved["a_factored"] = self._a_solver.factored_values
        if self._b_solver is not None:
            saved["b_factored"] = self._b_solver.factored_values
            saved["b_free"] = self._b_solver.free
        return saved

    def restore_solver_state(self, saved: Mapping[str, np.ndarray]) -> None:
        """Rebuild the lagged factorisations from :meth:`solver_state`.

        The next solve rewrites the matrix values and so starts from a stale factorisation, as
        it would have in the uninterrupted run.
        """
        state, operators = self.state, self.operators
        if "a_factored" in saved:
            operators.set_a_values(saved["a_factored"])
            self._a_solver = LaggedCholesky(
                operators.a_matrix, ~state.dirichlet, self.max_cg, ordering=operators.ordering,
                **self._shared_analysis("u"),
            )  # fmt: skip
        if "b_factored" in saved:
            operators.b_matrix.AsVector().FV().NumPy()[:] = saved["b_factored"]
            self._b_solver = LaggedCholesky(
                operators.b_matrix, saved["b_free"], self.max_cg, ordering=operators.ordering,
                **self._shared_analysis("v"),
            )  # fmt: skip
