"""Re-meshing about crack tips (ngat/remesh.py): Netgen's own elements of ε in a disc about the
tip, a conforming mesh, the fields carried over, and a resumed run that replays the patches.
"""

import csv

import numpy as np
import pytest
from netgen.geom2d import unit_square
from ngsolve import Mesh

from ngat.driver import run
from ngat.geometries import surfing
from ngat.geometry import unmeshed_edges
from ngat.parameters import ModelParameters, ParameterError, Parameters
from ngat.remesh import Patch, TipRemesher, mesh_region, splice
from ngat.state import ATState

EPS = 0.03


def smooth(coords):
    """A smooth field of the order of 1 (its P1 interpolant is carried over by the patch)."""
    return 1 - 0.2 * np.sin(4 * coords[:, 0]) * np.cos(3 * coords[:, 1])


def surfing_state():
    """The unstructured surfing mesh of maxh = 10ε, a crack band bisected along y = 0 up to
    x = 0.7 with v = 0 on it, and u, v_prev smooth elsewhere."""
    scene = surfing.make_scene(eps=EPS, structured=False)
    mesh = scene.make_mesh(10 * EPS)
    state = ATState(mesh, ModelParameters(eps=EPS), scene.loads)
    for _ in range(12):
        arrays = state.arrays
        centroid = arrays.coords[arrays.elements].mean(axis=1)
        near = (np.abs(centroid[:, 1]) < 2 * EPS + arrays.diameter) & (centroid[:, 0] < 0.72)
        marked = near & (arrays.diameter > 0.25 * EPS)
        if not marked.any():
            break
        state.mesh.SetRefinementFlags(marked.tolist())
        state.mesh.Refine()
        state.mesh_changed()
    coords = state.arrays.coords
    crack = (np.abs(coords[:, 1]) < 0.3 * EPS) & (coords[:, 0] > 0.6) & (coords[:, 0] < 0.7)
    state.v_values[:] = smooth(coords)
    state.v_values[crack] = 0.0
    state.v_prev.vec.data = state.v.vec
    state.u_values[:] = smooth(coords[:, ::-1])
    return scene, state


def test_the_disc_ahead_of_the_tip_gets_netgen_elements_of_eps_and_the_rest_is_kept():
    scene, state = surfing_state()
    keys = list(map(tuple, state.arrays.coords))
    before = {
        name: dict(zip(keys, getattr(state, name).vec.FV().NumPy(), strict=True))
        for name in ("u", "v", "v_prev")
    }
    area = state.arrays.area.sum()
    old_mesh, old_fields = state.mesh, {name: getattr(state, name) for name in ("u", "v", "v_prev")}
    remesher = TipRemesher(EPS, scene.slits, radius=10.0)
    assert remesher.remesh(state) == 1
    (patch,) = state.patches
    assert abs(patch.centre[0] - 0.7) < EPS and abs(patch.centre[1]) < EPS
    # A conforming mesh of the same domain.
    assert len(unmeshed_edges(state.mesh.ngmesh)) == 0
    assert abs(state.arrays.area.sum() - area) < 1e-12 * area
    assert set(state.mesh.GetMaterials()) == {"frame", "body"}
    # Netgen's own elements of about ε in the disc ahead of the tip.
    coords, elements = state.arrays.coords, state.arrays.elements
    centroid = coords[elements].mean(axis=1)
    ahead = centroid - patch.centre
    distance = np.linalg.norm(ahead, axis=1)
    inside = (distance > 2 * EPS) & (distance < 8 * EPS) & (ahead[:, 0] > 0)
    assert inside.sum() > 100
    assert np.median(state.arrays.diameter[inside]) == pytest.approx(EPS, rel=0.3)
    assert state.arrays.diameter[inside].max() < 1.6 * EPS
    # Kept vertices keep their values exactly, new ones take the P1 fields of the old mesh.
    inner = ~state.boundary_vertices  # the old fields are not single-valued on a slit
    points = old_mesh(coords[inner, 0], coords[inner, 1])
    for name, field in old_fields.items():
        values = getattr(state, name).vec.FV().NumPy()
        old = before[name]
        kept = np.array([tuple(c) in old for c in coords])
        assert 0.3 * len(coords) < kept.sum() < len(coords)
        free = kept & ~state.dirichlet  # u = g(t) on Ω_D is set anew
        assert all(values[i] == old[tuple(coords[i])] for i in np.flatnonzero(free)), name
        interpolant = np.asarray(field(points)).ravel()
        assert np.abs(values[inner] - interpolant)[~state.dirichlet[inner]].max() < 1e-12, name
    # The crack's elements stay where they were: its damaged vertices are all kept.
    assert (state.v_values < 0.5).sum() == sum(1 for value in before["v"].values() if value < 0.5)
    # The disc is Netgen's now: the same tip does not re-mesh again.
    assert remesher.remesh(state) == 0


def test_a_slit_tip_that_has_not_cracked_keeps_its_mesh():
    # Before its crack grows, a slit tip keeps the graded mesh the estimators give its
    # singularity (Netgen's ε there would reset the bisection levels the element floor counts).
    scene, state = surfing_state()
    coords = state.arrays.coords
    state.v_values[:] = smooth(coords)
    state.v_prev.vec.data = state.v.vec
    elements = state.mesh.ne
    assert TipRemesher(EPS, scene.slits, radius=10.0).remesh(state) == 0
    assert state.mesh.ne == elements and not state.patches


def test_a_divided_boundary_edge_splits_the_element_outside_it():
    """Next to much smaller elements Netgen divides the region's boundary; the outside
    element takes the new points through a fan, so no edge hangs."""
    mesh = Mesh(unit_square.GenerateMesh(maxh=0.1))
    for _ in range(10):
        coords = mesh.ngmesh.Coordinates()[:, :2]
        elements = mesh.ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(np.int64) - 1
        centroid = coords[elements].mean(axis=1)
        long = np.linalg.norm(coords[elements[:, 1]] - coords[elements[:, 0]], axis=1) > 0.01
        mesh.SetRefinementFlags((long & (np.abs(centroid[:, 0] - 0.45) < 0.05)).tolist())
        mesh.Refine()
    coords = mesh.ngmesh.Coordinates()[:, :2]
    elements = mesh.ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(np.int64) - 1
    centroid = coords[elements].mean(axis=1)
    region = (centroid[:, 0] > 0.52) & (centroid[:, 0] < 0.9) & (np.abs(centroid[:, 1] - 0.5) < 0.3)
    points, triangles, removed = mesh_region(coords, elements, region, h=0.05)
    assert (removed & ~region).any(), "no boundary edge was divided: the case tests nothing"
    new, old_vertex = splice(mesh, Patch(np.flatnonzero(removed), points, triangles, 1,
                                         np.array([0.7, 0.5]), 0.3))  # fmt: skip
    assert len(unmeshed_edges(new.ngmesh)) == 0
    xy = new.ngmesh.Coordinates()[:, :2]
    cells = new.ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(np.int64) - 1
    e1, e2 = xy[cells[:, 1]] - xy[cells[:, 0]], xy[cells[:, 2]] - xy[cells[:, 0]]
    d = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    assert abs(np.abs(d).sum() / 2 - 1.0) < 1e-12
    assert (np.sign(d) == np.sign(d[0])).all(), "the new elements are oriented as the old"
    assert (old_vertex >= 0).sum() < len(coords)


def test_remesh_radius_must_be_a_non_negative_number():
    with pytest.raises(ParameterError, match="remesh_radius"):
        Parameters().replace(remesh_radius=-1.0)


def read_rows(folder):
    with open(folder / "energies.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_a_resumed_run_replays_the_patches_and_ends_as_an_uninterrupted_run(tmp_path):
    dt = 2 * EPS / 0.4
    times = np.round(dt * np.arange(1, 6), 12)
    g_eff = surfing.effective_toughness(0.25 * EPS / np.sqrt(2), EPS)
    scene = surfing.make_scene(
        amplitude=np.sqrt(1.2 * g_eff), speed=0.4, ramp=0.05, eps=EPS, times=times,
        structured=False, half_width=6 * EPS, name="surfing-remesh",
    )  # fmt: skip
    parameters, times = scene.configure(overrides={"maxh": 10 * EPS, "remesh_radius": 10.0})
    reference = run(scene, parameters, times, tmp_path / "reference").records
    remeshed = [r["step"] for r in reference if r["remeshed"]]
    assert len(remeshed) >= 2 and remeshed[-1] >= 2, remeshed
    assert reference[-1]["tip1_x"] > surfing.CRACK_LENGTH + 5 * EPS, "the crack did not run"

    def interrupt(record):
        if record["step"] == 1:
            raise KeyboardInterrupt

    folder = tmp_path / "interrupted"
    with pytest.raises(KeyboardInterrupt):
        run(scene, parameters, times, folder, on_step=interrupt)
    run(scene, parameters, times, folder, resume=True)
    expected, resumed = read_rows(tmp_path / "reference"), read_rows(folder)
    assert len(resumed) == len(expected)
    for ours, theirs in zip(resumed, expected, strict=True):
        for column in ("total", "surface", "elements", "tip1_x", "remeshed", "am_iterations"):
            assert float(ours[column]) == pytest.approx(float(theirs[column]), rel=1e-12, abs=0)
