"""MKL PARDISO factorisations (ngat.pardiso): solutions, inertia, orderings, fallback.

Checked against scipy's sparse LU and numpy's dense eigenvalues on P1 matrices of a small
mesh; skipped where MKL is not installed (there ngat uses NGSolve's sparse Cholesky, checked
by the fallback test).
"""

import multiprocessing

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from netgen.geom2d import unit_square
from ngsolve import H1, BilinearForm, Mesh, dx, grad, x, y
from ngsolve.meshes import MakeStructured2DMesh
from threadpoolctl import threadpool_limits

import ngat.pardiso
from ngat.driver import run
from ngat.forms import MeshArrays, graph_matrix, sparse_from_coo, upper_graph
from ngat.pardiso import (
    PardisoInverse,
    background_ordering,
    sparse_inverse,
    vertex_ordering,
)
from ngat.scene import load_scene

needs_mkl = pytest.mark.skipif(not ngat.pardiso.AVAILABLE, reason="MKL is not installed")


@pytest.fixture(scope="module")
def p1():
    """Stiffness and mass matrices of P1 on a unit square (about 250 DOFs), left side fixed."""
    mesh = Mesh(unit_square.GenerateMesh(maxh=0.08))
    space = H1(mesh, order=1, dirichlet="left")
    u, w = space.TnT()
    stiffness = BilinearForm(grad(u) * grad(w) * dx).Assemble().mat
    mass = BilinearForm(u * w * dx).Assemble().mat
    free = np.array(space.FreeDofs(), dtype=bool)
    return as_scipy(stiffness), as_scipy(mass), free


def as_scipy(matrix):
    values, cols, rowptr = map(np.array, matrix.CSR())
    return sp.csr_matrix((values, cols, rowptr), shape=matrix.shape)


def as_ngsolve(matrix):
    coo = matrix.tocoo()
    return sparse_from_coo(coo.row, coo.col, coo.data, *matrix.shape)


def solve(inverse, matrix, rhs):
    x = matrix.CreateColVector()
    x.FV().NumPy()[:] = rhs
    return (inverse * x).Evaluate().FV().NumPy().copy()


@needs_mkl
def test_the_solution_is_that_of_the_free_block_and_zero_on_the_fixed_dofs(p1):
    stiffness, mass, free = p1
    matrix = stiffness + mass
    rhs = np.random.default_rng(0).random(matrix.shape[0])
    x = solve(PardisoInverse(as_ngsolve(matrix), free), as_ngsolve(matrix), rhs)
    expected = spla.spsolve(matrix[free][:, free].tocsc(), rhs[free])
    assert np.allclose(x[free], expected, rtol=1e-11, atol=1e-13 * np.abs(expected).max())
    assert not np.any(x[~free])


@needs_mkl
def test_a_matrix_stored_by_its_lower_triangle_is_factorised_to_the_same_bits(p1):
    stiffness, mass, free = p1
    matrix = stiffness + mass
    rhs = np.random.default_rng(1).random(matrix.shape[0])
    whole = as_ngsolve(matrix)
    lower = as_ngsolve(sp.tril(matrix, format="csr"))
    assert lower.nze < 0.6 * whole.nze
    x_whole = solve(PardisoInverse(whole, free), whole, rhs)
    assert np.array_equal(solve(PardisoInverse(lower, free), lower, rhs), x_whole)


@needs_mkl
def test_inverses_on_one_graph_share_one_analysis_each_in_a_slot_of_its_own(p1):
    """As a_j, b_j and the bounded v-step's b_j on fewer DOFs do on a mesh: one analysis."""
    stiffness, mass, free = p1
    first, second = stiffness + mass, stiffness + 5.0 * mass
    fewer = free.copy()
    fewer[np.flatnonzero(free)[::7]] = False
    a = PardisoInverse(as_ngsolve(first), free)
    b = PardisoInverse(as_ngsolve(second), fewer, analysis=a, slot=2)
    assert b.factor is a.factor and (a.slot, b.slot) == (1, 2)
    rhs = np.random.default_rng(5).random(first.shape[0])
    for inverse, matrix, mask in ((a, first, free), (b, second, fewer)):
        x = solve(inverse, as_ngsolve(matrix), rhs)  # a's after b's factorisation: its own slot
        expected = spla.spsolve(matrix[mask][:, mask].tocsc(), rhs[mask])
        assert np.allclose(x[mask], expected, rtol=1e-11, atol=1e-13 * np.abs(expected).max())
        assert not np.any(x[~mask])
        alone = PardisoInverse(as_ngsolve(matrix), mask)  # an analysis of its own
        assert np.array_equal(solve(alone, as_ngsolve(matrix), rhs), x)
    with pytest.raises(ValueError, match="one graph"):
        PardisoInverse(as_ngsolve(sp.tril(first, format="csr")), free, analysis=a, slot=3)
    with pytest.raises(ValueError, match="slot 4"):
        PardisoInverse(as_ngsolve(first), free, analysis=a, slot=4)


@needs_mkl
@pytest.mark.parametrize("shift", [0.0, 30.0, 300.0])
def test_the_factorisation_counts_the_negative_eigenvalues(p1, shift):
    stiffness, mass, free = p1
    matrix = stiffness - shift * mass
    eigenvalues = np.linalg.eigvalsh(matrix[free][:, free].toarray())
    assert np.min(np.abs(eigenvalues)) > 1e-6 * np.max(np.abs(eigenvalues))  # not singular
    inverse = PardisoInverse(as_ngsolve(matrix), free, definite=False)
    assert inverse.negative_eigenvalues == np.sum(eigenvalues < 0)
    if shift:
        assert inverse.negative_eigenvalues > 0


@needs_mkl
def test_update_refactorises_with_the_values_written_in_place(p1):
    stiffness, mass, free = p1
    matrix = as_ngsolve(stiffness + mass)
    inverse = PardisoInverse(matrix, free)
    rhs = np.random.default_rng(2).random(matrix.height)
    first = solve(inverse, matrix, rhs)
    matrix.AsVector().FV().NumPy()[:] = (stiffness + 5.0 * mass).data
    inverse.Update()
    again = solve(inverse, matrix, rhs)
    expected = spla.spsolve((stiffness + 5.0 * mass)[free][:, free].tocsc(), rhs[free])
    assert np.allclose(again[free], expected, rtol=1e-11, atol=1e-13 * np.abs(expected).max())
    assert not np.allclose(again, first)
    inverse.Update()
    assert np.array_equal(solve(inverse, matrix, rhs), again)  # the same values, the same bits


@needs_mkl
def test_one_vertex_ordering_serves_the_free_dofs_and_every_component(p1):
    stiffness, mass, free = p1
    n = stiffness.shape[0]
    ordering = vertex_ordering(as_ngsolve(stiffness + mass))
    assert np.array_equal(np.sort(ordering), np.arange(n))
    # Two components per vertex (component-major), coupled, the first fixed on the left side.
    block = sp.bmat([[stiffness + mass, 0.1 * mass], [0.1 * mass, stiffness + mass]], "csr")
    free2 = np.concatenate([free, np.ones(n, dtype=bool)])
    inverse = PardisoInverse(as_ngsolve(block), free2, ordering=ordering)
    expected = [c * n + i for i in ordering for c in (0, 1)]  # the fixed DOFs too
    assert np.array_equal(inverse.factor.ordering, expected), "vertex by vertex, in the order"
    rhs = np.random.default_rng(4).random(2 * n)
    x = solve(inverse, as_ngsolve(block), rhs)
    reference = spla.spsolve(block[free2][:, free2].tocsc(), rhs[free2])
    assert np.allclose(x[free2], reference, rtol=1e-11, atol=1e-13 * np.abs(reference).max())


@needs_mkl
def test_the_background_ordering_from_the_triangles_is_metis_ordering_of_the_p1_matrix():
    mesh = Mesh(unit_square.GenerateMesh(maxh=0.08))
    mesh.SetRefinementFlags([i % 3 == 0 for i in range(mesh.ne)])
    mesh.Refine()  # bisected: vertex numbers no longer follow the mesher's
    arrays = MeshArrays(mesh)
    matrix = graph_matrix(arrays)
    indptr, indices = upper_graph(arrays.elements, arrays.nv)
    _, expected_indptr, expected_indices = ngat.pardiso._upper_triangle(
        matrix, np.arange(arrays.nv)
    )
    assert np.array_equal(indptr, expected_indptr)
    assert np.array_equal(indices, expected_indices)
    expected = vertex_ordering(matrix)
    assert np.array_equal(background_ordering(lambda: (indptr, indices)).result(), expected)
    assert not np.array_equal(expected, np.arange(len(expected)))  # an ordering, not the identity


def test_without_mkl_the_inverse_is_ngsolves_sparse_cholesky(p1, monkeypatch):
    stiffness, mass, free = p1
    matrix = as_ngsolve(stiffness + mass)
    monkeypatch.setattr(ngat.pardiso, "AVAILABLE", False)
    inverse = sparse_inverse(matrix, free)
    assert not isinstance(inverse, PardisoInverse)
    assert not hasattr(inverse, "negative_eigenvalues")
    rhs = np.random.default_rng(3).random(matrix.height)
    expected = spla.spsolve((stiffness + mass)[free][:, free].tocsc(), rhs[free])
    x = solve(inverse, matrix, rhs)
    assert np.allclose(x[free], expected, rtol=1e-11, atol=1e-13 * np.abs(expected).max())


@needs_mkl
def test_a_run_without_mkl_reaches_the_same_states_to_round_off(tmp_path, monkeypatch):
    scene = load_scene("two-slits")
    overrides = {"adapt": "fixed", "maxh": 0.5, "eps": 0.5, "resolve_eps": False}
    parameters, _ = scene.configure(overrides=overrides)
    times = np.array([0.0, 0.5, 1.0])
    with_mkl = run(scene, parameters, times, tmp_path / "mkl")
    monkeypatch.setattr(ngat.pardiso, "AVAILABLE", False)
    without = run(scene, parameters, times, tmp_path / "cholesky")
    assert with_mkl.summary["versions"]["mkl"] != "none"
    assert without.summary["versions"]["mkl"] == "none"
    for a, b in zip(with_mkl.records, without.records, strict=True):
        assert a["am_iterations"] == b["am_iterations"]
        assert b["total"] == pytest.approx(a["total"], rel=1e-9)
        assert b["force"] == pytest.approx(a["force"], rel=1e-7, abs=1e-12)


@needs_mkl
@pytest.mark.parametrize("definite", [True, False])
def test_two_threads_factorise_to_the_same_bits_as_one(definite):
    """What lets ngat give MKL the cores while fixing every other pool (ngat.threads).

    On a mesh large enough for MKL to split the work (58k DOFs; two threads factorise
    it about 1.5 times faster), indefinite as well (shifted by the mass), with the inertia;
    and METIS's ordering, which runs on MKL's threads in the background.
    """
    space = H1(MakeStructured2DMesh(nx=240, ny=240), order=1, dirichlet="left")
    u, w = space.TnT()
    shift = 0.0 if definite else 2000.0
    form = BilinearForm(((1 + x * y) * grad(u) * grad(w) - shift * u * w) * dx).Assemble()
    free = np.array(space.FreeDofs(), dtype=bool)
    rhs = np.sin(np.arange(space.ndof))
    solutions, inertias, orderings = [], [], []
    for threads in (1, 2, 1, 2):
        with threadpool_limits(limits={"libmkl_rt": threads}):
            orderings.append(vertex_ordering(form.mat))
            inverse = PardisoInverse(form.mat, free, definite, orderings[-1])
            solutions.append(solve(inverse, form.mat, rhs))
            inertias.append(inverse.negative_eigenvalues)
    assert space.ndof > 50_000
    assert all(np.array_equal(ordering, orderings[0]) for ordering in orderings)
    assert all(np.array_equal(solution, solutions[0]) for solution in solutions)
    assert len(set(inertias)) == 1 and (inertias[0] > 0) != definite
    residual = as_scipy(form.mat) @ solutions[0] - rhs
    assert np.abs(residual[free]).max() < 1e-8 * np.abs(rhs).max()


@needs_mkl
def test_a_background_factorisation_gives_the_same_bits_and_the_solve_waits_for_it(p1):
    stiffness, mass, free = p1
    matrix = as_ngsolve(stiffness + mass)
    rhs = np.random.default_rng(5).random(matrix.height)
    inverse = PardisoInverse(matrix, free)
    matrix.AsVector().FV().NumPy()[:] = (stiffness + 7.0 * mass).data
    inverse.Update()
    expected = solve(inverse, matrix, rhs)
    matrix.AsVector().FV().NumPy()[:] = (stiffness + mass).data
    inverse.Update()
    matrix.AsVector().FV().NumPy()[:] = (stiffness + 7.0 * mass).data
    inverse.Update(background=True)  # returns at once; the next solve waits for the factors
    assert np.array_equal(solve(inverse, matrix, rhs), expected)


@needs_mkl
def test_a_definite_matrix_factorises_to_the_same_bits_whatever_mkls_threads():
    """The two-level factorisation runs on one thread, however many MKL has (TWO_LEVEL)."""
    space = H1(MakeStructured2DMesh(nx=160, ny=160), order=1, dirichlet="left")
    u, w = space.TnT()
    form = BilinearForm((1 + x * y) * grad(u) * grad(w) * dx).Assemble()
    free = np.array(space.FreeDofs(), dtype=bool)
    rhs = np.cos(np.arange(space.ndof))
    ordering = vertex_ordering(form.mat)
    solutions = []
    for threads in (2, 1, 2):
        with threadpool_limits(limits={"libmkl_rt": threads}):
            inverse = PardisoInverse(form.mat, free, ordering=ordering)
            assert inverse.factor.iparm[23] == ngat.pardiso.TWO_LEVEL
            solutions.append(solve(inverse, form.mat, rhs))
    assert all(np.array_equal(s, solutions[0]) for s in solutions)
    residual = as_scipy(form.mat) @ solutions[0] - rhs
    assert np.abs(residual[free]).max() < 1e-8 * np.abs(rhs).max()


def _factorise_in_background(matrix_and_free):
    matrix, free = matrix_and_free
    inverse = PardisoInverse(as_ngsolve(matrix), free, background=True)
    return solve(inverse, as_ngsolve(matrix), np.ones(matrix.shape[0]))


@needs_mkl
def test_a_forked_process_factorises_in_the_background_of_its_own(p1):
    """A child forked after the parent used its worker thread gets a worker of its own."""
    stiffness, mass, free = p1
    expected = _factorise_in_background((stiffness + mass, free))
    with multiprocessing.get_context("fork").Pool(1) as pool:
        result = pool.apply_async(_factorise_in_background, [(stiffness + mass, free)])
        assert np.array_equal(result.get(timeout=10), expected)
