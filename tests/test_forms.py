"""The lumped rule and the forms a_j, b_j (paper, Definition 2 and Hypothesis A)."""

import numpy as np
import pytest
from ngsolve import H1, TRIG, CoefficientFunction, H1LumpingFESpace, Integrate, grad, x, y
from ngsolve.meshes import MakeStructured2DMesh

from ngat.crack_density import crack_density
from ngat.forms import (
    LumpedAssembler,
    MeshArrays,
    a_form,
    b_form,
    distances,
    element_diameters,
    exact_dx,
    lumped_dx,
    row_sum,
    same_values,
    sparse_from_coo,
    vertex_rule,
)
from ngat.parameters import ModelParameters
from ngat.scene import load_scene
from ngat.state import ATState

AT2 = crack_density("at2", 0.05)
"""The paper's crack density with ε = 0.05."""


def test_vertex_rule_matches_ngsolve_lumping_rule():
    mesh = MakeStructured2DMesh(quads=False, nx=2, ny=2)
    reference = H1LumpingFESpace(mesh, order=1).GetIntegrationRules()[TRIG]
    ours = vertex_rule()
    assert sorted(p[:2] for p in reference.points) == sorted(p[:2] for p in ours.points)
    np.testing.assert_allclose(sorted(reference.weights), sorted(ours.weights))


def test_distances_are_numpys_norms_to_the_last_bit():
    rng = np.random.default_rng(7)
    points, point = rng.normal(size=(1000, 2)) * 10.0, rng.normal(size=2)
    assert np.array_equal(distances(points, point), np.linalg.norm(points - point, axis=1))
    assert distances(np.array([[3.0, 4.0]]), (0, 0))[0] == 5.0


def test_touching_elements_are_those_with_a_vertex_in_the_set():
    arrays = MeshArrays(load_scene("two-slits").make_mesh(0.5))
    mask = np.random.default_rng(8).random(arrays.nv) < 0.2
    touching = arrays.touching(mask)
    assert np.array_equal(touching, mask[arrays.elements].any(axis=1))
    assert 0 < touching.sum() < arrays.ne


def test_lumped_weights_sum_to_element_area():
    mesh = load_scene("two-slits").make_mesh(0.5)
    per_element = np.asarray(
        Integrate(CoefficientFunction(1) * lumped_dx(), mesh, element_wise=True)
    )
    np.testing.assert_allclose(per_element, MeshArrays(mesh).area, rtol=1e-13)
    np.testing.assert_allclose(per_element.sum(), 7 * 6, rtol=1e-13)


def test_lumped_rule_integrates_nodal_interpolant():
    # ∫ P_j(x²) = Σ_T |T|/3 Σ_vertices x_i², not ∫ x².
    mesh = MakeStructured2DMesh(quads=False, nx=4, ny=4)
    arrays = MeshArrays(mesh)
    exact = np.sum(arrays.area * arrays.vertex_mean(arrays.coords[:, 0] ** 2))
    assert abs(Integrate(x * x * lumped_dx(), mesh) - exact) < 1e-14
    assert abs(exact - 1 / 3) > 1e-3


@pytest.mark.parametrize("lumped", [True, False])
def test_fast_assembly_equals_ngsolve_forms(lumped):
    scene = load_scene("two-slits")
    state = ATState(scene.make_mesh(0.5), ModelParameters(), scene.loads)
    state.v.Set(0.5 + 0.4 * x * y / 42)
    state.u.Set(x * x - y)
    a = a_form(state.fes, state.v, 1e-5, lumped=lumped)
    b = b_form(state.fes, state.u, AT2, lumped=lumped)
    a.Assemble()
    b.Assemble()
    assembler = LumpedAssembler(state.arrays, a.mat, lumped=lumped)
    grad_u_sq = (state.arrays.gradient(state.u_values) ** 2).sum(axis=1)
    np.testing.assert_allclose(
        assembler.a_values(state.v_values, 1e-5), a.mat.AsVector().FV().NumPy(), atol=1e-12
    )
    np.testing.assert_allclose(
        assembler.b_values(grad_u_sq, AT2), b.mat.AsVector().FV().NumPy(), atol=1e-11
    )


def test_unlumped_forms_differ_from_lumped_ones():
    # The consistent-mass values must not coincide with the lumped ones (else the test above
    # would not tell the two apart): the mass moves weight off the diagonal.
    mesh = MakeStructured2DMesh(quads=False, nx=4, ny=4)
    a = a_form(H1(mesh, order=1), 1.0, 0.0).Assemble()
    lumped, consistent = (LumpedAssembler(MeshArrays(mesh), a.mat, lumped=k) for k in (True, False))
    rng = np.random.default_rng(1)
    v, grad_u_sq = rng.uniform(0, 1, mesh.nv), rng.uniform(0, 5, mesh.ne)
    assert np.abs(lumped.a_values(v, 0) - consistent.a_values(v, 0)).max() > 1e-3
    assert (
        np.abs(lumped.b_values(grad_u_sq, AT2) - consistent.b_values(grad_u_sq, AT2)).max() > 1e-3
    )
    # The total mass Σ_ab M_ab = ∫ 1 is the same, so the sums of all entries agree.
    np.testing.assert_allclose(
        lumped.b_values(grad_u_sq, AT2).sum(), consistent.b_values(grad_u_sq, AT2).sum()
    )


@pytest.mark.parametrize("lumping", [True, False])
def test_energies_equal_ngsolve_integrals(lumping):
    # I_j of eq. (7) with the vertex rule, or without P_j integrated exactly.
    scene = load_scene("two-slits")
    model = ModelParameters(lumping=lumping)
    state = ATState(scene.make_mesh(0.5), model, scene.loads)
    state.v.Set(0.5 + 0.4 * x * y / 42)
    state.u.Set(x * x - y)
    u, v = state.u, state.v
    rule = lumped_dx() if lumping else exact_dx()
    bulk = Integrate((v * v + model.eta) * grad(u) * grad(u) * rule, state.mesh)
    surface = Integrate(
        (model.alpha * (1 - v) * (1 - v) + model.eps * grad(v) * grad(v)) * rule, state.mesh
    )
    energies = state.energies()
    np.testing.assert_allclose([energies["bulk"], energies["surface"]], [bulk, surface], rtol=1e-12)
    other = ATState(state.mesh, ModelParameters(lumping=not lumping), scene.loads)
    other.u_values[:], other.v_values[:] = state.u_values, state.v_values
    assert abs(other.energies()["total"] / energies["total"] - 1) > 1e-4


def test_energies_computed_once_per_mesh_and_fields(monkeypatch):
    # The memo of ATState.energies: the same pair is computed once, a change of u, of v or of
    # the mesh anew, and every answer equals the functional's own.
    scene = load_scene("two-slits")
    state = ATState(scene.make_mesh(0.5), ModelParameters(), scene.loads)
    state.v.Set(0.5 + 0.4 * x * y / 42)
    state.u.Set(x * x - y)
    computed = []
    functional = state.functional
    original = functional.energies
    monkeypatch.setattr(functional, "energies", lambda *a: computed.append(1) or original(*a))

    def fresh():
        return original(state.arrays, state.u_values, state.v_values)

    first = state.energies()
    first["total"] = -1.0  # a caller's copy: the memo keeps its own
    assert state.energies() == fresh() and len(computed) == 1
    state.u_values[3] += 0.1
    assert state.energies() == fresh() and len(computed) == 2
    state.v_values[5] -= 0.1
    assert state.energies() == fresh() and len(computed) == 3
    state.mesh.Refine()
    state.mesh_changed()
    assert state.energies() == fresh() and len(computed) == 4


def test_b_matrix_is_an_m_matrix_on_a_nonobtuse_mesh():
    # Hypothesis A: right triangles have non-positive stiffness off-diagonals, and the lumped
    # mass adds to the diagonal only, so b_j has non-positive off-diagonals.
    mesh = MakeStructured2DMesh(quads=False, nx=6, ny=6)
    arrays = MeshArrays(mesh)
    rng = np.random.default_rng(0)
    fes_mat = a_form(H1(mesh, order=1), 1.0, 0.0)
    fes_mat.Assemble()
    assembler = LumpedAssembler(arrays, fes_mat.mat)
    values = assembler.b_values(rng.uniform(0, 50, arrays.ne), AT2)
    _, cols, rowptr = fes_mat.mat.CSR()
    rows = np.repeat(np.arange(arrays.nv), np.diff(np.asarray(rowptr, dtype=np.int64)))
    off = rows != np.asarray(cols, dtype=np.int64)
    assert values[off].max() <= 1e-14
    assert values[~off].min() > 0
    # Without lumping the mass has positive off-diagonals |T|/12 (|∇u|² + α): on the 36
    # hypotenuses, whose stiffness entry is 0 (right angle opposite), b_j is positive off the
    # diagonal even with ∇u = 0, so it is not an M-matrix on this non-obtuse mesh.
    alpha = 1 / (4 * 0.05)
    consistent = LumpedAssembler(arrays, fes_mat.mat, lumped=False).b_values(
        np.zeros(arrays.ne), AT2
    )
    positive = consistent[off][consistent[off] > 0]
    assert len(positive) == 2 * 36
    np.testing.assert_allclose(positive, 2 * arrays.area[0] / 12 * alpha, rtol=1e-12)


def test_unique_keys_is_numpys_unique_with_inverse():
    from ngat.forms import unique_keys

    keys = np.random.default_rng(1).integers(0, 1000, size=10_000)
    distinct, position, order = unique_keys(keys)
    expected, inverse = np.unique(keys, return_inverse=True)
    np.testing.assert_array_equal(distinct, expected)
    np.testing.assert_array_equal(position, inverse)
    np.testing.assert_array_equal(order, np.argsort(inverse, kind="stable"))


def test_row_sums_vertex_means_stiffness_sums_centroids_and_diameters_are_numpys_to_the_last_bit():
    # The fast paths promise the same numbers as numpy's reductions, which the runs' bit-for-bit
    # repeatability (checkpoints, the stored regression values) relies on.
    rng = np.random.default_rng(4)
    for columns in (1, 2, 3):
        values = rng.standard_normal((5000, columns)) * 10.0 ** rng.integers(-8, 8, (5000, 1))
        np.testing.assert_array_equal(row_sum(values), values.sum(axis=1))
    arrays = MeshArrays(load_scene("two-slits").make_mesh(0.5))
    v = rng.random(arrays.nv) * 10.0 ** rng.integers(-8, 8, arrays.nv)  # rounding order shows
    np.testing.assert_array_equal(arrays.vertex_mean(v), v[arrays.elements].mean(axis=1))
    corners = arrays.coords[arrays.elements]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    np.testing.assert_array_equal(arrays.area, 0.5 * np.abs(det))
    g1 = np.stack([e2[:, 1], -e2[:, 0]], axis=1) / det[:, None]
    g2 = np.stack([-e1[:, 1], e1[:, 0]], axis=1) / det[:, None]
    np.testing.assert_array_equal(arrays.grad_phi, np.stack([-(g1 + g2), g1, g2], axis=1))
    grad_phi = arrays.grad_phi
    stiffness = arrays.area[:, None, None] * np.einsum("eak,ebk->eab", grad_phi, grad_phi)
    np.testing.assert_array_equal(arrays.stiffness, stiffness)
    longest = np.linalg.norm(corners[:, [1, 2, 0]] - corners, axis=2).max(axis=1)
    np.testing.assert_array_equal(element_diameters(arrays.coords, arrays.elements), longest)
    weights = rng.random(arrays.ne) * 10.0 ** rng.integers(-8, 8, arrays.ne)
    repeated = np.bincount(arrays.elements.ravel(), np.repeat(weights, 3), minlength=arrays.nv)
    np.testing.assert_array_equal(arrays.vertex_sum(weights), repeated)
    centroid = arrays.coords[arrays.elements].mean(axis=1)
    np.testing.assert_array_equal(arrays.centroid, centroid)


def test_element_sums_are_the_scatter_of_the_element_matrices_to_the_last_bit():
    # a_j's and b_j's values come from products with per-mesh matrices of the element matrices;
    # their sums must be those of scattering c_T K_T with bincount (the order in which every
    # earlier release summed, which the stored regression values and the runs' repeatability
    # rely on), on a scalar and on a vector space, with a part given for every element or one
    # for all.
    from ngat.elasticity import elasticity
    from ngat.forms import graph_matrix

    arrays = MeshArrays(load_scene("two-slits").make_mesh(0.3))
    rng = np.random.default_rng(5)
    coefficient = rng.random(arrays.ne) * 10.0 ** rng.integers(-6, 2, arrays.ne)
    plane = elasticity("plane_strain", poisson=0.3)
    consistent = ((np.ones((3, 3)) + np.eye(3)) / 12)[None]
    cases = ((1, arrays.stiffness, consistent), (2, plane.element_stiffness(arrays), None))
    for components, stiffness, shared in cases:
        matrix = graph_matrix(arrays, components)
        assembler = LumpedAssembler(arrays, matrix, True, components, stiffness)
        for local in (stiffness, shared) if shared is not None else (stiffness,):
            products = coefficient[:, None, None] * local
            scattered = np.bincount(
                assembler.position, weights=products.ravel(), minlength=assembler.nnz
            )
            summed = assembler.element_sum(local) @ coefficient
            np.testing.assert_array_equal(summed, scattered)
            assert np.abs(summed).max() > 0
        np.testing.assert_array_equal(
            assembler.weighted_values([coefficient]), assembler.element_sum(stiffness) @ coefficient
        )


def test_recalled_element_quantities_are_those_of_the_current_values():
    # MeshArrays keeps |∇w|², ∇w and P_j(w²) of recent nodal values: asked again with equal
    # values it returns the same numbers (read-only), with changed values new ones.
    arrays = MeshArrays(load_scene("two-slits").make_mesh(0.5))
    rng = np.random.default_rng(7)
    v = rng.random(arrays.nv)
    gradient = arrays.gradient(v)
    first = arrays.squared_gradient(v)
    mean = arrays.square_mean(v)
    assert arrays.squared_gradient(v.copy()) is first
    assert arrays.square_mean(v.copy()) is mean
    assert not first.flags.writeable and not gradient.flags.writeable
    np.testing.assert_array_equal(first, (gradient**2).sum(axis=1))
    np.testing.assert_array_equal(mean, (v * v)[arrays.elements].mean(axis=1))
    v[0] += 0.5  # in place, as the half-steps change the fields
    changed = arrays.squared_gradient(v)
    element = np.flatnonzero((arrays.elements == 0).any(axis=1))[0]
    assert changed[element] != first[element]
    fresh = MeshArrays(load_scene("two-slits").make_mesh(0.5))
    np.testing.assert_array_equal(changed, fresh.squared_gradient(v))
    np.testing.assert_array_equal(arrays.square_mean(v), fresh.square_mean(v))
    np.testing.assert_array_equal(arrays.square_mean(v, lumped=False), fresh.square_mean(v, False))


@pytest.mark.parametrize("where", [0, 1, 500, 1000, 1001, 2001])
def test_same_values_tells_an_array_with_one_other_entry_apart(where):
    # The memos compare every 64th entry first, then all: a change anywhere counts.
    stored = np.random.default_rng(5).random(2002)
    values = stored.copy()
    assert same_values(stored, values)
    values[where] += 1e-15
    assert not same_values(stored, values)
    assert same_values(stored, values) == np.array_equal(stored, values)


def test_same_values_of_other_shapes_empty_arrays_and_nan_as_numpy_says():
    assert not same_values(np.zeros(5), np.zeros(6))
    assert same_values(np.zeros(0), np.zeros(0))
    assert same_values(np.zeros((2, 3), dtype=bool), np.zeros((2, 3), dtype=bool))
    nan = np.array([1.0, np.nan, 2.0])
    assert not same_values(nan, nan.copy())  # NaN equals nothing, as in numpy.array_equal


def test_sparse_from_coo_is_scipys_csr_with_duplicates_summed():
    from scipy.sparse import coo_matrix

    rng = np.random.default_rng(3)
    rows, cols = rng.integers(0, 40, 300), rng.integers(0, 30, 300)
    values = rng.standard_normal(300)
    ours = sparse_from_coo(rows, cols, values, 40, 30)
    theirs = coo_matrix((values, (rows, cols)), shape=(40, 30)).tocsr()
    theirs.sum_duplicates()
    theirs.sort_indices()
    data, indices, indptr = ours.CSR()
    np.testing.assert_array_equal(np.asarray(indptr), theirs.indptr)
    np.testing.assert_array_equal(np.asarray(indices), theirs.indices)
    np.testing.assert_allclose(np.asarray(data), theirs.data, rtol=1e-14)
