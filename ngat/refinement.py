"""Marking and local refinement: Dörfler or maximum marking, bisection by ``mesh.Refine()``.

Refinement keeps Ω_D and the slits exactly resolved (new points lie on the bisected edges, and
the two faces of a slit have distinct edges, so they stay apart) and prolongates every P1
GridFunction of the state exactly (``autoupdate=True``): u, v, the previous iterate and the
previous step's v that defines CR.
"""

from __future__ import annotations

import logging

import numpy as np

from ngat.pardiso import wait_background
from ngat.state import ATState
from ngat.threads import factorisation_threads, refinement_threads

__all__ = ["dorfler_marking", "maximum_marking", "mark", "refinable", "refine", "bisect", "rebuild"]

log = logging.getLogger(__name__)


def dorfler_marking(indicators: np.ndarray, theta: float = 0.5) -> np.ndarray:
    """Return the smallest set M with Σ_{T∈M} η_T² ≥ θ Σ_T η_T² (bulk marking).

    Parameters
    ----------
    indicators
        Squared element indicators η_T².
    theta
        Bulk fraction θ ∈ (0, 1].
    """
    order = np.argsort(indicators)[::-1]
    cumulative = np.cumsum(indicators[order])
    count = int(np.searchsorted(cumulative, theta * cumulative[-1])) + 1
    marked = np.zeros(len(indicators), dtype=bool)
    marked[order[: min(count, len(indicators))]] = True
    return marked & (indicators > 0)


def maximum_marking(indicators: np.ndarray, theta: float = 0.5) -> np.ndarray:
    """Return the elements with η_T ≥ θ max η_T (maximum strategy); ``indicators`` are η_T²."""
    return indicators >= theta**2 * indicators.max()


def mark(indicators: np.ndarray, strategy: str, theta: float) -> np.ndarray:
    """Mark with the named strategy, ``"dorfler"`` or ``"maximum"``."""
    if strategy == "dorfler":
        return dorfler_marking(indicators, theta)
    if strategy == "maximum":
        return maximum_marking(indicators, theta)
    raise ValueError(f"unknown marking strategy '{strategy}' (use dorfler or maximum)")


def refinable(state: ATState, h_floor: float) -> np.ndarray:
    """Return the elements that may still be bisected: diameter > 2 h_floor.

    The floor: where the estimator cannot decrease, refinement would run away. At the instant
    a crack forms, the jump of u concentrates in the thinnest element layer of the fresh crack
    band (η is tiny), so the indicators there do not shrink under refinement and Algorithm 2
    would bisect the same spot down to 1e−5. An element is therefore bisected only while its
    children stay at least ``h_floor`` wide (default ε/50: 1e−3, the paper's smallest element,
    at its ε = 0.05);
    conformity closure may still bisect a neighbour below the floor, by at most a factor 2.
    """
    return state.arrays.diameter > 2 * h_floor


def bisect(state: ATState, marked: np.ndarray) -> int:
    """Bisect the marked elements (``mesh.Refine()``) without rebuilding the state's operators.

    The P1 fields are prolongated; call :meth:`ngat.state.ATState.mesh_changed` (or use
    :func:`refine`) before solving on the new mesh. Several bisections in a row therefore cost
    one rebuild.

    Returns
    -------
    int
        Number of elements marked (0: mesh unchanged).
    """
    count = int(marked.sum())
    if count == 0:
        return 0
    with state.timer("refine"):
        state.mesh.SetRefinementFlags(marked.tolist())
        wait_background()
        with refinement_threads(factorisation_threads()):
            state.mesh.Refine()
    state.refinements.append(np.flatnonzero(marked))
    return count


def rebuild(state: ATState, order: bool = True) -> None:
    """Rebuild the state's operators after :func:`bisect` and set g(t_k) on the new Ω_D vertices.

    The new vertices of Ω_D take g(t_k) itself, not the interpolant of the coarser mesh.
    ``order``: start the mesh's ordering at once (:meth:`ngat.state.ATState.mesh_changed`);
    false for a mesh that is refined again before anything is solved on it.
    """
    state.mesh_changed(order)
    state.apply_load(state.t.Get())


def refine(state: ATState, marked: np.ndarray) -> int:
    """Bisect the marked elements (``mesh.Refine()``) and rebuild the state's operators.

    Parameters
    ----------
    state
        Fields and operators; updated for the refined mesh.
    marked
        Boolean element mask.

    Returns
    -------
    int
        Number of elements marked (0: mesh unchanged).
    """
    count = bisect(state, marked)
    if count:
        rebuild(state)
    return count
