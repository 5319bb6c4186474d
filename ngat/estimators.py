"""Residual a-posteriori estimators μ_j (u-step) and ν_j (v-step) of the paper, Proposition 4.

Both are sums of squared element indicators: an element residual weighted by h_T² (plus the
h_T⁴ term of the coefficient's gradient) and the jump of the normal flux over the element's
edges weighted by h_T. With P1 data, ∇u and ∇v are constant on each triangle and v is linear,
so every integral has a closed form: ∫_T w² = |T|/12 (Σ w_i² + (Σ w_i)²) for w linear with
vertex values w_i (the P1 mass matrix), and ∫_e (v² + η)² ds, a quartic in arc length, from the
end values of v on e. The edge structure (unique edges, their one or two elements, lengths and
normals) is built once per mesh by :class:`EdgeTopology`; the estimators are then a handful of
vectorised numpy operations.

A slit has distinct nodes on its two faces, so each face edge is a boundary edge with a single
element; like the outer boundary it carries the natural (Neumann) condition, and the flux
itself takes the place of the jump there.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy.sparse import csr_matrix

from ngat.crack_density import CrackDensity
from ngat.elasticity import AntiPlane, Elasticity
from ngat.forms import MeshArrays, Recall, row_sum

__all__ = ["EdgeTopology", "flux_jumps", "mu_estimator", "nu_estimator", "meets", "MASKS"]

MASKS = 4
"""Vertex masks whose edges and elements an :class:`EdgeTopology` keeps: Ω_D, two held
components of a plane model's u, and CR(t_k)."""


class EdgeTopology:
    """Edges of a P1 triangle mesh with their elements, lengths and unit normals.

    Local edge k of an element joins its local vertices k and (k + 1) mod 3 (the order of
    ``MeshArrays.elements``).

    Parameters
    ----------
    arrays
        Element geometry of the mesh.

    Attributes
    ----------
    vertices : (nedges, 2) int array
        End points of each edge, the smaller vertex number first.
    first, second : (nedges,) int arrays
        The two columns of ``vertices``, each contiguous.
    element_edges : (ne, 3) int array
        Edge number of each local edge of each element.
    elements : (nedges, 2) int array
        The element(s) of each edge; the second entry is −1 on a boundary edge.
    boundary : (nedges,) bool array
        Edges with a single element: the outer boundary and both faces of every slit.
    length : (nedges,) array
        Edge lengths |e|.
    normal : (nedges, 2) array
        A unit normal of each edge (fixed orientation; only squared fluxes are used).

    Raises
    ------
    ValueError
        If an edge belongs to more than two elements.
    """

    def __init__(self, arrays: MeshArrays):
        nv = arrays.nv
        keys, self.element_edges, order = arrays.edge_numbering
        counts = np.bincount(self.element_edges.ravel(), minlength=len(keys))
        if counts.max(initial=0) > 2:
            raise ValueError("an edge belongs to more than two elements: not a planar mesh")
        self.first, self.second = keys // nv, keys % nv
        self.vertices = arrays.edges
        self.boundary = counts == 1
        # Element-edges sorted by edge number: the first (and second) of each group.
        owner = order // 3
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.elements = np.full((len(keys), 2), -1, dtype=np.int64)
        self.elements[:, 0] = owner[first]
        interior = ~self.boundary
        self.elements[interior, 1] = owner[first[interior] + 1]
        tangent = arrays.coords[self.vertices[:, 1]] - arrays.coords[self.vertices[:, 0]]
        self.length = np.sqrt((tangent**2).sum(axis=1))
        self.normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1) / self.length[:, None]
        self._flux_jump = self._flux_jump_matrix(arrays)
        self._arrays = arrays
        self._recall = Recall(size=MASKS)

    @property
    def nedges(self) -> int:
        """Number of edges."""
        return len(self.vertices)

    def normal_flux_jump(self, values: np.ndarray) -> np.ndarray:
        """Return [∂_n w] on interior edges and ∂_n w on boundary edges, shape (nedges,).

        Parameters
        ----------
        values
            Nodal values of the P1 function w, shape (nv,).
        """
        return self._flux_jump @ values

    def element_flux_jump(self, flux: np.ndarray) -> np.ndarray:
        """Return [s n] on interior edges and s n on boundary edges, shape (nedges, c).

        Parameters
        ----------
        flux
            A flux s constant on each element, shape (ne, c, 2) (one row per component).
        """
        first, second = self.elements[:, 0], self.elements[:, 1]
        jump = flux[first] - np.where((second >= 0)[:, None, None], flux[second], 0.0)
        return np.einsum("eik,ek->ei", jump, self.normal)

    def _flux_jump_matrix(self, arrays: MeshArrays) -> csr_matrix:
        """Return the sparse map from nodal values to normal-flux jumps (≤ 6 entries per row).

        The flux of element T across edge e is n_e·∇w|_T = Σ_a w_a n_e·∇φ_a^T; the jump is the
        first element's flux minus the second's (none on boundary edges).
        """
        rows, cols, data = [], [], []
        for side, sign in ((0, 1.0), (1, -1.0)):
            edge = np.flatnonzero(self.elements[:, side] >= 0)
            element = self.elements[edge, side]
            weights = np.einsum("eak,ek->ea", arrays.grad_phi[element], self.normal[edge])
            rows.append(np.repeat(edge, 3))
            cols.append(arrays.elements[element].ravel())
            data.append(sign * weights.ravel())
        return csr_matrix(
            (np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))),
            shape=(len(self.vertices), arrays.nv),
        )

    def within(self, mask: np.ndarray) -> np.ndarray:
        """Return the edges with both end points in the vertex mask, shape (nedges,).

        Kept for the last few masks (Ω_D's, each held component's and CR(t_k) change with
        the mesh or the load step only; :class:`ngat.forms.Recall`).
        """
        return self._recall("within", mask, lambda m: m[self.first] & m[self.second])

    def meets(self, mask: np.ndarray) -> np.ndarray:
        """Return :func:`meets` of the mesh and the vertex mask, kept like :meth:`within`."""
        return self._recall("meets", mask, lambda m: meets(self._arrays, m))

    def element_sum(self, per_edge: np.ndarray) -> np.ndarray:
        """Return Σ_{e⊂∂T} per_edge[e] for every element T, shape (ne,).

        A product with the element–edge incidence, its entries stored in the order of the
        local edges: the sum of :func:`row_sum` over ``per_edge[element_edges]``, to the last
        bit, without the (ne, 3) gather.
        """
        return self._incidence @ per_edge

    @cached_property
    def _incidence(self) -> csr_matrix:
        """Element–edge incidence (ne × nedges), each row's entries in local edge order."""
        ne = len(self.element_edges)
        return csr_matrix(
            (np.ones(3 * ne), self.element_edges.ravel(), np.arange(0, 3 * ne + 1, 3)),
            shape=(ne, len(self.vertices)),
        )


def meets(arrays: MeshArrays, mask: np.ndarray) -> np.ndarray:
    """Return the elements with at least one vertex in the vertex mask, shape (ne,)."""
    first, second, third = arrays.corners
    return mask[first] | mask[second] | mask[third]


def _linear_square_integral(arrays: MeshArrays, corners: list[np.ndarray]) -> np.ndarray:
    """Return ∫_T w² for w linear on T with vertex values ``corners`` (three (ne,) arrays).

    The P1 mass matrix: |T|/12 (Σ w_a² + (Σ w_a)²), summed in the order of the corners (the
    numbers of :func:`row_sum` over the (ne, 3) values, without their strided columns).
    """
    first, second, third = corners
    squares = first * first + second * second + third * third
    total = first + second + third
    return arrays.area / 12 * (squares + total**2)


def _corner_values(arrays: MeshArrays, values: np.ndarray) -> list[np.ndarray]:
    """Return a P1 function's values at the first, second and third vertex of every element."""
    return [values[corner] for corner in arrays.corners]


def flux_jumps(
    arrays: MeshArrays, edges: EdgeTopology, elasticity: Elasticity, u: np.ndarray
) -> np.ndarray:
    """Return [s(u) n] on interior edges and s(u) n on boundary edges, shape (nedges, c).

    Anti-plane (s = ∇u): the exact sparse map of the nodal values,
    :meth:`EdgeTopology.normal_flux_jump`; plane models: the element fluxes σ/2 of
    :mod:`ngat.elasticity` applied to each edge's normal (with an energy split, those of the
    degraded part s⁺).
    """
    if elasticity.components == 1:
        return edges.normal_flux_jump(u)[:, None]
    return edges.element_flux_jump(elasticity.fluxes(elasticity.gradient(arrays, u))[0])


def mu_estimator(
    arrays: MeshArrays,
    edges: EdgeTopology,
    u: np.ndarray,
    v: np.ndarray,
    eta: float,
    dirichlet: np.ndarray,
    elasticity: Elasticity | None = None,
    fixed: np.ndarray | None = None,
) -> np.ndarray:
    """Return the squared indicators μ_j(u, v; T)² of the u-step (paper, Proposition 4 (i)).

    For every element T that does not meet Ω_D,

        μ_j(u, v; T)² = h_T⁴ ‖∇v‖⁴_{L∞(T)} ‖s(u)‖²_{L2(T)} + h_T² ‖2v s(u)∇v‖²_{L2(T)}
                        + h_T ‖(v² + η)[s(u) n]‖²_{L2(∂T∖Ω̄_D)},

    the residual of a_j(v; u, φ) = ∫ (P_j(v²) + η) s(u) : ∇φ = 0, with the flux s = ∇u of the
    paper (anti-plane) or s = σ(u)/2 of plane elasticity (:mod:`ngat.elasticity`,
    docs/plane-elasticity.md; with an energy split s⁺ in the first two terms and the flux
    (v² + η) s⁺ + s⁻ on edges): the element residual div((v² + η) s) = 2v s∇v for P1 u, and the
    jump of the normal flux (v² + η)[s n] on interior edges, the flux (v² + η) s n itself on
    Neumann edges (outer boundary outside Ω̄_D and both faces of each slit). For s = ∇u this is
    Proposition 4 (i) term by term. The paper prints the edge term as ‖(v² + η)|∇u|²‖; the
    flux jump is the residual's (see docs/design.md). Every integral is exact for P1 data.

    "Meets": an element meets Ω_D if one of its vertices is a Dirichlet vertex, and its
    indicator is 0. Edges with both end points in Ω̄_D are left out of the edge sums; given
    the element rule this changes nothing (no kept element has such an edge) and only makes
    the edge term follow the paper's ∂T∖Ω̄_D literally.

    Parameters
    ----------
    arrays
        Element geometry of the mesh.
    edges
        Edge topology of the same mesh.
    u, v
        DOF values of the displacement u and nodal values of the phase field v.
    eta
        Residual stiffness η.
    dirichlet
        Boolean vertex mask of Ω̄_D (the vertices whose u is fixed by the Dirichlet data).
    elasticity
        The model's energy density; default anti-plane (the paper).
    fixed
        Boolean mask of the DOFs of u held by Dirichlet data, faces and edges (default: none
        beyond ``dirichlet``). A component of the flux on an edge whose two end points hold
        that component is no residual and is left out (a Dirichlet edge of the outer boundary
        holding u_y leaves the traction's x component in the sum).

    Returns
    -------
    numpy.ndarray
        μ_j(u, v; T)², shape (ne,); μ_j(u, v) is the square root of the sum.
    """
    elasticity = elasticity or AntiPlane()
    h, h2, area = arrays.diameter, arrays.h2, arrays.area
    grad_v = arrays.gradient(v)
    flux, intact = elasticity.fluxes(elasticity.gradient(arrays, u))
    grad_v_sq = arrays.squared_gradient(v)
    coupling = np.sqrt((np.einsum("eik,ek->ei", flux, grad_v) ** 2).sum(axis=1))  # |s∇v|
    flux_sq = row_sum((flux * flux).reshape(arrays.ne, -1))  # |s|², numpy's sum to the last bit
    indicators = h2 * h2 * grad_v_sq * grad_v_sq * flux_sq * area
    v_squared = _linear_square_integral(arrays, _corner_values(arrays, v))  # ∫_T v²
    indicators += 4 * h2 * coupling * coupling * v_squared
    # ∫_e (v² + η)² ds for v linear from a to b along e: with a², ab, b² (products, not
    # powers, which numpy evaluates ten times slower) the quartic is a⁴ + a³b + a²b² + ab³ + b⁴.
    a, b = v[edges.first], v[edges.second]
    aa, ab, bb = a * a, a * b, b * b
    weight = edges.length * (
        (aa * aa + aa * ab + ab * ab + ab * bb + bb * bb) / 5
        + 2 * eta * (aa + ab + bb) / 3
        + eta**2
    )
    jumps = flux_jumps(arrays, edges, elasticity, u)
    held = np.zeros_like(jumps, dtype=bool)
    if fixed is not None:
        held = np.stack([edges.within(f) for f in fixed.reshape(elasticity.components, -1)], 1)
        jumps = np.where(held, 0.0, jumps)
    per_edge = weight * row_sum(jumps * jumps)
    if intact is not None:
        # The flux (v² + η) s⁺ + s⁻ of an energy split: its jump is (v² + η)[s⁺n] + [s⁻n].
        intact_jumps = np.where(held, 0.0, edges.element_flux_jump(intact))
        mean = edges.length * ((a**2 + a * b + b**2) / 3 + eta)  # ∫_e (v² + η) ds
        per_edge += 2 * mean * (jumps * intact_jumps).sum(axis=1)
        per_edge += edges.length * (intact_jumps**2).sum(axis=1)
    per_edge[edges.within(dirichlet)] = 0.0
    indicators += h * edges.element_sum(per_edge)
    indicators[edges.meets(dirichlet)] = 0.0
    return indicators


def nu_estimator(
    arrays: MeshArrays,
    edges: EdgeTopology,
    u: np.ndarray,
    v: np.ndarray,
    surface: CrackDensity,
    crack: np.ndarray,
    elasticity: Elasticity | None = None,
    gc: float = 1.0,
) -> np.ndarray:
    """Return the squared indicators ν_j(u, v; T)² of the v-step (paper, Proposition 4 (ii)).

    For every element T that does not meet CR(t_k), with α = 1/(4ε),

        ν_j(u, v; T)² = h_T⁴ ‖∇v‖²_{L∞(T)} ‖α + |∇u|²‖²_{L2(T)}
                        + h_T² ‖(α + |∇u|²)v − α‖²_{L2(T)} + ε² h_T ‖[∂_n v]‖²_{L2(∂T∖CR)},

    the residual of b_j(u; v, ψ) = 0, divided by G_c. For the plane models |∇u|² becomes
    W(u)/G_c, the energy density of :mod:`ngat.elasticity` (the v-equation only sees W; with
    an energy split, W⁺). For the AT1 crack density (:mod:`ngat.crack_density`) α becomes its
    q (0) in the reaction and its f (3/(16ε)) in the source, and ε its d (3ε/8).

    Where v = 1 the bound v ≤ 1 may hold v (always in AT1's elastic phase): there the
    residual's negative part, which would push v above 1, is the bound's multiplier, not an
    error. The element residual takes, at a vertex with v ≥ 1, only its positive part (for AT2
    the residual there is W/G_c ≥ 0, so the paper's estimator is unchanged).
    v is continuous, so the jump of ∇v across an edge is
    its normal part, [∂_n v]; on boundary edges (the whole outer boundary, Ω_D included, since
    v is free there, and both faces of each slit) the flux ∂_n v itself is used. Every
    integral is exact for P1 data ((α + |∇u|²)v − α is linear on T).

    "Meets": an element meets CR if one of its vertices is in the crack set, and its indicator
    is 0. Edges with both end points in CR are left out of the edge sums (no kept element has
    one; see :func:`mu_estimator`).

    Parameters
    ----------
    arrays
        Element geometry of the mesh.
    edges
        Edge topology of the same mesh.
    u, v
        DOF values of the displacement u and nodal values of the phase field v.
    surface
        Crack density γ (AT2: α = 1/(4ε) and ε, the paper's).
    crack
        Boolean vertex mask of CR(t_k), where v = 0 is imposed.
    elasticity
        The model's energy density; default anti-plane (the paper).
    gc
        Fracture toughness G_c.

    Returns
    -------
    numpy.ndarray
        ν_j(u, v; T)², shape (ne,); ν_j(u, v) is the square root of the sum.
    """
    h, h2, area = arrays.diameter, arrays.h2, arrays.area
    reaction = surface.reaction + (elasticity or AntiPlane()).degraded_density(arrays, u) / gc
    indicators = h2 * h2 * arrays.squared_gradient(v) * reaction * reaction * area
    residual = []
    for local in _corner_values(arrays, v):
        value = reaction * local - surface.source
        residual.append(np.where(local >= 1, np.maximum(value, 0.0), value))
    indicators += h2 * _linear_square_integral(arrays, residual)
    per_edge = surface.diffusion**2 * edges.length * edges.normal_flux_jump(v) ** 2
    per_edge[edges.within(crack)] = 0.0
    indicators += h * edges.element_sum(per_edge)
    indicators[edges.meets(crack)] = 0.0
    return indicators
