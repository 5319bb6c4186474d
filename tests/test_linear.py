"""Linear solvers of the half-steps (issue 6): CG with h1amg against sparse Cholesky.

Both solve the same lumped systems; CG to a relative residual of 1e−10, so the alternating
minimisation must end at the same (u, v), also when the bounded v-step's active set runs and
when the mesh is refined between solves.
"""

import logging

import numpy as np
import pytest
from ngsolve import H1

import ngat.pardiso
from ngat.diagnostics import Diagnostics
from ngat.driver import run
from ngat.forms import a_form
from ngat.geometries import surfing_mode_i
from ngat.halfsteps import HalfStepSolvers
from ngat.linear import AMGConjugateGradient, HeldCholesky, LaggedCholesky
from ngat.minimization import StepResult
from ngat.operators import LumpedOperators
from ngat.parameters import ParameterError, Parameters
from ngat.scene import load_scene
from ngat.state import ATState

SOLVERS = ("direct", "cg-h1amg")


def _runs(tmp_path_factory, overrides, times):
    scene = load_scene("two-slits")
    results = {}
    for solver in SOLVERS:
        parameters, _ = scene.configure(
            overrides={
                "eps": 0.2,
                "am_tol": 1e-6,
                "linear_solver": solver,
                "nonlinear": "am",
                **overrides,
            }  # the half-steps' solves only: Newton's coupled solve is always direct
        )
        results[solver] = run(scene, parameters, times, tmp_path_factory.mktemp(solver))
    return results


@pytest.fixture(scope="module")
def bounded(tmp_path_factory):
    """Fixed mesh, pointwise irreversibility: the v-step's active set runs at t = 1.4."""
    overrides = {
        "adapt": "fixed",
        "maxh": 0.2,
        "irreversibility": "pointwise",
        "resolve_eps": False,
    }
    return _runs(tmp_path_factory, overrides, np.array([0.0, 1.3, 1.4]))


@pytest.fixture(scope="module")
def adaptive(tmp_path_factory):
    """Algorithm 2: the mesh is refined between solves."""
    return _runs(tmp_path_factory, {"tol": 0.5}, np.array([0.0, 1.0]))


def _relative_difference(results, field):
    direct = getattr(results["direct"].state, field)
    iterative = getattr(results["cg-h1amg"].state, field)
    return np.linalg.norm(iterative - direct) / np.linalg.norm(direct)


@pytest.mark.parametrize("field", ["u_values", "v_values"])
def test_cg_h1amg_gives_the_direct_solution_with_active_bounds(bounded, field):
    assert bounded["direct"].records[-1]["v_bound_active"] > 0, "the active set should run"
    assert bounded["cg-h1amg"].records[-1]["v_bound_active"] > 0
    assert _relative_difference(bounded, field) < 1e-6


@pytest.mark.parametrize("field", ["u_values", "v_values"])
def test_cg_h1amg_gives_the_direct_solution_on_refined_meshes(adaptive, field):
    direct, iterative = adaptive["direct"].records[-1], adaptive["cg-h1amg"].records[-1]
    assert direct["refinements"] > 0
    assert iterative["elements"] == direct["elements"]
    assert _relative_difference(adaptive, field) < 1e-6


def test_cg_iterations_are_recorded(bounded):
    for record in bounded["cg-h1amg"].records:
        assert record["cg_iterations"] >= record["linear_solves"] > 0
        assert 0 < record["cg_max_iterations"] < 100
        assert "linear-not-converged" not in record["warnings"]
    assert all(r["cg_iterations"] == 0 for r in bounded["direct"].records)


def test_half_steps_count_every_cg_solve():
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"eps": 0.2})
    state = ATState(scene.make_mesh(0.5), parameters.model, scene.loads, scene.crack)
    steps = HalfStepSolvers(state, linear_solver="cg-h1amg")
    state.apply_load(1.0)
    steps.solve_u()
    steps.solve_v(state.crack_set())
    assert len(steps.statistics.cg_iterations) == steps.statistics.solves == 2
    assert min(steps.statistics.cg_iterations) > 0
    assert steps.statistics.cg_not_converged == 0


def test_a_j_is_written_once_for_the_same_u_and_v(monkeypatch):
    # A load step's reaction forces ask for the a_j its last v-step assembled already.
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"eps": 0.2})
    state = ATState(scene.make_mesh(0.5), parameters.model, scene.loads, scene.crack)
    state.apply_load(1.0)
    operators = LumpedOperators(state)
    written = operators.a_matrix.AsVector().FV().NumPy()
    computed, real = [], operators.u_matrix_values
    monkeypatch.setattr(operators, "u_matrix_values", lambda v=None: computed.append(v) or real(v))
    operators.assemble_a()
    operators.reaction_forces()
    assert len(computed) == 1
    state.v_values[:] = 0.5
    operators.assemble_a()
    assert len(computed) == 2 and np.array_equal(written, real())
    operators.assemble_a(np.full(state.arrays.nv, 0.25))  # another v: computed
    state.u_values[:] *= 2  # another u: computed (an energy split's a_j depends on u)
    operators.assemble_a()
    assert len(computed) == 4 and np.array_equal(written, real())
    operators.set_a_values(np.zeros_like(written))  # a restored factorisation's values
    operators.assemble_a()
    assert len(computed) == 5 and np.array_equal(written, real())


def test_invalid_linear_solver_is_named():
    with pytest.raises(ParameterError, match="linear_solver.*'gmres'"):
        Parameters().replace(linear_solver="gmres")


def test_cg_stopped_at_its_cap_is_reported(bounded, caplog):
    state = bounded["cg-h1amg"].state
    operators = LumpedOperators(state)
    operators.assemble_a()
    form = a_form(H1(state.mesh, order=1), state.v, state.model.eta)
    solver = AMGConjugateGradient([form], operators.a_matrix, ~state.dirichlet, maxiter=2)
    rhs, solution = operators.a_matrix.CreateColVector(), operators.a_matrix.CreateColVector()
    rhs.FV().NumPy()[:] = np.where(state.dirichlet, 0.0, 1.0)  # CG cannot meet it in 2 iterations
    with caplog.at_level(logging.WARNING, logger="ngat.linear"):
        solver.solve(rhs, solution)
    assert not solver.converged and solver.iterations == 2
    assert "CG with h1amg stopped at 2 iterations" in caplog.text
    diagnostics = Diagnostics("warn")
    found = diagnostics.check_step(state, StepResult(converged=True, cg_not_converged=1), 0.2, 0, 1)
    assert "linear-not-converged" in found


@pytest.mark.parametrize("model", ["plane_strain", "plane_stress"])
def test_vector_u_step_by_cg_with_block_h1amg_gives_the_direct_solution(model):
    # h1amg takes scalar spaces only: the vector u-step is preconditioned by one h1amg per
    # component on its diagonal block. The alternating minimisation must end where the direct
    # solver's does, with a damaged crack band (v = 0 on the slit's faces, the K_I field on the
    # frame), and CG must converge in a mesh-independent handful of iterations.
    scene = surfing_mode_i.make_scene(precrack=True)
    parameters, _ = scene.configure(overrides={"model": model, "eps": 0.05})
    fields = {}
    for solver in SOLVERS:
        state = ATState(scene.make_mesh(0.1), parameters.model, scene.loads, scene.crack)
        steps = HalfStepSolvers(state, linear_solver=solver)
        state.apply_load(0.2)
        for _ in range(3):
            steps.solve_u()
            steps.solve_v(state.crack_set())
        steps.solve_u()
        fields[solver] = state.u_values.copy(), state.v_values.copy()
        statistics = steps.statistics
    assert state.v_values.min() == 0.0 and state.elasticity.components == 2
    for direct, iterative in zip(fields["direct"], fields["cg-h1amg"], strict=True):
        assert np.linalg.norm(iterative - direct) <= 1e-8 * np.linalg.norm(direct)
    assert statistics.cg_not_converged == 0
    assert 0 < max(statistics.cg_iterations) < 100, statistics.cg_iterations


def test_split_with_cg_h1amg_is_refused():
    with pytest.raises(ParameterError, match="split=voldev"):
        Parameters().replace(model="plane_strain", split="voldev", linear_solver="cg-h1amg")


def test_held_cholesky_solves_the_subset_exactly(bounded):
    """A few DOFs held at 0 by the capacitance matrix: the solution of a new factorisation."""
    state = bounded["direct"].state
    operators = LumpedOperators(state)
    operators.assemble_b()
    free = ~state.crack_set()
    base = LaggedCholesky(operators.b_matrix, free, max_cg=0)
    rng = np.random.default_rng(0)
    held = rng.choice(np.flatnonzero(free), size=HeldCholesky.MAX_HELD, replace=False)
    subset = free.copy()
    subset[held] = False
    rhs = operators.b_matrix.CreateColVector()
    rhs.FV().NumPy()[:] = rng.standard_normal(len(free))
    expected, found = operators.b_matrix.CreateColVector(), operators.b_matrix.CreateColVector()
    LaggedCholesky(operators.b_matrix, subset, max_cg=0).solve(rhs, expected)
    HeldCholesky(base, subset).solve(rhs, found)
    assert np.all(found.FV().NumPy()[~subset] == 0.0)
    scale = np.abs(expected.FV().NumPy()).max()
    assert np.abs(found.FV().NumPy() - expected.FV().NumPy()).max() <= 1e-10 * scale
    # Nothing held: the base solution itself.
    LaggedCholesky(operators.b_matrix, free, max_cg=0).solve(rhs, expected)
    HeldCholesky(base, free).solve(rhs, found)
    assert np.abs(found.FV().NumPy() - expected.FV().NumPy()).max() <= 1e-12 * scale


def test_v_step_with_the_crack_decoupled_keeps_one_factorisation_per_mesh():
    """CR grows on the same mesh: the direct v-step keeps its factorisation (CR's rows and
    columns of b_j hold the diagonal only) and solves as a factorisation on the DOFs off CR."""
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"eps": 0.2})
    state = ATState(scene.make_mesh(0.25), parameters.model, scene.loads, scene.crack)
    steps = HalfStepSolvers(state, max_cg=0, bounded_v=False)
    state.apply_load(1.4)
    steps.solve_u()
    crack = np.zeros(state.arrays.nv, dtype=bool)
    crack[np.argsort(np.linalg.norm(state.arrays.coords - (2.0, 2.0), axis=1))[:40]] = True
    smaller = crack.copy()
    smaller[np.flatnonzero(crack)[::2]] = False
    steps.solve_v(smaller)
    solver = steps._b_solver
    u_before, v_start = state.u_values.copy(), state.v_values.copy()
    steps.solve_v(crack)
    assert steps._b_solver is solver and solver.free.all()
    assert np.all(state.v_values[crack] == 0.0)
    # The same v-step by a factorisation of the undecoupled b_j on the DOFs off CR.
    found = state.v_values.copy()
    state.v_values[:] = v_start
    state.v_values[crack] = 0.0
    operators = LumpedOperators(state)
    operators.assemble_b()
    residual, step = operators.b_matrix.CreateColVector(), operators.b_matrix.CreateColVector()
    residual.FV().NumPy()[:] = state.model.surface.source * state.arrays.mass
    residual.data -= operators.b_matrix * state.v.vec
    LaggedCholesky(operators.b_matrix, ~crack, max_cg=0).solve(residual, step)
    expected = state.v_values + step.FV().NumPy()
    assert np.array_equal(state.u_values, u_before)
    assert np.abs(found - expected).max() <= 1e-10


def test_held_cholesky_does_not_hold_the_decoupled_crack():
    """The bounded v-step's few active DOFs off CR, on the factorisation with CR decoupled: only
    they are held, and the solution is that of a factorisation of their own."""
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"eps": 0.2})
    state = ATState(scene.make_mesh(0.25), parameters.model, scene.loads, scene.crack)
    state.apply_load(1.4)
    HalfStepSolvers(state).solve_u()
    crack = np.zeros(state.arrays.nv, dtype=bool)
    crack[np.argsort(np.linalg.norm(state.arrays.coords - (2.0, 2.0), axis=1))[:40]] = True
    operators = LumpedOperators(state)
    operators.assemble_b(crack)
    base = LaggedCholesky(operators.b_matrix, np.ones_like(crack), max_cg=0)
    rng = np.random.default_rng(1)
    active = rng.choice(np.flatnonzero(~crack), size=HeldCholesky.MAX_HELD, replace=False)
    inactive = ~crack
    inactive[active] = False
    held = HeldCholesky(base, inactive, decoupled=crack)
    assert sorted(held.held) == sorted(active)
    rhs, found = operators.b_matrix.CreateColVector(), operators.b_matrix.CreateColVector()
    rhs.FV().NumPy()[:] = rng.standard_normal(len(crack))
    held.solve(rhs, found)
    expected = operators.b_matrix.CreateColVector()
    LaggedCholesky(operators.b_matrix, inactive, max_cg=0).solve(rhs, expected)
    scale = np.abs(expected.FV().NumPy()).max()
    assert np.abs(found.FV().NumPy() - expected.FV().NumPy()).max() <= 1e-10 * scale


@pytest.mark.skipif(not ngat.pardiso.AVAILABLE, reason="MKL is not installed")
def test_a_j_and_b_j_of_a_scalar_u_share_one_analysis_per_mesh():
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"eps": 0.2})
    state = ATState(scene.make_mesh(0.25), parameters.model, scene.loads, scene.crack)
    steps = HalfStepSolvers(state)
    state.apply_load(1.4)
    steps.solve_u()
    steps.solve_v(np.zeros(state.arrays.nv, dtype=bool))
    a, b = steps._a_solver.inverse, steps._b_solver.inverse
    assert a.factor is b.factor and (a.slot, b.slot) == (1, 2)
    assert not a.free.all() and b.free.all()  # u is fixed on Ω_D, v nowhere


def test_b_j_decouples_the_crack_it_is_given_each_time():
    # A grown crack, and the old one again, must each decouple their own rows and columns
    # and leave every other entry at b_j's value.
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"eps": 0.2})
    state = ATState(scene.make_mesh(0.25), parameters.model, scene.loads, scene.crack)
    state.apply_load(1.4)
    HalfStepSolvers(state).solve_u()
    operators = LumpedOperators(state)
    nearest = np.argsort(np.linalg.norm(state.arrays.coords - (2.0, 2.0), axis=1))
    small, grown = (np.isin(np.arange(state.arrays.nv), nearest[:k]) for k in (10, 40))
    operators.assemble_b()
    whole = operators.b_matrix.AsVector().FV().NumPy().copy()
    _, columns, rowptr = operators.b_matrix.CSR()
    rows = np.repeat(np.arange(len(rowptr) - 1), np.diff(np.asarray(rowptr, dtype=np.int64)))
    columns = np.asarray(columns, dtype=np.int64)
    for crack in (small, grown, small):
        operators.assemble_b(crack)
        values = operators.b_matrix.AsVector().FV().NumPy()
        # Zero off the diagonal in the crack's rows and columns, b_j's own values elsewhere.
        decoupled = (crack[rows] | crack[columns]) & (rows != columns)
        assert np.all(values[decoupled] == 0.0) and np.any(whole[decoupled] != 0.0)
        np.testing.assert_array_equal(values[~decoupled], whole[~decoupled])


def _half_step_fields(prepare: bool, perturb: bool = False):
    """(u, v) after three alternating iterations on a fixed mesh, with or without prepare."""
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"adapt": "fixed", "maxh": 0.3, "eps": 0.2})
    state = ATState(scene.make_mesh(0.3), parameters.model, scene.loads, scene.crack)
    state.apply_load(1.2)
    steps = HalfStepSolvers(state)
    for _ in range(3):
        crack = state.crack_set()
        steps.solve_u()
        if prepare:
            steps.prepare_v(crack)
        steps.solve_v(crack)
        if prepare:
            steps.prepare_u()
        if perturb:
            state.v_values[:] *= 0.999  # a Newton step, say: the prepared a_j is stale
    return state.u_values.copy(), state.v_values.copy(), steps.statistics.solves


@pytest.mark.parametrize("perturb", [False, True])
def test_prepared_half_steps_give_the_same_bits(perturb):
    """prepare_v and prepare_u only start the factorisations early (in the background)."""
    u, v, solves = _half_step_fields(prepare=False, perturb=perturb)
    u_prepared, v_prepared, solves_prepared = _half_step_fields(prepare=True, perturb=perturb)
    assert np.array_equal(u_prepared, u)
    assert np.array_equal(v_prepared, v)
    assert solves_prepared == solves
    assert np.abs(u).max() > 0.1 and v.min() < 0.99  # the iterations did something
