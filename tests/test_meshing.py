"""Meshing slit domains: a mesh Netgen leaves incomplete is refused with a maxh that works.

Netgen's surface mesher can leave part of a face without elements and report it only on its
console (e.g. where a slit runs closer to another boundary than ``maxh``); the mouth splitter
then met a fan with a hole in it and ended in an IndexError.
"""

import numpy as np
import pytest

from ngat.geometry import generate_mesh, glue, polygon_face, unmeshed_edges
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
