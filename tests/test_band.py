"""The crack band (adapt=band): elements tied to ε at the tips and wherever the crack goes."""

import copy

import numpy as np
import pytest
from scipy.spatial import cKDTree

from ngat.band import (
    BUFFER,
    DAMAGED,
    FEW_CENTRES,
    ONSET_RADIUS,
    TIP_RADIUS,
    CrackBand,
    band_elements,
    nearest_distance,
)
from ngat.driver import run
from ngat.halfsteps import HalfStepSolvers
from ngat.parameters import ParameterError, Parameters
from ngat.scene import load_scene
from ngat.state import ATState


def test_band_elements_are_those_within_the_radius():
    coords = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [5.0, 0.0], [6.0, 0.0], [5.0, 1.0]])
    elements = np.array([[0, 1, 2], [3, 4, 5]])
    diameter = np.full(2, np.sqrt(2))
    near = band_elements(coords, elements, diameter, np.array([[0.5, 0.5]]), 0.1)
    assert near.tolist() == [True, False]
    assert not band_elements(coords, elements, diameter, np.empty((0, 2)), 1.0).any()


def test_few_centres_are_measured_as_the_k_d_tree_measures_them():
    # Up to FEW_CENTRES centres (the crack tips) band_elements measures the distances itself:
    # the same elements as the k-d tree's search, on a graded mesh with a few thousand of them.
    scene = load_scene("two-slits")
    state = ATState(scene.make_mesh(0.5), Parameters().model, scene.loads)
    coords, elements, diameter = state.arrays.coords, state.arrays.elements, state.arrays.diameter
    rng = np.random.default_rng(2)
    for count in (1, 2, FEW_CENTRES):
        centres = 6 * rng.random((count, 2))
        for radius in (0.05, 0.3, 1.0):
            direct = band_elements(coords, elements, diameter, centres, radius)
            searched = band_elements(coords, elements, diameter, cKDTree(centres), radius)
            np.testing.assert_array_equal(direct, searched)
            assert direct.any()


def test_nearest_distance_is_exact_within_each_bound():
    # Bounds over five orders of magnitude, queried per power-of-two class: within its bound a
    # point gets its exact distance to the nearest centre, beyond it that distance or ∞.
    rng = np.random.default_rng(4)
    centres, points = rng.random((300, 2)), 3 * rng.random((2000, 2)) - 1
    bounds = 10.0 ** rng.uniform(-4, 1, len(points))
    exact = np.sqrt(((points[:, None] - centres[None]) ** 2).sum(axis=2)).min(axis=1)
    for given in (centres, cKDTree(centres)):
        distance = nearest_distance(given, points, bounds)
        within = exact <= bounds
        assert 0.2 < within.mean() < 0.9
        np.testing.assert_array_equal(distance[within], exact[within])
        assert np.all((distance[~within] == exact[~within]) | np.isinf(distance[~within]))
    assert nearest_distance(centres, points[:0], bounds[:0]).shape == (0,)


def two_slits_state(eps=0.05):
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(quick=True, overrides={"eps": eps})
    mesh = scene.make_mesh(parameters.adaptivity.maxh)
    state = ATState(mesh, parameters.model, scene.loads)
    adaptivity = parameters.adaptivity
    band = CrackBand(eps, adaptivity.band_h, scene.slits, adaptivity.floor * eps)
    return scene, state, band


def resolve_crack_line(state, band, rounds):
    """Put a crack along y = 3 from x = 1 to 5 (v = 0 there, 1 elsewhere, on the refined
    vertices too) and let the band refine until it is resolved or ``rounds`` have passed."""
    for _ in range(rounds):
        coords = state.arrays.coords
        line = (np.abs(coords[:, 1] - 3) < 1e-9 + 0.6 * state.arrays.diameter.max()) & (
            np.abs(coords[:, 0] - 3) <= 2
        )
        state.v_values[:] = np.where(line, 0.0, 1.0)
        if not band.refine(state):
            break


def assert_slit_tips_resolved(scene, state, radius, size, count):
    """Assert that more than ``count`` elements lie within ``radius`` of each slit tip, none of
    them wider than ``size``; return the elements' centroids."""
    arrays = state.arrays
    centroids = arrays.coords[arrays.elements].mean(axis=1)
    for _, tip in scene.slits:
        near = np.linalg.norm(centroids - tip, axis=1) < radius
        assert near.sum() > count
        assert arrays.diameter[near].max() <= size
    return centroids


def test_predictor_resolves_the_slit_tips_and_nothing_far_away():
    eps = 0.05
    scene, state, band = two_slits_state(eps)
    assert band.refine(state) > 0
    centroids = assert_slit_tips_resolved(scene, state, TIP_RADIUS * eps, band.target, 100)
    arrays = state.arrays
    far = np.linalg.norm(centroids - [3.0, 3.0], axis=1) > 1.0
    assert arrays.diameter[far].max() > 10 * band.target  # the rest stays coarse
    assert band.refine(state) == 0  # resolved: a second call does nothing


def test_slit_tips_are_resolved_to_onset_h_until_their_cracks_grow():
    # A band of 0.35ε with onset_h = 0.18: before the first step the discs of ONSET_RADIUS about
    # both slit tips are resolved to 0.18ε; once a crack has grown ε from its slit, its tip's
    # disc (TIP_RADIUS) follows the band.
    eps = 0.05
    scene, state, plain = two_slits_state(eps)
    band = CrackBand(eps, 0.35, scene.slits, 0.08 * eps, onset_h=0.18)
    assert band.refine(state) > 0
    assert_slit_tips_resolved(scene, state, ONSET_RADIUS * eps, 0.18 * eps, 50)
    assert 0.18 * eps < band.target
    # Marking alone, about the tip of a crack grown 10ε from the first slit and the second
    # slit's own tip: onset_h about the second, the band's target about the first.
    _, fresh, _ = two_slits_state(eps)
    coords, elements, diameter = fresh.arrays.coords, fresh.arrays.elements, fresh.arrays.diameter
    tips = np.array([[2.0, 2.5], scene.slits[1][1]])
    assert band.at_onset(tips).tolist() == [False, True]
    marked = band.marked(coords, elements, np.empty((0, 2)), tips, diameter)
    for tip, target, radius in zip(
        tips, (band.target, 0.18 * eps), (TIP_RADIUS, ONSET_RADIUS), strict=True
    ):
        disc = band_elements(coords, elements, diameter, tip[None], radius * eps)
        assert disc.any()
        np.testing.assert_array_equal(marked[disc], diameter[disc] > target)
    discs = band_elements(coords, elements, diameter, tips[:1], TIP_RADIUS * eps)
    discs |= band_elements(coords, elements, diameter, tips[1:], ONSET_RADIUS * eps)
    assert not marked[~discs].any()
    assert not plain.at_onset(tips).any()  # onset_h = 0: every tip follows the band


def test_damaged_set_and_its_buffer_are_resolved():
    eps = 0.05
    _, state, band = two_slits_state(eps)
    band.slits = []  # the damaged set alone
    # A crack along y = 3 from x = 1 to 5: v = 0 there, 1 elsewhere (on the refined vertices too).
    resolve_crack_line(state, band, rounds=8)
    arrays = state.arrays
    damaged = arrays.coords[state.v_values < DAMAGED]
    assert len(damaged) > 0
    assert band.under_resolved(state) == 0
    centroids = arrays.coords[arrays.elements].mean(axis=1)
    from scipy.spatial import cKDTree

    distance, _ = cKDTree(damaged).query(centroids)
    assert arrays.diameter[distance < BUFFER * eps].max() <= band.target


def grow_crack(state, band, x_end):
    """Set v = 0 on the line y = 3, 1 ≤ x ≤ x_end (1 elsewhere) and resolve the band once."""
    coords = state.arrays.coords
    line = (np.abs(coords[:, 1] - 3) < 1e-9 + 0.6 * state.arrays.diameter.max()) & (
        coords[:, 0] >= 1
    )
    state.v_values[:] = np.where(line & (coords[:, 0] <= x_end), 0.0, 1.0)
    return band.refine(state)


@pytest.mark.parametrize("trigger, fewest, most", [(1.0, 16, 20), (0.5, 1, 8)])
def test_a_running_crack_is_resolved_at_every_iteration_with_fewer_refinements(
    trigger, fewest, most
):
    # A crack front that advances by ε/5 per "iteration" (the break step of a running crack):
    # with the hysteresis the band is refined only after the front has crossed half of its
    # margin (every 4th iteration, measured 5 of 20; without it 20 of 20), yet after every
    # iteration no damaged element is wider than the target.
    eps = 0.05
    _, state, band = two_slits_state(eps)
    band.slits = []
    band.trigger = trigger
    for _ in range(6):  # the band around the initial crack, resolved
        if not grow_crack(state, band, 2.0):
            break
    fired = 0
    for k in range(1, 21):
        fired += grow_crack(state, band, 2.0 + 0.2 * eps * k) > 0
        assert band.under_resolved(state) == 0
    assert fewest <= fired <= most, fired


def test_searching_about_the_newly_damaged_vertices_refines_as_the_full_search():
    # After a call that refined nothing, the band searches on that mesh about the vertices
    # damaged since and the tips only; the meshes must be those of the full search.
    eps = 0.05
    runs = []
    for cached in (True, False):
        _, state, band = two_slits_state(eps)
        pristine = copy.copy(band)
        for _ in range(6):
            if not grow_crack(state, band, 2.0):
                break
        runs.append([])
        for k in range(1, 21):
            used = band if cached else copy.copy(pristine)
            runs[-1].append((grow_crack(state, used, 2.0 + 0.2 * eps * k), state.arrays.ne))
    assert runs[0] == runs[1]
    assert 1 <= sum(rounds > 0 for rounds, _ in runs[0]) < 20  # both paths were taken


def test_band_parameters_are_checked():
    with pytest.raises(ParameterError, match="band_h"):
        Parameters().replace(band_h=0.01, floor=0.02)
    Parameters().replace(adapt="paper", band_h=0.01, floor=0.02)  # no band: no conflict
    with pytest.raises(ParameterError, match="adapt must be one of band"):
        Parameters().replace(adapt="everywhere")
    assert Parameters().adaptivity.adapt == "band"
    with pytest.raises(ParameterError, match="band_search must be a number >= 1"):
        Parameters().replace(band_search=0.5)
    with pytest.raises(ParameterError, match="onset_h must be a non-negative number"):
        Parameters().replace(onset_h=-0.1)


@pytest.mark.parametrize("search", [1.0, 2.0])
def test_a_crack_that_runs_through_coarse_elements_ends_resolved(tmp_path, search):
    # two-slits at ε = 0.1 from a mesh of 5ε: at t = 1.5 the two cracks run through the body
    # and join in one load step, through elements that were 5ε wide when the step began; with
    # band_search = 2 they run on a band of twice the target, resolved once they stopped.
    scene = load_scene("two-slits")
    eps = 0.1
    overrides = {"eps": eps, "floor": 0.1, "band_search": search}
    parameters, _ = scene.configure(quick=True, overrides=overrides)
    adaptivity = parameters.adaptivity
    band = CrackBand(eps, adaptivity.band_h, scene.slits, adaptivity.floor * eps)
    result = run(scene, parameters, np.array([0.0, 1.5]), tmp_path)
    last = result.records[-1]
    assert last["connected"] is False and last["converged"]
    assert last["tip1_y"] > 3.9 and last["tip2_y"] < 2.1, "the cracks should have joined"
    assert band.under_resolved(result.state) == 0
    assert 0 < last["h_crack"] <= band.target
    assert last["band_refinements"] > result.records[0]["band_refinements"] > 0


def test_relative_tolerance_scales_with_the_load_like_the_estimators():
    # μ is linear in the load on a fixed mesh with v = 1, and so is TOL = tol_rel · I_j^{1/2}:
    # the refinement decision does not depend on the load scale.
    from ngat.minimization import estimate, tolerance

    _, state, _ = two_slits_state()
    steps = HalfStepSolvers(state)
    adaptivity = Parameters().adaptivity
    values = []
    for t in (0.5, 2.0):
        state.apply_load(t)
        steps.solve_u()
        mu = np.sqrt(estimate(state, "u", state.crack_set()).sum())
        values.append((mu, tolerance(state, adaptivity)))
    (mu_1, tol_1), (mu_2, tol_2) = values
    assert mu_2 / mu_1 == pytest.approx(4.0, rel=1e-9)
    assert tol_2 / tol_1 == pytest.approx(4.0, rel=1e-9)
    assert tolerance(state, adaptivity.__class__(adapt="paper")) == 0.3


def test_grading_bounds_the_elements_by_their_distance_from_the_crack():
    eps, grading = 0.05, 0.42
    _, state, band = two_slits_state(eps)
    band.slits = []
    band.grading = grading
    # A crack along y = 3 from x = 1 to 5 (as above), resolved with its graded surroundings.
    resolve_crack_line(state, band, rounds=12)
    arrays = state.arrays
    first = arrays.coords[arrays.elements[:, 0]]
    along = np.clip(first[:, 0], 1, 5)
    distance = np.hypot(first[:, 0] - along, first[:, 1] - 3)
    # Every element obeys the graded size (up to the spacing of the damaged vertices, which
    # are the centres, against the distance to the line measured here).
    allowed = band.target + grading * np.maximum(0.0, distance - BUFFER * eps)
    assert np.all(arrays.diameter <= allowed + band.target)
    # And the grading is what refined the flanks: without it they stay at the initial size.
    flank = (distance > 0.5) & (distance < 1.0) & (np.abs(first[:, 0] - 3) < 1.5)
    assert arrays.diameter[flank].max() < 0.25
    assert arrays.diameter[flank].max() <= band.target + grading * 1.0 + 1e-12


def test_the_band_is_graded_only_about_a_running_crack():
    # About a slit tip that has not cracked, μ grades the mesh towards the singularity; the
    # band's grading starts once a crack has grown ε from its slit.
    eps = 0.05
    _, plain, band = two_slits_state(eps)
    band.refine(plain)
    _, graded, band = two_slits_state(eps)
    band.grading = 0.42
    band.refine(graded)
    assert graded.mesh.ne == plain.mesh.ne
    tips = np.array([[2.0, 2.0], [4.0, 4.0]])
    assert not band.running(tips)
    tips[0, 1] += 1.01 * eps
    assert band.running(tips)
    band.slits = []
    assert band.running(np.empty((0, 2)))
