"""Crack extension: a predictor for a crack that runs within one load step.

Where a load step is unstable the crack runs far — a whole ligament — before the step's
iteration settles, and alternating minimisation moves its tip by a fraction of ε per
iteration: each v-step damages only where the last u-step concentrated the strain, just ahead
of the tip (measured: 0.1ε per iteration at ε = 0.0125 on ``two-slits``, 1000 iterations for
80ε). Newton's method does not help there, since I_j has negative curvature along the crack's
advance.

The predictor moves the tip region of each running crack forward along its path: with the
crack's end point e and tangent d fitted to its core behind the tip
(:meth:`CrackExtension.path`), on the vertices p within s + 3ε of e and not behind it,

    v(p) ← min(v(p), v(p − s d)),

the crack's profile translated by s (v only decreases, so v ≤ v(t_{k−1}) and v = 0 on
CR(t_k) still hold). With the crack band (:class:`ngat.band.CrackBand`) the translated crack's
band is refined first and the translation repeated on the finer mesh. A u-step and a v-step
then relax the translated pair, and the jump is accepted if I_j decreased; the iteration goes
on from there.

A crack runs when its tip (:func:`ngat.crack.crack_tips`) advanced in each of the last
:data:`RUN_WINDOW` iterations by at least :data:`RUN_ADVANCE` ε. The jump s starts at
:data:`FIRST_JUMP` ε, doubles after each accepted jump up to :data:`MAX_JUMP` ε and halves after
a rejected one; below :data:`FIRST_JUMP` ε the predictor waits for the crack to be seen running
again. A jump is shortened to what the path's curvature allows and left out where another
crack is near (:meth:`CrackExtension.planned`).

Measured (docs/stability.md, "Crack extension"): a single straight crack (SENT) runs through
its ligament in 43 iterations instead of 410; two cracks that run towards each other
(``two-slits``) end on a slightly different path with 2.8 % more energy and hardly fewer
iterations: where cracks race each other the step's path depends on how far each has come.
Hence it is an option (``crack_extension``), off by default.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from ngsolve import GridFunction

from ngat.band import DAMAGED, CrackBand
from ngat.crack import Slit, components, tips_of
from ngat.forms import distances
from ngat.halfsteps import HalfStepSolvers
from ngat.state import ATState

__all__ = ["CrackExtension"]

log = logging.getLogger(__name__)

RUN_WINDOW = 3
"""Iterations over which a tip must advance to be running."""
RUN_ADVANCE = 0.05
"""Least advance of a running tip per iteration, in units of ε."""
FIRST_JUMP = 2.0
"""First jump, in units of ε."""
MAX_JUMP = 32.0
"""Largest jump, in units of ε."""
MIN_JUMP = 1.0
"""Shortest jump worth a trial, in units of ε."""
REACH = 3.0
"""Radius around the translated tip region that the translation changes, in units of ε."""
CORE = 0.1
"""v below which a vertex belongs to the crack's core (the tip's threshold)."""
PATH_LENGTH = 8.0
"""Length of crack behind the tip whose core gives the path's tangent and curvature, in ε."""
DEVIATION = 0.25
"""Largest distance between a straight jump and the crack's curved path, in units of ε."""


class CrackExtension:
    """Jumps of running cracks along their direction of motion (see the module docstring).

    Parameters
    ----------
    eps
        Regularisation length ε.
    slits
        The scene's slits: the cracks grown from them are tracked.
    band
        The crack band, refined around each translated crack before the u-step, if any.
    """

    def __init__(self, eps: float, slits: Sequence[Slit], band: CrackBand | None = None):
        self.eps = eps
        self.slits = list(slits)
        self.band = band
        self.start()

    def start(self) -> None:
        """Begin a load step: forget the tips and the jump size."""
        self.tips: list[np.ndarray] = []
        self.jump = FIRST_JUMP * self.eps
        self.jumps = self.band_rounds = 0

    def running(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Return (tip, unit direction of motion) of every crack if all run, else nothing.

        A crack runs if its tip advanced in each of the last :data:`RUN_WINDOW` iterations by
        at least :data:`RUN_ADVANCE` ε. Cracks jump together or not at all: where several run
        in one step, their paths depend on how far each has come (two-slits' cracks, which
        meet, kinked where one jumped alone).
        """
        if len(self.tips) <= RUN_WINDOW:
            return []
        window = np.array(self.tips[-RUN_WINDOW - 1 :])  # (iterations, slits, 2)
        found = []
        for track in window.transpose(1, 0, 2):
            advance = np.linalg.norm(np.diff(track, axis=0), axis=1)
            if advance.min() < RUN_ADVANCE * self.eps:
                return []
            direction = track[-1] - track[0]
            found.append((track[-1], direction / np.linalg.norm(direction)))
        return found

    def path(
        self, state: ATState, tip: np.ndarray, motion: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float] | None:
        """Return the crack's end point, tangent and the longest jump its curvature allows.

        The crack's core {v < 0.1} within :data:`PATH_LENGTH` ε behind the tip is fitted by
        a parabola b = c₀ + c₁ a + c₂ a² in the frame of its principal axis (a along it, from the
        tip, b across): the tip's track wanders across the crack by a fraction of an element
        from one iteration to the next, the crack's core does not. A straight jump of s leaves
        a path of curvature κ = 2|c₂| by s²κ/2, so s is at most sqrt(2 δ / κ) with the
        deviation δ = :data:`DEVIATION` ε. ``None`` if the core behind the tip is shorter than half
        that length (a crack just leaving its slit).
        """
        coords = state.arrays.coords
        offset = coords - tip
        core = (
            (state.v_values < CORE)
            & (np.linalg.norm(offset, axis=1) <= PATH_LENGTH * self.eps)
            & (offset @ motion <= 0)
        )
        if core.sum() < 5:
            return None
        points = offset[core]
        _, _, axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
        along = axes[0] if axes[0] @ motion > 0 else -axes[0]
        across = np.array([-along[1], along[0]])
        if np.ptp(points @ along) < PATH_LENGTH * self.eps / 2:
            return None
        c2, c1, c0 = np.polyfit(points @ along, points @ across, 2)
        tangent = along + c1 * across
        curvature = 2 * abs(c2)
        longest = np.sqrt(2 * DEVIATION * self.eps / curvature) if curvature > 0 else np.inf
        return tip + c0 * across, tangent / np.linalg.norm(tangent), longest

    def planned(self, state: ATState) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Return (end point, tangent, jump) of each crack if all may jump now, else nothing.

        The jump is the current one, shortened to what the path's curvature allows
        (:meth:`path`) and to what another crack allows: cracks that meet bend towards each
        other, and a crack at distance D from a damaged vertex (v < ``DAMAGED``) of another
        crack (another component of the damaged set) is taken to bend with a radius D/2, so
        that a straight jump of s leaves its path by s²/D ≤ :data:`DEVIATION` ε. Tips whose
        jump would be shorter than :data:`MIN_JUMP` ε do not jump, and then no crack does.
        """
        runs = self.running()
        if not runs:
            return []
        coords, v = state.arrays.coords, state.v_values
        damaged = v < DAMAGED
        labels = components(state.arrays, damaged)
        indices = np.flatnonzero(damaged)
        found = []
        for tip, motion in runs:
            fitted = self.path(state, tip, motion)
            if fitted is None:
                return []
            end, tangent, longest = fitted
            distance = distances(coords[indices], tip)
            own = labels[indices[np.argmin(distance)]]
            other = distance[labels[indices] != own].min(initial=np.inf)
            # Near another crack at distance D the path bends with a radius of about D/2.
            jump = min(self.jump, longest, np.sqrt(DEVIATION * self.eps * other))
            if jump < MIN_JUMP * self.eps:
                return []
            found.append((end, tangent, jump))
        # One jump for all, the shortest any of them allows.
        jump = min(jump for _, _, jump in found)
        return [(end, tangent, jump) for end, tangent, _ in found]

    def translated(
        self, state: ATState, v: GridFunction, runs: list[tuple[np.ndarray, np.ndarray, float]]
    ) -> np.ndarray:
        """Return min(v, v(· − s d)) near each running tip, v elsewhere (nodal values)."""
        coords = state.arrays.coords
        values = v.vec.FV().NumPy().copy()
        for tip, direction, s in runs:
            offset = coords - tip
            near = np.flatnonzero(
                (np.linalg.norm(offset, axis=1) <= s + REACH * self.eps)
                & (offset @ direction >= -REACH * self.eps)
            )
            source = coords[near] - s * direction
            points = state.mesh(source[:, 0], source[:, 1])
            inside = points["nr"] >= 0
            shifted = v(points[inside]).ravel()
            near = near[inside]
            values[near] = np.minimum(values[near], shifted)
        return values

    def advance(self, state: ATState, half_steps: HalfStepSolvers, energy: float) -> bool:
        """Track the tips; jump the running cracks if that lowers I_j. Return whether it did.

        Parameters
        ----------
        state
            The iterate after its v-step; holds the jumped (u, v) if the jump is accepted, else
            the iterate (on a mesh that may have been refined for the trial).
        half_steps
            Solvers of the u-step.
        energy
            I_j of the iterate.
        """
        if not self.slits:
            return False
        self.tips.append(np.array(tips_of(state, self.slits)))
        runs = self.planned(state)
        if not runs:
            return False
        saved_u = GridFunction(state.fes_u, autoupdate=True)
        saved_v = GridFunction(state.fes, autoupdate=True)
        saved_u.vec.data = state.u.vec
        saved_v.vec.data = state.v.vec
        state.v_values[:] = self.translated(state, saved_v, runs)
        rounds = self.band.refine(state) if self.band else 0
        if rounds:
            # The iterate's energy on the refined mesh, with g(t_k) on the new vertices of Ω_D.
            self.band_rounds += rounds
            state.u.vec.data = saved_u.vec
            state.apply_load(state.t.Get())
            saved_u.vec.data = state.u.vec
            energy = state.functional.energies(
                state.arrays, state.u_values, saved_v.vec.FV().NumPy()
            )["total"]
            state.v_values[:] = self.translated(state, saved_v, runs)
        half_steps.solve_u()
        half_steps.solve_v(state.crack_set())
        trial = state.energies()["total"]
        accepted = trial < energy
        log.debug(
            "crack extension by %.3g (%.2f eps) at %s: I_j %.10g -> %.10g, %s",
            self.jump, self.jump / self.eps,
            [(np.round(e, 3).tolist(), np.round(d, 3).tolist(), j / self.eps) for e, d, j in runs],
            energy, trial,
            "accepted" if accepted else "rejected",
        )  # fmt: skip
        if accepted:
            self.jumps += 1
            self.jump = min(2 * self.jump, MAX_JUMP * self.eps)
            self.tips.append(np.array(tips_of(state, self.slits)))
            return True
        self.jump /= 2
        if self.jump < FIRST_JUMP * self.eps:
            self.jump, self.tips = FIRST_JUMP * self.eps, []
        state.u.vec.data = saved_u.vec
        state.v.vec.data = saved_v.vec
        return False
