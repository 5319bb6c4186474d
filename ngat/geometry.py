"""Slit domains: Netgen OCC faces with true cracks, meshed with distinct nodes on both faces.

A slit is drawn as a wire that runs up the slit and back down it. OCC then has two edges with
the same geometry and Netgen meshes them separately, so every interior slit node is duplicated.
The node where a slit meets the outer boundary (its mouth) is still shared by both faces;
:func:`split_slit_mouths` gives it a twin so that u can jump across the whole slit (paper,
Section 1.3: a slit domain is a polyhedral domain in the paper's sense).
"""

from __future__ import annotations

from collections.abc import Sequence

import netgen.meshing as ngm
import ngsolve
import numpy as np
from netgen.occ import Glue, OCCGeometry, Rectangle, WorkPlane

from ngat.state import SceneError

__all__ = ["polygon_face", "rectangle", "glue", "generate_mesh", "split_slit_mouths"]


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
        If a face of the shape got no elements.
    """
    ngmesh = OCCGeometry(shape, dim=2).GenerateMesh(maxh=maxh)
    split_slit_mouths(ngmesh)
    mesh = ngsolve.Mesh(ngmesh)
    missing = sorted({face.name for face in shape.faces} - set(mesh.GetMaterials()))
    if missing:
        raise SceneError(
            f"Netgen left the face(s) {', '.join(missing)} without elements: check that their "
            "outline does not cross itself"
        )
    return mesh


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
