"""The SENT scene: Dirichlet data per component on edges, reaction forces, equilibrium."""

import numpy as np
import pytest

from ngat.driver import run
from ngat.halfsteps import HalfStepSolvers
from ngat.results import read_records
from ngat.scene import load_scene
from ngat.state import ATState


@pytest.fixture(scope="module")
def elastic_records(tmp_path_factory):
    # The elastic branch of the quick variant on its initial mesh (no refinement; the crack
    # does not move, so the coarse notch tip is under-resolved on purpose).
    scene = load_scene("sent")
    overrides = {"adapt": "fixed", "resolve_eps": False}
    parameters, _ = scene.configure(quick=True, overrides=overrides)
    times = np.array([0.0, 1e-3, 2e-3, 3e-3])
    return run(scene, parameters, times, tmp_path_factory.mktemp("sent")).records


def test_top_edge_holds_only_u_y():
    scene = load_scene("sent")
    parameters, _ = scene.configure(quick=True)
    state = ATState(scene.make_mesh(0.1), parameters.model, scene.loads)
    steps = HalfStepSolvers(state)
    state.apply_load(2e-3)
    steps.solve_u()
    nv = state.arrays.nv
    top, bottom = state.region_vertices["top"], state.region_vertices["bottom"]
    ux, uy = state.u_values[:nv], state.u_values[nv:]
    np.testing.assert_array_equal(uy[top], 2e-3)
    np.testing.assert_array_equal(ux[bottom], 0.0)
    np.testing.assert_array_equal(uy[bottom], 0.0)
    # u_x is free on the top edge: the Poisson contraction moves it.
    assert np.ptp(ux[top]) > 1e-5
    assert set(steps.operators.reaction_forces()) == {
        "force_bottom_x", "force_bottom_y", "force_top_y", "force",
    }  # fmt: skip


def test_reactions_balance(elastic_records):
    # Up to the last v-step's change (the reactions use u of the step before it, am_tol).
    for record in elastic_records[1:]:
        scale = abs(record["force_top_y"])
        assert record["force_top_y"] > 0
        assert record["force_bottom_y"] == pytest.approx(-record["force_top_y"], rel=1e-4)
        assert abs(record["force_bottom_x"]) < 1e-4 * scale
        assert record["force"] == pytest.approx(record["force_top_y"], rel=1e-12)


def test_force_is_the_derivative_of_the_energy(elastic_records):
    # Before the crack moves, dI/dt = F (the trapezoidal rule on F, exact for linear F).
    t = np.array([r["t"] for r in elastic_records])
    total = np.array([r["total"] for r in elastic_records])
    force = np.array([r["force_top_y"] for r in elastic_records])
    np.testing.assert_allclose(np.diff(total), np.diff(t) * (force[1:] + force[:-1]) / 2, rtol=0.02)


class _Stop(Exception):
    pass


def test_resumed_plane_strain_run_equals_the_uninterrupted_one(tmp_path):
    # Checkpoints carry the vector u (both components), v and the adaptive mesh: a quick SENT
    # run stopped after its second load step and resumed writes the same rows, bit for bit.
    scene = load_scene("sent")
    parameters, _ = scene.configure(quick=True)
    times = np.array([0.0, 2e-3, 3e-3, 4e-3])
    run(scene, parameters, times, tmp_path / "whole")

    def stop(record):
        if record["step"] == 2:
            raise _Stop

    with pytest.raises(_Stop):
        run(scene, parameters, times, tmp_path / "cut", on_step=stop)
    run(scene, parameters, times, tmp_path / "cut", resume=True)
    whole, cut = (read_records(tmp_path / name / "energies.csv") for name in ("whole", "cut"))
    assert len(whole) == len(cut) == len(times)
    assert any(row["refinements"] != 0 for row in whole), "the run should refine"
    for ours, theirs in zip(cut, whole, strict=True):
        ours.pop("wall_s"), theirs.pop("wall_s")
        assert ours == theirs
