"""Detection of numerical trouble in a run, named in the log and the run summary.

Each load step is checked for: the alternating minimisation stopping at its iteration limit
(``not-converged``), an iterative linear solve stopping at its iteration cap above its tolerance
(``linear-not-converged``, ``linear_solver="cg-h1amg"``), NaN or Inf (``nan``, always an
error), v outside [0, 1] beyond round-off (``v-out-of-bounds``: Proposition 3 needs
Hypothesis A, which obtuse elements violate, unless the v-step is bounded), an iteration that
increased I_j although every half-step minimises it (``energy-increase``), and ε under-resolved
by the mesh (``eps-under-resolved``: the largest element meeting the crack {v < 0.1}, or before
a crack exists the most damaged vertex, is at least ε wide, so the profile 1 − exp(−d/(2ε)) is
not resolved and the crack costs ≈ 1 + h/(4ε) times G_c). Depending on ``on_problem`` each is a
warning (logged, listed in ``summary.json`` under ``diagnostics`` and in the step's
``warnings`` column) or an error that stops the run, with the results written so far kept.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np

from ngat.crack import Slit
from ngat.forms import distances
from ngat.minimization import StepResult
from ngat.parameters import ParameterError
from ngat.state import ATState

__all__ = [
    "Diagnostics",
    "ProblemError",
    "ROUND_OFF",
    "damage_zone",
    "crack_start",
    "check_fixed_mesh",
]

log = logging.getLogger(__name__)

ROUND_OFF = 1e-10


class ProblemError(RuntimeError):
    """A detected problem, raised when ``on_problem="error"``."""


def damage_zone(v: np.ndarray, elements: np.ndarray) -> tuple[np.ndarray, str]:
    """Return the elements where ε must be resolved, and where they are (for the message).

    Where a crack exists these are the elements meeting {v < 0.1}. Before that, once the body
    is damaged at all (min v < 0.9), they are the elements at the most damaged vertex: on a
    mesh too coarse for the profile, v never gets near 0 (the band of one element costs
    ≈ 1 + h/(4ε) times G_c), so {v < 0.1} stays empty although ε is not resolved.
    """
    near = v[elements]
    crack = (near < 0.1).any(axis=1)
    if crack.any():
        return crack, "where v < 0.1"
    v_min = float(v.min())
    if v_min >= 0.9:
        return np.zeros(len(elements), dtype=bool), ""
    return (near <= v_min).any(axis=1), f"at the most damaged point (min v = {v_min:.3g})"


def crack_start(state: ATState, slits: Sequence[Slit]) -> tuple[np.ndarray, str]:
    """Return the elements where a crack starts, and where they are (for the message).

    These are the elements at the vertex nearest to each slit's tip and those meeting the
    scene's imposed crack; a scene with neither may crack anywhere, so then every element.
    """
    arrays = state.arrays
    start = arrays.touching(state.initial_crack)
    for _, tip in slits:
        nearest = np.argmin(distances(arrays.coords, tip))
        start |= (arrays.elements == nearest).any(axis=1)
    if start.any():
        return start, "where the crack starts"
    return np.ones(len(arrays.elements), dtype=bool), "of the mesh"


def check_fixed_mesh(state: ATState, slits: Sequence[Slit], eps: float) -> None:
    """Raise :class:`~ngat.parameters.ParameterError` if a fixed mesh cannot resolve ε.

    ``adapt="fixed"`` never refines, so the elements where the crack starts
    (:func:`crack_start`) must already be narrower than ε, the criterion of
    ``eps-under-resolved``.
    """
    zone, where = crack_start(state, slits)
    h = float(state.arrays.diameter[zone].max())
    if h >= eps:
        raise ParameterError(
            f"adapt=fixed never refines, but the elements {where} are up to h = {h:.3g} ≥ "
            f"ε = {eps:g} wide: choose maxh below {eps:g} or adapt=band, or set "
            "resolve_eps=false to run under-resolved on purpose"
        )


class Diagnostics:
    """Collect the problems of a run.

    Parameters
    ----------
    on_problem
        ``"warn"`` or ``"error"``.
    """

    def __init__(self, on_problem: str = "warn"):
        self.on_problem = on_problem
        self.problems: list[dict[str, Any]] = []
        self._pending: str | None = None

    def report(
        self, kind: str, message: str, step: int, t: float, error: bool = False,
        raise_now: bool = True,
    ) -> None:  # fmt: skip
        """Record a problem; raise :class:`ProblemError` if it is an error.

        With ``raise_now=False`` the error is kept until :meth:`raise_if_error`, so that the
        caller can first write the step that showed it.
        """
        self.problems.append({"step": step, "t": t, "kind": kind, "message": message})
        log.warning("step %d, t=%.4g: %s: %s", step, t, kind, message)
        if error or self.on_problem == "error":
            self._pending = f"{kind} at t={t:.4g}: {message}"
            if raise_now:
                self.raise_if_error()

    @property
    def pending(self) -> bool:
        """Whether an error reported with ``raise_now=False`` waits for :meth:`raise_if_error`."""
        return self._pending is not None

    def raise_if_error(self) -> None:
        """Raise :class:`ProblemError` for an error reported with ``raise_now=False``."""
        if self._pending is not None:
            message, self._pending = self._pending, None
            raise ProblemError(message)

    def check_step(
        self,
        state: ATState,
        result: StepResult,
        eps: float,
        step: int,
        t: float,
        raise_now: bool = True,
    ) -> list[str]:
        """Check one finished load step; return the names of the problems found."""
        found = []
        v = state.v_values
        cause = (
            "Hypothesis A fails on this mesh"
            if state.model.lumping
            else "the consistent mass (lumping=false) breaks the maximum principle"
        )
        checks = [
            (
                "not-converged",
                not result.converged,
                f"stopped at the iteration limit ({result.iterations} iterations) with ‖Δv‖∞ = "
                f"{result.change:.3g}; where a crack runs through the body within one load step "
                "the iteration moves its tip by a fraction of ε per iteration, more so for small "
                f"ε: raise the limit (--set am_max_iter={2 * result.iterations})",
            ),
            (
                "linear-not-converged",
                result.cg_not_converged > 0,
                f"{result.cg_not_converged} CG solve(s) stopped at the iteration cap above the "
                "tolerance (the run continued with their last iterates): use linear_solver=direct",
            ),
            (
                "v-out-of-bounds",
                v.min() < -ROUND_OFF or v.max() > 1 + ROUND_OFF,
                f"v in [{v.min():.3g}, {v.max():.3g}]: {cause} (set bounded_v=true)",
            ),
            (
                "energy-increase",
                result.energy_increases > 0,
                f"I_j increased in {result.energy_increases} iteration(s) on an unchanged mesh",
            ),
        ]
        zone, where = damage_zone(v, state.arrays.elements)
        h_zone = float(state.arrays.diameter[zone].max()) if zone.any() else 0.0
        checks.append(
            (
                "eps-under-resolved",
                h_zone >= eps,
                f"elements up to h = {h_zone:.3g} ≥ ε = {eps:.3g} {where}: refine "
                "(adapt=band, or a smaller tol or floor) or increase eps",
            )
        )
        for kind, fired, message in checks:
            if fired:
                found.append(kind)
                self.report(kind, message, step, t, raise_now=raise_now)
        return found

    def summary(self) -> list[dict[str, Any]]:
        """Return the problems as a list for ``summary.json`` (one entry per step and kind)."""
        return list(self.problems)
