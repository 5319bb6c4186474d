"""Re-meshing ahead of crack tips: Netgen's own elements of size ε where a crack is about to run.

Bisection keeps the shape and orientation of an element's ancestor, so an initial element of
10ε bisected down to ε is a patch of a few congruent, equally oriented triangles, and the cost
of a lumped crack depends on its direction relative to them. Measured on ``surfing`` (R/ε = 100,
``docs/adaptivity.md``): a path of bisected 10ε elements holds a running crack to 0.95 of its
speed, Netgen's own elements of ε along the same path (the same crack band bisected on them)
let it run at 0.98. Adaptivity cannot know the path in advance, so :class:`TipRemesher`
re-meshes it as the crack comes: before a load step, the elements within ``radius · ε`` of each
running crack tip (:func:`ngat.crack.crack_tips`, :func:`ngat.crack.grown`) that no earlier
re-meshing made are replaced by a Netgen mesh of size ε of the region they cover
(``netgen.geom2d``, the region's boundary edges kept), so the rest of the mesh stays exactly as
it was. Kept are the elements that touch the crack (v < :data:`ngat.band.DAMAGED` now or at the
previous step), the boundary (a slit's two faces would close in ``netgen.geom2d``) or a
Dirichlet region: the region is undamaged body, where u and v are smooth.

Before meshing, the region's elements are bisected until their edges are at most
:data:`EDGE_FRACTION` · ε, so Netgen puts no point on the region's boundary (a boundary that
came out otherwise is refused and the mesh kept). The vertices outside the region keep their
values exactly, the new ones take the P1 fields at their points.

A :class:`Patch` records one re-meshing (the elements removed, the new points and elements), so
a checkpoint replays it without Netgen (:func:`splice`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import netgen.meshing as ngm
import ngsolve
import numpy as np
from netgen.geom2d import SplineGeometry
from scipy.spatial import cKDTree

from ngat.band import DAMAGED, mesh_geometry
from ngat.crack import GROWN, Slit, grown, tips_of
from ngat.forms import distances
from ngat.geometry import without_face_table
from ngat.refinement import bisect, rebuild
from ngat.state import ATState

__all__ = [
    "Patch",
    "TipRemesher",
    "EDGE_FRACTION",
    "apply_patch",
    "mesh_region",
    "patch_region",
    "splice",
]

log = logging.getLogger(__name__)

EDGE_FRACTION = 0.7
"""Longest edge of the region before meshing, in units of the target size: Netgen divides a
boundary segment longer than its local size, which would leave the region's boundary
non-conforming with the elements outside."""
TRIGGER = 0.5
"""Fraction of the radius inside which an element no re-meshing made triggers one."""
MAX_ROUNDS = 30
"""Bisection rounds of the region before meshing at most."""


@dataclass
class Patch:
    """One re-meshing of a region, enough to repeat it on the same mesh.

    Attributes
    ----------
    removed
        Indices of the elements replaced.
    points
        (m, 2) coordinates of the new vertices (numbered after the kept vertices).
    elements
        (k, 3) vertex numbers of the new elements: below ``len(mesh vertices)`` a vertex of the
        old mesh, from there on ``points`` in order.
    material
        Netgen material index (1-based) of the new elements.
    centre, radius
        The disc re-meshed (its elements are Netgen's own from then on).
    """

    removed: np.ndarray
    points: np.ndarray
    elements: np.ndarray
    material: int
    centre: np.ndarray
    radius: float


def patch_region(
    coords: np.ndarray,
    elements: np.ndarray,
    allowed: np.ndarray,
    centre: np.ndarray,
    radius: float,
) -> np.ndarray:
    """Return the elements of a re-meshing: ``allowed`` ones with centroid within ``radius``.

    Elements are dropped until the region is a 2-manifold with boundary (no vertex where the
    region's boundary passes twice, which Netgen's advancing front cannot close).
    """
    centroid = coords[elements].mean(axis=1)
    region = allowed & (distances(centroid, centre) < radius)
    for _ in range(10):
        edges = boundary_edges(elements[region])
        count = np.bincount(edges.ravel(), minlength=len(coords))
        pinched = count > 2
        if not pinched.any():
            break
        region &= ~pinched[elements].any(axis=1)
    return region


def boundary_edges(elements: np.ndarray) -> np.ndarray:
    """Return the edges of exactly one of ``elements``, each in its element's own order."""
    edges = elements[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, inverse, counts = np.unique(
        np.sort(edges, axis=1), axis=0, return_inverse=True, return_counts=True
    )
    return edges[counts[inverse.ravel()] == 1]


def mesh_region(
    coords: np.ndarray, elements: np.ndarray, region: np.ndarray, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Mesh the region of the ``region`` elements with Netgen elements of size ``h``.

    Netgen may divide a boundary edge of the region (near much smaller elements); each element
    outside with such an edge is then split into a fan about its centroid through the new
    points, so the mesh stays conforming.

    Returns
    -------
    (points, new_elements, removed) or None
        The new points (m, 2); the new elements (k, 3), numbered as the vertices of ``coords``
        and as ``len(coords) + i`` for ``points[i]``, oriented as ``elements``; the mask of the
        elements they replace. ``None`` if Netgen failed or left part of the region unmeshed.
    """
    det = _signed_areas(coords, elements)
    positive = elements[region].copy()
    positive[det[region] < 0] = positive[det[region] < 0][:, ::-1]
    edges = boundary_edges(positive)
    vertices = np.unique(edges)
    geometry = SplineGeometry()
    number = {int(v): geometry.AppendPoint(*map(float, coords[v])) for v in vertices}
    for a, b in edges:
        geometry.Append(["line", number[int(a)], number[int(b)]], leftdomain=1, rightdomain=0)
    try:
        ngmesh = geometry.GenerateMesh(maxh=h)
    except ngm.NgException:
        return None
    points = ngmesh.Coordinates()[:, :2]
    triangles = ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(np.int64) - 1
    distance, nearest = cKDTree(coords[vertices]).query(points)
    on_boundary = distance == 0.0
    new_det = _signed_areas(points, triangles)
    area = np.abs(det[region]).sum() / 2
    if on_boundary.sum() != len(vertices) or not np.isclose(np.abs(new_det).sum() / 2, area):
        return None
    numbers = np.empty(len(points), dtype=np.int64)
    numbers[on_boundary] = vertices[nearest[on_boundary]]
    numbers[~on_boundary] = len(coords) + np.arange((~on_boundary).sum())
    triangles = numbers[triangles]
    points = points[~on_boundary]
    removed = region.copy()
    hanging = _hanging_points(coords, points, edges, triangles)
    if hanging:
        points, fans, split = _split_outside(coords, elements, region, points, hanging)
        triangles = np.concatenate([triangles, fans])
        removed[split] = True
    all_xy = np.concatenate([coords, points])
    sign = np.sign(det[region][0])
    flip = np.sign(_signed_areas(all_xy, triangles)) != sign
    triangles[flip] = triangles[flip][:, ::-1]
    return points, triangles, removed


def _signed_areas(coords: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Return twice the signed area of each triangle."""
    xy = coords[triangles]
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    return e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]


def _hanging_points(
    coords: np.ndarray, points: np.ndarray, edges: np.ndarray, triangles: np.ndarray
) -> dict[tuple[int, int], list[int]]:
    """Return, per region boundary edge (a, b) that Netgen divided, its new points from a to b."""
    new = np.unique(boundary_edges(triangles))
    new = new[new >= len(coords)]
    hanging: dict[tuple[int, int], list[int]] = {}
    a, b = coords[edges[:, 0]], coords[edges[:, 1]]
    for point in new:
        xy = points[point - len(coords)]
        ab = b - a
        s = np.clip(np.einsum("ij,ij->i", xy - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        i = int(np.argmin(np.linalg.norm(xy - (a + s[:, None] * ab), axis=1)))
        hanging.setdefault((int(edges[i, 0]), int(edges[i, 1])), []).append(int(point))
    for (i, _), chain in hanging.items():
        chain.sort(key=lambda p: np.linalg.norm(points[p - len(coords)] - coords[i]))
    return hanging


def _split_outside(
    coords: np.ndarray,
    elements: np.ndarray,
    region: np.ndarray,
    points: np.ndarray,
    hanging: dict[tuple[int, int], list[int]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split each element outside the region with hanging points into a fan about its centroid.

    Returns
    -------
    points, fans, split
        The points with the centroids appended, the fans' triangles and the split elements.
    """
    # The owner of a divided edge holds both its ends: only such elements outside are looked at
    # (a dictionary of every directed edge outside cost 60 ms per re-meshing at 100k elements).
    ends = np.unique(np.array(list(hanging), dtype=np.int64))
    outside = np.flatnonzero(~region & (np.isin(elements, ends).sum(axis=1) >= 2))
    owner = {}
    for e in outside:
        for k in range(3):
            owner[(int(elements[e, k]), int(elements[e, (k + 1) % 3]))] = int(e)
    chains: dict[int, dict[tuple[int, int], list[int]]] = {}
    for (a, b), chain in hanging.items():
        e = owner.get((b, a), owner.get((a, b)))
        chains.setdefault(e, {})[(a, b)] = chain
    extra, fans = [], []
    all_xy = np.concatenate([coords, points])
    for e, divided in chains.items():
        corners = [int(v) for v in elements[e]]
        ring = []
        for k in range(3):
            p, q = corners[k], corners[(k + 1) % 3]
            ring.append(p)
            if (p, q) in divided:
                ring.extend(divided[(p, q)])
            elif (q, p) in divided:
                ring.extend(reversed(divided[(q, p)]))
        centre = len(coords) + len(points) + len(extra)
        extra.append(all_xy[corners].mean(axis=0))
        fans.extend((centre, ring[i], ring[(i + 1) % len(ring)]) for i in range(len(ring)))
    split = np.zeros(len(elements), dtype=bool)
    split[list(chains)] = True
    return np.concatenate([points, extra]), np.array(fans, dtype=np.int64), split


def splice(mesh: ngsolve.Mesh, patch: Patch) -> tuple[ngsolve.Mesh, np.ndarray]:
    """Return the mesh with the patch's elements in place of its removed ones.

    The boundary segments, materials and boundary names are the old mesh's; vertices that only
    removed elements had are dropped.

    Returns
    -------
    mesh : ngsolve.Mesh
        The new mesh.
    old_vertex : np.ndarray
        For each vertex of the new mesh the old vertex it is, or −1 for a patch point.
    """
    ngmesh = mesh.ngmesh
    coords, elements = mesh_geometry(mesh)
    index = ngmesh.Elements2D().NumPy()["index"].astype(np.int64)
    segments = ngmesh.Elements1D().NumPy()
    keep = np.ones(len(elements), dtype=bool)
    keep[patch.removed] = False
    all_coords = np.concatenate([coords, patch.points])
    all_elements = np.concatenate([elements[keep], patch.elements])
    all_index = np.concatenate([index[keep], np.full(len(patch.elements), patch.material)])
    used = np.zeros(len(all_coords), dtype=bool)
    used[all_elements.ravel()] = True
    used[segments["nodes"][:, :2].astype(np.int64).ravel() - 1] = True
    renumber = np.cumsum(used) - 1
    old_vertex = np.flatnonzero(used)
    old_vertex[old_vertex >= len(coords)] = -1
    with without_face_table():
        new = ngm.Mesh(dim=2)
    points = all_coords[used]
    new.AddPoints(np.column_stack([points, np.zeros(len(points))]))
    materials = [new.AddRegion(name, dim=2) for name in mesh.GetMaterials()]
    boundaries = [
        new.AddRegion(ngmesh.GetBCName(i), dim=1) for i in range(len(mesh.GetBoundaries()))
    ]
    for i in np.unique(all_index):
        chosen = all_elements[all_index == i]
        new.AddElements(2, materials[i - 1], renumber[chosen].astype(np.int32), base=0)
    seg_nodes = segments["nodes"][:, :2].astype(np.int64) - 1
    for i in np.unique(segments["index"]):
        chosen = seg_nodes[segments["index"] == i]
        new.AddElements(1, boundaries[i - 1], renumber[chosen].astype(np.int32), base=0)
    return ngsolve.Mesh(new), old_vertex


class TipRemesher:
    """Re-mesh a disc about each crack tip with Netgen elements of ε before a load step.

    Parameters
    ----------
    eps
        ε; the target size of the new elements.
    slits
        The scene's slits, whose cracks' tips are followed.
    radius
        Radius of the disc, in units of ε.
    """

    def __init__(self, eps: float, slits: Sequence[Slit], radius: float):
        self.eps = eps
        self.slits = slits
        self.radius = radius * eps

    def _native(self, state: ATState, centroid: np.ndarray) -> np.ndarray:
        """Return the elements inside a disc that an earlier re-meshing made (less a margin)."""
        native = np.zeros(len(centroid), dtype=bool)
        for patch in state.patches:
            distance = distances(centroid, patch.centre)
            native |= distance < patch.radius - 2 * self.eps
        return native

    def _allowed(self, state: ATState, among: np.ndarray | None = None) -> np.ndarray:
        """Return the elements a re-meshing may replace (see the module docstring).

        ``among``: a mask of the elements to check (the rest are returned as not allowed):
        the test against every earlier re-meshing's disc costs one distance per element and
        patch, 0.15 s per tip and load step at 180k elements and twenty patches.
        """
        arrays = state.arrays
        candidates = np.arange(arrays.ne) if among is None else np.flatnonzero(among)
        elements = arrays.elements[candidates]
        damaged = (state.v_values < DAMAGED) | (state.v_prev.vec.FV().NumPy() < DAMAGED)
        fixed = state.dirichlet_vertices | state.boundary_vertices | damaged | state.initial_crack
        allowed = np.zeros(arrays.ne, dtype=bool)
        kept = ~fixed[elements].any(axis=1)
        kept[kept] = ~self._native(state, arrays.centroid[candidates[kept]])
        allowed[candidates] = kept
        return allowed

    def remesh(self, state: ATState) -> int:
        """Re-mesh about every running crack tip whose disc holds elements no re-meshing made.

        A tip runs once it has grown :data:`ngat.crack.GROWN` · ε from its slit. A slit tip
        that has not cracked yet keeps the graded mesh the estimators give its singularity:
        Netgen's elements of ε there would reset the bisection levels that the element floor
        counts.

        Returns
        -------
        int
            The number of regions re-meshed.
        """
        tips = np.asarray(tips_of(state, self.slits))
        running = grown(tips, self.slits, GROWN * self.eps)
        return sum(self._remesh_at(state, tip) for tip in tips[running])

    def _remesh_at(self, state: ATState, tip: np.ndarray) -> bool:
        """Re-mesh the disc about one tip if it needs it; return whether the mesh changed."""
        with state.timer("remesh"):
            arrays = state.arrays
            distance = distances(arrays.centroid, tip) - arrays.diameter
            close = distance < TRIGGER * self.radius
            if not self._allowed(state, close).any():
                return False
            h = self.eps
            for _ in range(MAX_ROUNDS):
                arrays = state.arrays
                centroid = arrays.centroid
                disc = distances(centroid, tip) < self.radius
                disc &= ~arrays.touching(state.dirichlet_vertices)
                disc &= ~self._native(state, centroid)
                long = disc & (arrays.diameter > EDGE_FRACTION * h)
                if not long.any():
                    break
                bisect(state, long)
                rebuild(state, order=False)  # re-meshed next: no solve on this mesh
            region = patch_region(
                state.arrays.coords, state.arrays.elements, self._allowed(state), tip, self.radius
            )
            coords, elements = state.arrays.coords, state.arrays.elements
            if not region.any():
                return False
            meshed = mesh_region(coords, elements, region, h)
            if meshed is None:
                log.warning("re-meshing about the tip (%.4g, %.4g) failed: mesh kept", *tip)
                return False
            points, triangles, removed = meshed
            index = state.mesh.ngmesh.Elements2D().NumPy()["index"]
            material = int(index[np.flatnonzero(region)[0]])
            if (index[removed] != material).any():
                log.warning("re-meshing about the tip (%.4g, %.4g) meets another material", *tip)
                return False
            patch = Patch(np.flatnonzero(removed), points, triangles, material, tip, self.radius)
            apply_patch(state, patch)
            log.info(
                "re-meshed %d elements about the tip (%.4g, %.4g): %d Netgen elements",
                region.sum(), *tip, len(patch.elements),
            )  # fmt: skip
            return True


def apply_patch(state: ATState, patch: Patch) -> None:
    """Replace the state's mesh by :func:`splice`; carry u, v, v(t_{k−1}) and its change over.

    The kept vertices keep their values, the patch's points take the P1 fields' values there.
    """
    state.refinements.append(patch)
    mesh, old_vertex = splice(state.mesh, patch)
    kept = old_vertex >= 0
    points = state.mesh(patch.points[:, 0], patch.points[:, 1])
    values = {}
    for name in ("u", "v", "v_prev", "v_change"):
        field = getattr(state, name)
        old = field.vec.FV().NumPy().reshape(field.dim, -1)
        new = np.empty((field.dim, len(old_vertex)))
        new[:, kept] = old[:, old_vertex[kept]]
        new[:, ~kept] = np.asarray(field(points)).reshape(len(patch.points), field.dim).T
        values[name] = new.ravel()
    state.replace_mesh(mesh, values)
