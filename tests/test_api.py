"""The one-call Python API: ``ngat.run`` and ``ngat.load_results``."""

import logging

import numpy as np
import pytest

import ngat
from ngat import minimization
from ngat.output import OutputError
from ngat.parameters import ParameterError


def test_run_then_load_results_gives_the_same_records(tiny_run, tmp_path):
    scene, parameters = tiny_run
    steps = []
    result = ngat.run(scene, out=tmp_path / "r", plots=False, on_step=steps.append, **parameters)
    assert result.folder == tmp_path / "r"
    assert len(result.records) == len(steps) == 5
    assert result.summary["status"] == "completed"
    assert result.summary["parameters"]["eps"] == 0.2
    columns = result.columns
    assert columns["step"].tolist() == [0, 1, 2, 3, 4]
    assert columns["converged"].dtype == bool
    assert columns["total"].dtype == float and np.all(np.diff(columns["total"]) > 0)

    loaded = ngat.load_results(tmp_path / "r")
    assert loaded.records == result.records
    assert [type(v) for v in loaded.records[-1].values()] == [
        type(v) for v in result.records[-1].values()
    ]
    assert loaded.summary == result.summary
    assert loaded.state is None
    for name, column in columns.items():
        np.testing.assert_array_equal(loaded.columns[name], column, err_msg=name)
    fields = loaded.fields
    assert fields.field_data["t"][0] == 1.6
    assert {"u", "v"} <= set(fields.point_data)
    np.testing.assert_array_equal(fields.point_data["v"], result.fields.point_data["v"])
    assert np.isclose(fields.point_data["v"].min(), result.state.v_values.min(), atol=1e-6)


def test_scene_by_name_and_parameters_as_strings_as_on_the_command_line(tmp_path):
    result = ngat.run("profile-1d", out=tmp_path / "p", quick=True, eps="0.05", plots=False)
    assert result.summary["scene"] == "profile-1d"
    assert result.summary["parameters"]["maxh"] == 0.03  # the quick variant


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"epsilon": 0.1}, "did you mean 'eps'"),
        ({"eps": "small"}, "'eps' needs a value of type float"),
        ({"eps": -1}, "eps must be positive"),
        ({"am_max_iter": 2.5}, "'am_max_iter' needs a value of type int"),
        ({"overwrite": True, "resume": True}, "exclude each other"),
    ],
)
def test_bad_parameters_are_refused_before_anything_is_written(tmp_path, changes, words):
    with pytest.raises(ParameterError, match=words):
        ngat.run("profile-1d", out=tmp_path / "x", **changes)
    assert not (tmp_path / "x").exists()


def test_a_folder_holding_a_run_needs_overwrite_and_a_finished_run_needs_no_resume(
    tiny_run, tmp_path
):
    scene, parameters = tiny_run
    folder = tmp_path / "r"
    first = ngat.run(scene, out=folder, plots=False, **parameters)
    with pytest.raises(OutputError, match="already holds a run"):
        ngat.run(scene, out=folder, plots=False, **parameters)
    again = ngat.run(scene, out=folder, resume=True, plots=False, **parameters)
    assert again.state is None  # nothing computed: read back from the folder
    assert again.records == first.records
    replaced = ngat.run(scene, out=folder, overwrite=True, plots=False, **parameters)
    assert replaced.state is not None


def test_load_results_of_a_folder_without_a_run(tmp_path):
    with pytest.raises(OutputError, match="holds no results of a run"):
        ngat.load_results(tmp_path)


def test_ngat_run_is_the_api_and_ngat_driver_run_the_loop():
    import ngat.cli
    import ngat.driver
    import ngat.experiment

    assert ngat.run is ngat.experiment.run
    assert ngat.driver.run is not ngat.run


def test_a_long_load_step_logs_where_it_stands(tiny_run, tmp_path, caplog, monkeypatch):
    monkeypatch.setattr(minimization, "PROGRESS_EVERY", 2)
    scene, parameters = tiny_run
    with caplog.at_level(logging.INFO, logger="ngat.minimization"):
        result = ngat.run(scene, out=tmp_path / "r", plots=False, **parameters)
    lines = [r.getMessage() for r in caplog.records if r.name == "ngat.minimization"]
    assert len(lines) == sum(r["am_iterations"] // 2 for r in result.records) > 0
    first = next(r for r in result.records if r["am_iterations"] >= 2)
    assert lines[0].startswith(f"t={first['t']:g}: iteration 2, ‖Δv‖∞ = ")
    assert lines[0].endswith(" elements")
