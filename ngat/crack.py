"""Crack measures on a P1 mesh: where the cracks' tips are and whether the body still holds.

The measures work on the vertex graph whose edges are the element edges. Slits have distinct
nodes on their two faces (:mod:`ngat.geometry`), so no edge of this graph crosses a slit, and a
set of vertices is connected exactly when it is connected inside the body. Two sets are used:

- the crack set {v < threshold}: its component(s) touching a slit are that slit's crack, whose
  tip is the point of {v_h < threshold} (v_h the P1 interpolant) farthest from the slit's mouth
  (:func:`crack_tips`): a crack vertex or where v_h crosses the threshold on an edge leaving
  the crack, so that the tip moves continuously and not from vertex to vertex;
- the sound set {v ≥ threshold}: the body holds while it connects the Dirichlet regions
  (:func:`connects`); the fracture time of a run is the first load time at which it no longer does.

In a triangulation edges do not cross, so a crack set that is edge-connected from boundary to
boundary separates the sound vertices on its two sides: the two measures agree.
"""

from __future__ import annotations

from collections.abc import Sequence

import ngsolve
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ngat.forms import MeshArrays, distances, mesh_edges
from ngat.state import ATState, SceneError

__all__ = [
    "Slit",
    "mesh_edges",
    "components",
    "crack_tips",
    "tips_of",
    "connects",
    "check_slits",
]

Slit = tuple[tuple[float, float], tuple[float, float]]
"""A slit as a segment ``((x_mouth, y_mouth), (x_tip, y_tip))``."""
GROWN = 1.0
"""Growth from its slit's tip, in units of ε, from which a crack counts as running
(:func:`grown`): the crack band is graded and the tip re-meshed only about running cracks."""


def components(arrays: MeshArrays, mask: np.ndarray) -> np.ndarray:
    """Label the connected components of a vertex set in the graph of element edges.

    Parameters
    ----------
    arrays
        Element geometry of the mesh.
    mask
        (nv,) boolean: the vertex set.

    Returns
    -------
    np.ndarray
        (nv,) int labels (read-only): the component of each vertex of the set, ``-1`` outside
        it. Kept for the mesh's last sets: a load step's test of the sound set before any
        crack asks for the same set as the step before (3.6 ms at 21k elements).
    """
    return arrays.recall("components", mask, lambda m: _components(arrays.edges, m))


def _components(edges: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """:func:`components` on the given edges (all edges between vertices of the set among them)."""
    inside = np.flatnonzero(mask)
    labels = _labels(edges, mask, inside)
    out = np.full(len(mask), -1, dtype=labels.dtype)
    out[inside] = labels
    return out


def _labels(edges: np.ndarray, mask: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Return the component labels of the set's vertices ``inside`` (its ``flatnonzero``).

    The graph has the set's vertices only, so a small set costs little beyond the mask.
    """
    edges = edges[mask[edges[:, 0]] & mask[edges[:, 1]]]
    local = np.full(len(mask), -1, dtype=np.int64)
    local[inside] = np.arange(len(inside))
    graph = coo_matrix(
        (np.ones(len(edges), dtype=np.int8), (local[edges[:, 0]], local[edges[:, 1]])),
        shape=(len(inside), len(inside)),
    )
    return connected_components(graph, directed=False)[1]


def grown(tips: Sequence[tuple[float, float]], slits: Sequence[Slit], length: float) -> np.ndarray:
    """Return, per slit, whether its crack's tip lies ``length`` or farther from the slit's tip.

    Parameters
    ----------
    tips
        One tip per slit (:func:`crack_tips`).
    slits
        One segment ``((x_mouth, y_mouth), (x_tip, y_tip))`` per slit.
    length
        Growth from which a crack counts as grown.

    Returns
    -------
    np.ndarray
        (len(slits),) boolean.
    """
    if not slits:
        return np.zeros(0, dtype=bool)
    slit_tips = np.array([tip for _, tip in slits], dtype=float)
    return np.linalg.norm(np.asarray(tips, dtype=float) - slit_tips, axis=1) >= length


def _distance_to_segment(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Return the distance of each point to the segment [a, b]."""
    ab = b - a
    s = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + s[:, None] * ab), axis=1)


def crack_tips(
    arrays: MeshArrays, v: np.ndarray, slits: Sequence[Slit], threshold: float = 0.1
) -> list[tuple[float, float]]:
    """Return the tip of the crack grown from each slit.

    A slit's crack is the union of the components of {v < threshold} that reach the slit: that
    hold a vertex within one element size ``h`` of the slit segment, ``h`` the largest diameter of
    the elements at the vertex nearest to the slit tip. Its tip is the point of the crack's part
    of {v_h < threshold} farthest (Euclidean) from the slit's *mouth*: a crack vertex or the
    point where v_h crosses the threshold on an edge to a sound vertex (linear interpolation,
    below one element size from the farthest crack vertex). Measuring from the mouth, not the
    tip, keeps damage along the slit faces from being taken for the tip. When the cracks of two
    slits have joined, each slit's tip lies on the other slit's side (where the joined crack
    ends).

    Parameters
    ----------
    arrays
        Element geometry of the mesh.
    v
        (nv,) phase field at the vertices.
    slits
        One segment ``((x_mouth, y_mouth), (x_tip, y_tip))`` per slit.
    threshold
        Vertices with ``v < threshold`` are cracked.

    Returns
    -------
    list of (float, float)
        One tip per slit; the slit tip itself where no crack reaches the slit.
    """
    coords, v = arrays.coords, np.asarray(v, dtype=float)
    cracked = v < threshold
    # The edges with a cracked end: those within the crack and those leaving it.
    edges = arrays.edges[cracked[arrays.edges[:, 0]] | cracked[arrays.edges[:, 1]]]
    # Measured on the cracked vertices only: a few thousand of the mesh's 10⁵.
    inside = np.flatnonzero(cracked)
    labels, points = _labels(edges, cracked, inside), coords[inside]
    tips = []
    for mouth, tip in slits:
        mouth, tip = np.asarray(mouth, dtype=float), np.asarray(tip, dtype=float)
        touching = _distance_to_segment(points, mouth, tip) <= arrays.size_at(tip)
        member = np.isin(labels, labels[touching])
        if not member.any():
            tips.append((float(tip[0]), float(tip[1])))
            continue
        crack = np.zeros(len(v), dtype=bool)
        crack[inside[member]] = True
        crossings = _crossings(coords, edges, v, crack, cracked, threshold)
        candidates = np.vstack([points[member], crossings])
        far = candidates[np.argmax(distances(candidates, mouth))]
        tips.append((float(far[0]), float(far[1])))
    return tips


def tips_of(state: ATState, slits: Sequence[Slit]) -> list[tuple[float, float]]:
    """Return :func:`crack_tips` of the state's v, measured once per mesh and v.

    The crack band, the re-mesher and a step's record each ask for the tips of the same v
    (:meth:`ngat.state.ATState.of_v`).
    """
    key = ("crack_tips", tuple((tuple(mouth), tuple(tip)) for mouth, tip in slits))
    return state.of_v(key, lambda: crack_tips(state.arrays, state.v_values, slits))


def _crossings(
    coords: np.ndarray,
    edges: np.ndarray,
    v: np.ndarray,
    crack: np.ndarray,
    cracked: np.ndarray,
    threshold: float,
) -> np.ndarray:
    """Return the points where v_h = threshold on the edges from ``crack`` to sound vertices.

    With the crack vertices these are the corners of the crack's part of {v_h < threshold}
    (v_h the P1 interpolant), so its farthest point from the mouth is one of them. ``edges``
    holds at least every edge with an end in ``crack``.
    """
    first, second = edges.T
    inner = np.where(crack[first], first, second)
    outer = np.where(crack[first], second, first)
    leaving = (crack[first] != crack[second]) & ~cracked[outer]
    inner, outer = inner[leaving], outer[leaving]
    s = (threshold - v[inner]) / (v[outer] - v[inner])
    return coords[inner] + s[:, None] * (coords[outer] - coords[inner])


def connects(
    arrays: MeshArrays,
    v: np.ndarray,
    region_a: np.ndarray,
    region_b: np.ndarray,
    threshold: float = 0.1,
) -> bool:
    """Return whether the sound set {v ≥ threshold} connects two vertex sets.

    The body is broken between two Dirichlet regions when this is ``False``; the first load time
    at which that happens is the run's fracture time.

    Parameters
    ----------
    arrays
        Element geometry of the mesh.
    v
        (nv,) phase field at the vertices.
    region_a, region_b
        (nv,) boolean vertex masks, e.g. the DOFs of two Dirichlet regions.
    threshold
        Vertices with ``v ≥ threshold`` are sound.

    Returns
    -------
    bool
        ``True`` if one component of the sound set holds vertices of both regions.
    """
    labels = components(arrays, np.asarray(v) >= threshold)
    a = labels[np.asarray(region_a, dtype=bool) & (labels >= 0)]
    b = labels[np.asarray(region_b, dtype=bool) & (labels >= 0)]
    return bool(np.intersect1d(a, b).size)


def check_slits(mesh: ngsolve.Mesh, slits: Sequence[Slit], scene: str) -> None:
    """Raise :class:`~ngat.state.SceneError` if a slit's mouth or tip lies outside the mesh.

    A slit outside the domain has no crack to measure: its tip would be reported at the given
    point whatever happens.
    """
    for i, slit in enumerate(slits, start=1):
        for end, (x, y) in zip(("mouth", "tip"), slit, strict=True):
            if not mesh.Contains(x, y):
                raise SceneError(
                    f"scene '{scene}': the {end} ({x:g}, {y:g}) of slit {i} lies outside the "
                    "domain: fix 'slits' in the scene (mouth on the boundary, tip inside, on a "
                    "slit drawn in the geometry)"
                )
