"""Marking and refinement: Dörfler/maximum marking, exact prolongation, slits and Ω_D kept."""

import numpy as np
from ngsolve import Integrate, grad, x, y

from ngat.halfsteps import HalfStepSolvers
from ngat.parameters import ModelParameters
from ngat.refinement import dorfler_marking, maximum_marking, refinable, refine
from ngat.scene import load_scene
from ngat.state import ATState


def test_dorfler_marks_the_smallest_set_with_the_bulk_fraction():
    indicators = np.array([1.0, 9.0, 4.0, 0.5, 0.25, 16.0])
    marked = dorfler_marking(indicators, theta=0.5)
    # 16 alone is 52 % of 30.75: one element suffices.
    assert marked.tolist() == [False, False, False, False, False, True]
    marked = dorfler_marking(indicators, theta=0.8)
    # 16 + 9 = 25 ≥ 0.8 · 30.75 = 24.6.
    assert marked.tolist() == [False, True, False, False, False, True]


def test_maximum_strategy_marks_indicators_near_the_largest():
    indicators = np.array([1.0, 9.0, 4.0, 16.0]) ** 2  # squared
    assert maximum_marking(indicators, theta=0.5).tolist() == [False, True, False, True]


def test_refinement_prolongates_exactly_and_keeps_slits_and_dirichlet_region():
    scene = load_scene("two-slits")
    state = ATState(scene.make_mesh(0.5), ModelParameters(), scene.loads)
    steps = HalfStepSolvers(state)
    state.apply_load(1.0)
    steps.solve_u()
    state.v.Set(0.5 + 0.1 * x - 0.05 * y)
    mesh = state.mesh
    before = [Integrate(f, mesh) for f in (state.u, state.v, grad(state.u) * grad(state.u))]
    area_left = Integrate(1, mesh, definedon=mesh.Materials("left"))
    centre = state.arrays.coords[state.arrays.elements].mean(axis=1)
    marked = np.linalg.norm(centre - [2, 2], axis=1) < 1.0  # around the first slit tip
    assert refine(state, marked) == marked.sum()
    after = [Integrate(f, mesh) for f in (state.u, state.v, grad(state.u) * grad(state.u))]
    np.testing.assert_allclose(after, before, rtol=1e-12, atol=1e-12)  # ∫u ≈ 0 by symmetry
    assert abs(Integrate(1, mesh, definedon=mesh.Materials("left")) - area_left) < 1e-12
    assert state.arrays.ne > len(marked)
    # The slit stays open: u still jumps across it after a re-solve on the refined mesh.
    steps.solve_u()
    coords, u = state.arrays.coords, state.u_values
    on_slit = np.flatnonzero((coords[:, 0] == 2) & (coords[:, 1] > 1) & (coords[:, 1] < 2))
    keys, inverse = np.unique(np.round(coords[on_slit], 9), axis=0, return_inverse=True)
    assert np.all(np.bincount(inverse) == 2)
    spread = np.zeros(len(keys))
    np.maximum.at(spread, inverse, u[on_slit])
    low = np.full(len(keys), np.inf)
    np.minimum.at(low, inverse, u[on_slit])
    assert np.all(spread - low > 0.05)


def test_floor_stops_refinement():
    scene = load_scene("two-slits")
    state = ATState(scene.make_mesh(0.5), ModelParameters(), scene.loads)
    allowed = refinable(state, h_floor=0.2)
    assert np.all(state.arrays.diameter[allowed] > 0.4)
    assert not refinable(state, h_floor=1.0).any()


def test_quick_run_refines_only_near_tips_and_cracks(quick_run):
    result, _, _ = quick_run
    state = result.state
    arrays = state.arrays
    assert arrays.ne > 5 * 348, "the quick run should refine"
    small = arrays.diameter < 4 * arrays.diameter.min()
    centres = arrays.coords[arrays.elements[small]].mean(axis=1)
    cracked = arrays.coords[state.v_values < 0.5]
    tips = np.array([[2.0, 2.0], [4.0, 4.0]])
    near_tip = np.min(np.linalg.norm(centres[:, None] - tips[None], axis=2), axis=1) < 0.3
    # Or in a disc re-meshed about a running tip (its rim: the bisection that prepared it).
    assert len(state.patches) >= 2
    in_disc = np.zeros(len(centres), dtype=bool)
    for patch in state.patches:
        in_disc |= np.linalg.norm(centres - patch.centre, axis=1) < patch.radius + 2 * 0.05
    rest = ~near_tip & ~in_disc
    distance_to_crack = np.array(
        [np.min(np.linalg.norm(cracked - c, axis=1)) for c in centres[rest]]
    )
    assert np.all(distance_to_crack < 0.3)
    # And the coarse mesh survives away from the crack (corners of the body).
    assert arrays.diameter.max() > 0.3


def test_a_steps_mu_is_that_of_its_last_u_step(tmp_path):
    # Algorithm 2 tests μ_j(u^n, v^{n−1}) after every u-step; a step's record keeps the last
    # one (not μ of the final pair, which would cost another evaluation per step).
    from ngat.driver import run
    from ngat.minimization import estimate

    scene = load_scene("two-slits")
    parameters, _ = scene.configure(
        overrides={"adapt": "paper", "maxh": 0.5, "floor": 0.1, "tol": 0.5, "resolve_eps": False}
    )
    after_u = []

    def monitor(stage, state):
        if stage == "u":
            after_u.append(float(np.sqrt(estimate(state, "u", state.crack_set()).sum())))

    last = []  # μ after the last u-step of each load step
    times = np.array([0.0, 0.6, 1.0])
    records = run(
        scene, parameters, times, tmp_path, lambda record: last.append(after_u[-1]), monitor
    ).records
    assert [r["mu"] for r in records] == last
    assert all(0 < r["mu"] <= 0.5 for r in records[1:])


def test_refinement_variants_after_and_fixed(tmp_path):
    # "after" refines only once the alternating minimisation has converged, and leaves the
    # estimators at or below TOL on the elements above the floor; "fixed" never refines.
    from ngat.driver import run

    scene = load_scene("two-slits")
    records = {}
    for adapt in ("after", "fixed", "paper"):
        parameters, _ = scene.configure(
            overrides={"adapt": adapt, "maxh": 0.5, "floor": 0.1, "tol": 0.5, "resolve_eps": False}
        )
        result = run(scene, parameters, np.array([0.0, 0.6, 1.0]), tmp_path / adapt)
        records[adapt] = result.records[-1]
        assert all(r["converged"] for r in result.records)
    assert records["fixed"]["refinements"] == 0
    assert records["fixed"]["elements"] == 348
    for adapt in ("after", "paper"):
        assert records[adapt]["elements"] > 348
        assert records[adapt]["mu"] <= 0.5 and records[adapt]["nu"] <= 0.5
    # Same load, same critical point up to the discretisation: energies agree to a few %.
    assert abs(records["after"]["total"] / records["paper"]["total"] - 1) < 0.05
