"""The crack band: elements tied to ε wherever the crack is or is about to be.

The residual estimators μ and ν of Proposition 4 certify the current critical point. Ahead of a
crack tip the field is nearly homogeneous and the discrete v-equation holds almost exactly, so
μ and ν stay small there and Algorithm 2 leaves the initial elements in the crack's path. A crack
whose band of v = 0 is h wide costs G_eff(h) ≈ 1 + h/(4ε) + (h/ε)²/32 per unit length (scene
``surfing``), so coarse elements ahead of a tip hold it back or stop it.

:class:`CrackBand` refines, on top of the estimators, every element wider than the target
``band_h · ε`` (diameter) that

- lies within ``BUFFER · ε`` of a damaged vertex, v < ``DAMAGED`` (the crack and its profile
  1 − exp(−d/(2ε)), which reaches 0.5 at d = 2ε ln 2 ≈ 1.4ε; with the buffer the band reaches
  d ≈ 2.9ε, inside which lies 95 % of the crack's surface energy, e^{−d/ε} outside), or
- lies within ``TIP_RADIUS · ε`` of the tip of a slit's crack (:func:`ngat.crack.crack_tips`):
  before the crack moves, v near a tip resolved by elements of 10ε stays above 0.9 up to loads
  well past the Griffith load, so the damaged set alone would not refine there in time.

It is applied before each load step (predictor: the tips of v(t_{k−1})) and after every
v-step of the alternating minimisation (corrector: a crack that grew into coarse elements
during the iteration has them refined, and the iteration goes on on the refined mesh), so no
converged step has damage in elements wider than the target.

With a ``grading`` g > 0 the band is graded into the body: every element within reach of
the centres whose diameter exceeds ``band_h · ε + g · (d − BUFFER · ε)`` at distance d is
refined as well (a size field that grows linearly away from the crack, like a mesh that is
structured along a known crack path and graded away from it). The elastic field about a crack
then keeps its accuracy as the crack grows; without it the body far from the band stays as
coarse as μ leaves it. The grading starts once a slit's crack runs (has grown
:data:`ngat.crack.GROWN` · ε): about a slit tip that has not cracked μ grades the mesh towards
the singularity more finely, and a grading there only moves where μ stops refining.

With ``onset_h`` > 0 the disc of ``ONSET_RADIUS · ε`` about a slit tip whose crack has not grown
yet (by :data:`ngat.crack.GROWN` · ε) is resolved to ``onset_h · ε``, whatever the band's target:
before the crack moves, the energy lies in the singular field about the slit tip and in the
damage that forms there, and the crack's onset is decided there; once the crack runs, the band
along it holds its surface energy, G_eff(h) per unit length. On the paper's example a band of
0.27ε with discs of 0.18ε puts E(1.0) within 0.1 % of the converged reference (+0.091 %, against
+0.102 % with the slit tips in the band) and breaks at 1.40 (1.39 with a band of 0.18ε
throughout), with a fifth fewer elements after the break.

The refinement has hysteresis: it fires only when a coarse element comes within ``TRIGGER``
times those radii (a crack front that has crossed half of the resolved margin), and then
resolves the whole band. Without it a running crack moves the band's edge a little at every
iteration and every iteration pays for a bisection and a rebuild of the operators.

With ``band_search`` > 1 the target is coarser while a load step's iteration searches for its
crack (:meth:`CrackBand.search`): a crack that runs through the body in one step does so on
fewer new elements, and the band is resolved to its target once the iteration has converged,
after which it converges again on that mesh.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from ngat.crack import GROWN, Slit, grown, tips_of
from ngat.forms import distances, element_diameters
from ngat.refinement import bisect, rebuild
from ngat.state import ATState

__all__ = [
    "CrackBand",
    "DAMAGED",
    "BUFFER",
    "TIP_RADIUS",
    "ONSET_RADIUS",
    "FEW_CENTRES",
    "band_elements",
    "nearest_distance",
    "mesh_geometry",
]

log = logging.getLogger(__name__)

DAMAGED = 0.5
"""Vertices with v below this belong to the crack's core (d ≤ 1.4ε from a crack). AT2 has no
elastic phase: a homogeneous strain damages the body down to v = 3/4 before it softens, so a
higher threshold would take large strained regions for cracks."""
BUFFER = 1.5
"""Distance, in units of ε, around the damaged vertices that is resolved too."""
TIP_RADIUS = 3.0
"""Radius, in units of ε, of the disc around each crack tip resolved before a step."""
TRIGGER = 0.5
"""Fraction of ``BUFFER`` and ``TIP_RADIUS`` inside which a coarse element triggers the
refinement of the whole band. Measured on ``two-slits --quick``: 0.5 halves the band
refinements and keeps the fracture time; 0.25 lets the crack run into coarse elements before
they are refined and it breaks 0.05 late."""
ONSET_RADIUS = 2.0
"""Radius, in units of ε, of the disc about a slit tip resolved to ``onset_h`` (the crack's
onset). On the paper's example with ``onset_h`` 0.18ε: E(1.0) +0.082 % with 3ε, +0.091 % with 2ε,
+0.094 % with 1.5ε, and 2ε took 0.83 of the wall of 3ε (``docs/paper-example.md``)."""
FEW_CENTRES = 8
"""Most centres :func:`band_elements` measures directly rather than by a k-d tree."""
MAX_ROUNDS = 40
"""Bisection rounds of one :meth:`CrackBand.refine` at most (a 2^20 reduction of the area)."""


def mesh_geometry(mesh) -> tuple[np.ndarray, np.ndarray]:
    """Return the vertex coordinates and element vertex numbers of a triangle mesh.

    The coordinates are a view of Netgen's memory, valid while the mesh lives and is not
    refined (:class:`ngat.forms.MeshArrays` keeps a copy).
    """
    ngmesh = mesh.ngmesh
    elements = ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(np.int64) - 1
    return ngmesh.Coordinates()[:, :2], elements


def nearest_distance(
    centres: np.ndarray | cKDTree, points: np.ndarray, bounds: np.ndarray
) -> np.ndarray:
    """Return the distance from each point to the nearest centre, ∞ where that exceeds its bound.

    A k-d tree query with one bound for all points searches every point as far as the largest
    bound: on a graded mesh a few wide elements far from the crack set it for all. The points
    are therefore queried per power-of-two class of their bounds, each class with its own
    largest bound, and only those within their bound of the centres' bounding box (a crack's
    new damage lies about its tip). A distance within a point's bound is exact; beyond it, it
    may be exact or ∞.

    Parameters
    ----------
    centres
        (m, 2) points, or a ``cKDTree`` of them (built once where several queries share them).
    points
        (n, 2) query points.
    bounds
        (n,) distance beyond which a point's distance is not needed.
    """
    distance = np.full(len(points), np.inf)
    if len(points) == 0:
        return distance
    tree = centres if isinstance(centres, cKDTree) else cKDTree(centres)
    # A point farther than its bound from the centres' bounding box is not searched.
    (left, bottom), (right, top) = tree.mins, tree.maxes
    x, y = points[:, 0], points[:, 1]
    near = (x >= left - bounds) & (x <= right + bounds) & (y >= bottom - bounds)
    candidates = np.flatnonzero(near & (y <= top + bounds))
    classes = np.frexp(bounds[candidates])[1]
    for level in np.unique(classes):
        among = candidates[classes == level]
        distance[among] = tree.query(points[among], distance_upper_bound=bounds[among].max())[0]
    return distance


def _count(centres: np.ndarray | cKDTree) -> int:
    """Return the number of centres of an array or a ``cKDTree``."""
    return centres.n if isinstance(centres, cKDTree) else len(centres)


def _tree(centres: np.ndarray) -> np.ndarray | cKDTree:
    """Return a ``cKDTree`` of the centres, for queries that share them.

    Up to :data:`FEW_CENTRES` centres are returned as they are: :func:`band_elements` measures
    their distances directly.
    """
    return cKDTree(centres) if len(centres) > FEW_CENTRES else centres


def band_elements(
    coords: np.ndarray,
    elements: np.ndarray,
    diameter: np.ndarray,
    centres: np.ndarray | cKDTree,
    radius: float,
) -> np.ndarray:
    """Return the elements that come within ``radius`` of any of the ``centres``.

    An element is taken when its first vertex lies within ``radius + diameter`` of a centre,
    which holds for every element that meets the disc of that radius (and a few more). The
    search about each element stops at that distance (:func:`nearest_distance`), so elements
    far from every centre cost next to nothing. Up to :data:`FEW_CENTRES` centres given as an
    array (the crack tips) are measured directly instead, √(Δx² + Δy²) as the k-d tree does
    (the same numbers; 4 against 9 ms for two tips at 180k elements).

    Parameters
    ----------
    coords
        (nv, 2) vertex coordinates.
    elements
        (ne, 3) vertex numbers of the candidate elements.
    diameter
        (ne,) their diameters.
    centres
        (m, 2) points, or their ``cKDTree``.
    radius
        Distance from the points.

    Returns
    -------
    np.ndarray
        (ne,) boolean mask.
    """
    return _near(coords[elements[:, 0]], diameter, centres, radius)


def _near(
    points: np.ndarray, diameter: np.ndarray, centres: np.ndarray | cKDTree, radius: float
) -> np.ndarray:
    """:func:`band_elements` of the elements with first vertices ``points`` (n, 2)."""
    if len(points) == 0 or _count(centres) == 0:
        return np.zeros(len(points), dtype=bool)
    bounds = radius + diameter
    if isinstance(centres, cKDTree) or len(centres) > FEW_CENTRES:
        return nearest_distance(centres, points, bounds) <= bounds
    distance = np.full(len(points), np.inf)
    for centre in centres:
        np.minimum(distance, distances(points, centre), out=distance)
    return distance <= bounds


class CrackBand:
    """Refinement that keeps the crack band at ``band_h · ε`` (see the module docstring).

    Parameters
    ----------
    eps
        Regularisation length ε.
    band_h
        Target element diameter in the band, in units of ε.
    slits
        The scene's slits, whose cracks' tips are resolved before each step.
    h_floor
        Element floor (elements are never bisected below it, :func:`ngat.refinement.refinable`).
    trigger
        Fraction of the band's radii inside which a coarse element triggers a refinement
        (1: no hysteresis).
    grading
        Growth g of the target diameter per unit distance beyond the band (0: no grading).
    search
        Factor of the target while a load step's iteration searches for its crack
        (:meth:`search`; 1: none).
    onset_h
        Target element diameter, in units of ε, about the slit tips whose crack has not grown
        (0: the band's target, as for a tip that has grown).

    Attributes
    ----------
    target : float
        The element diameter the band is resolved to now: ``band_h · ε``, or ``search`` times
        that between :meth:`search` and :meth:`end_search`.
    """

    def __init__(
        self,
        eps: float,
        band_h: float,
        slits: Sequence[Slit],
        h_floor: float,
        trigger: float = TRIGGER,
        grading: float = 0.0,
        search: float = 1.0,
        onset_h: float = 0.0,
    ):
        self.eps = eps
        self.resolved = max(band_h * eps, 2 * h_floor)
        self.searched = max(search * band_h * eps, 2 * h_floor)
        self.onset = max(onset_h * eps, 2 * h_floor) if onset_h > 0 else 0.0
        self.target = self.resolved
        self.slits = list(slits)
        self.trigger = trigger
        self.grading = grading
        self._clear: dict[float, tuple] = {}  # target → (mesh arrays, damaged mask) found clear
        self._wide: dict[float, tuple] = {}  # diameter → (elements, wider elements' arrays)

    def search(self) -> None:
        """Resolve the band to the coarser target of a step's search for its crack.

        Where the load step is unstable, a crack runs a whole ligament before the iteration
        settles, hundreds of iterations in which the band follows its tip. On the coarser band
        (at ``band_search = 2``: twice the diameter, a quarter of the new elements) the crack
        finds its path; :meth:`end_search` then resolves the band to ``band_h · ε`` and the
        iteration converges again on that mesh, so a converged step has the same band either
        way, but the path is that of the coarser band.
        Measured on the paper's example from its checkpoint at t = 1.38 (the break step):
        139 iterations and 388 linear solves against 249 and 782, 184k against 200k elements
        (three iterations after the band was resolved), total energy 3.2261 against 3.2180
        (the converged reference: 3.2245).
        """
        self.target = self.searched

    def end_search(self) -> bool:
        """Set the target back to ``band_h · ε``; return whether a search was on."""
        searching = self.target != self.resolved
        self.target = self.resolved
        return searching

    def tips(self, state: ATState) -> np.ndarray:
        """Return the slits' crack tips (of v), one row per slit (none without slits)."""
        if not self.slits:
            return np.empty((0, 2))
        return np.array(tips_of(state, self.slits))

    def running(self, tips: np.ndarray) -> bool:
        """Return whether the band is graded: a crack runs (without slits: always).

        A crack runs once it has grown :data:`ngat.crack.GROWN` · ε from its slit. A slit tip
        that has not cracked yet is left to μ, which grades the mesh towards its singularity
        more finely than the band's grading would.
        """
        return not self.slits or bool(grown(tips, self.slits, GROWN * self.eps).any())

    def at_onset(self, tips: np.ndarray) -> np.ndarray:
        """Return which tips are resolved to ``onset_h · ε``: those of cracks that have not grown.

        No tip without ``onset_h``: every tip's disc is then the band's, of ``TIP_RADIUS · ε``
        at its target.
        """
        if not self.onset or not self.slits:
            return np.zeros(len(tips), dtype=bool)
        return ~grown(tips, self.slits, GROWN * self.eps)

    def marked(
        self,
        coords: np.ndarray,
        elements: np.ndarray,
        damaged: np.ndarray | cKDTree,
        tips: np.ndarray,
        diameter: np.ndarray | None = None,
    ) -> np.ndarray:
        """Return the elements wider than the target within the band around the centres.

        About the slit tips whose crack tip is at onset (:meth:`at_onset`) the target is
        ``onset_h · ε``: about the slit's tip, which the singular field and the crack's onset
        surround, not about the tip of v, which moves by up to ε before the crack counts as
        grown (a disc that followed it was refined again at every iteration of the step).

        Parameters
        ----------
        coords, elements
            Vertex coordinates and element vertex numbers of the current mesh.
        damaged
            The damaged vertices (v < ``DAMAGED``), or their ``cKDTree``.
        tips
            The crack tips (:meth:`tips`).
        diameter
            The elements' diameters, if known (else computed).
        """
        if diameter is None:
            diameter = element_diameters(coords, elements)
        marked = np.zeros(len(elements), dtype=bool)
        onset, radius = self.at_onset(tips), TIP_RADIUS * self.eps
        if onset.any():
            fine, points, width = self._wider(coords, elements, diameter, self.onset)
            slit_tips = np.array([tip for _, tip in self.slits], dtype=float)[onset]
            marked[fine] = _near(points, width, slit_tips, ONSET_RADIUS * self.eps)
            tips = tips[~onset]
        coarse, points, width = self._wider(coords, elements, diameter, self.target)
        if len(coarse) == 0:
            return marked
        near = _near(points, width, damaged, BUFFER * self.eps)
        near |= _near(points, width, tips, radius)
        marked[coarse[near]] = True
        return marked

    def _wider(
        self, coords: np.ndarray, elements: np.ndarray, diameter: np.ndarray, size: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the elements wider than ``size``: their numbers, first vertices and diameters.

        Kept for the last ``elements`` array per size: a load step's iterations ask
        :meth:`marked` about the same mesh after every v-step, and the gathers cost more than
        the distances to the tips.
        """
        kept = self._wide.get(size)
        if kept is not None and kept[0] is elements:
            return kept[1]
        wider = np.flatnonzero(diameter > size)
        found = (wider, coords[elements[wider, 0]], diameter[wider])
        self._wide[size] = (elements, found)
        return found

    def graded(
        self,
        coords: np.ndarray,
        elements: np.ndarray,
        centres: np.ndarray | cKDTree,
        diameter: np.ndarray | None = None,
    ) -> np.ndarray:
        """Return the elements wider than ``target + grading · (d − BUFFER · ε)``.

        d is the distance from an element to the nearest centre, measured from its first
        vertex less its diameter (a lower bound); elements beyond the distance where the
        allowed size exceeds the widest element are never marked.

        Parameters
        ----------
        coords, elements
            Vertex coordinates and element vertex numbers of the current mesh.
        centres
            The damaged vertices and the crack tips (:meth:`tips`), stacked, or their
            ``cKDTree``.
        diameter
            The elements' diameters, if known (else computed).
        """
        marked = np.zeros(len(elements), dtype=bool)
        if self.grading <= 0 or _count(centres) == 0:
            return marked
        if diameter is None:
            diameter = element_diameters(coords, elements)
        coarse = np.flatnonzero(diameter > self.target)
        if len(coarse) == 0:
            return marked
        width = diameter[coarse]
        margin = BUFFER * self.eps
        # Beyond margin + (w − target)/grading + w an element of width w is never marked.
        reach = margin + (width - self.target) / self.grading + width
        distance = nearest_distance(centres, coords[elements[coarse, 0]], reach)
        allowed = self.target + self.grading * np.maximum(0.0, distance - width - margin)
        marked[coarse] = width > allowed
        return marked

    def triggered(
        self,
        coords: np.ndarray,
        elements: np.ndarray,
        damaged: np.ndarray | cKDTree,
        tips: np.ndarray | cKDTree,
    ) -> bool:
        """Return whether any of the (marked) elements lies within ``trigger`` times the radii.

        Parameters
        ----------
        coords
            Vertex coordinates of the current mesh.
        elements
            Vertex numbers of the elements :meth:`marked` returned (the trigger's reach lies
            inside the band's, so no other element can trigger).
        damaged, tips
            The damaged vertices (v < ``DAMAGED``) and the crack tips (:meth:`tips`), or
            their ``cKDTree``.
        """
        diameter = element_diameters(coords, elements)
        reach = self.trigger * self.eps
        return bool(
            band_elements(coords, elements, diameter, damaged, reach * BUFFER).any()
            or band_elements(coords, elements, diameter, tips, reach * TIP_RADIUS).any()
        )

    def refine(self, state: ATState) -> int:
        """Bisect the band until no element in it is wider than the target, if it needs it.

        Nothing is done unless a coarse element lies within ``trigger`` times the band's radii
        (the grading, if any, is refined along with the band)
        (hysteresis, see the module docstring). After a call that did nothing, the next call
        on the same mesh with the same target (each of the search's and the resolved one:
        a load step alternates them) searches about the vertices damaged since and the tips
        only: the trigger's reach about the union of two vertex sets is the union of their
        reaches, and the vertices damaged then had no coarse element within it (the search
        about all damaged vertices after every v-step cost 0.17 s at 200k elements). The
        centres (damaged vertices, tips) are taken once, on the current mesh: bisection only
        adds vertices between old ones, so the damaged set of the prolongated v lies within
        the band around them; the operators are rebuilt once, after the last bisection.

        Parameters
        ----------
        state
            Fields and mesh; refined in place (u, v and the previous step's v prolongated).

        Returns
        -------
        int
            Number of bisection rounds (0: no coarse element within the trigger's reach).
        """
        arrays = state.arrays
        with state.timer("band"):
            coords, elements = arrays.coords, arrays.elements
            is_damaged = state.v_values < DAMAGED
            damaged, tips = coords[is_damaged], self.tips(state)
            # k-d trees of the damaged vertices, built once for the trigger and every bisection
            # round (of all of them only when they are searched, or the band is refined); the
            # tips are few and measured directly (band_elements).
            damaged_tree = None
            clear = self._clear.get(self.target)
            if clear is not None and clear[0] is arrays:
                searched = _tree(coords[is_damaged & ~clear[1]])
            else:
                searched = damaged_tree = _tree(damaged)
            marked = self.marked(coords, elements, searched, tips, arrays.diameter)
            triggered = self.triggered(coords, elements[marked], searched, tips)
        if not triggered:
            self._clear[self.target] = (arrays, is_damaged)
            return 0
        self._clear = {}
        if damaged_tree is None:
            with state.timer("band"):
                damaged_tree = _tree(damaged)
                marked = self.marked(coords, elements, damaged_tree, tips, arrays.diameter)
        graded = self.running(tips)
        everywhere = _tree(np.concatenate([damaged, tips]) if graded else np.empty((0, 2)))
        rounds = 0
        with state.timer("band"):
            marked |= self.graded(coords, elements, everywhere, arrays.diameter)
        while rounds < MAX_ROUNDS:
            known = len(coords)  # the vertices before this round's bisection
            if not bisect(state, marked):
                break
            rounds += 1
            with state.timer("band"):
                coords, elements = mesh_geometry(state.mesh)
                # Only an element the round made can be marked: bisection keeps the vertices'
                # numbers and every element it makes holds one of the new vertices, and the
                # elements it kept were not marked (the centres are the same in every round).
                first, second, third = (elements[:, i] >= known for i in range(3))
                new = np.flatnonzero(first | second | third)
                diameter = element_diameters(coords, elements[new])
                marked = np.zeros(len(elements), dtype=bool)
                marked[new] = self.marked(coords, elements[new], damaged_tree, tips, diameter)
                marked[new] |= self.graded(coords, elements[new], everywhere, diameter)
        if rounds:
            rebuild(state)
            log.debug("crack band: %d rounds, %d elements", rounds, state.arrays.ne)
        return rounds

    def under_resolved(self, state: ATState) -> int:
        """Return how many damaged elements (a vertex with v < ``DAMAGED``) exceed the target."""
        arrays = state.arrays
        damaged = arrays.touching(state.v_values < DAMAGED)
        return int((damaged & (arrays.diameter > self.target)).sum())
