"""The optimal 1-D profile (docs/design.md scene 4): v = 1 − exp(−d/(2ε)) and unit surface energy.

On the structured mesh of ``profile-1d`` a v that depends only on y reduces the lumped problem
exactly to a 1-D lumped problem, solved here in a few lines of numpy.
"""

import dataclasses

import numpy as np
import pytest

from ngat.driver import run
from ngat.geometries.profile_1d import HALF_HEIGHT, LENGTH
from ngat.scene import load_scene

EPS = 0.05


def discrete_1d_energy(h, eps, band):
    """Lumped P1 surface energy of the 1-D minimiser on y_j = j h, |y| ≤ H, v = 0 at y ∈ cracked."""
    n = round(HALF_HEIGHT / h)
    y = h * np.arange(-n, n + 1)
    alpha = 1 / (4 * eps)
    mass = np.full(len(y), h)
    mass[[0, -1]] = h / 2
    stiffness = (
        np.diag(np.r_[1, 2 * np.ones(len(y) - 2), 1]) - np.eye(len(y), k=1) - np.eye(len(y), k=-1)
    ) / h
    matrix = eps * stiffness + alpha * np.diag(mass)
    rhs = alpha * mass
    cracked = np.isclose(y, 0) | (band & np.isclose(y, h))
    free = ~cracked
    v = np.zeros(len(y))
    v[free] = np.linalg.solve(matrix[np.ix_(free, free)], rhs[free])
    return alpha * mass @ (1 - v) ** 2 + eps * v @ stiffness @ v, y, v


def profile_run(tmp_path, h, band):
    scene = load_scene("profile-1d")
    if band:
        scene = dataclasses.replace(
            scene, crack=lambda xy: (np.abs(xy[:, 1]) < 1e-12) | (np.abs(xy[:, 1] - h) < 1e-12)
        )
    parameters, times = scene.configure(overrides={"maxh": h, "eps": EPS})
    result = run(scene, parameters, times, tmp_path / f"h{h}-{band}")
    return result.records[-1]["surface"] / LENGTH, result.state


@pytest.mark.parametrize("band", [False, True])
def test_surface_energy_equals_discrete_1d_value_and_tends_to_one(tmp_path, band):
    errors, ratios = [], []
    for h in [0.05, 0.025, 0.0125]:
        energy, _ = profile_run(tmp_path, h, band)
        reference, _, _ = discrete_1d_energy(h, EPS, band)
        assert abs(energy - reference) < 1e-8 * reference
        predicted = (h / EPS) ** 2 / 32 + (h / (4 * EPS) if band else 0)
        ratios.append((energy - 1) / predicted)
        errors.append(energy - 1)
    # The deviation from 1 follows the stated asymptotics and vanishes as h/ε → 0.
    np.testing.assert_allclose(ratios, 1, atol=0.2)
    assert errors[0] > errors[1] > errors[2] > 0
    rate = np.polyfit(np.log([0.05, 0.025, 0.0125]), np.log(errors), 1)[0]
    assert abs(rate - (1 if band else 2)) < 0.15


def test_v_matches_the_optimal_profile(tmp_path):
    h = 0.0125
    _, state = profile_run(tmp_path, h, band=False)
    d = np.abs(state.arrays.coords[:, 1])
    error = np.abs(state.v_values - (1 - np.exp(-d / (2 * EPS))))
    # Stated tolerance: second order in h/ε, max nodal error below (h/ε)²/4 = 0.016.
    assert error.max() < (h / EPS) ** 2 / 4
    _, y, v = discrete_1d_energy(h, EPS, band=False)
    # Equal to the 1-D discrete profile up to the corners of the strip, where a corner vertex's
    # lumped mass (one or two triangles) differs from the 1-D half-mass by O(h²): 3e-7 here.
    np.testing.assert_allclose(
        state.v_values, np.interp(state.arrays.coords[:, 1], y, v), atol=1e-6
    )


def test_at1_profile_is_nodally_exact_with_the_predicted_energy(tmp_path):
    # AT1 (crack_density=at1): the 1-D minimiser is v = 1 − (1 − |y|/(2ε))² for |y| < 2ε and
    # v = 1 beyond (the bound v ≤ 1 holds it there). The lumped P1 solution interpolates it
    # exactly; per element of the support the vertex rule overestimates ∫ 3/(8ε)(1 − v) by
    # h³/(64 ε³) and the P1 gradient underestimates ∫ (3ε/8)|v'|² by h³/(128 ε³), so with
    # 4ε/h elements the surface energy is exactly 1 + (h/ε)²/32.
    scene = load_scene("profile-1d")
    for h in [0.025, 0.0125]:
        overrides = {"maxh": h, "eps": EPS, "crack_density": "at1"}
        parameters, times = scene.configure(overrides=overrides)
        result = run(scene, parameters, times, tmp_path / f"at1-{h}")
        d = np.abs(result.state.arrays.coords[:, 1])
        exact = np.where(d < 2 * EPS, 1 - (1 - d / (2 * EPS)) ** 2, 1.0)
        np.testing.assert_allclose(result.state.v_values, exact, atol=1e-12)
        surface = result.records[-1]["surface"] / LENGTH
        assert surface == pytest.approx(1 + (h / EPS) ** 2 / 32, rel=1e-10)
