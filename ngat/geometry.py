"""Slit domains: Netgen OCC faces with true cracks, meshed with distinct nodes on both faces.

A slit is drawn as a wire that runs up the slit and back down it. OCC then has two edges with
the same geometry and Netgen meshes them separately, so every interior slit node is duplicated.
The node where a slit meets the outer boundary (its mouth) is still shared by both faces;
:func:`split_slit_mouths` gives it a twin so that u can jump across the whole slit (paper,
Section 1.3: a slit domain is a polyhedral domain in the paper's sense).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import netgen.meshing as ngm
import ngsolve
import numpy as np
from netgen.occ import Glue, OCCGeometry, Rectangle, WorkPlane

from ngat.state import SceneError

__all__ = [
    "polygon_face",
    "rectangle",
    "glue",
    "generate_mesh",
    "split_slit_mouths",
    "check_mesh_size",
    "unmeshed_edges",
    "MAX_ELEMENTS",
]

MAX_ELEMENTS = 10**7
"""Initial triangles at most. The initial mesh is meant to be coarse (adaptivity refines where
the crack is); a maxh that asks for more is a slip, and Netgen would fail or run out of memory."""


def polygon_face(points: Sequence[tuple[float, float]], name: str):
    """Return an OCC face bounded by a closed polygon; slits are out-and-back runs of points.

    Parameters
    ----------
    points
        Corners in order; a slit from ``p`` to ``q`` is written ``..., p, q, p, ...``.
    name
        Material name of the face.
    """
    xy = np.asarray(points, dtype=float)
    signed_area = np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
    if signed_area < 0:
        # OCC fails to triangulate some clockwise faces with slits (and Netgen then drops the
        # face without an error): always run counter-clockwise.
        points = [points[0], *points[:0:-1]]
    wp = WorkPlane().MoveTo(*points[0])
    for p in points[1:]:
        wp.LineTo(*p)
    face = wp.Close().Face()
    face.faces.name = name
    return face


def rectangle(x0: float, y0: float, x1: float, y1: float, name: str):
    """Return the OCC face ``(x0, x1) x (y0, y1)`` named ``name``."""
    face = Rectangle(x1 - x0, y1 - y0).Face().Move((x0, y0, 0))
    face.faces.name = name
    return face


def glue(faces):
    """Glue faces into one conforming shape (shared edges are meshed once)."""
    return Glue(list(faces))


@contextmanager
def without_face_table() -> Iterator[None]:
    """Let the Netgen meshes created inside keep no table of faces in their topology.

    A Netgen mesh's topology numbers its edges and faces, and ``Mesh.Refine`` rebuilds it after
    every bisection; on a triangle mesh the faces are the triangles themselves, and nothing
    ngat computes asks for them (its P1 and vector P1 spaces have vertex DOFs only; edges,
    which the bisection needs, stay). Without the table a refinement of a 65k-element mesh
    took 52 instead of 75 ms, and the paper's example gave the same numbers to the last bit.
    The flag is read when a mesh is created and kept by it through its refinements; it is
    Netgen's default (on) again when the block ends, so meshes made elsewhere keep the table.
    """
    ngm.Mesh.EnableTableClass("faces", False)
    try:
        yield
    finally:
        ngm.Mesh.EnableTableClass("faces", True)


def generate_mesh(shape, maxh: float) -> ngsolve.Mesh:
    """Mesh an OCC shape with triangles of size ``maxh`` and open every slit mouth.

    Parameters
    ----------
    shape
        A 2-D OCC shape (faces named as materials).
    maxh
        Largest element size.

    Returns
    -------
    ngsolve.Mesh
        Mesh whose slits have distinct nodes on both faces, mouths included.

    Raises
    ------
    SceneError
        If ``maxh`` asks for more than :data:`MAX_ELEMENTS` triangles, if Netgen left part of
        the shape unmeshed (it does so without an error, e.g. where a slit runs closer to another
        boundary than ``maxh``; the message names a ``maxh`` that works), or if a face of the
        shape got no elements.
    """
    check_mesh_size(shape, maxh)
    ngmesh = OCCGeometry(shape, dim=2).GenerateMesh(maxh=maxh)
    hole = unmeshed_edges(ngmesh)
    if len(hole):
        raise SceneError(_meshing_failure(shape, maxh, ngmesh.Coordinates()[hole[0]].mean(axis=0)))
    split_slit_mouths(ngmesh)
    mesh = ngsolve.Mesh(ngmesh)
    missing = sorted({face.name for face in shape.faces} - set(mesh.GetMaterials()))
    if missing:
        raise SceneError(
            f"Netgen left the face(s) {', '.join(missing)} without elements: check that their "
            "outline does not cross itself"
        )
    return mesh


def check_mesh_size(shape, maxh: float) -> None:
    """Raise :class:`~ngat.state.SceneError` if ``maxh`` asks for too many triangles.

    The count is estimated as the shape's area over that of an equilateral triangle of side
    ``maxh``; the limit is :data:`MAX_ELEMENTS`.
    """
    area = float(sum(face.mass for face in shape.faces))
    triangle = math.sqrt(3) / 4
    smallest = math.sqrt(area / triangle / MAX_ELEMENTS)
    if maxh < smallest:
        raise SceneError(
            f"maxh={maxh:g} is too small for the geometry (area {area:.3g}): it would take "
            f"more than {MAX_ELEMENTS:.0e} triangles; choose maxh >= {smallest:.2g} (the "
            "initial mesh should be coarse, adaptivity refines where the crack is)"
        )


def unmeshed_edges(ngmesh: ngm.Mesh) -> np.ndarray:
    """Return the element edges that border a part of the domain Netgen left without elements.

    In a complete mesh an edge of exactly one element is a boundary segment (a slit's two
    faces have distinct segments); any other such edge borders a hole in the mesh.

    Returns
    -------
    np.ndarray
        (m, 2) 0-based point numbers; empty for a complete mesh.
    """
    elements = ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(np.int64) - 1
    segments = np.sort(ngmesh.Elements1D().NumPy()["nodes"][:, :2].astype(np.int64) - 1, axis=1)
    edges = np.sort(elements[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    single = unique[counts == 1]
    width = len(ngmesh.Points())
    on_boundary = np.isin(single @ [width, 1], segments @ [width, 1])
    return single[~on_boundary]


def _slits(shape) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """Return the slit segments of a shape: the edges that occur twice (out and back)."""
    ends = [tuple(sorted(((e.start.x, e.start.y), (e.end.x, e.end.y)))) for e in shape.edges]
    return sorted({end for end in ends if ends.count(end) > 1})


def _meshing_failure(shape, maxh: float, hole: np.ndarray) -> str:
    """Return the message for a mesh with a hole at ``hole``: where, and a ``maxh`` that works."""
    where = f"({hole[0]:.3g}, {hole[1]:.3g})"
    slits = _slits(shape)
    if slits:
        a, b = min(
            slits, key=lambda s: np.linalg.norm(np.subtract(s[0], hole) + np.subtract(s[1], hole))
        )
        where += f", next to the slit ({a[0]:g}, {a[1]:g})–({b[0]:g}, {b[1]:g})"
    problem = f"Netgen left part of the domain unmeshed at maxh={maxh:g} (at {where})"
    h = maxh
    for _ in range(6):
        h /= 2
        try:
            check_mesh_size(shape, h)
        except SceneError:
            break
        if not len(unmeshed_edges(OCCGeometry(shape, dim=2).GenerateMesh(maxh=h))):
            return f"{problem}: maxh={h:g} meshes it"
    return f"{problem}: no maxh down to {h:g} meshes it; check the geometry there"


def _fan_components(elements: np.ndarray, around: np.ndarray, cut: set) -> list[list[int]]:
    """Group the elements around one point into components joined by shared, uncut edges."""
    labels = list(range(len(around)))

    def find(i: int) -> int:
        while labels[i] != i:
            i = labels[i]
        return i

    for i in range(len(around)):
        for j in range(i + 1, len(around)):
            shared = set(elements[around[i]]) & set(elements[around[j]])
            if len(shared) == 2 and tuple(sorted(shared)) not in cut:
                labels[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i, e in enumerate(around):
        groups.setdefault(find(i), []).append(int(e))
    return sorted(groups.values())


def split_slit_mouths(ngmesh: ngm.Mesh) -> int:
    """Give every point whose element fan falls apart a twin point per extra fan component.

    Around an interior point the elements form a cycle, around a boundary point one chain; at a
    slit mouth they form two chains (one per face) that only meet at the point. Two elements
    are joined across an edge unless the edge is *cut*: meshed as two boundary segments (the
    two OCC edges of a slit without an interior node). Counting elements ``n_el`` and joining
    edges ``n_int`` at each point finds the points to split in one vectorised pass
    (``n_el - n_int`` is the number of chains); only those few points are visited in Python.

    Parameters
    ----------
    ngmesh
        Netgen mesh, modified in place (points added, element and segment nodes renumbered).

    Returns
    -------
    int
        Number of points added.
    """
    el2 = ngmesh.Elements2D().NumPy()
    el1 = ngmesh.Elements1D().NumPy()
    elements = el2["nodes"][:, :3].astype(np.int64) - 1
    segments = el1["nodes"][:, :2].astype(np.int64) - 1
    npoints = len(ngmesh.Points())
    seg_pairs, seg_counts = np.unique(np.sort(segments, axis=1), axis=0, return_counts=True)
    cut = {tuple(pair) for pair in seg_pairs[seg_counts >= 2].tolist()}
    edges = np.sort(elements[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    joining = unique[(counts == 2) & ~np.array([tuple(e) in cut for e in unique.tolist()])]
    n_el = np.bincount(elements.ravel(), minlength=npoints)
    n_int = np.bincount(joining.ravel(), minlength=npoints)
    coords = ngmesh.Coordinates()
    added = 0
    for p in np.flatnonzero(n_el - n_int >= 2):
        around = np.flatnonzero((elements == p).any(axis=1))
        components = _fan_components(elements, around, cut)
        numbers = [p + 1]
        for _ in components[1:]:
            twin = ngmesh.Add(ngm.MeshPoint(ngm.Pnt(coords[p, 0], coords[p, 1], 0.0)))
            numbers.append(int(twin.nr))
            added += 1
        for number, component in zip(numbers, components, strict=True):
            for e in component:
                nodes = el2[e]["nodes"]
                nodes[nodes == p + 1] = number
                el2[e]["nodes"] = nodes
        # Segments at p go to the component holding their other node; duplicated segments of a
        # cut edge are dealt out one per component.
        dealt: dict[int, int] = {}
        for s in np.flatnonzero((segments == p).any(axis=1)):
            other = segments[s][segments[s] != p][0]
            owners = [
                k for k, comp in enumerate(components) if any(other in elements[e] for e in comp)
            ]
            k = owners[min(dealt.get(other, 0), len(owners) - 1)]
            dealt[other] = dealt.get(other, 0) + 1
            nodes = el1[s]["nodes"]
            nodes[nodes == p + 1] = numbers[k]
            el1[s]["nodes"] = nodes
        for number, component in zip(numbers, components, strict=True):
            elements[component] = np.where(
                elements[component] == p, number - 1, elements[component]
            )
        segments = el1["nodes"][:, :2].astype(np.int64) - 1
    return added
