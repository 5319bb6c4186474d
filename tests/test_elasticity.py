"""Plane elasticity in the one lumped functional: forms, energy density, homogeneous damage."""

import numpy as np
import pytest
from ngsolve import CF, Integrate, x, y

from ngat.crack_density import crack_density
from ngat.elasticity import PlaneElasticity, elasticity, lame
from ngat.estimators import nu_estimator
from ngat.forms import (
    LumpedAssembler,
    MeshArrays,
    a_form,
    b_form,
    exact_dx,
    graph_matrix,
    graph_positions,
    lumped_dx,
)
from ngat.geometry import generate_mesh, glue, rectangle
from ngat.halfsteps import HalfStepSolvers
from ngat.minimization import alternating_minimization
from ngat.operators import LumpedOperators
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
        arrays, a.mat, lumped, density.components, density.element_stiffness(arrays)
    )
    reference = a.mat.AsVector().FV().NumPy()
    ours = vector.a_values(state.v_values, 1e-5)
    np.testing.assert_allclose(ours, reference, atol=1e-12 * abs(reference).max())
    scalar = LumpedAssembler(arrays, b.mat, lumped)
    reference = b.mat.AsVector().FV().NumPy()
    ours = scalar.b_values(density.density(arrays, state.u_values), crack_density("at2", 0.05))
    np.testing.assert_allclose(ours, reference, atol=1e-12 * abs(reference).max())


@pytest.mark.parametrize("model", ["antiplane", "plane_strain"])
def test_operators_write_the_forms_into_their_own_graph(model):
    # LumpedOperators build their graphs from the mesh's edges (ngat.forms.graph_matrix): the
    # same graphs as NGSolve's assembly of a_form and b_form, and the same values.
    if model == "antiplane":
        state = ATState(framed_square(0.25), ModelParameters(), {"frame": lambda t: 0 * t})
        state.u.Set(x * x - y)
    else:
        state = plane_state(model)
        state.u.Set(CF((x * x - y, 0.3 * x * y + y)))
    state.v.Set(0.5 + 0.3 * x * y)
    density = state.elasticity
    operators = LumpedOperators(state)
    operators.assemble_a()
    operators.assemble_b()
    a = a_form(state.fes_u, state.v, state.model.eta, bilinear=density.bilinear).Assemble()
    b = b_form(state.fes, state.u, state.model.surface, bilinear=density.bilinear).Assemble()
    for ours, form in ((operators.a_matrix, a.mat), (operators.b_matrix, b.mat)):
        for mine, theirs in zip(ours.CSR()[1:], form.CSR()[1:], strict=True):
            np.testing.assert_array_equal(np.asarray(mine), np.asarray(theirs))
        reference = form.AsVector().FV().NumPy()
        values = ours.AsVector().FV().NumPy()
        np.testing.assert_allclose(values, reference, atol=1e-12 * abs(reference).max())


@pytest.mark.parametrize("components", [1, 2])
def test_graph_positions_are_where_a_search_of_the_graph_finds_the_couplings(components):
    # graph_positions computes every element coupling's entry from the edge numbers; a search
    # of the couplings' keys among the sorted rows of graph_matrix must find the same entries.
    mesh = framed_square(0.25)
    mesh.Refine()
    arrays = MeshArrays(mesh)
    position, diagonal = graph_positions(arrays, components)
    matrix = graph_matrix(arrays, components)  # CSR() views the matrix's memory
    _, cols, rowptr = (np.asarray(a, dtype=np.int64) for a in matrix.CSR())
    n = len(rowptr) - 1
    keys = np.repeat(np.arange(n), np.diff(rowptr)) * n + cols
    dofs = np.hstack([arrays.elements + k * arrays.nv for k in range(components)])
    local = dofs[:, :, None] * n + dofs[:, None, :]
    np.testing.assert_array_equal(position, np.searchsorted(keys, local))
    np.testing.assert_array_equal(keys[position], local)
    np.testing.assert_array_equal(keys[diagonal], np.arange(n) * (n + 1))
    with pytest.raises(ValueError, match="build it with graph_matrix"):
        LumpedAssembler(arrays, graph_matrix(arrays, components + 1), components=components)


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
    force = LumpedOperators(state).reaction_forces()["force"]
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
    steps = HalfStepSolvers(state)
    state.apply_load(t)
    rng = np.random.default_rng(3)
    free = ~state.dirichlet
    steps.solve_u()
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


@pytest.mark.parametrize("model", ["plane_strain", "plane_stress"])
def test_voldev_split_parts_sum_to_the_unsplit_model(model):
    # W⁺ + W⁻ = W, s⁺ + s⁻ = s and K_dev + K_vol = K on a field with elements in tension and
    # in compression; W⁻ lives only where tr ε < 0, and K_vol is the bulk modulus' part.
    state = plane_state(model, split="voldev")
    state.u.Set(CF((0.1 * x * x - 0.05 * y, 0.03 * x * y - 0.08 * y * y)))
    split, arrays, u = state.elasticity, state.arrays, state.u_values
    whole = elasticity(model, E, NU)
    tension = split.tension(arrays, u)
    assert tension.any() and not tension.all()
    W_plus, W_minus = split.degraded_density(arrays, u), split.intact_density(arrays, u)
    W = whole.density(arrays, u)
    np.testing.assert_allclose(W_plus + W_minus, W, rtol=1e-12, atol=1e-13 * W.max())
    assert np.all(W_minus[tension] == 0) and np.all(W_minus[~tension] > 0)
    assert np.all(W_plus >= 0)
    gradient = split.gradient(arrays, u)
    plus, minus = split.fluxes(gradient)
    np.testing.assert_allclose(plus + minus, whole.flux(gradient), atol=1e-15)
    dev, vol = split.parts(arrays)
    np.testing.assert_allclose(dev + vol, whole.element_stiffness(arrays), atol=1e-14)
    # K_vol u · u = |T| (K/2) (tr ε)², with K = λ + 2μ/d (d = 3 plane strain, 2 plane stress).
    lam, mu = whole.lam, whole.mu
    bulk = lam + 2 * mu / (3 if model == "plane_strain" else 2)
    local = u[split.element_dofs(arrays)]
    trace = gradient[:, 0, 0] + gradient[:, 1, 1]
    volumetric = arrays.area * bulk / 2 * trace**2
    np.testing.assert_allclose(
        np.einsum("ea,eab,eb->e", local, vol, local), volumetric, atol=1e-12 * volumetric.max()
    )


def test_voldev_newton_gradient_and_hessian_are_those_of_the_energy(assert_newton_matches_ngsolve):
    # The split energy is C¹ and piecewise quadratic: away from tr ε = 0 its Hessian is that of
    # the element's quadratic piece, which NGSolve's linearisation of IfPos gives as well.
    state = plane_state("plane_strain", gc=0.4, eps=0.1, split="voldev")
    state.u.Set(CF((0.1 * x * x - 0.05 * y, 0.03 * x * y - 0.08 * y * y)))
    tension = state.elasticity.tension(state.arrays, state.u_values)
    assert tension.any() and not tension.all()
    rng = np.random.default_rng(5)
    assert_newton_matches_ngsolve(state, state.u_values.copy(), rng.random(state.arrays.nv))


def u_step_under_load(split: str):
    """Return the state and its half-step solvers after one u-step: load 5, v varying."""
    state = plane_state("plane_strain", split=split)
    steps = HalfStepSolvers(state)
    state.apply_load(5.0)
    state.v.Set(0.2 + 0.8 * (x - 0.5) ** 2 + 0.5 * y * y)
    steps.solve_u()
    return state, steps


def u_step_gradient(state, steps) -> np.ndarray:
    """Return A(u) u, the gradient of the u-step's energy at u (a split's A at its own u)."""
    operators = steps.operators
    residual = operators.a_matrix.CreateColVector()
    operators.assemble_a()
    residual.data = operators.a_matrix * state.u.vec
    return residual.FV().NumPy().copy()


def test_voldev_u_step_is_the_minimiser_of_the_split_energy():
    # With v varying and a load that compresses part of the body, the semismooth Newton u-step
    # ends at a u whose own tension pattern makes it stationary: the gradient 2 A(P(u)) u of
    # the convex C¹ bulk energy vanishes at the free DOFs, so u is its minimiser.
    state, steps = u_step_under_load("voldev")
    tension = state.elasticity.tension(state.arrays, state.u_values)
    assert tension.any() and not tension.all()
    r = u_step_gradient(state, steps)
    assert np.abs(r[~state.dirichlet]).max() < 1e-10 * np.abs(r).max()
    # The unsplit u-step on the same v gives another u, with more energy in compression.
    unsplit, _ = u_step_under_load("none")
    assert np.abs(unsplit.u_values - state.u_values).max() > 1e-3 * np.abs(state.u_values).max()


def test_voldev_homogeneous_compression_degrades_only_the_deviatoric_part():
    # u = -t ε x with tr ε < 0: W⁺ = μ|dev ε|², W⁻ = (K/2)(tr ε)², and the homogeneous AT2
    # damage is v = α G_c/(α G_c + W⁺) (the volumetric part does not drive the crack).
    gc, t = 0.4, -3.0
    state = plane_state("plane_strain", gc=gc, eps=0.1, split="voldev")
    state.apply_load(t)
    parameters = Parameters().replace(
        model="plane_strain", adapt="fixed", nonlinear="am", am_tol=1e-12, gc=gc, eps=0.1,
        split="voldev",
    )  # fmt: skip
    alternating_minimization(state, parameters.solver, parameters.adaptivity)
    lam, mu = lame(E, NU)
    strain = t * STRAIN
    trace = np.trace(strain)
    assert trace < 0
    W_plus = mu * ((strain**2).sum() - trace**2 / 3)
    W_minus = (lam + 2 * mu / 3) / 2 * trace**2
    arrays = state.arrays
    np.testing.assert_allclose(state.elasticity.degraded_density(arrays, state.u_values), W_plus,
                               rtol=1e-6)  # fmt: skip
    alpha = state.model.alpha
    v = alpha * gc / (alpha * gc + W_plus)
    np.testing.assert_allclose(state.v_values, v, rtol=1e-7)
    bulk = ((v * v + state.model.eta) * W_plus + W_minus) * 1.5**2
    assert state.energies()["bulk"] == pytest.approx(bulk, rel=1e-6)


def test_split_on_the_antiplane_model_is_refused():
    from ngat.parameters import ParameterError

    with pytest.raises(ParameterError, match="antiplane model has no volumetric strain"):
        Parameters().replace(split="voldev")
    with pytest.raises(ParameterError, match="split must be one of"):
        Parameters().replace(model="plane_strain", split="star")
    with pytest.raises(ParameterError, match="split=spectral .* needs model=plane_strain"):
        Parameters().replace(model="plane_stress", split="spectral")


MIXED = CF((0.1 * x * x - 0.05 * y + 0.07 * x * y, 0.03 * x * y - 0.08 * y * y + 0.02 * x))
"""A displacement whose elements have principal strains of both signs and both traces."""


def test_spectral_split_parts_and_weights_give_the_split_energy():
    # W⁺ + W⁻ = W and s⁺ + s⁻ = s; W± = s±:ε (degree-2 homogeneity); with c_T the u-step's
    # element matrix Σ_k w_k K_k gives u_T·(Σ w_k K_k) u_T = |T| (c W⁺ + W⁻), and with c = 1
    # it is the unsplit element matrix.
    state = plane_state("plane_strain", split="spectral")
    state.u.Set(MIXED)
    split, arrays, u = state.elasticity, state.arrays, state.u_values
    whole = elasticity("plane_strain", E, NU)
    signs = split.tension(arrays, u)
    assert signs[:, 0].any() and not signs[:, 0].all()
    assert (signs[:, 1] & ~signs[:, 2]).any() and (signs[:, 1] == signs[:, 2]).any()
    W_plus, W_minus = split.degraded_density(arrays, u), split.intact_density(arrays, u)
    W = whole.density(arrays, u)
    np.testing.assert_allclose(W_plus + W_minus, W, rtol=1e-12, atol=1e-13 * W.max())
    assert np.all(W_plus >= 0) and np.all(W_minus >= 0)
    gradient = split.gradient(arrays, u)
    plus, minus = split.fluxes(gradient)
    np.testing.assert_allclose(plus + minus, whole.flux(gradient), atol=1e-15)
    np.testing.assert_allclose(np.einsum("eij,eij->e", plus, gradient), W_plus, atol=1e-14)
    parts, local = split.parts(arrays), u[split.element_dofs(arrays)]
    c = np.random.default_rng(3).random(arrays.ne)
    weights = split.weights(arrays, u, c)
    matrix = sum(w[:, None, None] * k for w, k in zip(weights, parts, strict=True))
    np.testing.assert_allclose(
        np.einsum("ea,eab,eb->e", local, matrix, local),
        arrays.area * (c * W_plus + W_minus),
        rtol=1e-12, atol=1e-14 * (arrays.area * W).max(),
    )  # fmt: skip
    weights = split.weights(arrays, u, np.ones(arrays.ne))
    unsplit = sum(w[:, None, None] * k for w, k in zip(weights, parts, strict=True))
    np.testing.assert_allclose(unsplit, whole.element_stiffness(arrays), atol=1e-13)


def test_spectral_split_keeps_half_of_a_pure_shear():
    # ε = γ (e₁⊗e₂ + e₂⊗e₁) has principal strains ±γ: W⁺ = W⁻ = μγ², where the
    # volumetric–deviatoric split degrades all of W = 2μγ².
    gamma = 0.01
    state = plane_state("plane_strain", split="spectral")
    state.u.Set(CF((gamma * y, gamma * x)))
    arrays, u = state.arrays, state.u_values
    mu = lame(E, NU)[1]
    np.testing.assert_allclose(state.elasticity.degraded_density(arrays, u), mu * gamma**2)
    np.testing.assert_allclose(state.elasticity.intact_density(arrays, u), mu * gamma**2)
    voldev = elasticity("plane_strain", E, NU, split="voldev")
    np.testing.assert_allclose(voldev.degraded_density(arrays, u), 2 * mu * gamma**2)


def test_spectral_newton_gradient_and_hessian_are_those_of_the_energy(
    assert_newton_matches_ngsolve,
):
    # The spectral energy is C¹; away from ρ = 0 and from sign changes of the eigenvalues its
    # Hessian is NGSolve's linearisation of the closed-form eigenvalues p ± ρ.
    state = plane_state("plane_strain", gc=0.4, eps=0.1, split="spectral")
    state.u.Set(MIXED)
    rng = np.random.default_rng(7)
    assert_newton_matches_ngsolve(state, state.u_values.copy(), rng.random(state.arrays.nv))


def test_spectral_u_step_is_the_minimiser_of_the_split_energy():
    # The Newton u-step ends where the gradient A(u) u of the convex C¹ bulk energy vanishes at
    # the free DOFs, and at another u than the volumetric–deviatoric split's.
    state, steps = u_step_under_load("spectral")
    signs = state.elasticity.tension(state.arrays, state.u_values)
    assert (signs[:, 1] & ~signs[:, 2]).any()
    r = u_step_gradient(state, steps)
    assert np.abs(r[~state.dirichlet]).max() < 1e-9 * np.abs(r).max()
    voldev, _ = u_step_under_load("voldev")
    assert np.abs(voldev.u_values - state.u_values).max() > 1e-3 * np.abs(state.u_values).max()


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_spectral_split_of_an_isotropic_strain(sign):
    # ε = ±0.01 I has equal principal strains (ρ = 0, the Hessian's limit): in tension all of
    # W degrades and the element matrix is c K, in compression none does and it is K.
    state = plane_state("plane_strain", split="spectral")
    state.u.Set(CF((sign * 0.01 * x, sign * 0.01 * y)))
    split, arrays, u = state.elasticity, state.arrays, state.u_values
    W = elasticity("plane_strain", E, NU).density(arrays, u)
    W_plus = split.degraded_density(arrays, u)
    np.testing.assert_allclose(W_plus, W if sign > 0 else 0 * W, atol=1e-15)
    c = np.full(arrays.ne, 0.3)
    weights = split.weights(arrays, u, c)
    matrix = sum(w[:, None, None] * k for w, k in zip(weights, split.parts(arrays), strict=True))
    factor = 0.3 if sign > 0 else 1.0
    np.testing.assert_allclose(matrix, factor * split.element_stiffness(arrays), atol=1e-13)
