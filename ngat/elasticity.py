"""The elastic energy density W of each model: anti-plane (the paper), plane strain, plane stress.

Every model shares one lumped functional,

    I_j(u, v) = ∫ (P_j(v²) + η) W(u) + G_c [α P_j((1 − v)²) + ε |∇v|²],   α = 1/(4ε),

the paper's eq. (7) with the energy density W of the model:

- ``antiplane``: u is the scalar out-of-plane displacement and W = |∇u|² (the paper);
- ``plane_strain``: u = (u_x, u_y) and W = μ ε(u):ε(u) + (λ/2) (tr ε(u))², with the Lamé
  constants of Young's modulus E and Poisson's ratio ν;
- ``plane_stress``: the same with λ replaced by the plane-stress λ* = 2λμ/(λ + 2μ).

W is a quadratic form, W(u) = s(u) : ∇u with the flux s = ∇u (anti-plane) or s = σ(u)/2
(σ = 2μ ε + λ tr ε I), so the u-step's bilinear form is a_j(v; u, φ) = ∫ (P_j(v²) + η) s(u) : ∇φ
and a_j(v; u, u) = ∫ (P_j(v²) + η) W(u). With P1 elements ∇u, ε(u), s(u) and W(u) are constant
on each triangle. Units: lengths in the scene's unit L, E and W in units of force/L² (energy per
area, plane problems per unit thickness), G_c in energy per length of crack (force/L).

A plane model may split W = W⁺ + W⁻ and degrade only W⁺ (``split=voldev``,
:class:`VolumetricDeviatoricSplit`, or ``split=spectral``, :class:`SpectralSplit`): I_j then
has (P_j(v²) + η) W⁺ + W⁻ in place of (P_j(v²) + η) W, and every method below has its split
counterpart (``degraded_density``, ``intact_density``, ``fluxes``, ``parts`` and ``weights``);
without a split they return W, 0 and the one element matrix.

An :class:`Elasticity` gives the P1 space of u and, from it, the symbolic bilinear form (the
definition, :func:`ngat.forms.a_form`), the element matrices of the fast assembly
(:class:`ngat.forms.LumpedAssembler`), the density per element (the v-step, the energies, ν of
:mod:`ngat.estimators`) and the flux with its edge jumps (μ).
"""

from __future__ import annotations

import ngsolve
import numpy as np
from ngsolve import H1, IfPos, InnerProduct, Sym, Trace, VectorH1, grad

from ngat.forms import MeshArrays

__all__ = [
    "Elasticity",
    "AntiPlane",
    "PlaneElasticity",
    "VolumetricDeviatoricSplit",
    "SpectralSplit",
    "lame",
    "elasticity",
]


class Elasticity:
    """Energy density W of one model (see the module docstring).

    Attributes
    ----------
    components : int
        Components of u: 1 (anti-plane) or 2 (plane).
    modulus : float
        Stiffness scale c of a_j: the energy norm of u is at least sqrt(c) ‖∇u‖ (up to Korn's
        constant), so μ/sqrt(c) bounds the u-residual in the dual of the energy norm
        (:func:`ngat.minimization.estimate`). 1 for the anti-plane W = |∇u|², the shear
        modulus μ for the plane models.
    """

    components = 1
    modulus = 1.0

    def space(self, mesh: ngsolve.Mesh) -> ngsolve.FESpace:
        """Return the P1 space of u on ``mesh`` (updated with the mesh)."""
        raise NotImplementedError

    def bilinear(self, u, phi) -> ngsolve.CoefficientFunction:
        """Return s(u) : ∇φ as a CoefficientFunction of trial/test functions or GridFunctions."""
        raise NotImplementedError

    def component_bilinear(self, i: int, u, phi) -> ngsolve.CoefficientFunction:
        """Return s(u eᵢ) : ∇(φ eᵢ) for scalar u, φ: the i-th diagonal block of the bilinear.

        The block-diagonal part of the u-step's operator, whose blocks are scalar forms that
        ``h1amg`` accepts (:class:`ngat.linear.AMGConjugateGradient`); by Korn's inequality it
        is spectrally equivalent to the whole operator.
        """
        raise NotImplementedError

    def element_dofs(self, arrays: MeshArrays) -> np.ndarray:
        """Return the DOF numbers of u on each element, shape (ne, 3 · components)."""
        raise NotImplementedError

    def element_stiffness(self, arrays: MeshArrays) -> np.ndarray:
        """Return ∫_T s(φ_a) : ∇φ_b for the local DOFs of :meth:`element_dofs`."""
        raise NotImplementedError

    def gradient(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return ∇u on each element, shape (ne, components, 2), from the DOF values of u."""
        nv = arrays.nv
        return np.stack(
            [arrays.gradient(u[i * nv : (i + 1) * nv]) for i in range(self.components)], axis=1
        )

    def flux(self, gradient: np.ndarray) -> np.ndarray:
        """Return s(u) per element, shape (ne, components, 2), from :meth:`gradient`."""
        raise NotImplementedError

    def density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return W(u) on each element, shape (ne,)."""
        raise NotImplementedError

    # -- the energy split: W = W⁺ + W⁻, only W⁺ degraded (none by default) -------------------
    split = False
    piecewise_quadratic = True
    """Whether the u-step's energy is quadratic on each piece of a finite pattern
    (:meth:`tension`): then the semismooth Newton u-step ends when a step keeps the pattern."""

    def degraded_density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return W⁺(u), the part of W that v degrades (all of W without a split)."""
        return self.density(arrays, u)

    def intact_density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray | None:
        """Return W⁻(u), the part v does not degrade; ``None`` without a split."""
        return None

    def fluxes(self, gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Return the fluxes (s⁺, s⁻) of W⁺ and W⁻ (W^± = s^± : ∇u); s⁻ is ``None`` unsplit."""
        return self.flux(gradient), None

    def parts(self, arrays: MeshArrays) -> list[np.ndarray]:
        """Return element matrices K_k whose weighted sum is the u-step's (:meth:`weights`)."""
        return [self.element_stiffness(arrays)]

    def weights(self, arrays: MeshArrays, u: np.ndarray, c: np.ndarray) -> list[np.ndarray]:
        """Return the element weights of :meth:`parts` in a_j, with c_T = ∫_T P_j(v²)/|T| + η.

        Without a split the u-step's element matrix is c_T K_T: one part, weight c.
        """
        return [c]

    def tension(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray | None:
        """Return the split's pattern per element (e.g. tr ε ≥ 0); ``None`` without a split."""
        return None

    def degraded_form(self, u) -> ngsolve.CoefficientFunction:
        """Return W⁺(u) as a CoefficientFunction (all of W without a split)."""
        return self.bilinear(u, u)

    def intact_form(self, u) -> ngsolve.CoefficientFunction | None:
        """Return W⁻(u) as a CoefficientFunction; ``None`` without a split."""
        return None


class AntiPlane(Elasticity):
    """W = |∇u|², the paper's anti-plane displacement (u scalar, s = ∇u)."""

    def space(self, mesh: ngsolve.Mesh) -> ngsolve.FESpace:
        """Return P1 (``H1`` of order 1)."""
        return H1(mesh, order=1, autoupdate=True)

    def bilinear(self, u, phi) -> ngsolve.CoefficientFunction:
        """Return ∇u·∇φ."""
        return grad(u) * grad(phi)

    def component_bilinear(self, i: int, u, phi) -> ngsolve.CoefficientFunction:
        """Return ∇u·∇φ (one component: the whole bilinear)."""
        return grad(u) * grad(phi)

    def element_dofs(self, arrays: MeshArrays) -> np.ndarray:
        """Return the element vertices (P1 DOF = vertex)."""
        return arrays.elements

    def element_stiffness(self, arrays: MeshArrays) -> np.ndarray:
        """Return ∫_T ∇φ_a·∇φ_b."""
        return arrays.stiffness

    def flux(self, gradient: np.ndarray) -> np.ndarray:
        """Return ∇u."""
        return gradient

    def density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return |∇u|²."""
        return arrays.squared_gradient(u)


class PlaneElasticity(Elasticity):
    """W = μ ε:ε + (λ/2)(tr ε)² of isotropic plane elasticity (u = (u_x, u_y), s = σ/2).

    The DOFs of u are those of NGSolve's ``VectorH1``: all x components (one per vertex),
    then all y components.

    Parameters
    ----------
    lam, mu
        Lamé constants λ and μ (λ* for plane stress, see :func:`elasticity`).
    """

    components = 2

    def __init__(self, lam: float, mu: float):
        self.lam = lam
        self.mu = mu
        self.modulus = mu

    def space(self, mesh: ngsolve.Mesh) -> ngsolve.FESpace:
        """Return P1 vector fields (``VectorH1`` of order 1)."""
        return VectorH1(mesh, order=1, autoupdate=True)

    def bilinear(self, u, phi) -> ngsolve.CoefficientFunction:
        """Return σ(u):ε(φ)/2 = μ ε(u):ε(φ) + (λ/2) div u div φ."""
        return self.mu * InnerProduct(Sym(grad(u)), Sym(grad(phi))) + self.lam / 2 * Trace(
            grad(u)
        ) * Trace(grad(phi))

    def component_bilinear(self, i: int, u, phi) -> ngsolve.CoefficientFunction:
        """Return μ/2 ∇u·∇φ + (μ + λ)/2 ∂ᵢu ∂ᵢφ, the bilinear of u eᵢ and φ eᵢ."""
        return (
            self.mu / 2 * grad(u) * grad(phi) + (self.mu + self.lam) / 2 * grad(u)[i] * grad(phi)[i]
        )

    def element_dofs(self, arrays: MeshArrays) -> np.ndarray:
        """Return (x₀, x₁, x₂, y₀, y₁, y₂): vertex numbers, then vertex numbers + nv."""
        return np.hstack([arrays.elements, arrays.elements + arrays.nv])

    def element_stiffness(self, arrays: MeshArrays) -> np.ndarray:
        """Return |T| [μ/2 (δ_ij ∇φ_a·∇φ_b + ∂_j φ_a ∂_i φ_b) + λ/2 ∂_i φ_a ∂_j φ_b].

        Row (i, a) and column (j, b) belong to the test function φ_a e_i and the trial
        function φ_b e_j, ordered as in :meth:`element_dofs`.
        """
        g = arrays.grad_phi  # (ne, 3, 2): ∂_k φ_a
        laplace = np.einsum("eak,ebk->eab", g, g)
        eye = np.eye(2)
        local = (
            self.mu / 2 * (eye[None, :, None, :, None] * laplace[:, None, :, None, :])
            + self.mu / 2 * np.einsum("eaj,ebi->eiajb", g, g)
            + self.lam / 2 * np.einsum("eai,ebj->eiajb", g, g)
        )
        return arrays.area[:, None, None] * local.reshape(-1, 6, 6)

    def strain(self, gradient: np.ndarray) -> np.ndarray:
        """Return ε = (∇u + ∇uᵀ)/2 per element."""
        return (gradient + gradient.transpose(0, 2, 1)) / 2

    def flux(self, gradient: np.ndarray) -> np.ndarray:
        """Return σ/2 = μ ε + (λ/2) tr ε I."""
        strain = self.strain(gradient)
        trace = strain[:, 0, 0] + strain[:, 1, 1]
        return self.mu * strain + self.lam / 2 * trace[:, None, None] * np.eye(2)

    def density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return μ ε:ε + (λ/2)(tr ε)²."""
        strain = self.strain(self.gradient(arrays, u))
        trace = strain[:, 0, 0] + strain[:, 1, 1]
        return self.mu * (strain**2).sum(axis=(1, 2)) + self.lam / 2 * trace**2


class VolumetricDeviatoricSplit(PlaneElasticity):
    """W⁺ = μ |dev ε|² + (K/2)⟨tr ε⟩₊², W⁻ = (K/2)⟨tr ε⟩₋² (Amor, Marigo, Maurini 2009).

    Only the deviatoric and the tensile volumetric energy degrade, so a crack does not
    interpenetrate and compression does not break the material. |dev ε|² = ε:ε − (tr ε)²/d and
    K = λ + 2μ/d with d = 3 in plane strain (the deviator of the 3-D strain with ε_zz = 0) and
    d = 2 in plane stress (the in-plane deviator, with λ*); W⁺ + W⁻ = W. With P1 elements tr ε
    is constant per element, so the split is elementwise: the u-step's element matrix is
    c_T K_dev + (c_T if tr ε_T ≥ 0 else 1) K_vol, with K_vol = |T| (K/2) div φ_a div φ_b and
    K_dev the rest of the element matrix. The u-step's energy is then piecewise quadratic and
    convex, and :meth:`ngat.halfsteps.HalfStepSolvers.solve_u` minimises it by a semismooth
    Newton method.

    Parameters
    ----------
    lam, mu
        Lamé constants λ (λ* for plane stress) and μ.
    dimension
        d of the deviator: 3 (plane strain) or 2 (plane stress).
    """

    split = True

    def __init__(self, lam: float, mu: float, dimension: int):
        super().__init__(lam, mu)
        self.dimension = dimension
        self.bulk = lam + 2 * mu / dimension

    def parts(self, arrays: MeshArrays) -> list[np.ndarray]:
        """Return [K_dev, K_vol] (see the class docstring)."""
        g = arrays.grad_phi
        volumetric = (
            self.bulk / 2 * arrays.area[:, None, None]
            * np.einsum("eai,ebj->eiajb", g, g).reshape(-1, 6, 6)
        )  # fmt: skip
        return [self.element_stiffness(arrays) - volumetric, volumetric]

    def tension(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return tr ε ≥ 0 per element."""
        gradient = self.gradient(arrays, u)
        return gradient[:, 0, 0] + gradient[:, 1, 1] >= 0

    def weights(self, arrays: MeshArrays, u: np.ndarray, c: np.ndarray) -> list[np.ndarray]:
        """Return [c, c where tr ε ≥ 0 else 1]."""
        return [c, np.where(self.tension(arrays, u), c, 1.0)]

    def _split_trace(self, gradient: np.ndarray):
        strain = self.strain(gradient)
        trace = strain[:, 0, 0] + strain[:, 1, 1]
        return strain, np.maximum(trace, 0.0), np.minimum(trace, 0.0)

    def degraded_density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return μ (ε:ε − (tr ε)²/d) + (K/2)⟨tr ε⟩₊²."""
        strain, positive, negative = self._split_trace(self.gradient(arrays, u))
        trace = positive + negative
        deviatoric = (strain**2).sum(axis=(1, 2)) - trace**2 / self.dimension
        return self.mu * deviatoric + self.bulk / 2 * positive**2

    def intact_density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return (K/2)⟨tr ε⟩₋²."""
        _, _, negative = self._split_trace(self.gradient(arrays, u))
        return self.bulk / 2 * negative**2

    def fluxes(self, gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return s⁺ = μ (ε − tr ε I/d) + (K/2)⟨tr ε⟩₊ I and s⁻ = (K/2)⟨tr ε⟩₋ I."""
        strain, positive, negative = self._split_trace(gradient)
        eye = np.eye(2)
        trace = (positive + negative)[:, None, None]
        plus = self.mu * (strain - trace / self.dimension * eye) + (
            self.bulk / 2 * positive[:, None, None] * eye
        )
        return plus, self.bulk / 2 * negative[:, None, None] * eye

    def degraded_form(self, u) -> ngsolve.CoefficientFunction:
        """Return W⁺(u) as a CoefficientFunction."""
        strain = Sym(grad(u))
        trace = Trace(strain)
        deviatoric = InnerProduct(strain, strain) - trace * trace / self.dimension
        return self.mu * deviatoric + self.bulk / 2 * IfPos(trace, trace * trace, 0)

    def intact_form(self, u) -> ngsolve.CoefficientFunction:
        """Return W⁻(u) as a CoefficientFunction."""
        trace = Trace(Sym(grad(u)))
        return self.bulk / 2 * IfPos(trace, 0, trace * trace)


class SpectralSplit(PlaneElasticity):
    """W⁺ = (λ/2)⟨tr ε⟩₊² + μ ε₊:ε₊, W⁻ = W − W⁺ (Miehe, Hofacker and Welschinger 2010).

    ε₊ = Σᵢ ⟨εᵢ⟩₊ nᵢ ⊗ nᵢ is the tensile part of the strain in its eigenbasis: compression along
    a principal direction keeps its energy, so a sheared body keeps half of its shear energy
    (pure shear ε = γ(e₁ ⊗ e₂ + e₂ ⊗ e₁): W⁺ = W⁻ = μγ²), where the volumetric–deviatoric
    split degrades all of it. Plane strain only: ε_zz = 0 is then the third eigenvalue.

    In the invariants p = tr ε/2, q = (ε_xx − ε_yy)/2, r = ε_xy the eigenvalues are p ± ρ,
    ρ = (q² + r²)^{1/2}, and W⁺(p, q, r) = (λ/2)⟨2p⟩₊² + μ(⟨p + ρ⟩₊² + ⟨p − ρ⟩₊²) is convex, C¹
    and homogeneous of degree 2, so its Hessian H⁺ satisfies H⁺ (p, q, r) = ∇W⁺ (Euler). With
    P1 elements p, q, r are constant per element and linear in the element's DOFs, p = b_p·u_T
    (likewise q, r), so the u-step's element matrix is |T| Σ_{kl} (c_T H⁺_kl + H⁻_kl) b_k b_lᵀ/2:
    six fixed parts b_k b_lᵀ (:meth:`parts`) weighted by the Hessian's entries (:meth:`weights`),
    and A(u) u is the gradient of the u-step's energy. Unlike the volumetric–deviatoric split,
    H⁺ turns with the eigenvectors, so the energy is not quadratic on finitely many pieces: the
    semismooth Newton u-step runs until its step is small (:attr:`piecewise_quadratic`).

    Parameters
    ----------
    lam, mu
        Lamé constants λ and μ.
    """

    split = True
    piecewise_quadratic = False
    PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    """The entries (k, l) of the symmetric 3 × 3 Hessian in (p, q, r), one part each."""

    @staticmethod
    def invariants(gradient: np.ndarray) -> tuple[np.ndarray, ...]:
        """Return p = tr ε/2, q = (ε_xx − ε_yy)/2, r = ε_xy and ρ = (q² + r²)^{1/2}."""
        p = (gradient[:, 0, 0] + gradient[:, 1, 1]) / 2
        q = (gradient[:, 0, 0] - gradient[:, 1, 1]) / 2
        r = (gradient[:, 0, 1] + gradient[:, 1, 0]) / 2
        return p, q, r, np.hypot(q, r)

    def _energy(self, gradient: np.ndarray, clip) -> np.ndarray:
        """Return (λ/2) clip(tr ε)² + μ (clip(ε₁)² + clip(ε₂)²) with clip = ⟨·⟩₊ or ⟨·⟩₋."""
        p, _, _, rho = self.invariants(gradient)
        return self.lam / 2 * clip(2 * p, 0.0) ** 2 + self.mu * (
            clip(p + rho, 0.0) ** 2 + clip(p - rho, 0.0) ** 2
        )

    def degraded_density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return W⁺ = (λ/2)⟨tr ε⟩₊² + μ(⟨ε₁⟩₊² + ⟨ε₂⟩₊²)."""
        return self._energy(self.gradient(arrays, u), np.maximum)

    def intact_density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return W⁻ = W − W⁺ = (λ/2)⟨tr ε⟩₋² + μ(⟨ε₁⟩₋² + ⟨ε₂⟩₋²)."""
        return self._energy(self.gradient(arrays, u), np.minimum)

    def fluxes(self, gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return s⁺ = (λ/2)⟨tr ε⟩₊ I + μ ε₊ and s⁻ = s − s⁺.

        ε₊ = ⟨p + ρ⟩₊ (I + N)/2 + ⟨p − ρ⟩₊ (I − N)/2 with N = [[q, r], [r, −q]]/ρ, the
        difference of the two eigenprojections (where ρ = 0 both coefficients agree and N
        drops out).
        """
        p, q, r, rho = self.invariants(gradient)
        safe = np.where(rho > 0, rho, 1.0)
        n = np.stack([np.stack([q, r], -1), np.stack([r, -q], -1)], -2) / safe[:, None, None]
        big, small = np.maximum(p + rho, 0.0), np.maximum(p - rho, 0.0)
        eye = np.eye(2)
        tensile = ((big + small) / 2)[:, None, None] * eye + ((big - small) / 2)[:, None, None] * n
        plus = self.lam / 2 * np.maximum(2 * p, 0.0)[:, None, None] * eye + self.mu * tensile
        return plus, self.flux(gradient) - plus

    def _directions(self, arrays: MeshArrays) -> list[np.ndarray]:
        """Return b_p, b_q, b_r: (ne, 6) rows with p = b_p·u_T (DOFs of :meth:`element_dofs`)."""
        g = arrays.grad_phi  # (ne, 3, 2)
        gx, gy = g[:, :, 0], g[:, :, 1]
        return [
            np.hstack([gx, gy]) / 2,
            np.hstack([gx, -gy]) / 2,
            np.hstack([gy, gx]) / 2,
        ]

    def parts(self, arrays: MeshArrays) -> list[np.ndarray]:
        """Return |T| b_k b_kᵀ and |T| (b_k b_lᵀ + b_l b_kᵀ) for the pairs of :data:`PAIRS`."""
        b = self._directions(arrays)
        area = arrays.area[:, None, None]
        parts = []
        for i, j in self.PAIRS:
            outer = np.einsum("ei,ej->eij", b[i], b[j])
            parts.append(area * (outer if i == j else outer + outer.transpose(0, 2, 1)))
        return parts

    def hessians(self, gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the Hessians of W⁺ and of W in (p, q, r), each (ne, 3, 3)."""
        p, q, r, rho = self.invariants(gradient)
        lam, mu = self.lam, self.mu
        up, down = p + rho > 0, p - rho > 0  # H(ε₁), H(ε₂): which principal strains degrade
        f_pp = 2 * mu * (up.astype(float) + down)
        f_prho = 2 * mu * (up.astype(float) - down)
        # F_ρ/ρ = 2μ(⟨p + ρ⟩₊ − ⟨p − ρ⟩₊)/ρ without the cancellation of a difference over a
        # round-off ρ: 4μ with both principal strains positive, 0 with neither, 2μ(p + ρ)/ρ
        # with one (then ρ ≥ |p|). Where ρ = 0 any direction n = (q, r)/ρ gives the same Hessian.
        distinct = rho > 0
        safe = np.where(distinct, rho, 1.0)
        quotient = np.where(down, 4 * mu, np.where(up, 2 * mu * (p + rho) / safe, 0.0))
        nq = np.where(distinct, q / safe, 1.0)
        nr = np.where(distinct, r / safe, 0.0)
        plus = np.empty((len(p), 3, 3))
        plus[:, 0, 0] = 4 * lam * (p > 0) + f_pp
        plus[:, 0, 1] = plus[:, 1, 0] = f_prho * nq
        plus[:, 0, 2] = plus[:, 2, 0] = f_prho * nr
        plus[:, 1, 1] = f_pp * nq**2 + quotient * nr**2
        plus[:, 2, 2] = f_pp * nr**2 + quotient * nq**2
        plus[:, 1, 2] = plus[:, 2, 1] = (f_pp - quotient) * nq * nr
        whole = np.zeros_like(plus)
        whole[:, 0, 0] = 4 * (lam + mu)
        whole[:, 1, 1] = whole[:, 2, 2] = 4 * mu
        return plus, whole

    def weights(self, arrays: MeshArrays, u: np.ndarray, c: np.ndarray) -> list[np.ndarray]:
        """Return (c H⁺_kl + H⁻_kl)/2 for the pairs of :data:`PAIRS` (half the Hessian)."""
        plus, whole = self.hessians(self.gradient(arrays, u))
        total = (c[:, None, None] - 1.0) * plus + whole
        return [total[:, i, j] / 2 for i, j in self.PAIRS]

    def tension(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return the signs of tr ε and of the two eigenvalues, (ne, 3)."""
        p, _, _, rho = self.invariants(self.gradient(arrays, u))
        return np.stack([p > 0, p + rho > 0, p - rho > 0], axis=1)

    def degraded_form(self, u) -> ngsolve.CoefficientFunction:
        """Return W⁺(u) as a CoefficientFunction (eigenvalues p ± ρ in closed form)."""
        return self._form(u, lambda a: IfPos(a, a * a, 0))

    def intact_form(self, u) -> ngsolve.CoefficientFunction:
        """Return W⁻(u) as a CoefficientFunction."""
        return self._form(u, lambda a: IfPos(a, 0, a * a))

    def _form(self, u, square) -> ngsolve.CoefficientFunction:
        strain = Sym(grad(u))
        p = Trace(strain) / 2
        q, r = (strain[0, 0] - strain[1, 1]) / 2, strain[0, 1]
        rho = ngsolve.sqrt(q * q + r * r)
        return self.lam / 2 * square(2 * p) + self.mu * (square(p + rho) + square(p - rho))


def lame(young: float, poisson: float) -> tuple[float, float]:
    """Return the Lamé constants (λ, μ) of Young's modulus E and Poisson's ratio ν."""
    return young * poisson / ((1 + poisson) * (1 - 2 * poisson)), young / (2 * (1 + poisson))


def elasticity(
    model: str, young: float = 1.0, poisson: float = 0.0, split: str = "none"
) -> Elasticity:
    """Return the energy density of ``model`` (one of :data:`MODELS`).

    Parameters
    ----------
    model
        One of :data:`ngat.parameters.MODELS`: ``"antiplane"`` (W = |∇u|², E and ν unused),
        ``"plane_strain"`` or ``"plane_stress"``.
    young, poisson
        E and ν of the plane models (−1 < ν < 1/2).
    split
        ``"none"``, ``"voldev"`` (plane models): :class:`VolumetricDeviatoricSplit`, or
        ``"spectral"`` (plane strain): :class:`SpectralSplit`.
    """
    if model == "antiplane":
        return AntiPlane()
    lam, mu = lame(young, poisson)
    if model == "plane_stress":
        lam = 2 * lam * mu / (lam + 2 * mu)
    if split == "voldev":
        return VolumetricDeviatoricSplit(lam, mu, 3 if model == "plane_strain" else 2)
    if split == "spectral":
        return SpectralSplit(lam, mu)
    return PlaneElasticity(lam, mu)
