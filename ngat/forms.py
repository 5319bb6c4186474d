"""Lumped P1 forms a_j and b_j (paper, Definition 2) and their fast in-place assembly.

The vertex rule integrates ``P_j(f)`` exactly for P1 data, so one rule, used for every term, gives
the mass-lumped functional I_j of eq. (7). The forms are written as NGSolve BilinearForms
(:func:`a_form`, :func:`b_form`): they are the definition. The matrix graph is built once per
mesh from its edges (:func:`graph_matrix`, NGSolve's graph of those forms), and every solve then
gets its values from :class:`LumpedAssembler`, which writes them in place from precomputed element
stiffness matrices (one vectorised ``bincount``) so that the sparse Cholesky factor is
refreshed with ``Inverse.Update()``, reusing its symbolic part; a test checks that these
values equal the assembled forms.

With ``lumped=False`` every lumped term is integrated exactly instead (:func:`exact_dx`): P_j(v²)
becomes v² in a_j and the mass of b_j becomes the consistent P1 mass |T|/12 (1 + δ_ab). That
variant has positive off-diagonal mass entries, so the v-step matrix is not an M-matrix and the
discrete maximum principle (Proposition 3) can fail on any mesh; it exists to show what lumping
buys (``lumping`` in :class:`ngat.parameters.ModelParameters`).
"""

from __future__ import annotations

from functools import cached_property

import ngsolve
import numpy as np
from ngsolve import TRIG, BilinearForm, IntegrationRule, dx, grad
from pyngcore import Array_D_S, Array_I_S
from scipy.sparse import csc_matrix, csr_matrix

from ngat.crack_density import CrackDensity

__all__ = [
    "vertex_rule",
    "element_diameters",
    "element_geometry",
    "vertex_size",
    "distances",
    "row_sum",
    "lumped_dx",
    "exact_dx",
    "a_form",
    "b_form",
    "graph_matrix",
    "graph_positions",
    "sparse_from_coo",
    "mesh_edges",
    "upper_graph",
    "edge_numbering",
    "unique_keys",
    "MeshArrays",
    "LumpedAssembler",
    "Recall",
    "same_values",
    "RECALLED",
    "SAMPLE",
]

RECALLED = 3
"""Distinct inputs whose per-element quantities a mesh's arrays keep (:class:`Recall`):
u, v and 1 − v, each asked for several times per iteration."""
SAMPLE = 64
"""Stride of the entries compared before all of them, to reject a stored input cheaply."""


class Recall:
    """Per-mesh quantities of nodal values, kept for the last few distinct inputs.

    An iteration asks for the same per-element quantity of u or v several times (the
    half-step's matrix, both estimators, the energies of the tolerance and of the record),
    each at 1–2 ms at 180k elements, while a comparison with a stored copy of the nodal values
    costs 0.05 ms. Results are read-only, and equal inputs give the very numbers a new
    evaluation would.

    Parameters
    ----------
    size
        Distinct inputs kept per quantity.
    """

    def __init__(self, size: int = RECALLED):
        self.size = size
        self._recent: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}

    def __call__(self, name: str, values: np.ndarray, compute) -> np.ndarray:
        """Return ``compute(values)``, or the result of an earlier call with equal values."""
        recent = self._recent.setdefault(name, [])
        for key, result in recent:
            if same_values(key, values):
                return result
        result = compute(values)
        result.flags.writeable = False
        recent.insert(0, (np.array(values), result))
        del recent[self.size :]
        return result


def same_values(stored: np.ndarray, values: np.ndarray) -> bool:
    """Return whether two arrays are equal: a memo's stored input and a new one.

    Every :data:`SAMPLE`-th entry is compared first: different fields, or a field before and
    after a solve, differ almost everywhere, so a memo asked with new values, as it mostly is,
    costs a sixty-fourth of a full comparison.
    """
    return np.array_equal(stored[::SAMPLE], values[::SAMPLE]) and np.array_equal(stored, values)


def vertex_rule() -> IntegrationRule:
    """Return the vertex (trapezoidal) rule on the reference triangle, weights 1/6 each."""
    return IntegrationRule(points=[(0, 0), (1, 0), (0, 1)], weights=[1 / 6] * 3)


def lumped_dx():
    """Return ``dx`` with the vertex rule: ``∫ f dx`` becomes ``∫ P_j f dx`` for P1 data."""
    return dx(intrules={TRIG: vertex_rule()})


def exact_dx():
    """Return ``dx`` with a degree-2 rule: exact for every term of a_j and b_j with P1 data."""
    return dx(intrules={TRIG: IntegrationRule(TRIG, 2)})


def a_form(fes: ngsolve.FESpace, v, eta: float, lumped: bool = True, bilinear=None) -> BilinearForm:
    """Return a_j(v; u, φ) = ∫ (P_j(v²) + η) ∇u·∇φ (paper, Definition 2).

    Parameters
    ----------
    fes
        P1 space of u.
    v
        Phase field (GridFunction or CoefficientFunction), frozen during the u-step.
    eta
        Residual stiffness η.
    lumped
        ``False``: ∫ (v² + η) ∇u·∇φ, integrated exactly (consistent-mass variant).
    bilinear
        s(u) : ∇φ of the model, :meth:`ngat.elasticity.Elasticity.bilinear`; default
        ∇u·∇φ (anti-plane, the paper).
    """
    u, phi = fes.TnT()
    density = grad(u) * grad(phi) if bilinear is None else bilinear(u, phi)
    form = BilinearForm(fes, symmetric=True)
    form += (v * v + eta) * density * (lumped_dx() if lumped else exact_dx())
    return form


def b_form(
    fes: ngsolve.FESpace,
    u,
    surface: CrackDensity,
    lumped: bool = True,
    bilinear=None,
    gc: float = 1.0,
) -> BilinearForm:
    """Return b_j(u; v, ψ) without its constant part: ∫ P_j(vψ)(|∇u|² + α) + ε ∇v·∇ψ.

    The remaining term of Definition 2, ``-α ∫ P_j(ψ)``, is the right-hand side of the v-step
    (for P1 test functions ∫ P_j(ψ) = ∫ ψ, so it is the same without lumping). The form is
    that of I_j divided by G_c: |∇u|² becomes W(u)/G_c. With the crack density γ of
    :mod:`ngat.crack_density`, α becomes its q and ε its d (AT2: the paper's α and ε).

    Parameters
    ----------
    fes
        P1 space of v.
    u
        Displacement, frozen during the v-step.
    surface
        Crack density γ (AT2: α = 1/(4ε) and ε).
    lumped
        ``False``: ∫ vψ (|∇u|² + α), integrated exactly (the consistent P1 mass).
    bilinear
        s(u) : ∇φ of the model (W(u) = s(u) : ∇u), :meth:`ngat.elasticity.Elasticity.bilinear`;
        default ∇u·∇φ (anti-plane, the paper).
    gc
        Fracture toughness G_c.
    """
    density = grad(u) * grad(u) if bilinear is None else bilinear(u, u)
    v, psi = fes.TnT()
    form = BilinearForm(fes, symmetric=True)
    form += (
        (density / gc + surface.reaction) * v * psi + surface.diffusion * grad(v) * grad(psi)
    ) * (lumped_dx() if lumped else exact_dx())
    return form


def sparse_from_coo(
    rows: np.ndarray, cols: np.ndarray, values: np.ndarray, height: int, width: int
) -> ngsolve.la.SparseMatrixd:
    """Return NGSolve's ``SparseMatrixd.CreateFromCOO`` of numpy triplets (duplicates summed).

    ``CreateFromCOO`` takes its own integer and float arrays; numpy arrays are converted entry
    by entry, Python lists 2.5 times faster, and filling its arrays through their NumPy views
    costs next to nothing (the P1 graph at 180k elements: 0.03 s against 0.16 s from lists).
    """

    def array(kind, data: np.ndarray):
        out = kind(len(data))
        out.NumPy()[:] = data
        return out

    return ngsolve.la.SparseMatrixd.CreateFromCOO(
        array(Array_I_S, rows), array(Array_I_S, cols), array(Array_D_S, values), height, width
    )


def graph_matrix(arrays: MeshArrays, components: int = 1) -> ngsolve.la.SparseMatrixd:
    """Return a zero matrix whose graph couples every two DOFs of an element.

    The graph NGSolve's assembly of a_j or b_j allocates on a P1 space of ``components``
    components (DOFs component-major, as in ``VectorH1``): every component of a vertex with
    every component of itself and of its neighbours along the mesh's edges, built from the
    edges by :func:`sparse_from_coo` (0.03 s at 180k elements, where an assembly with an empty
    integration rule took 0.28 s); ``tests/test_elasticity.py`` checks it against NGSolve's.
    Its values come from :class:`LumpedAssembler`.
    """
    n = arrays.nv
    edges, diagonal = arrays.edges, np.arange(n)
    first = np.concatenate([edges[:, 0], edges[:, 1], diagonal])
    second = np.concatenate([edges[:, 1], edges[:, 0], diagonal])
    shift = n * np.arange(components)
    rows = np.broadcast_to((shift[:, None] + first)[:, None], (components, components, len(first)))
    cols = np.broadcast_to((shift[:, None] + second)[None], (components, components, len(first)))
    size = components * n
    return sparse_from_coo(rows.ravel(), cols.ravel(), np.zeros(rows.size), size, size)


def graph_positions(arrays: MeshArrays, components: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Return where the element couplings and the diagonal sit in :func:`graph_matrix`'s values.

    Row a of the P1 graph G holds, sorted, the lower ends lo < a of the edges into a, then a,
    then the upper ends hi > a of the edges out of a. The mesh's edges are numbered by their
    (lo, hi) (:func:`edge_numbering`), so the entries (lo, hi) of a row follow each other in
    edge order, and the entries (hi, lo) in the order of one stable sort of the upper ends:
    every position is arithmetic on the edge numbers (a search of the 9 ne element couplings
    among the graph's entries took 76 ms at 180k elements). With c components (DOFs
    component-major), row (I, a) starts at I c nnz(G) + c rowptr_G[a] and holds (J, b) at
    J deg(a) + the position of b in row a of G.

    Parameters
    ----------
    arrays
        Element geometry of the mesh.
    components
        Components of the P1 space (as for :func:`graph_matrix`).

    Returns
    -------
    position : (ne, 3 c, 3 c) int array
        The entry of every pair of local DOFs (I, i) (component I of local vertex i).
    diagonal : (c nv,) int array
        The entry (k, k) of every DOF k.
    """
    nv, el = arrays.nv, arrays.elements
    keys, element_edges, _ = arrays.edge_numbering
    lo, hi = keys // nv, keys % nv
    out_degree, in_degree = np.bincount(lo, minlength=nv), np.bincount(hi, minlength=nv)
    degree = in_degree + 1 + out_degree
    rowptr = np.concatenate([[0], np.cumsum(degree)])
    diagonal = rowptr[:-1] + in_degree
    edge = np.arange(len(keys))
    forward = diagonal[lo] + 1 + edge - (np.cumsum(out_degree) - out_degree)[lo]  # (lo, hi)
    by_hi = np.argsort(hi, kind="stable")
    backward = np.empty(len(keys), dtype=np.int64)  # (hi, lo)
    backward[by_hi] = rowptr[hi[by_hi]] + edge - (np.cumsum(in_degree) - in_degree)[hi[by_hi]]
    in_g = np.empty((arrays.ne, 3, 3), dtype=np.int64)
    for k in range(3):  # local edge k joins local vertices k and k + 1
        i, j, e = k, (k + 1) % 3, element_edges[:, k]
        ahead, behind = forward[e], backward[e]
        in_g[:, i, i] = diagonal[el[:, i]]
        in_g[:, i, j] = np.where(el[:, i] < el[:, j], ahead, behind)
        in_g[:, j, i] = ahead + behind - in_g[:, i, j]  # the other of the two
    if components == 1:
        return in_g, diagonal
    c, nnz = components, rowptr[-1]
    shift = np.arange(c)
    position = (
        (shift[:, None] * c * nnz)[None, :, :, None, None]
        + ((c - 1) * rowptr[el])[:, None, :, None, None]
        + shift[None, None, None, :, None] * degree[el][:, None, :, None, None]
        + in_g[:, None, :, None, :]
    )
    on_diagonal = (
        (shift * c * nnz)[:, None]
        + (c * rowptr[:-1] + diagonal - rowptr[:-1])[None]
        + shift[:, None] * degree[None]
    )
    return position.reshape(arrays.ne, 3 * c, 3 * c), on_diagonal.ravel()


def unique_keys(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the sorted distinct keys, the position of every key among them, and the sort.

    The same as ``np.unique(keys, return_inverse=True)`` for integer keys, by one stable sort:
    on the millions of keys of a sparsity graph several times faster than ``np.unique``
    without ``return_inverse`` (a hash table, then a sort) followed by ``np.searchsorted``.
    The sort lists the keys by position, equal keys in their order in ``keys``.

    Parameters
    ----------
    keys
        (n,) integer keys.
    """
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    first = np.empty(len(keys), dtype=bool)
    first[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    position = np.empty(len(keys), dtype=np.int64)
    position[order] = np.cumsum(first) - 1
    return ordered[first], position, order


def edge_numbering(elements: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the edges of a triangle mesh numbered by their keys lo · size + hi (lo < hi).

    Local edge k of an element joins its local vertices k and (k + 1) mod 3.

    Parameters
    ----------
    elements
        (ne, 3) vertex numbers of the triangles.
    size
        More than the largest vertex number.

    Returns
    -------
    keys : (n_edges,) int array
        The sorted distinct keys.
    element_edges : (ne, 3) int array
        The edge number of every local edge of every element.
    order : (3 ne,) int array
        The local edges (element · 3 + k) by edge number, an edge's elements in element order.
    """
    start, end = elements, elements[:, [1, 2, 0]]
    keys = np.minimum(start, end).astype(np.int64) * size + np.maximum(start, end)
    distinct, position, order = unique_keys(keys.ravel())
    return distinct, position.reshape(-1, 3), order


def mesh_edges(elements: np.ndarray) -> np.ndarray:
    """Return the unique edges of a triangle mesh, shape (n_edges, 2), smaller vertex first.

    Parameters
    ----------
    elements
        (ne, 3) vertex numbers of the triangles.
    """
    size = int(elements.max(initial=-1)) + 1
    keys = edge_numbering(elements, size)[0]
    return np.stack([keys // size, keys % size], axis=1)


def upper_graph(elements: np.ndarray, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the CSR graph (indptr, indices) of a P1 matrix's upper triangle on a mesh.

    Row a holds a and the upper ends of the edges out of a, sorted: the graph
    :func:`ngat.pardiso.vertex_ordering` reads from :func:`graph_matrix`, to the entry, built
    from the triangles alone (no mesh arrays), so that METIS can start on a new mesh first.
    The worker thread numbers the edges for it while the main thread numbers them again for
    the mesh's arrays (:attr:`MeshArrays.edge_numbering`): done twice, on two cores, so that
    neither waits for the other.

    Parameters
    ----------
    elements
        (ne, 3) vertex numbers of the triangles.
    nv
        Number of vertices.
    """
    diagonal = np.arange(nv, dtype=np.int64)
    keys = np.sort(np.concatenate([edge_numbering(elements, nv)[0], diagonal * (nv + 1)]))
    counts = np.bincount(keys // nv, minlength=nv)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    return indptr, (keys % nv).astype(np.int32)


def row_sum(values: np.ndarray) -> np.ndarray:
    """Return ``values.sum(axis=1)`` of an (n, k) array with few columns, column by column.

    The same numbers as numpy's reduction (which adds a short row in order), several times
    faster for k = 2 or 3, where the reduction's per-row overhead dominates.
    """
    total = values[:, 0].copy()
    for column in range(1, values.shape[1]):
        total += values[:, column]
    return total


def corner_components(coords: np.ndarray, elements: np.ndarray) -> tuple[list, list]:
    """Return the x and the y coordinates of every element's three corners, as (ne,) arrays.

    Gathered component by component: faster than the (ne, 3, 2) stack ``coords[elements]``
    and its strided columns.
    """
    corners = [elements[:, i] for i in range(3)]
    x, y = ([component[corner] for corner in corners] for component in coords.T)
    return x, y


def element_diameters(coords: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """Return the diameter h_T (longest edge) of each triangle.

    The root of the longest squared edge: the same numbers as the longest of the edges'
    lengths (the square root is monotone and correctly rounded), with one root per element
    and the coordinates gathered component by component (3.6 times faster at 145k elements).
    """
    x, y = corner_components(coords, elements)

    def squared(i: int, j: int) -> np.ndarray:
        dx, dy = x[j] - x[i], y[j] - y[i]
        return dx * dx + dy * dy

    return np.sqrt(np.maximum(np.maximum(squared(0, 1), squared(1, 2)), squared(2, 0)))


def distances(points: np.ndarray, point) -> np.ndarray:
    """Return the distance of each of the (n, 2) ``points`` to one ``point``.

    √(Δx² + Δy²) column by column: the numbers of ``np.linalg.norm(points - point, axis=1)``
    to the last bit, without its sums over rows of two (seven times as fast at 10⁵ points).
    """
    x, y = np.asarray(point, dtype=float)
    dx, dy = points[:, 0] - x, points[:, 1] - y
    return np.sqrt(dx * dx + dy * dy)


def vertex_size(
    coords: np.ndarray, elements: np.ndarray, diameter: np.ndarray, point: tuple[float, float]
) -> float:
    """Return the largest diameter of the elements at the vertex nearest to ``point``."""
    nearest = np.argmin(distances(coords, point))
    at = elements == nearest
    return float(diameter[at[:, 0] | at[:, 1] | at[:, 2]].max())


def element_geometry(
    coords: np.ndarray, elements: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the areas |T|, the gradients ∇φ_a (ne, 3, 2) and the stiffness ∫_T ∇φ_a·∇φ_b.

    Component by component, on (ne,) arrays gathered once per vertex coordinate, and with
    the stiffness's symmetric entries computed once: every number is that of the same
    arithmetic on the (ne, 3, 2) stack of the elements' coordinates, to the last bit
    (products commute exactly, and (−a)/b = −(a/b)), in a little over half its time (8.7
    against 15.8 ms at 79k elements, once per new mesh).
    """
    (x0, x1, x2), (y0, y1, y2) = corner_components(coords, elements)
    e1x, e1y, e2x, e2y = x1 - x0, y1 - y0, x2 - x0, y2 - y0
    det = e1x * e2y - e1y * e2x
    area = 0.5 * np.abs(det)
    # Rows of the inverse Jacobian give ∇λ1, ∇λ2; ∇λ0 = -(∇λ1 + ∇λ2).
    g1 = (e2y / det, -e2x / det)
    g2 = (-e1y / det, e1x / det)
    g0 = (-(g1[0] + g2[0]), -(g1[1] + g2[1]))
    gradients = (g0, g1, g2)
    grad_phi = np.empty((len(elements), 3, 2))
    stiffness = np.empty((len(elements), 3, 3))
    for a in range(3):
        grad_phi[:, a, 0], grad_phi[:, a, 1] = gradients[a]
        for b in range(a, 3):
            # ∇φ_a·∇φ_b as two products and a sum, then |T|: einsum's numbers.
            entry = gradients[a][0] * gradients[b][0]
            entry += gradients[a][1] * gradients[b][1]
            entry *= area
            stiffness[:, a, b] = stiffness[:, b, a] = entry
    return area, grad_phi, stiffness


class MeshArrays:
    """Element geometry of a P1 triangle mesh as numpy arrays, computed once per mesh.

    Attributes
    ----------
    elements : (ne, 3) int array
        Vertex (= P1 DOF) numbers of each triangle.
    material : (ne,) int array
        Material number of each triangle (its position in ``mesh.GetMaterials()``).
    coords : (nv, 2) array
        Vertex coordinates.
    area : (ne,) array
        Element areas |T|.
    grad_phi : (ne, 3, 2) array
        Gradients of the barycentric coordinates on each element.
    stiffness : (ne, 3, 3) array
        Element stiffness matrices ∫_T ∇φ_a·∇φ_b.
    mass : (nv,) array
        Lumped mass ∫ φ_i (the vertex rule).
    diameter : (ne,) array
        Element diameters h_T (longest edge).
    """

    def __init__(self, mesh: ngsolve.Mesh):
        ngmesh = mesh.ngmesh
        triangles = ngmesh.Elements2D().NumPy()
        self.elements = triangles["nodes"][:, :3].astype(np.int64) - 1
        self.material = triangles["index"].astype(np.int64) - 1
        self.coords = ngmesh.Coordinates()[:, :2].copy()
        self.nv = len(self.coords)
        self.ne = len(self.elements)
        self.area, self.grad_phi, self.stiffness = element_geometry(self.coords, self.elements)
        self.mass = self.vertex_sum(self.area / 3)
        self.diameter = element_diameters(self.coords, self.elements)
        self._sizes_at: dict[tuple[float, float], float] = {}
        self._recall = Recall()

    def size_at(self, point: tuple[float, float]) -> float:
        """Return the largest diameter of the elements at the vertex nearest to ``point``.

        Computed once per mesh and point (the crack measures ask it at the slit tips after
        every v-step, :func:`ngat.crack.crack_tips`).
        """
        key = (float(point[0]), float(point[1]))
        if key not in self._sizes_at:
            self._sizes_at[key] = vertex_size(self.coords, self.elements, self.diameter, key)
        return self._sizes_at[key]

    @cached_property
    def edge_numbering(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:func:`edge_numbering` of the mesh with keys lo · nv + hi; computed once per mesh."""
        return edge_numbering(self.elements, self.nv)

    @cached_property
    def edges(self) -> np.ndarray:
        """Unique edges (n_edges, 2), smaller vertex first; computed once per mesh."""
        keys = self.edge_numbering[0]
        return np.stack([keys // self.nv, keys % self.nv], axis=1)

    @cached_property
    def _gradient_matrix(self) -> csr_matrix:
        """Sparse map from nodal values to element gradients, rows (x, y) per element."""
        rows = np.repeat(np.arange(2 * self.ne).reshape(-1, 2), 3, axis=0).reshape(self.ne, 3, 2)
        cols = np.broadcast_to(self.elements[:, :, None], (self.ne, 3, 2))
        return csr_matrix(
            (self.grad_phi.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * self.ne, self.nv)
        )

    @cached_property
    def stiffness_diagonal(self) -> np.ndarray:
        """The diagonals ∫_T |∇φ_a|² of the element stiffness matrices, (ne, 3), contiguous."""
        return np.ascontiguousarray(np.diagonal(self.stiffness, axis1=1, axis2=2))

    @cached_property
    def h2(self) -> np.ndarray:
        """Squared element diameters h_T²."""
        return self.diameter * self.diameter

    def gradient(self, values: np.ndarray) -> np.ndarray:
        """Return the constant gradient of a P1 function on every element, shape (ne, 2)."""
        return self._recall(
            "gradient", values, lambda w: (self._gradient_matrix @ w).reshape(self.ne, 2)
        )

    def squared_gradient(self, values: np.ndarray) -> np.ndarray:
        """Return |∇w|² of a P1 function w on every element (the same numbers as summing rows)."""

        def compute(w: np.ndarray) -> np.ndarray:
            gradient = self.gradient(w)
            return gradient[:, 0] * gradient[:, 0] + gradient[:, 1] * gradient[:, 1]

        return self._recall("squared_gradient", values, compute)

    @cached_property
    def _incidence(self) -> csc_matrix:
        """Vertex–element incidence (nv × ne), each column's entries in local vertex order."""
        return csc_matrix(
            (np.ones(3 * self.ne), self.elements.ravel(), np.arange(0, 3 * self.ne + 1, 3)),
            shape=(self.nv, self.ne),
        )

    def vertex_sum(self, weights: np.ndarray) -> np.ndarray:
        """Return Σ_{T ∋ a} weights_T at every vertex a (a lumped mass weighted per element).

        The numbers of ``numpy.bincount`` over the elements' vertices with each weight
        repeated three times, to the last bit (the product sums element by element, in that
        order), without the repeated weights.
        """
        return self._incidence @ weights

    def recall(self, name: str, values: np.ndarray, compute) -> np.ndarray:
        """Return ``compute(values)``, kept for equal values on this mesh (:class:`Recall`)."""
        return self._recall(name, values, compute)

    def vertex_mean(self, values: np.ndarray) -> np.ndarray:
        """Return the mean of nodal values over each element's vertices: ∫_T P_j f / |T|.

        A product with the element–vertex incidence (the transpose of :meth:`vertex_sum`'s),
        whose rows hold each element's vertices in local order: the sum runs first, second,
        third vertex, so the numbers are those of ``values[elements].mean(axis=1)`` to the
        last bit, without its (ne, 3) gather (0.41 against 0.58 ms for the three gathered
        columns at 114k elements).
        """
        return (self._element_vertex @ values) / 3

    @cached_property
    def _element_vertex(self) -> csr_matrix:
        """Element–vertex incidence (ne × nv): :attr:`_incidence` transposed once per mesh.

        The transpose shares its arrays; ``.T`` at every call built a new matrix object (0.2 s
        of the paper's example, in 1,706 calls).
        """
        return self._incidence.T

    @cached_property
    def bounding_diameter(self) -> float:
        """Diameter of the vertices' bounding box, once per mesh."""
        return float(np.linalg.norm(self.coords.max(axis=0) - self.coords.min(axis=0)))

    @cached_property
    def centroid(self) -> np.ndarray:
        """Element centroids (ne, 2): :meth:`vertex_mean` of the coordinates, once per mesh."""
        return self.vertex_mean(self.coords)

    @cached_property
    def corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The first, second and third vertex of every element, each contiguous."""
        return tuple(np.ascontiguousarray(self.elements[:, i]) for i in range(3))

    def touching(self, mask: np.ndarray) -> np.ndarray:
        """Return which elements have a vertex in the (nv,) boolean ``mask``.

        Corner by corner (:attr:`corners`): the booleans of ``mask[elements].any(axis=1)``,
        eight times as fast at 10⁵ elements.
        """
        first, second, third = self.corners
        return mask[first] | mask[second] | mask[third]

    def square_mean(self, values: np.ndarray, lumped: bool = True) -> np.ndarray:
        """Return ∫_T P_j(w²) / |T| per element for a P1 function w, or ∫_T w² / |T| unlumped.

        Exactly: ∫_T w² = |T|/12 (Σ w_a² + (Σ w_a)²) over the vertex values w_a.
        """

        def compute(w: np.ndarray) -> np.ndarray:
            if lumped:
                return self.vertex_mean(w * w)
            local = w[self.elements]
            return (row_sum(local * local) + row_sum(local) ** 2) / 12

        return self._recall(f"square_mean_{lumped}", values, compute)


class LumpedAssembler:
    """Write the values of a_j and b_j into matrices with a fixed graph, without NGSolve assembly.

    Parameters
    ----------
    arrays
        Element geometry of the mesh.
    matrix
        A matrix with the graph of :func:`graph_matrix` (NGSolve's assembly on the P1 space of
        that mesh allocates the same); only its size is read, the positions follow from the
        mesh's edges (:func:`graph_positions`).
    lumped
        ``True``: the lumped forms of Definition 2; ``False``: every lumped term integrated
        exactly (``a_form(..., lumped=False)``, ``b_form(..., lumped=False)``).
    components, stiffness
        Components of the matrix's space and its element matrices (ne, 3c, 3c) in the order of
        :meth:`ngat.elasticity.Elasticity.element_dofs`; default a scalar P1 space and
        ∫_T ∇φ_a·∇φ_b. A vector space of u passes those of its model (``element_stiffness``).
    parts
        Element matrices whose weighted sum is a_j (:meth:`weighted_values`,
        :meth:`ngat.elasticity.Elasticity.parts`); default the stiffness alone.

    Raises
    ------
    ValueError
        If ``matrix`` has not as many entries as that graph.
    """

    def __init__(
        self,
        arrays: MeshArrays,
        matrix: ngsolve.la.SparseMatrixd,
        lumped: bool = True,
        components: int = 1,
        stiffness: np.ndarray | None = None,
        parts: list[np.ndarray] | None = None,
    ):
        position, self.diagonal = graph_positions(arrays, components)
        self.position = position.ravel()
        self.nnz = components * components * (2 * len(arrays.edges) + arrays.nv)
        if matrix.nze != self.nnz:
            raise ValueError(
                f"the matrix has {matrix.nze} entries, the P1 graph of {components} component(s) "
                f"on this mesh {self.nnz}: build it with graph_matrix"
            )
        self.arrays = arrays
        self.lumped = lumped
        self.stiffness = arrays.stiffness if stiffness is None else stiffness
        self.parts = [self.stiffness] if parts is None else parts
        self._stiffness = self.element_sum(self.stiffness)
        self._parts = [
            self._stiffness if part is self.stiffness else self.element_sum(part)
            for part in self.parts
        ]
        self.laplace = self._stiffness @ np.ones(arrays.ne)

    def element_sum(self, local: np.ndarray) -> csc_matrix:
        """Return the matrix that maps element weights c to the values of Σ_T c_T local_T.

        Column T holds the entries of the element matrix local_T (or of ``local[0]`` for
        every T) at their positions in the graph. Its product sums element by element, in
        the order of ``numpy.bincount`` over the scattered products c_T local_T, so the values
        are those of that scatter to the last bit, 4.6 times faster at 145k elements (1.2 ms
        against 5.5 ms: no (ne, 3c, 3c) array of products).
        """
        ne = self.arrays.ne
        per_element = local[0].size
        entries = np.broadcast_to(local, (ne, *local.shape[1:])).ravel()
        columns = np.arange(0, per_element * ne + 1, per_element)
        return csc_matrix((entries, self.position, columns), shape=(self.nnz, ne))

    @cached_property
    def _consistent_mass(self) -> csc_matrix:
        """:meth:`element_sum` of the consistent element mass over |T|, (1 + δ_ab)/12."""
        return self.element_sum(((np.ones((3, 3)) + np.eye(3)) / 12)[None])

    def weighted_values(self, weights: list[np.ndarray]) -> np.ndarray:
        """Return the values of Σ_k Σ_T weights_k,T parts_k,T (an energy split's a_j).

        With the stiffness as the one part and weight mean(v²) + η this is :meth:`a_values`.
        """
        values = self._parts[0] @ weights[0]
        for weight, part in zip(weights[1:], self._parts[1:], strict=True):
            values += part @ weight
        return values

    def a_values(self, v: np.ndarray, eta: float) -> np.ndarray:
        """Return the values of a_j(v; ·, ·): element coefficient mean(v²) + η times stiffness.

        The mean of v² over T is :meth:`MeshArrays.square_mean` (lumped or exact): ∇u·∇φ is
        constant on T.
        """
        return self._stiffness @ (self.arrays.square_mean(v, self.lumped) + eta)

    def b_values(self, grad_u_sq: np.ndarray, surface: CrackDensity) -> np.ndarray:
        """Return the values of b_j(u; ·, ·): ε·stiffness plus mass weighted with |∇u|² + α.

        ``grad_u_sq`` is |∇u|² (anti-plane) or W(u)/G_c per element (:func:`b_form`); α and ε
        are the q and d of the crack density (AT2: the paper's).

        The mass is lumped (diagonal) or, with ``lumped=False``, the consistent element mass
        |T|/12 (1 + δ_ab).
        """
        reaction, diffusion = surface.reaction, surface.diffusion
        arrays = self.arrays
        if not self.lumped:
            return diffusion * self.laplace + self._consistent_mass @ (
                arrays.area * (grad_u_sq + reaction)
            )
        diagonal = arrays.vertex_sum(arrays.area * (grad_u_sq + reaction) / 3)
        values = diffusion * self.laplace
        values[self.diagonal] += diagonal
        return values
