"""The mesh pictures drawn by a process started with the run (``ngat.picture_process``): the same
files as drawn in the run's own process, drawn there anyway when that process fails, and no
process left behind."""

import psutil
import pytest

import ngat
from ngat.experiment import draw_pictures
from ngat.parameters import ParameterError
from ngat.picture_process import PictureProcess
from ngat.plotting import plot_mesh_pictures

MESH_PICTURES = ["mesh_final.png", "mesh_zoom.png"]


@pytest.fixture
def finished_run(tiny_run, tmp_path):
    """A results folder of the tiny run, without pictures, and the scene's slits."""
    scene, parameters = tiny_run
    folder = tmp_path / "r"
    ngat.run(scene, out=folder, plots=False, **parameters)
    return folder, scene.slits


def picture_processes() -> list:
    return [
        child
        for child in psutil.Process().children(recursive=True)
        if "ngat.picture_process" in " ".join(child.cmdline())
    ]


def test_the_process_draws_the_mesh_pictures_the_run_would_draw(finished_run, tmp_path):
    folder, slits = finished_run
    process = PictureProcess()
    assert process.draw(folder, slits)
    written = process.result()
    assert [path.name for path in written] == MESH_PICTURES
    drawn = {name: (folder / name).read_bytes() for name in MESH_PICTURES}
    for path in written:
        path.unlink()
    assert [path.name for path in plot_mesh_pictures(folder, slits=slits)] == MESH_PICTURES
    for name in MESH_PICTURES:
        assert (folder / name).read_bytes() == drawn[name], name
    assert not picture_processes()


def test_a_process_that_died_leaves_the_mesh_pictures_to_the_run(finished_run):
    folder, slits = finished_run
    process = PictureProcess()
    process._process.kill()
    process._process.wait()
    written = draw_pictures(folder, slits, process)
    assert [path.name for path in written] == [
        "energies.png", "v_final.png", *MESH_PICTURES,
    ]  # fmt: skip
    assert all(path.stat().st_size > 5_000 for path in written)
    assert not picture_processes()


def test_a_process_that_fails_to_draw_answers_none(finished_run):
    folder, slits = finished_run
    (folder / "mesh_final.png").mkdir()  # savefig cannot write there
    process = PictureProcess()
    assert process.draw(folder, slits)
    assert process.result() is None
    assert not picture_processes()


def test_a_run_with_pictures_ends_its_picture_process(tiny_run, tmp_path):
    scene, parameters = tiny_run
    ngat.run(scene, out=tmp_path / "r", **parameters)
    assert (tmp_path / "r" / "mesh_zoom.png").exists()
    assert not picture_processes()
    # Bad input stops the run before its first step: the process ends all the same.
    with pytest.raises(ParameterError):
        ngat.run(scene, out=tmp_path / "bad", **{**parameters, "eps": -1.0})
    assert not picture_processes()
