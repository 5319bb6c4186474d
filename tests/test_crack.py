"""Crack measures on the two-slits mesh with phase fields drawn by hand."""

import numpy as np
import pytest
from ngsolve import H1, GridFunction

import ngat.crack
from ngat.crack import components, connects, crack_tips, mesh_edges, tips_of
from ngat.forms import MeshArrays
from ngat.geometries.two_slits import SLITS
from ngat.parameters import Parameters
from ngat.scene import load_scene
from ngat.state import ATState


@pytest.fixture(scope="module")
def two_slits():
    mesh = load_scene("two-slits").make_mesh(0.25)
    fes = H1(mesh, order=1)
    regions = {
        name: np.array(fes.GetDofs(mesh.Materials(name)), dtype=bool) for name in ("left", "right")
    }
    return MeshArrays(mesh), regions


def band(coords, a, b, half_width):
    """Return v = 0 within ``half_width`` of the segment [a, b], v = 1 elsewhere."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    s = np.clip((coords - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    distance = np.linalg.norm(coords - (a + s[:, None] * (b - a)), axis=1)
    return np.where(distance < half_width, 0.0, 1.0)


def test_mesh_edges_are_unique_and_sorted(two_slits):
    arrays, _ = two_slits
    edges = mesh_edges(arrays.elements)
    assert np.all(edges[:, 0] < edges[:, 1])
    assert len(np.unique(edges, axis=0)) == len(edges)
    # Every edge bounds one or two triangles: 3 ne = 2 (interior edges) + boundary edges.
    all_edges = np.sort(arrays.elements[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(all_edges, axis=0, return_counts=True)
    assert set(counts) == {1, 2} and len(counts) == len(edges)


def test_components_never_cross_a_slit(two_slits):
    arrays, _ = two_slits
    x, y = arrays.coords.T
    # A thin strip hugging both faces of the lower slit, below its tip: two components.
    strip = (np.abs(x - 2) < 0.2) & (y > 0.5) & (y < 1.5)
    labels = components(arrays, strip)
    left = np.unique(labels[strip & (x < 2 - 1e-9)])
    right = np.unique(labels[strip & (x > 2 + 1e-9)])
    assert len(np.intersect1d(left, right)) == 0
    assert np.all(labels[~strip] == -1)


def test_components_of_a_set_asked_again_are_recalled_and_a_new_set_is_labelled_anew(two_slits):
    # A load step tests the sound set for a break: before any crack it is the whole mesh at
    # every step, and is labelled once; a set that changed must not get the old labels.
    arrays, _ = two_slits
    x, y = arrays.coords.T
    whole = np.ones(arrays.nv, dtype=bool)
    first = components(arrays, whole)
    assert components(arrays, whole.copy()) is first and not first.flags.writeable
    cut = ~((np.abs(x - 3) < 0.3) & (y > -1))  # a vertical channel through the whole body
    labels = components(arrays, cut)
    assert len(np.unique(first)) == 1 and len(np.unique(labels[cut])) == 2
    assert np.all(labels[~cut] == -1)


def test_intact_body_has_the_slit_tips_and_connects(two_slits):
    arrays, regions = two_slits
    v = np.ones(arrays.nv)
    assert crack_tips(arrays, v, SLITS) == [(2.0, 2.0), (4.0, 4.0)]
    assert connects(arrays, v, regions["left"], regions["right"])


def test_crack_tip_is_the_end_of_the_band_grown_from_the_slit(two_slits):
    arrays, regions = two_slits
    v = band(arrays.coords, (2, 2), (2.8, 2.8), 0.2)
    # A damaged spot that does not touch any slit changes nothing.
    v = np.minimum(v, band(arrays.coords, (5, 1), (5.3, 1.3), 0.2))
    tips = crack_tips(arrays, v, SLITS)
    assert np.linalg.norm(np.subtract(tips[0], (2.8, 2.8))) < 0.2 + 0.25
    assert np.hypot(*np.subtract(tips[0], (2, 0))) > np.hypot(0.8, 2.8) - 1e-9
    assert tips[1] == (4.0, 4.0)
    assert connects(arrays, v, regions["left"], regions["right"])


def test_crack_tip_lies_on_the_threshold_level_set_between_vertices():
    mesh = load_scene("two-slits").make_mesh(0.25)
    arrays = MeshArrays(mesh)
    along = (arrays.coords - 2) @ np.array([1.0, 1.0]) / np.sqrt(2)
    v_h = GridFunction(H1(mesh, order=1))
    for end in (0.9, 0.93, 0.96):  # the band's end moves by less than an element
        v = np.maximum(band(arrays.coords, (2, 2), (4, 4), 0.3), np.clip(along - end, 0, 1))
        v_h.vec.FV().NumPy()[:] = v
        (x, y), _ = crack_tips(arrays, v, SLITS)
        assert abs(v_h(mesh(x, y)) - 0.1) < 1e-9  # on the level set, not at a vertex
        # v_h is linear along the band's axis there: the tip follows the end continuously.
        assert abs((x + y - 4) / np.sqrt(2) - (end + 0.1)) < 0.3, (x, y)


def test_joined_cracks_break_the_body(two_slits):
    arrays, regions = two_slits
    v = band(arrays.coords, (2, 2), (4, 4), 0.2)
    assert not connects(arrays, v, regions["left"], regions["right"])
    tips = crack_tips(arrays, v, SLITS)
    # Each slit's crack now ends at the other slit's tip.
    assert np.linalg.norm(np.subtract(tips[0], (4, 4))) < 0.45
    assert np.linalg.norm(np.subtract(tips[1], (2, 2))) < 0.45


def test_a_slit_is_a_cut_of_the_sound_set(two_slits):
    arrays, regions = two_slits
    # A band from the lower slit's tip to the top: with the slit it cuts the body in two...
    v = band(arrays.coords, (2, 2), (2, 6), 0.2)
    assert not connects(arrays, v, regions["left"], regions["right"])
    # ...but a gap of a few elements between band and slit tip leaves it whole.
    v = band(arrays.coords, (2, 3), (2, 6), 0.2)
    assert connects(arrays, v, regions["left"], regions["right"])


def test_threshold_decides_what_is_cracked(two_slits):
    arrays, regions = two_slits
    v = 0.5 * band(arrays.coords, (2, 2), (4, 4), 0.2) + 0.05
    assert not connects(arrays, v, regions["left"], regions["right"], threshold=0.1)
    assert connects(arrays, v, regions["left"], regions["right"], threshold=0.01)


def test_tips_of_measures_each_v_once_per_mesh(monkeypatch):
    scene = load_scene("two-slits")
    state = ATState(scene.make_mesh(0.5), Parameters().model, scene.loads)
    measured = []
    monkeypatch.setattr(
        ngat.crack, "crack_tips", lambda *args: measured.append(1) or crack_tips(*args)
    )
    state.v_values[:] = band(state.arrays.coords, (2, 2), (2.8, 2.8), 0.2)
    first = tips_of(state, SLITS)
    assert first == crack_tips(state.arrays, state.v_values, SLITS)
    assert np.hypot(*np.subtract(first[0], (2.8, 2.8))) < 0.2 + 0.5
    assert tips_of(state, SLITS) == first and len(measured) == 1
    state.v_values[:] = 1.0  # another v: measured anew
    assert tips_of(state, SLITS) == [(2.0, 2.0), (4.0, 4.0)] and len(measured) == 2
    state.mesh.Refine()  # another mesh with the same (prolongated) v: measured anew
    state.mesh_changed()
    assert tips_of(state, SLITS) == [(2.0, 2.0), (4.0, 4.0)] and len(measured) == 3
