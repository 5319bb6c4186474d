"""The matrices of the two half-steps on one mesh, written in place at the current fields.

a_j(v; u, φ) of the u-step and b_j(u; v, ψ) of the v-step (paper, Algorithm 1, steps 2.1 and
2.2; Definition 2) as NGSolve sparse matrices. Per mesh each graph is built once, from the
mesh's edges (:func:`ngat.forms.graph_matrix`); every assembly of
a_j (:func:`ngat.forms.a_form`) or b_j (:func:`~ngat.forms.b_form`) then writes the values in
place from the element coefficients of the functional (:class:`ngat.functional.LumpedFunctional`)
by the vectorised :class:`ngat.forms.LumpedAssembler`,
so that a factorisation can be refreshed with its symbolic part kept. The reaction forces are
the residual of the u-equation at the Dirichlet DOFs, so they live here too.

:class:`LumpedOperators` belongs to one mesh of an :class:`ngat.state.ATState` (the state holds
the mesh and the fields); :class:`ngat.halfsteps.HalfStepSolvers` makes a new one after every
refinement.
"""

from __future__ import annotations

import functools

import numpy as np

from ngat.forms import LumpedAssembler, graph_matrix, same_values
from ngat.state import ATState

__all__ = ["LumpedOperators"]


class LumpedOperators:
    """a_j and b_j of a state's current mesh, and the reaction forces.

    Parameters
    ----------
    state
        Mesh and fields; the operators serve its mesh as it is now (``state.arrays``).

    Attributes
    ----------
    a_matrix, b_matrix
        The matrices of a_j (on the space of u) and b_j (on the P1 space of v); for a scalar
        u they share the graph.
    assembler, b_assembler
        Their in-place assemblers; ``b_assembler`` holds the positions of the element couplings
        in the P1 graph (which Newton's block graph is built from, :mod:`ngat.newton`).
    stiffness_parts
        The element matrices of a_j's parts (one without an energy split).
    arrays
        The mesh arrays the operators were built on.
    ordering
        A fill-reducing ordering of the mesh's vertices shared by every sparse factorisation
        on it (a_j, b_j, Newton's Hessian; :func:`ngat.pardiso.vertex_ordering`), computed in
        the background from the moment the mesh exists
        (:meth:`ngat.state.ATState.start_ordering`; the first use waits for it); ``None``
        where NGSolve's sparse Cholesky computes its own.
    """

    def __init__(self, state: ATState):
        self.state = state
        self.arrays = arrays = state.arrays
        model, density = state.model, state.elasticity
        with state.timer("assembly"):
            # The graphs come from the edges (b_j's is a_j's when u is scalar), the values from
            # the vectorised assemblers (equal to a_form and b_form, tests/test_forms.py).
            self.b_matrix = graph_matrix(arrays)
            self._ordering = state.vertex_ordering
            if density.components == 1:
                self.a_matrix = self.b_matrix.CreateMatrix()
            else:
                self.a_matrix = graph_matrix(arrays, density.components)
            # Without a split the one part is the stiffness: one array, one product matrix.
            parts = density.parts(arrays)
            stiffness = parts[0] if len(parts) == 1 else density.element_stiffness(arrays)
            self.assembler = LumpedAssembler(
                arrays, self.a_matrix, model.lumping, density.components, stiffness, parts
            )
            self.stiffness_parts = self.assembler.parts
            self._a_inputs: tuple[np.ndarray, ...] | None = None  # (v, u) of a_matrix's values
            if density.components == 1:
                self.b_assembler = self.assembler
            else:
                self.b_assembler = LumpedAssembler(arrays, self.b_matrix, model.lumping)

    @property
    def ordering(self) -> np.ndarray | None:
        """The vertices' fill-reducing ordering (see the class's attributes)."""
        return self._ordering.result() if self._ordering else None

    def u_matrix_values(self, v: np.ndarray | None = None) -> np.ndarray:
        """Return the values of a_j(v; ·, ·) at the current v, or ``v`` (and u, with a split).

        Each element contributes c_T K_T, c_T = ∫_T P_j(v²)/|T| + η; with an energy split, the
        weights of its parts follow the sign of tr ε(u) on T (:mod:`ngat.elasticity`).
        """
        state = self.state
        c = state.functional.coefficient(self.arrays, state.v_values if v is None else v)
        weights = state.functional.u_step_weights(self.arrays, state.u_values, c)
        return self.assembler.weighted_values(weights)

    def assemble_a(self, v: np.ndarray | None = None) -> None:
        """Write a_j(v; ·, ·) at the current fields (or at ``v``) into ``a_matrix``, in place.

        Nothing is written if the matrix holds a_j of these very u and v already: a load
        step's reaction forces ask for the a_j its last v-step prepared for an iteration that
        convergence then made unnecessary (0.37 s of the paper's example).
        """
        state = self.state
        inputs = (state.v_values if v is None else v, state.u_values)
        if self._a_inputs is not None and all(map(same_values, self._a_inputs, inputs)):
            return
        self.a_matrix.AsVector().FV().NumPy()[:] = self.u_matrix_values(v)
        self._a_inputs = tuple(np.array(array) for array in inputs)

    def set_a_values(self, values: np.ndarray) -> None:
        """Write given values into ``a_matrix`` (a restored factorisation's)."""
        self.a_matrix.AsVector().FV().NumPy()[:] = values
        self._a_inputs = None

    def assemble_b(self, crack: np.ndarray | None = None) -> None:
        """Write b_j(u; ·, ·) at the current u into ``b_matrix``, in place.

        b_j of Definition 2 with W⁺(u)/G_c in place of |∇u|² and the model's crack density
        (:mod:`ngat.crack_density`). With ``crack`` (the DOFs of CR(t_k), where the v-step
        fixes v = 0) their couplings are left out: their rows and columns hold the diagonal
        only, and a factorisation of the matrix on all DOFs solves the v-step with v fixed
        there, whatever CR is (one ordering per mesh, :class:`ngat.linear.LaggedCholesky`).
        """
        state = self.state
        density = state.functional.v_step_density(self.arrays, state.u_values)
        values = self.b_assembler.b_values(density, state.model.surface)
        if crack is not None and crack.any():
            rows, columns = self._b_entries
            values[(crack[rows] | crack[columns]) & (rows != columns)] = 0.0
        self.b_matrix.AsVector().FV().NumPy()[:] = values

    @functools.cached_property
    def _b_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """Row and column of each stored entry of ``b_matrix``."""
        _, columns, rowptr = self.b_matrix.CSR()
        counts = np.diff(np.asarray(rowptr, dtype=np.int64))
        return np.repeat(np.arange(len(counts)), counts), np.asarray(columns, dtype=np.int64)

    def reaction_forces(self) -> dict[str, float]:
        """Return the reaction force on each Dirichlet region and the load's conjugate force.

        The residual r = A u of the u-equation vanishes at free DOFs; at a DOF of Ω_D it is the
        nodal reaction. ``force_<region>`` = 2 Σ_{i∈Ω_D} r_i is the derivative of the bulk
        energy with respect to a uniform shift of u on that region (plane models:
        ``force_<region>_x`` and ``_y`` per component); ``force`` = 2 r·∂g/∂t is the derivative
        of the bulk energy with respect to the load parameter t.
        """
        state = self.state
        self.assemble_a()
        product = self.a_matrix.CreateColVector()
        product.data = self.a_matrix * state.u.vec
        residual = 2 * product.FV().NumPy()
        components = state.elasticity.components
        forces = {}
        for name, dofs in state.region_dofs.items():
            if components == 1:
                forces[f"force_{name}"] = float(residual[dofs].sum())
                continue
            per_component = np.where(dofs, residual, 0.0).reshape(components, -1).sum(axis=1)
            for i in state.load_components[name]:
                forces[f"force_{name}_{'xy'[i]}"] = float(per_component[i])
        rate = state.load_rate_values()
        forces["force"] = float(np.dot(residual[state.dirichlet], rate[state.dirichlet]))
        return forces
