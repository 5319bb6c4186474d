"""The crack density of the functional: AT2 (the paper) or AT1.

The surface term of I_j is G_c ∫ γ(v, ∇v), a regularised crack length:

- ``at2`` (the paper's eq. 7): γ = α P_j((1 − v)²) + ε |∇v|², α = 1/(4ε). Damage starts at
  any load: v < 1 wherever W > 0.
- ``at1``: γ = 3/(8ε) (1 − v) + (3ε/8) |∇v|², a crack density linear in 1 − v. Below the
  critical energy density W_c = 3 G_c/(16ε) the minimiser keeps v = 1 (an elastic phase);
  the v-step needs the bound v ≤ 1, which the bounded v-step has
  (:meth:`ngat.halfsteps.HalfStepSolvers.solve_v`).

Both are normalised so that the optimal one-dimensional profile of a crack costs G_c per unit
length (AT1 is that of Tanné et al., J. Mech. Phys. Solids 110 (2018), with ℓ = ε; its
discrete toughness is G_c (1 + 3h/(8ε)) against the (1 + h/(4ε)) of AT2). Both are quadratic
in v and share one form,

    γ = q (1 − v)² + 2 (f − q)(1 − v) + d |∇v|²,

with (q, f, d) = (α, α, ε) for AT2 and (0, 3/(16ε), 3ε/8) for AT1, so that the v-step (I_j
stationary in v, divided by 2 G_c) reads

    ∫ P_j(vψ) (W/G_c + q) + d ∇v·∇ψ = f ∫ ψ,

the paper's b_j(u; v, ψ) = α ∫ P_j(ψ) for AT2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ngat.forms import MeshArrays

__all__ = ["CRACK_DENSITIES", "CrackDensity", "crack_density"]

CRACK_DENSITIES = ("at2", "at1")
"""The crack densities γ of the surface term (see the module docstring)."""


@dataclass(frozen=True)
class CrackDensity:
    """γ = q (1 − v)² + 2 (f − q)(1 − v) + d |∇v|² (see the module docstring).

    Attributes
    ----------
    name
        ``"at2"`` or ``"at1"``.
    reaction
        q: the coefficient of P_j(vψ) in b_j besides W/G_c (α for AT2, 0 for AT1).
    source
        f: the right-hand side of the v-step, f ∫ ψ (α for AT2, 3/(16ε) for AT1).
    diffusion
        d: the coefficient of ∇v·∇ψ (ε for AT2, 3ε/8 for AT1).
    """

    name: str
    reaction: float
    source: float
    diffusion: float

    def density(self, v):
        """Return γ(v, ∇v) as a CoefficientFunction (integrate it with the vertex rule)."""
        from ngsolve import grad

        q, f = self.reaction, self.source
        return q * (1 - v) * (1 - v) + 2 * (f - q) * (1 - v) + self.diffusion * grad(v) * grad(v)

    def energy(self, arrays: MeshArrays, v: np.ndarray, lumped: bool = True) -> float:
        """Return ∫ γ for the P1 function v: the surface energy divided by G_c.

        P_j((1 − v)²) by the vertex rule, or exactly with ``lumped=False``
        (:meth:`ngat.forms.MeshArrays.square_mean`); P_j(1 − v) integrates exactly.
        """
        q, f = self.reaction, self.source
        return float(
            q * np.dot(arrays.area, arrays.square_mean(1 - v, lumped))
            + 2 * (f - q) * np.dot(arrays.mass, 1 - v)
            + self.diffusion * np.sum(arrays.area * arrays.squared_gradient(v))
        )

    def critical_density(self) -> float:
        """Return the energy density W_c/G_c below which v = 1 is the minimiser (0 for AT2)."""
        return self.source - self.reaction


def crack_density(name: str, eps: float) -> CrackDensity:
    """Return the crack density ``name`` (one of :data:`CRACK_DENSITIES`) of length ε."""
    if name == "at1":
        return CrackDensity("at1", 0.0, 3 / (16 * eps), 3 * eps / 8)
    return CrackDensity("at2", 1 / (4 * eps), 1 / (4 * eps), eps)
