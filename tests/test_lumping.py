"""What mass lumping buys: the discrete maximum principle 0 ≤ v ≤ 1 (Proposition 3, issue 6).

With u ≡ 0 the v-step minimises ∫ α(1 − v)² + ε|∇v|² with v = 0 on a line. On the aligned
structured mesh of ``profile-1d`` a v depending on y only reduces the lumped problem exactly to
1-D: v_i = 1 − r^i at the node rows, with 0 < r < 1 the decaying root of the three-point stencil.
The consistent mass reduces to the 1-D consistent mass away from the side walls x = 0, L; its
off-diagonal −ε/h + αh/6 is positive for h > √24 ε, and then r < 0: v overshoots 1 next to the
line although the mesh satisfies Hypothesis A.
"""

import numpy as np
import pytest

from ngat.geometries.obtuse_line import scene as obtuse
from ngat.geometries.profile_1d import aligned_mesh
from ngat.geometries.profile_1d import scene as profile
from ngat.halfsteps import HalfStepSolvers
from ngat.parameters import ModelParameters
from ngat.state import ATState

EPS, H = 0.01, 0.1  # h = 10 ε > √24 ε


def decay_ratio(eps: float, h: float, lumped: bool) -> float:
    """Return the root |r| < 1 of off·r² + diag·r + off = 0 for the 1-D P1 v-step stencil."""
    alpha = 1 / (4 * eps)
    off = -eps / h + (0 if lumped else alpha * h / 6)
    diag = 2 * eps / h + (alpha * h if lumped else 4 * alpha * h / 6)
    return (-diag + np.sqrt(diag**2 - 4 * off**2)) / (2 * off)


def v_step(scene, mesh, lumping: bool, bounded_v: bool, **model) -> tuple[ATState, HalfStepSolvers]:
    """Return the state and its solvers after one u-step and one v-step at t = 0 (u ≡ 0)."""
    state = ATState(mesh, ModelParameters(lumping=lumping, **model), scene.loads, scene.crack)
    steps = HalfStepSolvers(state, bounded_v=bounded_v)
    state.apply_load(0.0)
    steps.solve_u()
    steps.solve_v(state.crack_set())
    return state, steps


def row(state: ATState, y: float, x: float | None = None) -> np.ndarray:
    """Return v at the vertices with that y (and that x, if given)."""
    coords = state.arrays.coords
    mask = np.abs(coords[:, 1] - y) < 1e-9
    if x is not None:
        mask &= np.abs(coords[:, 0] - x) < 1e-9
    return state.v_values[mask]


def test_lumped_v_step_obeys_the_maximum_principle_on_a_nonobtuse_mesh():
    state, _ = v_step(profile, aligned_mesh(H), lumping=True, bounded_v=False, eps=EPS)
    r = decay_ratio(EPS, H, lumped=True)
    assert 0 < r < 0.1
    for i in (1, 2, 3):
        np.testing.assert_allclose(row(state, i * H), 1 - r**i, rtol=1e-9)
        np.testing.assert_allclose(row(state, -i * H), 1 - r**i, rtol=1e-9)
    assert state.v_values.min() >= 0
    assert state.v_values.max() <= 1


def test_consistent_mass_v_step_overshoots_on_the_same_mesh():
    state, _ = v_step(profile, aligned_mesh(H), lumping=False, bounded_v=False, eps=EPS)
    r = decay_ratio(EPS, H, lumped=False)
    assert -0.2 < r < -0.15
    # Away from the side walls: the 1-D consistent-mass solution, 17 % above 1 next to the line.
    for i in (1, 2, 3):
        np.testing.assert_allclose(row(state, i * H, x=0.5), 1 - r**i, rtol=1e-5)
    assert state.v_values.max() > 1.17
    assert state.v_values.min() >= 0, "the undershoot is that of 1 − r² = 0.97, not below 0"


def test_resolved_eps_hides_the_failure():
    # h = ε/2 < √24 ε: the reduced 1-D stencil is an M-matrix again and v stays in [0, 1],
    # although the 2-D consistent mass still has positive off-diagonals on the hypotenuses.
    eps, h = 0.05, 0.025
    assert decay_ratio(eps, h, lumped=False) > 0
    state, _ = v_step(profile, aligned_mesh(h), lumping=False, bounded_v=False, eps=eps)
    assert state.v_values.min() >= -1e-12
    assert state.v_values.max() <= 1 + 1e-12


@pytest.mark.parametrize("lumping, v_max", [(True, 1.0222297), (False, 1.0294994)])
def test_obtuse_mesh_overshoots_with_and_without_lumping(lumping, v_max):
    # Hypothesis A fails: the lumped v-step overshoots too, the consistent one by a third more.
    state, _ = v_step(obtuse, obtuse.make_mesh(0.05), lumping=lumping, bounded_v=False)
    assert state.v_values.max() == pytest.approx(v_max, abs=1e-6)
    assert state.v_values.min() >= 0


@pytest.mark.parametrize(
    "scene, mesh, model",
    [
        (profile, lambda: aligned_mesh(H), {"eps": EPS}),
        (obtuse, lambda: obtuse.make_mesh(0.05), {}),
    ],
    ids=["profile", "obtuse"],
)
def test_bounded_v_step_keeps_the_consistent_mass_v_in_unit_interval(scene, mesh, model):
    state, steps = v_step(scene, mesh(), lumping=False, bounded_v=True, **model)
    v = state.v_values
    assert steps.bound_active > 0
    assert v.min() >= -1e-12
    assert v.max() <= 1 + 1e-12
    # Karush–Kuhn–Tucker conditions of min I_j over 0 ≤ v ≤ 1: the gradient B v − α m vanishes
    # where v is inside, is ≤ 0 where v = 1 and ≥ 0 where v = 0 (off the crack line).
    operators = steps.operators
    operators.b_matrix.AsVector().FV().NumPy()[:] = operators.assembler.b_values(
        np.zeros(state.arrays.ne), state.model.surface
    )
    gradient = operators.b_matrix.CreateColVector()
    gradient.data = operators.b_matrix * state.v.vec
    gradient = gradient.FV().NumPy() - state.model.alpha * state.arrays.mass
    free = ~state.crack_set()
    scale = np.abs(gradient).max()
    inside = free & (v > 1e-12) & (v < 1 - 1e-12)
    assert np.abs(gradient[inside]).max(initial=0) < 1e-10 * scale
    assert gradient[free & (v >= 1 - 1e-12)].max() < 1e-10 * scale
    assert gradient[free & (v <= 1e-12)].min(initial=0) > -1e-10 * scale
    # The unconstrained v-step on the same mesh does leave [0, 1].
    unbounded, _ = v_step(scene, mesh(), lumping=False, bounded_v=False, **model)
    assert unbounded.v_values.max() > 1.02
