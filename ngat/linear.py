"""Linear solves of the half-steps: sparse Cholesky, refreshed only when it stops paying.

Between two alternating-minimisation iterations the matrices of a_j and b_j change only where v
or ∇u changed, and less and less as the iteration converges. :class:`LaggedCholesky` therefore
keeps the last numeric factorisation as a preconditioner for conjugate gradients on the current
matrix; when CG needs more than ``max_cg`` iterations, the factorisation is refreshed with
``Inverse.Update()`` (same graph and free DOFs: the ordering and symbolic analysis are reused)
and the system is solved directly. With ``max_cg = 0`` every solve refactorises.
"""

from __future__ import annotations

import numpy as np
from ngsolve import BitArray
from ngsolve.krylovspace import CGSolver
from ngsolve.la import BaseVector, SparseMatrixd

__all__ = ["LaggedCholesky"]


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
    """

    def __init__(self, matrix: SparseMatrixd, free: np.ndarray, max_cg: int, tol: float = 1e-10):
        self.matrix = matrix
        self.free = free.copy()
        self.inverse = matrix.Inverse(BitArray(free), inverse="sparsecholesky")
        # The values behind the factorisation: a checkpoint keeps them (ngat.checkpoint).
        self.factored_values = matrix.AsVector().FV().NumPy().copy()
        self.max_cg = max_cg
        self.tol = tol
        self.stale = False
        self.factorizations = 1
        self.cg_iterations = 0

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
        if self.stale:
            self.inverse.Update()
            self.factored_values = self.matrix.AsVector().FV().NumPy().copy()
            self.factorizations += 1
            self.stale = False
        out.data = self.inverse * rhs
