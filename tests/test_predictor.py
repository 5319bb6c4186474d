"""The linear predictor of v across load steps (ngat.minimization.predict_v)."""

import numpy as np
import pytest

from ngat import driver
from ngat.driver import run
from ngat.halfsteps import HalfStepSolvers
from ngat.minimization import PREDICTOR_MAX, predict_v
from ngat.parameters import ModelParameters
from ngat.scene import load_scene
from ngat.state import ATState


def two_slits_state(irreversibility="crtol"):
    scene = load_scene("two-slits")
    model = ModelParameters(eps=0.2, irreversibility=irreversibility)
    return ATState(scene.make_mesh(0.5), model, scene.loads, scene.crack)


def test_prediction_is_the_clipped_extrapolation():
    state = two_slits_state()
    rng = np.random.default_rng(0)
    v_prev = rng.uniform(0.0, 1.0, state.arrays.nv)
    v_prev[:4] = (0.01, 0.99, 0.5, 0.5)
    change = rng.uniform(-0.02, 0.02, state.arrays.nv)
    state.v_prev.vec.FV().NumPy()[:] = v_prev
    state.v_values[:] = v_prev
    change[:2] = (-0.02, 0.02)  # extrapolated past 0 and 1
    state.v_change.vec.FV().NumPy()[:] = change
    assert predict_v(state, 2.0)
    assert np.array_equal(state.v_values, np.clip(v_prev + 2.0 * change, 0.0, 1.0))
    assert (state.v_values == 0.0).any() and (state.v_values == 1.0).any()


def test_pointwise_irreversibility_caps_the_prediction_at_the_last_v():
    state = two_slits_state("pointwise")
    v_prev = np.full(state.arrays.nv, 0.5)
    state.v_prev.vec.FV().NumPy()[:] = v_prev
    state.v_values[:] = v_prev
    change = np.where(np.arange(state.arrays.nv) % 2 == 0, 0.02, -0.02)
    state.v_change.vec.FV().NumPy()[:] = change
    assert predict_v(state, 1.0)
    assert np.array_equal(state.v_values, np.minimum(v_prev + change, v_prev))


@pytest.mark.parametrize("largest", [0.0, 2 * PREDICTOR_MAX])
def test_no_prediction_without_a_trend_or_after_a_jump(largest):
    state = two_slits_state()
    state.v_change.vec.FV().NumPy()[:] = 0.0
    state.v_change.vec.FV().NumPy()[0] = -largest
    before = state.v_values.copy()
    assert not predict_v(state, 1.0)
    assert np.array_equal(state.v_values, before)


def test_predicted_steps_end_where_the_paper_start_ends_in_fewer_solves(tmp_path):
    # Load steps of Δt = 0.02 before the cracks grow (eps = 0.2, fixed coarse mesh): each step
    # converges to the same critical point within the stopping tolerance, from either start.
    scene = load_scene("two-slits")
    times = np.round(np.arange(0.0, 1.01, 0.02), 10)
    runs = {}
    for predictor in (True, False):
        parameters, _ = scene.configure(
            overrides={
                "eps": 0.2,
                "maxh": 0.25,
                "adapt": "fixed",
                "resolve_eps": False,
                "predictor": predictor,
            }  # fmt: skip
        )
        runs[predictor] = run(scene, parameters, times, tmp_path / str(predictor)).records
    solves = {key: sum(r["linear_solves"] for r in records) for key, records in runs.items()}
    assert solves[True] < 0.7 * solves[False], solves
    for ours, theirs in zip(runs[True], runs[False], strict=True):
        assert ours["total"] == pytest.approx(theirs["total"], rel=1e-4, abs=1e-12)


def test_the_next_steps_start_prepared_in_the_background_changes_no_bit(tmp_path, monkeypatch):
    # The driver factorises a_j at the next step's (predicted) start while it writes a step;
    # each step's first u-step claims that factorisation, and every number is as without it.
    scene = load_scene("two-slits")
    times = np.round(np.arange(0.0, 0.41, 0.04), 10)
    parameters, _ = scene.configure(
        overrides={"eps": 0.2, "maxh": 0.25, "adapt": "fixed", "resolve_eps": False}
    )
    claims = []
    claim = HalfStepSolvers._claim

    def counted(self, stage, *inputs):
        claimed = claim(self, stage, *inputs)
        claims.append((stage, claimed))
        return claimed

    def step(*args, **kwargs):
        claims.append(("start", False))
        return minimize(*args, **kwargs)

    minimize = driver.alternating_minimization
    monkeypatch.setattr(HalfStepSolvers, "_claim", counted)
    monkeypatch.setattr(driver, "alternating_minimization", step)
    prepared = run(scene, parameters, times, tmp_path / "prepared").records
    first_u = [
        next(claimed for stage, claimed in claims[i + 1 :] if stage == "u")
        for i, (stage, _) in enumerate(claims)
        if stage == "start"
    ]
    monkeypatch.setattr(driver, "prepare_next_step", lambda *args: None)
    plain = run(scene, parameters, times, tmp_path / "plain").records
    # Every step after the first starts from the prepared factorisation.
    assert first_u == [False] + [True] * (len(times) - 1)
    for ours, theirs in zip(prepared, plain, strict=True):
        for key in ("bulk", "surface", "total", "force", "mu", "nu", "linear_solves"):
            assert ours[key] == theirs[key], key
