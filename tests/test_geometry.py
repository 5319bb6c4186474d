"""Slits are true cracks: u jumps across every slit node, mouth included, also after refinement."""

import numpy as np
import pytest

from ngat.halfsteps import HalfStepSolvers
from ngat.parameters import ModelParameters
from ngat.scene import load_scene
from ngat.state import ATState


@pytest.mark.parametrize("rounds", [0, 2])
def test_u_jumps_across_every_slit_node(rounds):
    scene = load_scene("two-slits")
    mesh = scene.make_mesh(0.5)
    for _ in range(rounds):
        mesh.Refine()
    state = ATState(mesh, ModelParameters(), {"left": lambda t: -t, "right": lambda t: t})
    steps = HalfStepSolvers(state)
    state.apply_load(1.0)
    steps.solve_u()
    coords, u = state.arrays.coords, state.u_values
    x, y = coords[:, 0], coords[:, 1]
    for slit, tip in [((x == 2) & (y < 2), (2, 2)), ((x == 4) & (y > 4), (4, 4))]:
        nodes = np.flatnonzero(slit)
        keys, inverse, counts = np.unique(
            np.round(coords[nodes], 9), axis=0, return_inverse=True, return_counts=True
        )
        # Every slit point except the tip has exactly two nodes, the mouth among them.
        assert np.all(counts == 2), f"slit points with a single node: {keys[counts != 2]}"
        assert np.any(np.isclose(keys[:, 1], 0) | np.isclose(keys[:, 1], 6)), "mouth missing"
        jumps = np.zeros(len(keys))
        np.maximum.at(jumps, inverse, u[nodes])
        low = np.full(len(keys), np.inf)
        np.minimum.at(low, inverse, u[nodes])
        assert np.all(jumps - low > 0.05), "u does not jump across some slit node"
        assert len(np.flatnonzero(np.all(np.isclose(coords, tip), axis=1))) == 1


def test_dirichlet_region_is_a_material():
    scene = load_scene("two-slits")
    mesh = scene.make_mesh(0.5)
    assert {"left", "right", "body"} == set(mesh.GetMaterials())
    state = ATState(mesh, ModelParameters(), scene.loads)
    left = state.region_dofs["left"]
    assert np.all(state.arrays.coords[left, 0] <= 1e-12)
    assert np.isclose(state.arrays.coords[left, 0].min(), -0.5)


@pytest.mark.parametrize("name", ["two-slits", "sent", "profile-1d"])
def test_region_vertices_are_the_dofs_ngsolve_gives_the_regions(name):
    # The loads' regions (materials of two-slits, boundaries of sent, a boundary of the 1-D
    # profile) and a crack named by a region come from the element arrays; they must be the
    # DOFs of fes.GetDofs.
    scene = load_scene(name)
    parameters, _ = scene.configure(quick=True)
    mesh = scene.make_mesh(parameters.adaptivity.maxh)
    mesh.Refine()
    state = ATState(mesh, parameters.model, scene.loads, scene.crack)
    for region in scene.loads:
        kind = mesh.Materials if region in mesh.GetMaterials() else mesh.Boundaries
        expected = np.array(state.fes.GetDofs(kind(region)), dtype=bool)
        np.testing.assert_array_equal(state.region_vertices[region], expected)
        assert expected.any() and not expected.all()
        # A scene's crack given as a region's name: v = 0 there from the start.
        cracked = ATState(mesh, parameters.model, scene.loads, region)
        np.testing.assert_array_equal(cracked.initial_crack, expected)
