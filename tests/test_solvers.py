"""Nonlinear solvers and pointwise irreversibility (issue 6).

Over-relaxed and Anderson-accelerated alternating minimisation and Newton's method must reach
the same critical point as plain alternating minimisation, with fewer linear solves where the
crack moves; Newton's gradient and Hessian must be those of I_j (eq. 7).
"""

import numpy as np
import pytest
import scipy.sparse as sp

import ngat.minimization
import ngat.pardiso
from ngat.driver import run
from ngat.forms import sparse_from_coo
from ngat.halfsteps import HalfStepSolvers
from ngat.minimization import CRACKED, load_bearing_change
from ngat.newton import NewtonSolver
from ngat.parameters import NONLINEAR_SOLVERS
from ngat.scene import load_scene
from ngat.state import ATState
from ngat.strategies import (
    RATE_MAX,
    STRATEGIES,
    AlternatingMinimization,
    NewtonSwitch,
    estimated_error,
    nonlinear_strategy,
    remaining_iterations,
)
from ngat.threads import FixedThreads

TIMES = np.array([0.0, 0.5, 1.0, 1.2, 1.3])  # the last two steps are in the growth phase


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    scene = load_scene("two-slits")
    results = {}
    for solver in NONLINEAR_SOLVERS:
        parameters, _ = scene.configure(
            overrides={
                "adapt": "fixed",
                "maxh": 0.1,
                "eps": 0.2,
                "am_tol": 1e-6,
                "nonlinear": solver,
            }
        )
        results[solver] = run(scene, parameters, TIMES, tmp_path_factory.mktemp(solver))
    return results


@pytest.mark.parametrize("solver", NONLINEAR_SOLVERS[1:])
def test_same_energy_as_plain_alternating_minimization(runs, solver):
    for ours, plain in zip(runs[solver].records, runs["am"].records, strict=True):
        assert ours["converged"]
        assert abs(ours["total"] / max(plain["total"], 1e-300) - 1) < 1e-6 or plain["total"] < 1e-12


def test_anderson_needs_fewer_linear_solves_in_the_growth_phase(runs):
    growth = slice(3, None)
    plain = sum(r["linear_solves"] for r in runs["am"].records[growth])
    anderson = sum(r["linear_solves"] for r in runs["anderson"].records[growth])
    assert anderson < 0.6 * plain, (anderson, plain)


@pytest.mark.parametrize("solver", ["newton", "anderson-newton"])
def test_newton_needs_fewer_iterations_in_the_growth_phase(runs, solver):
    growth = slice(3, None)
    plain = sum(r["am_iterations"] for r in runs["am"].records[growth])
    newton = sum(r["am_iterations"] for r in runs[solver].records[growth])
    assert sum(r["newton_steps"] for r in runs[solver].records[growth]) > 0
    assert newton < 0.3 * plain, (newton, plain)


def test_newton_gradient_and_hessian_are_those_of_the_energy(assert_newton_matches_ngsolve):
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"adapt": "fixed", "maxh": 0.5, "eps": 0.2})
    state = ATState(scene.make_mesh(0.5), parameters.model, scene.loads, scene.crack)
    state.apply_load(1.3)
    rng = np.random.default_rng(1)
    u = state.u_values + 0.1 * rng.random(state.arrays.nv)
    assert_newton_matches_ngsolve(state, u, rng.random(state.arrays.nv))


def newton_hessian(newton: NewtonSolver) -> sp.csr_matrix:
    """Return the whole projected Hessian Newton factorised last, from its upper triangle."""
    size = len(newton.indptr) - 1
    upper = sp.csr_matrix((newton.values, newton.entry_cols, newton.indptr), (size, size))
    return upper + sp.triu(upper, k=1).T


@pytest.mark.parametrize("mkl", [True, False])
def test_factorising_the_upper_triangle_is_factorising_the_hessian(mkl, monkeypatch):
    # Newton's matrix stores ∇²I_j on and above the diagonal: PARDISO reads no more, nor does
    # NGSolve's sparse Cholesky (ngat's factorisation without MKL) of its mirror, so both must
    # solve as with the whole Hessian.
    if not mkl:
        monkeypatch.setattr(ngat.pardiso, "AVAILABLE", False)
    elif not ngat.pardiso.AVAILABLE:
        pytest.skip("MKL is not installed")
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"adapt": "fixed", "maxh": 0.5, "eps": 0.2})
    state = ATState(scene.make_mesh(0.5), parameters.model, scene.loads, scene.crack)
    state.apply_load(1.3)
    threads = FixedThreads()
    try:
        newton = NewtonSolver(state)
        newton._factorise(state.crack_set())
        assert isinstance(newton.factor, ngat.pardiso.Pardiso) == mkl
        hessian = newton_hessian(newton)
        assert abs(hessian - hessian.T).max() == 0
        assert hessian.nnz > 1.5 * np.count_nonzero(newton.values)  # both triangles
        rows, cols, values = sp.find(hessian)
        whole = sparse_from_coo(rows, cols, values, *hessian.shape)
        rhs = np.random.default_rng(3).random(hessian.shape[0])
        x = whole.CreateColVector()
        x.FV().NumPy()[:] = rhs
        expected = (whole.Inverse(inverse="sparsecholesky") * x).Evaluate().FV().NumPy()
        assert np.allclose(newton._apply_inverse(rhs), expected, rtol=1e-9, atol=1e-12)
    finally:
        threads.restore()


def test_pointwise_irreversibility_keeps_v_below_the_previous_step(tmp_path):
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(
        overrides={"adapt": "fixed", "maxh": 0.1, "eps": 0.2, "irreversibility": "pointwise"}
    )
    states, previous, worst = [], [None], [0.0]

    def monitor(stage, state):
        if not states:
            states.append(state)

    def on_step(record):
        v = states[0].v_values.copy()
        if previous[0] is not None:
            worst[0] = max(worst[0], float(np.max(v - previous[0])))
        previous[0] = v

    result = run(scene, parameters, TIMES, tmp_path / "pointwise", on_step=on_step, monitor=monitor)
    assert worst[0] <= 1e-12
    assert result.records[-1]["v_min"] < 0.5, "the test should damage the body"
    assert result.records[-1]["v_bound_active"] > 0


def indefinite_state() -> ATState:
    """A coarse two-slits state at t = 1.3 with random u and small v: far from a minimiser, so
    that the Hessian of I_j is indefinite."""
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"adapt": "fixed", "maxh": 0.5, "eps": 0.2})
    state = ATState(scene.make_mesh(0.5), parameters.model, scene.loads, scene.crack)
    state.apply_load(1.3)
    rng = np.random.default_rng(2)
    state.u_values[:] += 0.5 * rng.random(state.arrays.nv)
    state.v_values[:] = 0.3 * rng.random(state.arrays.nv)
    return state


def test_negative_curvature_direction_has_the_curvature_it_reports():
    newton = NewtonSolver(indefinite_state())
    _, _, _, gradient, held = newton._factorise(newton.state.crack_set())
    residual = np.where(held, 0.0, -gradient)
    found = newton.negative_curvature(residual, newton._apply_inverse(residual))
    assert found is not None, "random (u, v) with small v should show negative curvature"
    direction, curvature = found
    hessian = newton_hessian(newton)
    assert curvature < 0
    assert direction @ hessian @ direction == pytest.approx(curvature, rel=1e-8)
    assert not np.any(direction[held])
    if hasattr(newton.factor, "negative_eigenvalues"):  # PARDISO counts them (inertia)
        eigenvalues = np.linalg.eigvalsh(hessian.toarray())
        assert newton.factor.negative_eigenvalues == np.sum(eigenvalues < 0) > 0


def test_newton_step_moves_the_state_downhill_or_leaves_it_as_it_was():
    # The line search tries its steps in the state itself: a rejected step must restore
    # (u, v) to the bit, an accepted one leave I_j of the new iterate, decreased, memoised.
    state = indefinite_state()
    u, v = state.u_values.copy(), state.v_values.copy()
    start = state.energies()["total"]
    newton = NewtonSolver(state)
    assert newton.step(state.crack_set(), ceiling=-np.inf) == ""
    assert np.array_equal(state.u_values, u) and np.array_equal(state.v_values, v)
    assert newton.step(state.crack_set())
    assert not np.array_equal(state.v_values, v)
    energy = state.functional.energies(state.arrays, state.u_values, state.v_values)["total"]
    assert state.energies()["total"] == energy < start


@pytest.mark.parametrize("ritz_tol", [1.0, 0.01])
def test_negative_curvature_search_returns_a_settled_ritz_pair(ritz_tol):
    # The escape's direction d = H⁻¹x must come from a Ritz pair (θ, x) of H⁻¹ whose
    # residual ‖H⁻¹x − θx‖ = ‖d − θ Hd‖ is at most ritz_tol |θ| (x = Hd, ‖x‖ = 1); a search
    # that stopped at the first negative Ritz value would leave it larger, and the escape's
    # direction would hang on round-off.
    state = indefinite_state()
    newton = NewtonSolver(state, lanczos_steps=60, ritz_tol=ritz_tol)
    _, _, _, gradient, held = newton._factorise(state.crack_set())
    residual = np.where(held, 0.0, -gradient)
    direction, curvature = newton.negative_curvature(residual, newton._apply_inverse(residual))
    x = newton_hessian(newton) @ direction
    assert np.linalg.norm(x) == pytest.approx(1.0, rel=1e-8)
    assert np.linalg.norm(direction - curvature * x) <= ritz_tol * abs(curvature)


def test_newton_leaves_saddles_and_breaks_with_converged_alternating_minimization(tmp_path):
    # On the obtuse-line mesh a Newton step from an alternating-minimisation iterate near a
    # saddle lands on another branch unless the negative curvature there is found and followed:
    # the body then broke at 0.46 instead of 0.50, with energies up to 1.6e-3 above.
    scene = load_scene("obtuse-line")
    times = np.round(np.arange(0.0, 0.561, 0.02), 10)
    runs = {}
    for solver, tol in (("am", 1e-6), ("newton", 1e-3)):
        parameters, _ = scene.configure(
            overrides={"nonlinear": solver, "am_tol": tol, "am_max_iter": 20000}
        )
        runs[solver] = run(scene, parameters, times, tmp_path / solver)
    newton, plain = runs["newton"], runs["am"]
    assert plain.summary["fracture_time"] == 0.5
    assert abs(newton.summary["fracture_time"] - 0.5) <= 0.02 + 1e-12  # one load step
    assert sum(r["escapes"] for r in newton.records) > 0
    for ours, converged in zip(newton.records, plain.records, strict=True):
        assert ours["converged"] and converged["converged"]
        assert ours["total"] == pytest.approx(converged["total"], rel=5e-4)


def test_remaining_iterations_of_a_linearly_converging_iteration():
    # Changes 0.1, 0.05, 0.025, ...: from 0.05 down to 1e-3 takes log2(50) = 5.64 more halvings.
    assert remaining_iterations(0.05, 0.1, 1e-3) == pytest.approx(np.log2(50))
    assert remaining_iterations(0.05, 0.04, 1e-3) == np.inf  # not contracting (near a saddle)
    assert remaining_iterations(0.05, np.inf, 1e-3) == 0.0  # no rate yet
    assert remaining_iterations(1e-4, 1e-3, 1e-3) == 0.0


@pytest.mark.parametrize("rate", [0.6, 0.9, 0.98])
def test_estimated_error_is_the_distance_to_the_limit_of_a_geometric_sequence(rate):
    # v_n = ρ^n → 0: changes ρ^{n−1}(1 − ρ), and ρ/(1 − ρ) times the last one is ρ^n exactly.
    n = 40
    change, previous = rate ** (n - 1) * (1 - rate), rate ** (n - 2) * (1 - rate)
    assert estimated_error(change, previous) == pytest.approx(rate**n, rel=1e-12)
    # The plain test would stop long before: the change is (1 − ρ)/ρ times the error.
    assert change < estimated_error(change, previous) or rate <= 0.5


def test_estimated_error_is_the_change_where_the_iteration_contracts_fast_and_caps_the_rate():
    assert estimated_error(1e-3, 1e-2) == 1e-3  # ρ = 0.1: the change bounds the error
    assert estimated_error(1e-3, np.inf) == 1e-3  # no rate yet
    assert estimated_error(1e-3, 1e-3) == pytest.approx(1e-3 * RATE_MAX / (1 - RATE_MAX))
    # Newton is tried where the contraction test is far away, though the change is near am_tol.
    assert remaining_iterations(1.19e-3, 1.31e-3, 1e-3) > 20
    assert remaining_iterations(1.19e-3, 1.31e-3, 1e-3, contraction=False) < 2


def test_contraction_test_does_not_stop_a_creeping_iteration_early(tmp_path):
    # obtuse-line with plain alternating minimisation: stopped on ‖Δv‖∞ < 1e-3 the body breaks
    # one load step late (0.52), the crack still creeping when the test holds; converged
    # (am_tol 1e-4 to 1e-6) it breaks at 0.50. The contraction test at the same am_tol does.
    scene = load_scene("obtuse-line")
    times = np.round(np.arange(0.0, 0.561, 0.02), 10)
    breaks = {}
    for stop in ("change", "contraction"):
        parameters, _ = scene.configure(
            overrides={"nonlinear": "am", "am_stop": stop, "am_max_iter": 20000}
        )
        breaks[stop] = run(scene, parameters, times, tmp_path / stop).summary["fracture_time"]
    assert breaks == {"change": 0.52, "contraction": 0.5}


def test_load_bearing_change_is_the_change_outside_the_crack():
    v_old = np.array([1.0, 0.6, 0.1, 0.006, 0.0])
    v = np.array([0.999, 0.59, 0.09, 0.005, 0.0])
    # Full weight down to v̄ = CRACKED = 1/4, then v̄ / CRACKED: at v̄ = 0.0055 the 1e-3 counts
    # 2.2e-5.
    weights = np.minimum(1.0, (v + v_old) / 2 / CRACKED)
    np.testing.assert_allclose(weights, [1.0, 1.0, 0.38, 0.022, 0.0])
    assert load_bearing_change(v[:2], v_old[:2]) == pytest.approx(0.01)
    assert load_bearing_change(v[3:], v_old[3:]) == pytest.approx(2.2e-5)
    assert load_bearing_change(v, v_old) == pytest.approx(0.01)


def test_contraction_test_ignores_the_drift_of_v_inside_an_open_crack(tmp_path, monkeypatch):
    # After the body broke, v inside the crack band drifts towards 0 as the crack opens; with
    # the change measured everywhere (CRACKED → 0) the later steps take two iterations each,
    # with the change outside the crack one, on the same meshes and with the same energies.
    # Each step starts from v(t_{k−1}) (the predictor would extrapolate the drift as well).
    scene = load_scene("two-slits")
    times = np.round(np.arange(0.0, 2.01, 0.05), 10)
    parameters, _ = scene.configure(
        overrides={"adapt": "fixed", "maxh": 0.08, "eps": 0.1, "predictor": False}
    )
    results = {}
    for name, cracked in (("everywhere", 1e-12), ("outside", CRACKED)):
        monkeypatch.setattr(ngat.minimization, "CRACKED", cracked)
        results[name] = run(scene, parameters, times, tmp_path / name)
    broken = [
        [r for r in result.records if r["t"] > result.summary["fracture_time"] + 0.06]
        for result in results.values()
    ]
    assert results["everywhere"].summary["fracture_time"] == 1.45
    assert results["outside"].summary["fracture_time"] == 1.45
    assert [r["am_iterations"] for r in broken[1]] == [1] * len(broken[1])
    assert sum(r["am_iterations"] for r in broken[0]) >= 1.5 * len(broken[0])
    np.testing.assert_allclose(
        [r["total"] for r in broken[1]], [r["total"] for r in broken[0]], rtol=1e-4
    )


def test_every_nonlinear_solver_has_a_strategy():
    assert set(STRATEGIES) == set(NONLINEAR_SOLVERS)


def test_newton_switch_keeps_the_newton_solver_of_a_state_across_load_steps():
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(overrides={"adapt": "fixed", "maxh": 0.5, "eps": 0.2})
    strategy = nonlinear_strategy(parameters.solver)
    assert isinstance(strategy, NewtonSwitch)
    state = ATState(scene.make_mesh(0.5), parameters.model, scene.loads, scene.crack)
    half_steps = HalfStepSolvers(state)
    strategy.start(state, half_steps)
    newton = strategy.newton
    strategy.start(state, half_steps)
    assert strategy.newton is newton
    other = ATState(scene.make_mesh(0.5), parameters.model, scene.loads, scene.crack)
    strategy.start(other, HalfStepSolvers(other))
    assert strategy.newton.state is other


class _Energy:
    """A state reduced to what NewtonSwitch reads: I_j, the mesh's size and CR."""

    def __init__(self):
        self.total = 100.0
        self.arrays = type("Arrays", (), {"ne": 10})()

    def energies(self):
        return {"total": self.total}

    def crack_set(self):
        return np.zeros(0, dtype=bool)


class _Newton:
    """A Newton solver whose every step is accepted and lowers I_j by ``gain``."""

    def __init__(self, state, gains):
        self.state, self.gains, self.attempts = state, gains, []

    def step(self, crack, ceiling):
        self.attempts.append(self.iteration)
        self.state.total -= self.gains(len(self.attempts))
        return "escape"


def _attempts(gains, iterations=40):
    """Return the iterations after which NewtonSwitch tried a step; each plain one gains 1."""
    state = _Energy()
    strategy = NewtonSwitch(AlternatingMinimization(), switch=0.1, am_tol=1e-3)
    strategy.newton = newton = _Newton(state, gains)
    for n in range(1, iterations + 1):
        state.total -= 1.0  # the plain iteration's decrease
        newton.iteration = n
        strategy.after_iteration(state, 0.01 * 0.97**n)  # a creeping iteration: Newton's place
    return newton.attempts


def test_newton_waits_2_4_8_iterations_after_steps_that_gain_less_than_an_iteration():
    # An attempt makes the next iteration's rate unknown (no attempt there); a step that
    # gains less than the plain iteration before it adds a wait of 2, 4, 8, … iterations.
    assert np.diff(_attempts(lambda k: 0.5)).tolist() == [4, 6, 10, 18]
    # Steps that pay are tried after every other iteration.
    assert np.diff(_attempts(lambda k: 2.0)).tolist() == [2] * 19
    # One that pays again ends the wait: the next unpaid step waits 2 again.
    gaps = np.diff(_attempts(lambda k: 2.0 if k == 3 else 0.5)).tolist()
    assert gaps[:4] == [4, 6, 2, 4]
