"""Linear solvers of one matrix: a sparse direct factorisation, or CG with NGSolve's h1amg.

The factorisation is :func:`ngat.pardiso.sparse_inverse`'s: MKL PARDISO, or NGSolve's sparse
Cholesky where MKL is not installed.

Between two alternating-minimisation iterations the matrices of a_j and b_j change only where v
or ∇u changed, and less and less as the iteration converges. :class:`LaggedCholesky` therefore
keeps the last numeric factorisation as a preconditioner for conjugate gradients on the current
matrix; when CG needs more than ``max_cg`` iterations, the factorisation is refreshed with
``Inverse.Update()`` (same graph and free DOFs: the ordering and symbolic analysis are reused)
and the system is solved directly. With ``max_cg = 0`` every solve refactorises.
:class:`HeldCholesky` solves with a few more DOFs held by the factorisation at hand (the bounded
v-step's active set), where a factorisation of its own would need a new ordering.

:class:`AMGConjugateGradient` is the iterative alternative (``linear_solver="cg-h1amg"``): CG
preconditioned by NGSolve's algebraic multigrid ``h1amg``, rebuilt for every new matrix. The
h1amg preconditioner coarsens by weights computed from the element matrices, which it only sees
during ``BilinearForm.Assemble()``, and it takes its free DOFs from the form's space; so each
refresh writes the free DOFs into a P1 space reserved for the solver and assembles the form.
h1amg accepts scalar spaces only: a vector u-step is preconditioned block by block, one h1amg
per component on the diagonal block of its operator (block Jacobi; by Korn's inequality the
block diagonal is spectrally equivalent to the whole elasticity operator).
Which solver serves which half-step, and when, is :class:`ngat.halfsteps.HalfStepSolvers`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from ngsolve import BilinearForm, BitArray, IntRange, Preconditioner
from ngsolve.krylovspace import CGSolver
from ngsolve.la import BaseMatrix, BaseVector, Embedding, SparseMatrixd

from ngat.pardiso import PardisoInverse, sparse_inverse

__all__ = ["LaggedCholesky", "HeldCholesky", "AMGConjugateGradient"]

log = logging.getLogger(__name__)


class LaggedCholesky:
    """Solve A x = b on the free DOFs while the values of A change in place.

    Parameters
    ----------
    matrix
        Sparse matrix whose values the caller rewrites between solves.
    free
        Boolean mask of the free DOFs (fixed for the lifetime of the object).
    max_cg
        Largest number of CG iterations accepted with a stale factorisation.
    tol
        Relative residual reduction required from CG.
    ordering
        Fill-reducing ordering of the mesh's vertices (:func:`ngat.pardiso.sparse_inverse`).
    background
        Factorise in the background (:meth:`refresh`).
    analysis, slot
        A solver of a matrix with the same graph whose symbolic analysis this one shares, and
        the slot of that analysis it factorises into (:class:`ngat.pardiso.PardisoInverse`).
    """

    def __init__(
        self,
        matrix: SparseMatrixd,
        free: np.ndarray,
        max_cg: int,
        tol: float = 1e-10,
        ordering: np.ndarray | None = None,
        background: bool = False,
        analysis: LaggedCholesky | None = None,
        slot: int = 1,
    ):
        self.matrix = matrix
        self.free = free.copy()
        self.inverse = sparse_inverse(
            matrix, free, ordering=ordering, background=background,
            analysis=analysis.inverse if analysis else None, slot=slot,
        )  # fmt: skip
        self.max_cg = max_cg
        self._factored = self._values_to_keep()
        self.tol = tol
        self.stale = False
        self.factorizations = 1
        self.cg_iterations = 0

    def _values_to_keep(self) -> np.ndarray | None:
        """Return a copy of the values just factorised if a stale solve may use them (CG)."""
        return self.matrix.AsVector().FV().NumPy().copy() if self.max_cg > 0 else None

    @property
    def factored_values(self) -> np.ndarray:
        """The values behind the factorisation, which a checkpoint keeps (ngat.checkpoint).

        With ``max_cg = 0`` a solve after new values always refactorises first, so the
        factorisation's own values never act again and the matrix's current ones serve (not
        copied at every refactorisation: a megabyte-sized copy, a thousand times a run).
        """
        if self._factored is not None:
            return self._factored
        return self.matrix.AsVector().FV().NumPy().copy()

    def values_changed(self) -> None:
        """Note that the caller rewrote the matrix values."""
        self.stale = True

    def solve(self, rhs: BaseVector, out: BaseVector) -> None:
        """Set ``out`` to A⁻¹ rhs on the free DOFs (0 elsewhere)."""
        if self.stale and self.max_cg > 0:
            cg = CGSolver(self.matrix, self.inverse, tol=self.tol, maxiter=self.max_cg)
            out[:] = 0.0
            cg.Solve(rhs, out)
            self.cg_iterations += cg.iterations
            if cg.iterations < self.max_cg:
                return
        self.refresh()
        out.data = self.inverse * rhs

    def refresh(self, background: bool = False) -> None:
        """Refactorise with the current values if they changed since the last factorisation.

        ``background``: with PARDISO the factorisation runs on while the caller computes, and
        the next solve waits for it (:meth:`ngat.pardiso.Pardiso.factorise`).
        """
        if self.stale:
            if isinstance(self.inverse, PardisoInverse):
                self.inverse.Update(background)
            else:
                self.inverse.Update()
            self._factored = self._values_to_keep()
            self.factorizations += 1
            self.stale = False


class HeldCholesky:
    """Solve A x = b with a few of a :class:`LaggedCholesky`'s free DOFs held at 0.

    A new free set needs a new factorisation, symbolic analysis included (several times a numeric
    refactorisation). Where only a few DOFs S of the factorised set F are held (the bounded v-step's
    active set, usually a handful of vertices next to the crack), the capacitance matrix gives the
    solution on I = F − S exactly from the factorisation at hand: with y = A_FF⁻¹ b̃ (b on I, 0 on
    S) and the columns W = A_FF⁻¹ E_S of the held DOFs,

        x = y − W (W_SS)⁻¹ y_S

    satisfies A_II x_I = b_I and x_S = 0 (W_SS, a principal block of the inverse of an SPD
    matrix, is SPD). Cost: |S| + 1 back-substitutions.

    Parameters
    ----------
    base
        The factorisation of A on F (refactorised first if its values are stale).
    free
        The free DOFs I, a subset of ``base.free``.
    decoupled
        DOFs of F whose rows and columns of A hold the diagonal only (the v-step's crack
        set): with the right-hand side 0 there the solution is 0 there, nothing to hold.
    """

    MAX_HELD = 10
    """Most held DOFs worth |S| back-substitutions instead of a new factorisation."""

    def __init__(self, base: LaggedCholesky, free: np.ndarray, decoupled: np.ndarray | None = None):
        base.refresh()
        self.base = base
        self.free = free.copy()
        held = base.free & ~free
        if decoupled is not None:
            held &= ~decoupled
        self.held = np.flatnonzero(held)
        self._rhs = base.matrix.CreateColVector()
        self._out = base.matrix.CreateColVector()
        columns = []
        for index in self.held:
            self._rhs[:] = 0.0
            self._rhs.FV().NumPy()[index] = 1.0
            self._out.data = base.inverse * self._rhs
            columns.append(self._out.FV().NumPy().copy())
        self.columns = np.column_stack(columns) if columns else np.empty((len(free), 0))
        self.capacitance = self.columns[self.held]

    def solve(self, rhs: BaseVector, out: BaseVector) -> None:
        """Set ``out`` to the solution on the free DOFs (0 elsewhere)."""
        self._rhs.FV().NumPy()[:] = np.where(self.free, rhs.FV().NumPy(), 0.0)
        self._out.data = self.base.inverse * self._rhs
        y = self._out.FV().NumPy()
        if len(self.held):
            y = y - self.columns @ np.linalg.solve(self.capacitance, y[self.held])
        out.FV().NumPy()[:] = np.where(self.free, y, 0.0)


class AMGConjugateGradient:
    """Solve A x = b on the free DOFs by CG preconditioned with NGSolve's ``h1amg``.

    CG runs on ``matrix`` (the values the caller writes with :class:`ngat.forms.LumpedAssembler`,
    the same operator as the direct solver's); the preconditioner is built on the NGSolve
    assembly of ``forms``: one form equals the matrix to round-off (``tests/test_forms.py``);
    several are the diagonal blocks of a vector operator, one per component (DOFs blocked by
    component, as in ``VectorH1``), each with its own h1amg. A solve that
    stops at ``maxiter`` before reducing the preconditioned residual by ``tol`` keeps its last
    iterate, logs a warning and sets :attr:`converged` to ``False``; the half-step solvers count
    such solves (:class:`ngat.halfsteps.LinearStatistics`) and the run's diagnostics report them
    as ``linear-not-converged`` (:mod:`ngat.diagnostics`).

    Parameters
    ----------
    forms
        Bilinear forms of A (one) or of its diagonal blocks (one per component), each on a P1
        space reserved for this solver: their free DOFs are overwritten at every refresh. Their
        coefficients must follow the caller's fields, so that ``Assemble()`` gives the
        current values.
    matrix
        Sparse matrix of A, values rewritten by the caller between solves.
    free
        Boolean mask of the free DOFs.
    tol
        Reduction of the preconditioned residual norm √(rᵀPr) required from CG.
    maxiter
        CG iteration cap per solve.

    Attributes
    ----------
    iterations : int
        CG iterations of the last solve.
    converged : bool
        Whether the last solve reached the tolerance.
    """

    def __init__(
        self,
        forms: Sequence[BilinearForm],
        matrix: SparseMatrixd,
        free: np.ndarray,
        tol: float = 1e-10,
        maxiter: int = 2000,
    ):
        self.forms = list(forms)
        self.matrix = matrix
        # Registered before the first Assemble(), which builds them; composed after it.
        self.blocks = [Preconditioner(form, "h1amg") for form in self.forms]
        self.preconditioner: BaseMatrix | None = None
        self.free = free.copy()
        self.tol = tol
        self.maxiter = maxiter
        self.stale = True
        self.iterations = 0
        self.converged = True

    def values_changed(self, free: np.ndarray | None = None) -> None:
        """Note that the caller rewrote the matrix values (and, if given, the free DOFs)."""
        if free is not None:
            self.free = free.copy()
        self.stale = True

    def _compose(self) -> BaseMatrix:
        """Return the h1amg of one form, or Σᵢ Eᵢ Pᵢ Eᵢᵀ over the component blocks."""
        if len(self.blocks) == 1:
            return self.blocks[0]
        start, total = 0, None
        for form, block in zip(self.forms, self.blocks, strict=True):
            n = form.space.ndof
            embedding = Embedding(self.matrix.height, IntRange(start, start + n))
            term = embedding @ block @ embedding.T
            total = term if total is None else total + term
            start += n
        return total

    def _rebuild(self) -> None:
        """Write the free DOFs into the forms' spaces and assemble: h1amg is built anew."""
        start = 0
        for form in self.forms:
            n = form.space.ndof
            freedofs = form.space.FreeDofs()
            freedofs.Set()
            freedofs &= BitArray(self.free[start : start + n])
            form.Assemble()
            start += n
        if self.preconditioner is None:
            self.preconditioner = self._compose()
        self.stale = False

    def solve(self, rhs: BaseVector, out: BaseVector) -> None:
        """Set ``out`` to A⁻¹ rhs on the free DOFs (0 elsewhere), starting CG from 0."""
        if self.stale:
            self._rebuild()
        # NGSolve's CGSolver counts the initial residual as an iteration.
        cg = CGSolver(self.matrix, self.preconditioner, tol=self.tol, maxiter=self.maxiter + 1)
        cg.Solve(rhs, out)
        first, last = cg.residuals[0], cg.residuals[-1]
        self.iterations = len(cg.residuals) - 1
        self.converged = last <= self.tol * first
        if not self.converged:
            log.warning(
                "CG with h1amg stopped at %d iterations with relative residual %.3g > %.0e "
                "(%d free DOFs)",
                self.iterations, last / first, self.tol, int(self.free.sum()),
            )  # fmt: skip
