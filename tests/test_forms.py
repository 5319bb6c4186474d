"""The lumped rule and the forms a_j, b_j (paper, Definition 2 and Hypothesis A)."""

import numpy as np
from ngsolve import H1, TRIG, CoefficientFunction, H1LumpingFESpace, Integrate, x, y
from ngsolve.meshes import MakeStructured2DMesh

from ngat.forms import LumpedAssembler, MeshArrays, a_form, b_form, lumped_dx, vertex_rule
from ngat.parameters import ModelParameters
from ngat.scene import load_scene
from ngat.state import ATState


def test_vertex_rule_matches_ngsolve_lumping_rule():
    mesh = MakeStructured2DMesh(quads=False, nx=2, ny=2)
    reference = H1LumpingFESpace(mesh, order=1).GetIntegrationRules()[TRIG]
    ours = vertex_rule()
    assert sorted(p[:2] for p in reference.points) == sorted(p[:2] for p in ours.points)
    np.testing.assert_allclose(sorted(reference.weights), sorted(ours.weights))


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


def test_fast_assembly_equals_ngsolve_forms():
    scene = load_scene("two-slits")
    state = ATState(scene.make_mesh(0.5), ModelParameters(), scene.loads)
    state.v.Set(0.5 + 0.4 * x * y / 42)
    state.u.Set(x * x - y)
    a, b = a_form(state.fes, state.v, 1e-5), b_form(state.fes, state.u, 0.05)
    a.Assemble()
    b.Assemble()
    assembler = LumpedAssembler(state.arrays, a.mat)
    grad_u_sq = (state.arrays.gradient(state.u_values) ** 2).sum(axis=1)
    np.testing.assert_allclose(
        assembler.a_values(state.v_values, 1e-5), a.mat.AsVector().FV().NumPy(), atol=1e-12
    )
    np.testing.assert_allclose(
        assembler.b_values(grad_u_sq, 0.05), b.mat.AsVector().FV().NumPy(), atol=1e-11
    )


def test_b_matrix_is_an_m_matrix_on_a_nonobtuse_mesh():
    # Hypothesis A: right triangles have non-positive stiffness off-diagonals, and the lumped
    # mass adds to the diagonal only, so b_j has non-positive off-diagonals.
    mesh = MakeStructured2DMesh(quads=False, nx=6, ny=6)
    arrays = MeshArrays(mesh)
    rng = np.random.default_rng(0)
    fes_mat = a_form(H1(mesh, order=1), 1.0, 0.0)
    fes_mat.Assemble()
    assembler = LumpedAssembler(arrays, fes_mat.mat)
    values = assembler.b_values(rng.uniform(0, 50, arrays.ne), 0.05)
    _, cols, rowptr = fes_mat.mat.CSR()
    rows = np.repeat(np.arange(arrays.nv), np.diff(np.asarray(rowptr, dtype=np.int64)))
    off = rows != np.asarray(cols, dtype=np.int64)
    assert values[off].max() <= 1e-14
    assert values[~off].min() > 0
