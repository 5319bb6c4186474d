"""Plane elasticity in the one lumped functional: forms, energy density, homogeneous damage."""

import numpy as np
import pytest
from ngsolve import CF, Integrate, x, y

from ngat.crack_density import crack_density
from ngat.elasticity import PlaneElasticity, elasticity, lame
from ngat.estimators import nu_estimator
from ngat.forms import LumpedAssembler, a_form, b_form, exact_dx, lumped_dx
from ngat.geometry import generate_mesh, glue, rectangle
from ngat.minimization import alternating_minimization
from ngat.parameters import ModelParameters, Parameters
from ngat.state import ATState

E, NU = 2.5, 0.3
STRAIN = np.array([[0.02, 0.015], [0.015, -0.01]])
"""A homogeneous strain with all three components."""


def framed_square(maxh: float = 0.25):
    """Return a mesh of the unit square ``body`` inside the ``frame`` [−0.25, 1.25]²."""
    d = 0.25
    strips = [(-d, -d, 1 + d, 0), (-d, 1, 1 + d, 1 + d), (-d, 0, 0, 1), (1, 0, 1 + d, 1)]
    frame = [rectangle(*strip, "frame") for strip in strips]
    return generate_mesh(glue([*frame, rectangle(0, 0, 1, 1, "body")]), maxh)


def affine_load(t):
    """u = t ε x (plus a rotation, which costs no energy) on the frame."""
    (a, b), (c, d) = STRAIN
    return CF((t * (a * x + (b + 0.01) * y), t * ((c - 0.01) * x + d * y)))


def textbook_density(model: str) -> float:
    """W of :data:`STRAIN` from the textbook formulas in E and ν (not from λ, μ)."""
    exx, eyy, exy = STRAIN[0, 0], STRAIN[1, 1], STRAIN[0, 1]
    shear = E / (1 + NU) * exy**2
    if model == "plane_stress":
        return E / (2 * (1 - NU**2)) * (exx**2 + eyy**2 + 2 * NU * exx * eyy) + shear
    factor = E / (2 * (1 + NU) * (1 - 2 * NU))
    return factor * ((1 - NU) * (exx**2 + eyy**2) + 2 * NU * exx * eyy) + shear


def plane_state(model: str, maxh: float = 0.25, **values) -> ATState:
    parameters = ModelParameters(model=model, young=E, poisson=NU, **values)
    return ATState(framed_square(maxh), parameters, {"frame": affine_load})


def test_lame_constants():
    lam, mu = lame(E, NU)
    assert mu == pytest.approx(E / (2 * (1 + NU)), rel=1e-15)
    assert lam == pytest.approx(E * NU / ((1 + NU) * (1 - 2 * NU)), rel=1e-15)
    stress = elasticity("plane_stress", E, NU)
    assert stress.lam == pytest.approx(E * NU / (1 - NU**2), rel=1e-14)


@pytest.mark.parametrize("lumped", [True, False])
def test_vector_assembly_equals_ngsolve_forms(lumped):
    state = plane_state("plane_strain", lumping=lumped)
    state.v.Set(0.5 + 0.3 * x * y)
    state.u.Set(CF((x * x - y, 0.3 * x * y + y)))
    density = state.elasticity
    a = a_form(state.fes_u, state.v, 1e-5, lumped=lumped, bilinear=density.bilinear).Assemble()
    b = b_form(
        state.fes, state.u, crack_density("at2", 0.05), lumped=lumped, bilinear=density.bilinear
    ).Assemble()
    arrays = state.arrays
    vector = LumpedAssembler(
        arrays, a.mat, lumped, density.element_dofs(arrays), density.element_stiffness(arrays)
    )
    reference = a.mat.AsVector().FV().NumPy()
    ours = vector.a_values(state.v_values, 1e-5)
    np.testing.assert_allclose(ours, reference, atol=1e-12 * abs(reference).max())
    scalar = LumpedAssembler(arrays, b.mat, lumped)
    reference = b.mat.AsVector().FV().NumPy()
    ours = scalar.b_values(density.density(arrays, state.u_values), crack_density("at2", 0.05))
    np.testing.assert_allclose(ours, reference, atol=1e-12 * abs(reference).max())


@pytest.mark.parametrize("model", ["plane_strain", "plane_stress"])
def test_bulk_energy_equals_integrated_density(model):
    # bulk = ∫ (P_j(v²) + η) W(u): W is constant per element, so the vertex rule is exact.
    state = plane_state(model)
    state.v.Set(0.5 + 0.3 * x * y)
    state.u.Set(CF((x * x - y, 0.3 * x * y + y)))
    density = state.elasticity.bilinear(state.u, state.u)
    bulk = Integrate((state.v * state.v + 1e-5) * density * lumped_dx(), state.mesh)
    assert state.energies()["bulk"] == pytest.approx(bulk, rel=1e-12)
    exact = Integrate(density * exact_dx(), state.mesh)
    W = state.elasticity.density(state.arrays, state.u_values)
    assert np.dot(state.arrays.area, W) == pytest.approx(exact, rel=1e-12)


@pytest.mark.parametrize("model", ["plane_strain", "plane_stress"])
def test_homogeneous_strain_gives_the_homogeneous_damage(model):
    # u = t ε x on Ω_D (interpolated 1e−9 inside its elements, so 1e−7 below): u stays affine,
    # and v = α G_c/(α G_c + W) everywhere (∇v = 0), the AT2 minimiser of
    # (v² + η) W + G_c α (1 − v)² over constants.
    gc, t = 0.4, 1.5
    state = plane_state(model, gc=gc, eps=0.1)
    state.apply_load(t)
    parameters = Parameters().replace(
        model=model, adapt="fixed", nonlinear="am", am_tol=1e-12, gc=gc, eps=0.1
    )
    alternating_minimization(state, parameters.solver, parameters.adaptivity)
    W = t**2 * textbook_density(model)
    assert isinstance(state.elasticity, PlaneElasticity)
    np.testing.assert_allclose(state.elasticity.density(state.arrays, state.u_values), W, rtol=1e-7)
    alpha = state.model.alpha
    v = alpha * gc / (alpha * gc + W)
    np.testing.assert_allclose(state.v_values, v, rtol=1e-7)
    area = 1.5**2
    energies = state.energies()
    assert energies["bulk"] == pytest.approx((v * v + state.model.eta) * W * area, rel=1e-7)
    assert energies["surface"] == pytest.approx(gc * alpha * (1 - v) ** 2 * area, rel=1e-7)
    # dI/dt at fixed v: 2 (v² + η) W / t |Ω|.
    force = state.reaction_forces()["force"]
    assert force == pytest.approx(2 * (v * v + state.model.eta) * W / t * area, rel=1e-7)


def test_scalar_load_on_a_plane_model_is_refused():
    from ngat.state import SceneError

    with pytest.raises(SceneError, match="2"):
        ATState(framed_square(), ModelParameters(model="plane_strain"), {"frame": lambda t: t * x})


@pytest.mark.parametrize(
    "values, word",
    [
        ({"model": "plane"}, "model"),
        ({"poisson": 0.5}, "poisson"),
        ({"young": -1.0}, "young"),
        ({"gc": 0.0}, "gc"),
        ({"model": "plane_strain", "linear_solver": "cg-h1amg"}, "linear_solver"),
    ],
)
def test_bad_model_parameters_name_the_parameter(values, word):
    from ngat.parameters import ParameterError

    with pytest.raises(ParameterError, match=word):
        Parameters().replace(**values)


@pytest.mark.parametrize("model", ["plane_strain", "plane_stress"])
def test_newton_gradient_and_hessian_are_those_of_the_energy(model, assert_newton_matches_ngsolve):
    # Newton's vectorised ∇I_j and ∇²I_j against NGSolve's linearisation of the same energy.
    state = plane_state(model, gc=0.4, eps=0.1)
    state.apply_load(1.5)
    rng = np.random.default_rng(2)
    u = state.u_values + 0.01 * rng.random(len(state.u_values))
    assert_newton_matches_ngsolve(state, u, rng.random(state.arrays.nv))


def test_newton_steps_converge_to_the_homogeneous_damage():
    # From a perturbed (u, v), projected Newton steps on the coupled plane-strain system reach
    # the exact minimiser (u affine, v = αG_c/(αG_c + W)) quadratically.
    from ngat.newton import NewtonSolver

    gc, t = 0.4, 1.5
    state = plane_state("plane_strain", gc=gc, eps=0.1)
    state.apply_load(t)
    rng = np.random.default_rng(3)
    free = ~state.dirichlet
    state.solve_u()
    state.u_values[free] += 1e-3 * rng.standard_normal(free.sum())
    W = t**2 * textbook_density("plane_strain")
    alpha = state.model.alpha
    exact = alpha * gc / (alpha * gc + W)
    state.v_values[:] = exact + 0.05 * rng.standard_normal(state.arrays.nv)
    newton, crack = NewtonSolver(state), np.zeros(state.arrays.nv, dtype=bool)
    errors = []
    for _ in range(6):
        assert newton.step(crack)
        errors.append(np.abs(state.v_values - exact).max())
    assert errors[-1] < 1e-7
    assert errors[2] < errors[1] ** 1.5


@pytest.mark.parametrize("ratio", [0.5, 2.0])
def test_at1_has_an_elastic_phase_then_the_homogeneous_damage(ratio):
    # AT1: the minimiser of (v² + η) W + G_c 3/(8ε) (1 − v) over constants v ≤ 1 is v = 1 up to
    # W_c = 3 G_c/(16ε) and v = W_c/W beyond (η neglected: 1e−5 relative).
    gc, eps = 0.4, 0.1
    critical = 3 * gc / (16 * eps)
    t = np.sqrt(ratio * critical / textbook_density("plane_strain"))
    state = plane_state("plane_strain", gc=gc, eps=eps, crack_density="at1")
    state.apply_load(t)
    parameters = Parameters().replace(
        model="plane_strain", adapt="fixed", nonlinear="am", am_tol=1e-12, gc=gc, eps=eps,
        crack_density="at1",
    )  # fmt: skip
    alternating_minimization(state, parameters.solver, parameters.adaptivity)
    W = ratio * critical
    v = min(1.0, critical / W)
    np.testing.assert_allclose(state.v_values, v, rtol=1e-7)
    area = 1.5**2
    energies = state.energies()
    assert energies["surface"] == pytest.approx(gc * 3 / (8 * eps) * (1 - v) * area, abs=1e-7)
    # ν is the residual of the v-step where v is free and only its positive part where v = 1
    # (there the rest is the bound's multiplier): 0 in both phases up to the AM tolerance,
    # although in the elastic phase the residual W/G_c − 3/(16ε) is −0.94.
    nu = nu_estimator(
        state.arrays, state.edges, state.u_values, state.v_values, state.model.surface,
        np.zeros(state.arrays.nv, dtype=bool), state.elasticity, gc,
    )  # fmt: skip
    assert nu.sum() < 1e-12


def test_at1_newton_gradient_and_hessian_are_those_of_the_energy(assert_newton_matches_ngsolve):
    state = plane_state("plane_strain", gc=0.4, eps=0.1, crack_density="at1")
    state.apply_load(1.5)
    rng = np.random.default_rng(4)
    u = state.u_values + 0.01 * rng.random(len(state.u_values))
    assert_newton_matches_ngsolve(state, u, rng.random(state.arrays.nv))


def test_at1_without_the_bounded_v_step_is_refused():
    from ngat.parameters import ParameterError

    with pytest.raises(ParameterError, match="crack_density=at1 needs bounded_v=true"):
        Parameters().replace(crack_density="at1", bounded_v=False)
    with pytest.raises(ParameterError, match="crack_density"):
        Parameters().replace(crack_density="at3")
