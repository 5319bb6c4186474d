"""The discrete functional I_j (paper, eq. 7) of one model: its value, gradient and Hessian.

I_j(u, v) = ∫ (P_j(v²) + η) W⁺(u) + W⁻(u) + G_c γ_j(v), with the elastic energy density W of
the model (:mod:`ngat.elasticity`; W⁺ = W and W⁻ = 0 without an energy split) and the crack
density γ of :mod:`ngat.crack_density` (AT2: the paper's α P_j((1 − v)²) + ε |∇v|²).
:class:`LumpedFunctional` is the one place where I_j is written out as numbers: the energies of
the records, the bulk energy of the split u-step's line search, the coefficients of the two
half-steps' quadratic forms a_j and b_j (which :class:`ngat.state.ATState` writes into its
matrices), and the gradient and Hessian of Newton's method (:mod:`ngat.newton`).
:meth:`LumpedFunctional.energy_form` states the same functional as an NGSolve ``Variation`` with
the vertex rule: the definition, against which the tests check the vectorised gradient and
Hessian (1e−12).

With c_T = mean_T(v²) + η, the lumped mass m and K_T the element matrix of the model's a_j
(∇φ_a·∇φ_b |T| for the anti-plane model):

- ∂I/∂u = 2 Σ_T c_T K_T u,  ∂I/∂v = 2 G_c (B(u) v − f m)  (B: the matrix of b_j, Definition 2,
  with W⁺(u)/G_c in place of |∇u|²; q, f, d of the crack density in place of α, α, ε);
- ∂²I/∂u² = 2 Σ_T c_T K_T,  ∂²I/∂v² = 2 G_c B(u),
  ∂²I/∂v_a∂u_b = (4/3) v_a (K_T u)_b on each element T ∋ a, b.
"""

from __future__ import annotations

import ngsolve
import numpy as np
from ngsolve import BilinearForm, Variation

from ngat.elasticity import Elasticity, elasticity
from ngat.forms import MeshArrays, lumped_dx
from ngat.parameters import ModelParameters

__all__ = ["LumpedFunctional"]


class LumpedFunctional:
    """I_j of one model (see the module docstring).

    Parameters
    ----------
    model
        ε, η, G_c, the crack density and the elastic model.
    density
        The model's energy density; default that of ``model``
        (:func:`ngat.elasticity.elasticity`).
    """

    def __init__(self, model: ModelParameters, density: Elasticity | None = None):
        self.model = model
        self.density = density or elasticity(model.model, model.young, model.poisson, model.split)

    def bulk(self, arrays: MeshArrays, u: np.ndarray, c: np.ndarray) -> float:
        """Return ∫ c W⁺(u) + W⁻(u), with c = P_j(v²) + η per element."""
        density = self.density
        bulk = np.sum(arrays.area * c * density.degraded_density(arrays, u))
        intact = density.intact_density(arrays, u)
        if intact is not None:
            bulk += np.dot(arrays.area, intact)
        return float(bulk)

    def u_step_weights(self, arrays: MeshArrays, u: np.ndarray, c: np.ndarray) -> list[np.ndarray]:
        """Return the element weights of a_j's parts, the u-step's quadratic form (half of ∂²I/∂u²).

        ``c`` = P_j(v²) + η per element; with an energy split the weights of its parts follow
        the sign of tr ε(u) on each element (:meth:`ngat.elasticity.Elasticity.weights`).
        """
        return self.density.weights(arrays, u, c)

    def v_step_density(self, arrays: MeshArrays, u: np.ndarray) -> np.ndarray:
        """Return W⁺(u)/G_c per element: b_j's reaction coefficient (half of ∂²I/∂v² / G_c)."""
        return self.density.degraded_density(arrays, u) / self.model.gc

    def coefficient(self, arrays: MeshArrays, v: np.ndarray) -> np.ndarray:
        """Return c_T = ∫_T P_j(v²)/|T| + η per element (exact mean of v² with lumping off)."""
        return arrays.square_mean(v, self.model.lumping) + self.model.eta

    def energies(self, arrays: MeshArrays, u: np.ndarray, v: np.ndarray) -> dict[str, float]:
        """Return bulk, surface and total energy of I_j (eq. 7).

        With ``lumping=False`` the P_j in eq. (7) are dropped and the integrals are exact.

        Parameters
        ----------
        arrays
            Element geometry of the mesh.
        u, v
            DOF values of the two P1 fields.
        """
        model = self.model
        bulk = self.bulk(arrays, u, self.coefficient(arrays, v))
        surface = model.gc * model.surface.energy(arrays, v, model.lumping)
        return {"bulk": bulk, "surface": float(surface), "total": float(bulk + surface)}

    def gradient(self, arrays: MeshArrays, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Return ∇I_j at (u, v), stacked (∂I/∂u, ∂I/∂v)."""
        model, density = self.model, self.density
        el, area = arrays.elements, arrays.area
        (flux, intact), grad_v = density.fluxes(density.gradient(arrays, u)), arrays.gradient(v)
        c = arrays.vertex_mean(v * v) + model.eta
        # (K_T u)_(i,a) = |T| s_i·∇φ_a: a_j(v; u, φ_a e_i) on T (s = c s⁺ + s⁻ with a split).
        flux_u = np.einsum("eak,eik->eia", arrays.grad_phi, flux) * (area * c)[:, None, None]
        if intact is not None:
            flux_u += np.einsum("eak,eik->eia", arrays.grad_phi, intact) * area[:, None, None]
        flux_v = np.einsum("eak,ek->ea", arrays.grad_phi, grad_v) * area[:, None]
        g_u = 2 * np.bincount(
            density.element_dofs(arrays).ravel(), weights=flux_u.ravel(), minlength=len(u)
        )
        energy = density.degraded_density(arrays, u)
        strain = arrays.vertex_sum(area * energy / 3)
        surface = model.surface
        # 2 G_c m (q v − f) written as −2 G_c m (q (1 − v) + f − q): for AT2 (f = q) the
        # rounding of the paper's −2 G_c α m (1 − v), so anti-plane runs repeat bit for bit.
        g_v = 2 * (
            strain * v - model.gc * surface.reaction * arrays.mass * (1 - v)
            - model.gc * (surface.source - surface.reaction) * arrays.mass
            + model.gc * surface.diffusion
            * np.bincount(el.ravel(), weights=flux_v.ravel(), minlength=arrays.nv)
        )  # fmt: skip
        return np.concatenate([g_u, g_v])

    def hessian_constant(self, arrays: MeshArrays) -> np.ndarray:
        """Return the element blocks of ∂²I/∂v² that v and u leave alone: 2 G_c d K_T, (ne, 3, 3).

        They are the whole block off the diagonal; on it :meth:`hessian_terms` adds the mass
        term. d is the crack density's diffusion coefficient (AT2: the paper's ε).
        """
        surface = self.model.surface
        return 2 * self.model.gc * surface.diffusion * arrays.stiffness

    def hessian_terms(
        self,
        arrays: MeshArrays,
        u: np.ndarray,
        v: np.ndarray,
        out: tuple[np.ndarray, np.ndarray],
    ) -> list[np.ndarray]:
        """Write the element terms of ∇²I_j at (u, v) that change with them into ``out``.

        ∂²I/∂u² = Σ_k Σ_T 2 w_k,T K_k,T over the parts K_k of a_j
        (:meth:`ngat.elasticity.Elasticity.parts`): the weights 2 w_k are returned, one (ne,)
        array per part. ∂²I/∂v² = 2 G_c B(u): :meth:`hessian_constant` off the diagonal and, on
        it, 2 G_c d K_T,aa + 2 |T| (W⁺(u) + G_c q)/3, written into ``out[0]``. The coupling
        ∂²I/∂v_a∂u_b = (4/3) |T| v_a (s·∇φ_b) is written into ``out[1]``.

        Parameters
        ----------
        arrays
            Element geometry of the mesh.
        u, v
            DOF values of the two P1 fields.
        out
            Arrays of shapes (ne, 3) and (ne, 3, 3c) for the c components of u: views of
            the one buffer per mesh of :class:`ngat.newton.NewtonSolver`, which scatters it as
            it is.

        Returns
        -------
        list of np.ndarray
            2 w_k per part of a_j.
        """
        model, density = self.model, self.density
        el, area = arrays.elements, arrays.area
        diagonal, vu = out
        flux = density.fluxes(density.gradient(arrays, u))[0]
        weights = self.u_step_weights(arrays, u, arrays.square_mean(v) + model.eta)
        surface = model.surface
        mass_term = area * (density.degraded_density(arrays, u) + model.gc * surface.reaction) / 3
        np.multiply(2 * model.gc * surface.diffusion, arrays.stiffness_diagonal, out=diagonal)
        diagonal += 2 * mass_term[:, None]
        u_flux = np.einsum("eik,ebk->eib", flux, arrays.grad_phi).reshape(arrays.ne, -1)
        # The outer product of 4|T|/3 v_a and s∇φ_b, by einsum: twice as fast as broadcasting's
        # inner loops of three, and each entry the same single product.
        np.einsum("ea,eb->eab", ((4 / 3) * area)[:, None] * v[el], u_flux, out=vu)
        return [2 * w for w in weights]

    def energy_form(self, space: ngsolve.FESpace) -> BilinearForm:
        """Return I_j(u, v) as an NGSolve energy on ``space``, the product of u's space and P1.

        ``form.Energy``, ``form.Apply`` and ``form.AssembleLinearization`` then give I_j, its
        gradient and its Hessian.
        """
        model, density = self.model, self.density
        u, v = space.TrialFunction()
        energy = (v * v + model.eta) * density.degraded_form(u) + model.gc * model.surface.density(
            v
        )
        intact = density.intact_form(u)
        if intact is not None:
            energy += intact
        form = BilinearForm(space)
        form += Variation(energy * lumped_dx())
        return form
