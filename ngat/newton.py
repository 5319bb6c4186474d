"""Newton's method on the coupled (u, v) system of one load step, with an energy line search.

I_j(u, v) of eq. (7) is a polynomial in the nodal values; its gradient and Hessian are exact
(:class:`ngat.functional.LumpedFunctional`, which also states I_j as an NGSolve energy, the
definition the tests check them against) and, unlike alternating minimisation, Newton sees the
coupling block ∂²I_j/∂u∂v. This module writes the Hessian into one sparse matrix per mesh (the
blocks that are fixed element matrices times weights by a product per mesh, the others by a
scatter of their element blocks) and solves with it.

A Newton step solves H δ = −∇I_j with u fixed on Ω_D and v fixed on CR(t_k) and on the bounds
where the gradient pushes v out of [0, 1] (a projected Newton method), then backtracks along
P(w + s δ), s = 1, ½, ¼, … until I_j decreases by the Armijo condition. Away from a minimiser
the Hessian may be indefinite and δ no descent direction: the step is then rejected and the
caller continues with alternating minimisation, so Newton starts from an
alternating-minimisation iterate (:class:`ngat.strategies.NewtonSwitch`).

Newton is attracted by saddles of I_j as much as by minimisers, and the quasi-static path
passes near saddles exactly where the crack is about to move. Before a Newton step,
:meth:`NewtonSolver.negative_curvature` therefore looks for negative curvature with a few
Lanczos steps on H⁻¹ and, if it finds some, the step follows it instead (as alternating
minimisation, a descent method, eventually does). MKL PARDISO's factorisation of H counts its
negative eigenvalues (:mod:`ngat.pardiso`); where it counts none, no search can find any and
none is made.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.linalg import eigh_tridiagonal
from scipy.sparse import csc_matrix

from ngat.halfsteps import HalfStepSolvers
from ngat.parameters import ParameterError
from ngat.pardiso import dof_ordering, symmetric_factor
from ngat.state import ATState

__all__ = ["NewtonSolver"]

log = logging.getLogger(__name__)


class NewtonSolver:
    """Projected Newton steps on I_j(u, v) for the current mesh of an :class:`ATState`.

    The Hessian's graph (the P1 graph, four blocks) and the symbolic part of its sparse
    factorisation are built once per mesh; every step writes the values in place. Fixed DOFs
    get identity rows, so the graph and the factorisation's free set never change.

    Parameters
    ----------
    state
        Mesh, fields and model.
    half_steps
        The half-steps' solvers of ``state``, whose operators hold the P1 graph the Hessian's
        blocks are built from (:attr:`ngat.halfsteps.HalfStepSolvers.operators`); default new
        ones.
    armijo
        Sufficient-decrease constant c of I(P(w + sδ)) ≤ I(w) + c s ∇I·δ.
    max_halvings
        Backtracking steps before the Newton step is rejected.
    lanczos_steps
        Most Lanczos steps of the search for negative curvature (on the obtuse-line scene
        five missed the saddles that ten found).
    escape_size
        ‖d_v‖∞ of the first trial step along a direction d of negative curvature (the line
        search halves it until I_j falls). On the paper's example's break step, resumed six
        times from t = 1.39 (once as it is, five times with v perturbed by 1e−9 of itself),
        0.5 took 112–131 iterations (median 122) against 132–142 (136.5) with 0.1, 285–339
        linear solves against 336–383, and ended at I_j = 3.2246–3.2351 against 3.2504–3.2511
        (the converged reference: 3.2253): the longer first trial lets the cracks take the
        lower path. 1.0 gave the same steps as 0.5 in those runs.
    ritz_tol
        The search for negative curvature ends once a negative Ritz value θ has a Ritz pair
        whose residual ‖H⁻¹x − θx‖ is at most ``ritz_tol`` · |θ| (or at ``lanczos_steps``).
        Stopping at the first negative Ritz value left that residual at several |θ| (3.4 in
        ``tests/test_solvers.py``) and the break step at the mercy of round-off: where the
        value is near 0, round-off decides the step at which it appears and so the escape's
        direction. On the paper's example from t = 1.40 to the end, five draws with v
        perturbed by 1e−9 of itself (``scripts/bench_break_step.py --samples 4 --to-end``):
        127–170 iterations (median 149) and I_j(1.6) = 3.2534–3.2588 that way; with 1.0,
        122–171 (126) and 3.2443–3.2456 (the converged reference: 3.2434), 320 against 393
        solves at the median; on its quick variant 157–175 (164) against 196–233 (213). With
        0.3 all five draws took the same path, 134 iterations on the paper's example but 237
        on the quick variant; 0.1 ended at 3.2742.

    Attributes
    ----------
    certified : float
        ‖δ_v‖∞ of the last full Newton step from a point without negative curvature; a
        shorter next step skips the search (0 when there is none).
    solves : int
        Newton systems solved since the last :meth:`restart`.
    curvature_solves : int
        Further solves with a factorisation already computed, in the search for negative
        curvature (:meth:`negative_curvature`), since the last :meth:`restart`.
    values : numpy.ndarray or None
        The projected Hessian as last factorised: its entries on and above the diagonal at
        ``entry_rows``, ``entry_cols`` (``None`` if one was not finite: the solves then give
        NaN and the step is rejected).
    """

    def __init__(
        self,
        state: ATState,
        half_steps: HalfStepSolvers | None = None,
        armijo: float = 1e-4,
        max_halvings: int = 10,
        lanczos_steps: int = 10,
        escape_size: float = 0.5,
        ritz_tol: float = 1.0,
    ):
        if not state.model.lumping:
            raise ParameterError(
                "Newton steps are derived for the lumped functional (eq. 7): with lumping=false "
                "choose nonlinear=am, overrelaxed or anderson"
            )
        self.state = state
        self.half_steps = half_steps or HalfStepSolvers(state)
        self.armijo = armijo
        self.max_halvings = max_halvings
        self.lanczos_steps = lanczos_steps
        self.escape_size = escape_size
        self.ritz_tol = ritz_tol
        self.certified = 0.0
        self.solves = 0
        self.curvature_solves = 0
        self.factor = self.values = None
        self._arrays = None

    def _setup(self) -> None:
        """Build the upper triangle's graph, the scatter positions and the work arrays.

        The Hessian couples, on each element, the DOFs of u (``element_dofs`` of the model: c
        components, component-major) and of v (behind u's): every one of its (c + 1)² blocks has
        the graph G of the P1 space, whose positions of the element couplings the assembler of
        b_j already holds (:class:`ngat.operators.LumpedOperators`). PARDISO reads the entries on
        and above the diagonal in CSR (:class:`ngat.pardiso.Pardiso`), so the graph is built as
        just that, without a sparse matrix to extract it from (at 84k DOFs NGSolve's COO
        constructor and the extraction took 27–48 and 29–47 ms per mesh). Row (I, a) holds, in
        block I, the part U_a of row a of G from a on, then row a of G whole in each block
        J > I: sorted, as the rows of G are. Its entry (J, b) lies behind the row's start by
        the position of b in U_a if J = I, by |U_a| + (J − I − 1) deg(a) + the position of b in
        row a of G if J > I: each local entry's position follows by that arithmetic, without a
        search. The element matrices are symmetric; their entries on and below the diagonal go
        to the mirrored entry above it, those above to a discarded slot behind the matrix, so
        that every entry sums the same local values in the same order as a lower triangle
        would.
        """
        state = self.state
        arrays = state.arrays
        c = state.elasticity.components
        operators = self.half_steps.operators
        graph = operators.b_assembler
        _, cols_g, rowptr_g = operators.b_matrix.CSR()
        cols_g, rowptr_g = np.asarray(cols_g, dtype=np.int64), np.asarray(rowptr_g, np.int64)
        n, degree = len(rowptr_g) - 1, np.diff(rowptr_g)
        upper_g = rowptr_g[1:] - graph.diagonal  # |U_a|, the diagonal included
        components = np.arange(c + 1)
        lengths = upper_g[None, :] + (c - components)[:, None] * degree[None, :]  # (c + 1, n)
        self.indptr = np.concatenate([[0], np.cumsum(lengths)])
        self.nnz = int(self.indptr[-1])
        start = self.indptr[:-1].reshape(c + 1, n)
        rows_g = np.repeat(np.arange(n), degree)
        entries = np.arange(len(cols_g))
        in_u = entries >= graph.diagonal[rows_g]
        self.entry_cols = np.empty(self.nnz, dtype=np.int64)
        for i in range(c + 1):
            a, k = rows_g[in_u], entries[in_u]
            self.entry_cols[start[i][a] + k - graph.diagonal[a]] = i * n + cols_g[in_u]
            for j in range(i + 1, c + 1):
                row = start[i] + upper_g + (j - i - 1) * degree - rowptr_g[:-1]
                self.entry_cols[row[rows_g] + entries] = j * n + cols_g
        self.entry_rows = np.repeat(np.arange((c + 1) * n), lengths.ravel())
        self.diagonal = start.ravel()  # U_a begins with a
        el, ne = arrays.elements, arrays.ne
        # [e, i, j]: where local vertex i sits in the row of G of local vertex j (mirrored), and
        # vertex j (columns). Contiguous, so that the sums below run in one loop: broadcasting's
        # inner loops of three took three times as long.
        mirrored = np.ascontiguousarray(graph.position.reshape(ne, 3, 3).transpose(0, 2, 1))
        columns = np.broadcast_to(el[:, None, :], (ne, 3, 3)).ravel()
        above = el[:, None, :] > el[:, :, None]  # (ne, 3, 3): b > a, above the diagonal of G
        # The positions of the element blocks uu (ne, I, i, J, j), vv (ne, i, j) and
        # vu (ne, i, J, j); self.nnz where an entry is discarded.
        uu = np.empty((ne, c, 3, c, 3), dtype=np.int64)
        vv = np.empty((ne, 3, 3), dtype=np.int64)
        vu = np.empty((ne, 3, c, 3), dtype=np.int64)
        local_blocks = {(i, j): uu[:, i, :, j] for i in range(c) for j in range(c)}
        local_blocks |= {(c, j): vu[:, :, j] for j in range(c)}
        local_blocks[c, c] = vv
        for (i, j), out in local_blocks.items():  # block row i, block column j: row (j, b)
            if j > i:
                out[...] = self.nnz
                continue
            if i == j:
                row = start[j] - graph.diagonal
            else:
                row = start[j] + upper_g + (i - j - 1) * degree - rowptr_g[:-1]
            np.add(row.take(columns).reshape(ne, 3, 3), mirrored, out=out)
            if i == j:
                np.copyto(out, self.nnz, where=above)
        self._curvature = self._fixed_terms(uu.reshape(ne, -1), vv, operators.stiffness_parts)
        # The terms that change with (u, v): vv's diagonal and vu, scattered by one bincount.
        self.position = np.concatenate([np.diagonal(vv, axis1=1, axis2=2).ravel(), vu.ravel()])
        self._local = np.empty(len(self.position))
        self._terms = (
            self._local[: 3 * ne].reshape(ne, 3),
            self._local[3 * ne :].reshape(ne, 3, -1),
        )
        self.factor = None
        self.certified = 0.0
        self._arrays = arrays

    def _fixed_terms(self, uu: np.ndarray, vv: np.ndarray, parts: list[np.ndarray]) -> csc_matrix:
        """Return the matrix that maps the weights of ∂²I/∂u²'s parts to the Hessian's values.

        Column (T, k) holds the entries of the element matrix K_k,T of a_j's part k at their
        positions ``uu`` (ne, 9c²) in the graph, the discarded ones in a last row (``nnz``) that
        the product drops; a last column holds the sums of ∂²I/∂v²'s entries off the diagonal,
        which do not change (:meth:`ngat.functional.LumpedFunctional.hessian_constant`). Its
        product with the weights 2 w_k,T (:meth:`ngat.functional.LumpedFunctional.hessian_terms`)
        and 1 sums element by element, as the bincount of the scattered products would: to the
        last bit with one part (the same single products, in the same order).
        """
        ne, nnz, state = len(uu), self.nnz, self.state
        constant = state.functional.hessian_constant(state.arrays)
        constant[:, [0, 1, 2], [0, 1, 2]] = 0.0  # the diagonal is hessian_terms'
        fixed = np.bincount(vv.ravel(), weights=constant.ravel(), minlength=nnz + 1)
        # Off the diagonal, the last block row (v) holds only vv's entries: U_a less a.
        v_rows = self.diagonal[-state.arrays.nv :]
        where = np.ones(nnz - v_rows[0], dtype=bool)
        where[v_rows - v_rows[0]] = False
        where = v_rows[0] + np.flatnonzero(where)
        size = ne * len(parts) * uu.shape[1]
        entries = np.empty(size + len(where))
        rows = np.empty(len(entries), dtype=np.int64)
        for k, part in enumerate(parts):
            entries[:size].reshape(ne, len(parts), -1)[:, k] = part.reshape(ne, -1)
        rows[:size].reshape(ne, len(parts), -1)[...] = uu[:, None, :]
        entries[size:], rows[size:] = fixed[where], where
        columns = np.append(np.arange(0, size + 1, uu.shape[1]), len(entries))
        return csc_matrix((entries, rows, columns), shape=(nnz + 1, len(columns) - 1))

    def hessian_values(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Return the values of ∇²I_j at (u, v) on and above the diagonal, in the graph's order."""
        state = self.state
        # Into one buffer per mesh: a new array of this size costs its page faults every time.
        weights = state.functional.hessian_terms(state.arrays, u, v, self._terms)
        values = self._curvature @ np.append(np.stack(weights, axis=1).ravel(), 1.0)
        values = values[: self.nnz]  # the last row holds the discarded entries
        values += np.bincount(self.position, weights=self._local, minlength=self.nnz)
        return values

    def _factorise(self, crack: np.ndarray) -> tuple:
        """Assemble and factorise the projected Hessian at the state's (u, v).

        Returns
        -------
        tuple
            u, v (copies), the upper bound of v, ∇I_j and the held DOFs: u on Ω_D, v on CR(t_k)
            and where the gradient pushes v out of its bounds.
        """
        state = self.state
        if self._arrays is not state.arrays:
            with state.timer("assembly"):
                self._setup()
        u, v = state.u_values.copy(), state.v_values.copy()
        upper = state.v_prev.vec.FV().NumPy() if state.model.irreversibility == "pointwise" else 1.0
        with state.timer("assembly"):
            gradient = state.functional.gradient(state.arrays, u, v)
            g_v = gradient[len(u) :]
            held = np.concatenate(
                [state.dirichlet, crack | ((v <= 0) & (g_v > 0)) | ((v >= upper) & (g_v < 0))]
            )
            values = self.hessian_values(u, v)
            values[held[self.entry_rows] | held[self.entry_cols]] = 0.0
            values[self.diagonal[held]] = 1.0
        finite = bool(np.isfinite(values).all())  # else the solves give NaN: step rejected
        self.values = values if finite else None
        with state.timer("solve"):
            if self.factor is None:
                ordering = self.half_steps.operators.ordering  # of the vertices
                if ordering is not None:
                    ordering = dof_ordering(ordering, len(held))
                self.factor = symmetric_factor(self.indptr, self.entry_cols, False, ordering)
            if finite:
                self.factor.factorise(values)
        return u, v, upper, gradient, held

    def step(self, crack: np.ndarray, ceiling: float = np.inf) -> str:
        """Try one Newton step from the state's (u, v); return whether the state moved.

        If a few Lanczos steps find negative curvature of I_j, the step goes along that
        direction instead (:meth:`negative_curvature`): Newton's method is attracted by saddles
        as much as by minimisers, and the quasi-static path passes near saddles exactly where
        the crack is about to move, where alternating minimisation (a descent method) leaves
        along the direction of negative curvature.

        Parameters
        ----------
        crack
            Boolean DOF mask of CR(t_k), where v stays 0.
        ceiling
            The step is accepted only if I_j ends at or below this value as well (an
            accelerated iterate may lie above the last plain iterate's energy).

        Returns
        -------
        str
            ``"newton"`` or ``"escape"`` (a step along negative curvature) if the state now
            holds the new iterate; ``""`` if the direction was not a descent direction or no
            step length decreased I_j (the state is unchanged).
        """
        u, v, upper, gradient, held = self._factorise(crack)
        residual = np.where(held, 0.0, -gradient)
        if not np.any(residual):
            return ""
        with self.state.timer("solve"):
            delta = self._apply_inverse(residual)
            self.solves += 1
            size = np.max(np.abs(delta[len(u) :]))
            found = None
            if size >= self.certified and self._indefinite():
                found = self.negative_curvature(residual, delta)
        self.certified = 0.0
        if found is not None:
            direction, curvature = found
            # Downhill to first order, scaled to ‖d_v‖∞ = escape_size.
            slope = float(np.dot(gradient, direction))
            factor = -np.sign(slope or -1.0) * self.escape_size
            factor /= max(np.max(np.abs(direction[len(u) :])), 1e-300)
            log.debug("negative curvature %.3g: stepping along it", curvature)
            accepted = self._line_search(
                u, v, factor * direction, factor * slope, curvature * factor**2, crack, upper,
                ceiling,
            )  # fmt: skip
            return "escape" if accepted else ""
        slope = float(np.dot(gradient, delta))
        if not slope < 0:
            log.debug("Newton direction is not a descent direction (∇I·δ = %.3g)", slope)
            return ""
        scale = self._line_search(u, v, delta, slope, 0.0, crack, upper, ceiling)
        if scale == 1:
            # A full step from a point without negative curvature: while the next steps are
            # shorter (Newton's local convergence), they need no new check.
            self.certified = size
        return "newton" if scale else ""

    def restart(self) -> None:
        """Forget the last check for negative curvature and count from zero (a new load step)."""
        self.certified = 0.0
        self.solves = self.curvature_solves = 0

    def _indefinite(self) -> bool:
        """Whether the factorised Hessian may have a negative eigenvalue.

        PARDISO's L D Lᵀ factorisation counts them (Sylvester's law of inertia): with none, no
        search can find negative curvature. NGSolve's sparse Cholesky does not count them.
        """
        return getattr(self.factor, "negative_eigenvalues", 1) > 0

    def _apply_inverse(self, x: np.ndarray) -> np.ndarray:
        """Return H⁻¹ x with the current factorisation (NaN if H was not finite)."""
        if self.values is None:
            return np.full(len(x), np.nan)
        return self.factor.solve(x)

    def negative_curvature(
        self, start: np.ndarray, image: np.ndarray
    ) -> tuple[np.ndarray, float] | None:
        """Look for a direction d with dᵀHd < 0 by a few Lanczos steps on H⁻¹.

        A Ritz vector x of H⁻¹ with Ritz value θ < 0 gives d = H⁻¹x with dᵀHd = xᵀH⁻¹x = θ
        (‖x‖ = 1). Near a saddle the negative eigenvalue λ of H is small, so 1/λ is an extreme
        eigenvalue of H⁻¹, which Lanczos finds first; the search goes on until that Ritz pair
        has settled (``ritz_tol``). Started from the Newton system's right side, whose solve
        is the first step; every further step is one solve with the factorisation at hand,
        counted in :attr:`curvature_solves`.

        Parameters
        ----------
        start
            Starting vector (nonzero, zero on held DOFs).
        image
            H⁻¹ ``start``.

        Returns
        -------
        tuple or None
            (d, dᵀHd), or ``None`` if no negative Ritz value appeared.
        """
        steps = self.lanczos_steps
        basis, images = np.empty((steps, len(start))), np.empty((steps, len(start)))
        diagonal, offdiagonal = np.zeros(steps), np.zeros(steps)
        norm = np.linalg.norm(start)
        basis[0], images[0] = start / norm, image / norm
        for k in range(steps):
            if k:
                images[k] = self._apply_inverse(basis[k])
                self.curvature_solves += 1
            diagonal[k] = basis[k] @ images[k]
            ritz, vectors = eigh_tridiagonal(diagonal[: k + 1], offdiagonal[:k])
            # Full reorthogonalisation against the basis so far.
            w = images[k] - basis[: k + 1].T @ (basis[: k + 1] @ images[k])
            offdiagonal[k] = np.linalg.norm(w)
            ended = k + 1 == steps or offdiagonal[k] <= 1e-10 * abs(diagonal[k])
            # ‖H⁻¹x − θx‖ of the Ritz pair (θ, x) is β_k |y_k|, y's last entry.
            settled = offdiagonal[k] * abs(vectors[-1, 0]) <= self.ritz_tol * abs(ritz[0])
            if ritz[0] < -1e-8 * np.max(np.abs(ritz)) and (settled or ended):
                return images[: k + 1].T @ vectors[:, 0], float(ritz[0])
            if ended:
                return None
            basis[k + 1] = w / offdiagonal[k]
        return None

    def _line_search(self, u, v, direction, slope, curvature, crack, upper, ceiling) -> float:
        """Backtrack along P(w + s d) until I_j ≤ I(w) + c (s ∇I·d + s² dᵀHd / 2) and ≤ ceiling.

        Returns the accepted s (the state then holds the new iterate), or 0 if none decreased I_j.
        The trials are evaluated in the state (:meth:`ngat.state.ATState.energies`): I_j at
        (u, v) is the one the caller measured, and that of the accepted trial the one it asks
        for next, both memoised there.
        """
        state = self.state
        n = len(u)
        start = state.energies()["total"]  # the state holds (u, v)
        scale = 1.0
        for _ in range(self.max_halvings + 1):
            state.u_values[:] = u + scale * direction[:n]
            state.v_values[:] = np.clip(v + scale * direction[n:], 0.0, upper)
            state.v_values[crack] = 0.0
            energy = state.energies()["total"]
            model = scale * slope + 0.5 * scale**2 * curvature
            if energy <= min(start + self.armijo * model, ceiling):
                return scale
            scale /= 2
        state.u_values[:] = u
        state.v_values[:] = v
        log.debug("Newton line search found no decrease of I_j")
        return 0.0
