"""The u-step estimator μ of plane elasticity on a mode-I slit: rates and effectivity.

Question: does μ for a_j(v; u, φ) = ∫ (P_j(v²) + η) σ(u):ε(φ)/2 (docs/plane-elasticity.md)
estimate the energy-norm error of P1 plane strain, and does refinement driven by it recover
the optimal rate? The body is the strip of ``surfing-mode-i`` with its pre-crack; on the frame
Ω_D, u is Williams' mode-I field about the slit's tip (v ≡ 1, G = 1), the exact solution, which
is singular like r^{1/2} at the tip. Uniform refinement then converges at ndof^{−1/4} and
Dörfler marking (θ = 0.5) on μ at ndof^{−1/2}. The error ‖u − u_h‖ is the energy norm
(∫_body W(u − u_h))^{1/2}, integrated with 8 extra orders; effectivity = μ/‖u − u_h‖.

Run ``python scripts/plane_estimator_rates.py`` (``--out`` default
``results/plane_estimator_rates``: ``rates.csv``, ``rates.png``); ``--max-dofs`` caps the
sequences. :func:`sequence` is what ``tests/test_plane_estimators.py`` runs on small meshes.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
from ngsolve import CF, Grad, InnerProduct, Integrate, Trace, dx, x, y

from ngat.geometries import surfing_mode_i as mode_i
from ngat.halfsteps import HalfStepSolvers
from ngat.minimization import estimate
from ngat.parameters import ModelParameters
from ngat.refinement import dorfler_marking, refine
from ngat.state import ATState


def energy_error(state: ATState, exact: CF) -> float:
    """Return (∫_body W(u − u_h))^{1/2} for the exact displacement ``exact``."""
    jacobian = CF(
        (exact[0].Diff(x), exact[0].Diff(y), exact[1].Diff(x), exact[1].Diff(y)), dims=(2, 2)
    )
    error = jacobian - Grad(state.u)
    strain = (error + error.trans) / 2
    model = state.elasticity
    density = model.mu * InnerProduct(strain, strain) + model.lam / 2 * Trace(strain) ** 2
    body = dx(definedon=state.mesh.Materials("body"), bonus_intorder=8)
    return float(np.sqrt(Integrate(density * body, state.mesh)))


def sequence(marking: str, max_dofs: float, maxh: float = 0.1) -> list[dict]:
    """Return ndof, μ, the energy error and the effectivity of successive meshes.

    Parameters
    ----------
    marking
        ``"uniform"`` (every element bisected; each mesh.Refine() with all marks halves h)
        or ``"adaptive"`` (Dörfler, θ = 0.5, on μ).
    max_dofs
        Stop after the first mesh with more DOFs of u.
    maxh
        Size of the initial (unstructured) mesh.
    """
    scene = mode_i.make_scene(amplitude=1.0, ramp=0, speed=0)
    model = ModelParameters(model="plane_strain", young=mode_i.YOUNG, poisson=mode_i.POISSON)
    state = ATState(scene.make_mesh(maxh), model, scene.loads)
    steps = HalfStepSolvers(state)
    exact = mode_i.tip_field(1.0, mode_i.CRACK_LENGTH)
    rows = []
    while True:
        state.apply_load(1.0)
        steps.solve_u()
        indicators = estimate(state, "u", np.zeros(state.arrays.nv, dtype=bool))
        mu, error = float(np.sqrt(indicators.sum())), energy_error(state, exact)
        rows.append({"ndof": state.fes_u.ndof, "mu": mu, "error": error, "effectivity": mu / error})
        if state.fes_u.ndof > max_dofs:
            return rows
        marked = (
            np.ones(state.arrays.ne, dtype=bool)
            if marking == "uniform"
            else dorfler_marking(indicators, 0.5)
        )
        refine(state, marked)


def rate(rows: list[dict], key: str, skip: int = 0) -> float:
    """Return the least-squares slope of log ``key`` against log ndof after ``skip`` meshes."""
    ndof = np.log([r["ndof"] for r in rows[skip:]])
    return float(np.polyfit(ndof, np.log([r[key] for r in rows[skip:]]), 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/plane_estimator_rates"))
    parser.add_argument("--max-dofs", type=float, default=2e5)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 4.5))
    table = []
    for marking, style in (("uniform", "o"), ("adaptive", "s")):
        rows = sequence(marking, args.max_dofs)
        skip = len(rows) // 2
        print(
            f"{marking}: mu rate {rate(rows, 'mu', skip):.3f}, error rate "
            f"{rate(rows, 'error', skip):.3f}, effectivity "
            f"{min(r['effectivity'] for r in rows):.2f}-{max(r['effectivity'] for r in rows):.2f}"
        )
        table += [{"marking": marking, **r} for r in rows]
        ndof = [r["ndof"] for r in rows]
        axis.loglog(ndof, [r["mu"] for r in rows], style + "-", label=f"μ, {marking}")
        axis.loglog(ndof, [r["error"] for r in rows], style + "--", label=f"‖u − u_h‖, {marking}")
    axis.set_xlabel("DOFs of u")
    axis.set_ylabel("estimate / energy-norm error")
    axis.set_title("plane strain, mode-I slit (v ≡ 1)")
    axis.legend()
    figure.tight_layout()
    figure.savefig(args.out / "rates.png", dpi=120)
    with open(args.out / "rates.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(table[0]))
        writer.writeheader()
        writer.writerows(table)


if __name__ == "__main__":
    main()
