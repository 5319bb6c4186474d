"""Pictures come with the run: ``ngat run`` and ``ngat.run`` draw them when the run ends, however
it ends; ``ngat plot`` keeps one set of snapshots."""

import logging

import pytest
from matplotlib.image import imread

import ngat
import ngat.plotting
from ngat.cli import main

PICTURES = ["energies.png", "v_final.png", "mesh_final.png", "mesh_zoom.png"]


def assert_picture(path):
    assert path.exists(), path
    pixels = imread(path)[..., :3]
    assert pixels.std() > 0.02, f"{path.name} is (nearly) one colour"


def stop_at_step(k, error):
    def on_step(record):
        if record["step"] == k:
            raise error

    return on_step


def test_quick_run_leaves_the_pictures_unless_told_not_to(tmp_path):
    out = tmp_path / "p"
    assert main(["run", "profile-1d", "--quick", "--quiet", "--out", str(out)]) == 0
    for name in PICTURES:
        assert_picture(out / name)
    bare = tmp_path / "bare"
    assert main(["run", "profile-1d", "--quick", "--quiet", "--no-plots", "--out", str(bare)]) == 0
    assert not list(bare.glob("*.png"))


@pytest.mark.parametrize("error", [RuntimeError("the run broke"), KeyboardInterrupt()])
def test_failed_or_interrupted_run_draws_what_it_has_and_keeps_its_error(tiny_run, tmp_path, error):
    scene, parameters = tiny_run
    out = tmp_path / "r"
    with pytest.raises(type(error)) as raised:
        ngat.run(scene, out=out, on_step=stop_at_step(2, error), **parameters)
    assert raised.value is error
    assert len(ngat.load_results(out).records) == 3
    for name in PICTURES:
        assert_picture(out / name)


def test_a_failure_to_draw_never_hides_the_runs_error(tiny_run, tmp_path, monkeypatch, caplog):
    scene, parameters = tiny_run

    def broken(*args, **kwargs):
        raise ValueError("a picture broke")

    monkeypatch.setattr(ngat.plotting, "plot_results", broken)
    with caplog.at_level(logging.INFO), pytest.raises(RuntimeError, match="the run broke"):
        stop = stop_at_step(1, RuntimeError("the run broke"))
        ngat.run(scene, out=tmp_path / "r", on_step=stop, **parameters)
    assert "pictures not drawn: ValueError: a picture broke" in caplog.text
    # After a run that went well, a failure to draw is a bug like any other and says so.
    with pytest.raises(ValueError, match="a picture broke"):
        ngat.run(scene, out=tmp_path / "ok", **parameters)
    assert ngat.load_results(tmp_path / "ok").summary["status"] == "completed"


def test_plot_twice_leaves_only_the_second_set_of_snapshots(tiny_run, tmp_path):
    scene, parameters = tiny_run
    out = tmp_path / "r"
    ngat.run(scene, out=out, plots=False, **parameters)
    assert main(["plot", str(out), "--times", "0.4", "0.8", "--quiet"]) == 0
    assert sorted(p.name for p in out.glob("v_t*.png")) == ["v_t0.4000.png", "v_t0.8000.png"]
    assert main(["plot", str(out), "--times", "1.2", "--quiet"]) == 0
    assert sorted(p.name for p in out.glob("v_t*.png")) == ["v_t1.2000.png"]
    for name in PICTURES:
        assert_picture(out / name)
