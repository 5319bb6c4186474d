"""Detection (issue 6): each problem fires on a case built for it, quiet on the quick run."""

import json

import numpy as np
import pytest

from ngat.checkpoint import load_checkpoint
from ngat.diagnostics import ProblemError
from ngat.driver import run
from ngat.geometries.obtuse_line import scene as OBTUSE
from ngat.halfsteps import HalfStepSolvers
from ngat.minimization import ConvergenceError, iteration_limit
from ngat.parameters import ParameterError
from ngat.scene import load_scene
from ngat.state import ATState


def problems(folder):
    return {p["kind"] for p in json.loads((folder / "summary.json").read_text())["diagnostics"]}


def test_quiet_on_the_quick_run(quick_run):
    result, _, folder = quick_run
    assert problems(folder) == set()
    assert all(r["warnings"] == "" for r in result.records)


def test_v_out_of_bounds_without_hypothesis_a(tmp_path):
    # Obtuse triangles: the unconstrained v-step overshoots 1 next to the line v = 0.
    parameters, times = OBTUSE.configure(overrides={"bounded_v": False})
    result = run(OBTUSE, parameters, times, tmp_path / "free")
    assert result.records[-1]["v_max"] > 1.01
    assert "v-out-of-bounds" in problems(tmp_path / "free")
    # The bounded v-step keeps v in [0, 1] on the same mesh and reports nothing.
    parameters, times = OBTUSE.configure()
    result = run(OBTUSE, parameters, times, tmp_path / "bounded")
    assert result.records[-1]["v_max"] <= 1 + 1e-12
    assert result.records[-1]["v_bound_active"] > 0
    assert "v-out-of-bounds" not in problems(tmp_path / "bounded")


def test_v_out_of_bounds_without_lumping(tmp_path):
    # Non-obtuse aligned mesh, h = 10 ε: the lumped v-step keeps 0 ≤ v ≤ 1, the consistent
    # mass overshoots by 30 % at the side walls (tests/test_lumping.py) and is detected.
    scene = load_scene("profile-1d")
    changes = {"adapt": "fixed", "maxh": 0.1, "eps": 0.01, "bounded_v": False, "nonlinear": "am"}
    changes["resolve_eps"] = False  # h = 10 ε on purpose
    for lumping in (True, False):
        parameters, times = scene.configure(overrides={**changes, "lumping": lumping})
        result = run(scene, parameters, times, tmp_path / str(lumping))
        assert ("v-out-of-bounds" in problems(tmp_path / str(lumping))) is not lumping
    assert result.records[-1]["v_max"] == pytest.approx(1.2997450, abs=1e-6)
    messages = [
        p["message"] for p in result.summary["diagnostics"] if p["kind"] == "v-out-of-bounds"
    ]
    assert "lumping=false" in messages[0]
    # On the obtuse mesh it fires with and without lumping.
    parameters, times = OBTUSE.configure(
        overrides={"bounded_v": False, "lumping": False, "nonlinear": "am"}
    )
    result = run(OBTUSE, parameters, times, tmp_path / "obtuse")
    assert result.records[-1]["v_max"] == pytest.approx(1.0294994, abs=1e-6)
    assert "v-out-of-bounds" in problems(tmp_path / "obtuse")


def coarse_two_slits(**overrides):
    scene = load_scene("two-slits")
    changes = {"adapt": "fixed", "maxh": 0.5, "resolve_eps": False, **overrides}
    parameters, _ = scene.configure(overrides=changes)
    return scene, parameters, np.array([0.0, 1.5])


def test_not_converged(tmp_path):
    scene, parameters, times = coarse_two_slits(am_max_iter=2, eps=1.0)
    result = run(scene, parameters, times, tmp_path / "run")
    assert not result.records[-1]["converged"]
    assert problems(tmp_path / "run") == {"not-converged"}
    assert "not-converged" in result.records[-1]["warnings"]
    message = result.summary["diagnostics"][0]["message"]
    assert "(2 iterations)" in message and "--set am_max_iter=4" in message


def test_default_iteration_limit_grows_as_one_over_eps():
    # Ten iterations per ε of the bounding box's diagonal, sqrt(7² + 6²) = 9.22, at least 1000.
    scene = load_scene("two-slits")
    mesh = scene.make_mesh(0.5)
    limits = {}
    for eps in (0.5, 0.05, 0.0125):
        parameters, _ = scene.configure(overrides={"eps": eps})
        state = ATState(mesh, parameters.model, scene.loads, scene.crack)
        limits[eps] = iteration_limit(state, parameters.solver)
    assert limits == {0.5: 1000, 0.05: 1844, 0.0125: 7376}
    parameters, _ = scene.configure(overrides={"eps": 0.0125, "am_max_iter": 30})
    assert iteration_limit(state, parameters.solver) == 30


def test_eps_under_resolved(tmp_path):
    # ε = 0.2 on the initial mesh (elements up to 0.5): the crack band is not resolved.
    scene, parameters, _ = coarse_two_slits(eps=0.2)
    result = run(scene, parameters, np.array([0.0, 1.5, 2.5]), tmp_path / "run")
    assert result.records[-1]["v_min"] < 0.1
    assert problems(tmp_path / "run") == {"eps-under-resolved"}


def test_eps_under_resolved_before_any_crack(tmp_path):
    # Elements 5ε wide: the body never cracks (min v stays near 0.7, {v < 0.1} is empty), and
    # the too coarse mesh at the most damaged point must still be named.
    scene = load_scene("two-slits")
    parameters, _ = scene.configure(
        overrides={"adapt": "fixed", "maxh": 0.25, "resolve_eps": False}
    )
    result = run(scene, parameters, np.array([0.0, 1.0, 1.6]), tmp_path / "run")
    assert 0.1 < result.records[-1]["v_min"] < 0.9
    assert problems(tmp_path / "run") == {"eps-under-resolved"}
    assert "most damaged point" in (tmp_path / "run" / "run.log").read_text()


def test_newton_without_lumping_is_refused():
    for solver in ("newton", "anderson-newton"):
        with pytest.raises(ParameterError, match="needs lumping=true.*lumping=false set"):
            OBTUSE.configure(overrides={"lumping": False, "nonlinear": solver})


def test_energy_increase_is_detected(tmp_path, monkeypatch):
    # A broken v-step (it adds noise after solving) makes an iteration increase I_j.
    solve_v = HalfStepSolvers.solve_v

    def noisy(self, crack):
        solve_v(self, crack)
        v = self.state.v_values
        rng = np.random.default_rng(len(v))
        v[~crack] = np.clip(v[~crack] - 0.2 * rng.random((~crack).sum()), 0, 1)

    monkeypatch.setattr(HalfStepSolvers, "solve_v", noisy)
    scene, parameters, times = coarse_two_slits(am_max_iter=5, eps=0.5)
    run(scene, parameters, times, tmp_path / "run")
    assert "energy-increase" in problems(tmp_path / "run")


def test_nan_stops_the_run_and_is_named(tmp_path, monkeypatch):
    solve_u = HalfStepSolvers.solve_u

    def poisoned(self):
        solve_u(self)
        if self.state.t.Get() > 1:
            self.state.u_values[0] = np.nan

    monkeypatch.setattr(HalfStepSolvers, "solve_u", poisoned)
    scene, parameters, times = coarse_two_slits(eps=0.5)
    with pytest.raises(ConvergenceError):
        run(scene, parameters, times, tmp_path / "run")
    assert problems(tmp_path / "run") == {"nan"}
    rows = (tmp_path / "run" / "energies.csv").read_text().strip().splitlines()
    assert len(rows) == 2, "the step before the NaN is kept"


def test_on_problem_error_stops_after_writing_the_step_and_its_checkpoint(tmp_path):
    scene, parameters, _ = coarse_two_slits(
        am_max_iter=2, eps=1.0, on_problem="error", checkpoint_every=1e9
    )
    with pytest.raises(ProblemError, match="not-converged"):
        run(scene, parameters, np.array([0.0, 1.5, 1.6]), tmp_path / "run")
    rows = (tmp_path / "run" / "energies.csv").read_text().strip().splitlines()
    assert len(rows) == 3
    # Long before the next checkpoint is due, but the error ends the run: its step is kept.
    assert load_checkpoint(tmp_path / "run").step == 1
