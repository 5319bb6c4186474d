"""Meshing slit domains: a mesh Netgen leaves incomplete is refused with a maxh that works.

Netgen's surface mesher can leave part of a face without elements and report it only on its
console (e.g. where a slit runs closer to another boundary than ``maxh``); the mouth splitter
then met a fan with a hole in it and ended in an IndexError. The scenes' meshes keep no
table of faces, which Netgen's bisection would rebuild after every refinement.
"""

import ngsolve
import numpy as np
import pytest

from ngat.geometry import generate_mesh, glue, polygon_face, unmeshed_edges
from ngat.scene import load_scene
from ngat.state import SceneError

# A band 0.16 high with a slit of length 2 along its middle, from the left side.
BAND = [(0, 0.92), (8, 0.92), (8, 1.08), (0, 1.08), (0, 1), (2, 1), (0, 1)]


def band():
    return glue([polygon_face(BAND, "body")])


def test_incomplete_mesh_is_refused_with_a_maxh_that_works():
    with pytest.raises(SceneError) as refusal:
        generate_mesh(band(), 0.2)
    message = str(refusal.value)
    assert "\n" not in message
    assert "unmeshed at maxh=0.2" in message
    assert "next to the slit (0, 1)–(2, 1)" in message
    maxh = float(message.rsplit("maxh=", 1)[1].split()[0])
    assert maxh < 0.2
    mesh = generate_mesh(band(), maxh)
    assert len(unmeshed_edges(mesh.ngmesh)) == 0
    xy = mesh.ngmesh.Coordinates()
    elements = mesh.ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(int) - 1
    d1, d2 = xy[elements[:, 1]] - xy[elements[:, 0]], xy[elements[:, 2]] - xy[elements[:, 0]]
    assert 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]).sum() == pytest.approx(1.28)
    # The mouth (0, 1) is split: one node per face of the slit.
    assert np.sum(np.hypot(xy[:, 0], xy[:, 1] - 1) < 1e-12) == 2


def test_complete_meshes_have_no_unmeshed_edges():
    from ngat.geometries.two_slits import geometry

    for maxh in (0.5, 0.25):
        mesh = generate_mesh(geometry(), maxh)
        assert len(unmeshed_edges(mesh.ngmesh)) == 0


def _bisected(mesh, rounds=3):
    """Bisect the elements nearest to (3, 3) three times; return coordinates and triangles."""
    for _ in range(rounds):
        xy = mesh.ngmesh.Coordinates()[:, :2]
        elements = mesh.ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(int) - 1
        centre = xy[elements].mean(axis=1)
        mesh.SetRefinementFlags(list(np.hypot(*(centre - 3).T) < 0.5))
        mesh.Refine()
    return mesh.ngmesh.Coordinates(), mesh.ngmesh.Elements2D().NumPy()["nodes"]


def test_scene_meshes_keep_no_face_table_and_bisect_as_with_it():
    # Without the table of faces (ngat.geometry.without_face_table) Netgen's bisection makes
    # the same vertices and triangles; a mesh made outside the block keeps the table.
    scene = load_scene("two-slits")
    lean = scene.make_mesh(0.5)
    assert lean.nface == 0 and lean.nedge > 0
    full = ngsolve.Mesh(lean.ngmesh.Copy())
    assert full.nface == full.ne
    coords, triangles = _bisected(lean)
    assert lean.nface == 0 and lean.ne > 1.5 * full.ne
    expected_coords, expected_triangles = _bisected(full)
    np.testing.assert_array_equal(coords, expected_coords)
    np.testing.assert_array_equal(triangles, expected_triangles)
