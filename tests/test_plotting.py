"""``ngat plot``: the pictures of a finished and of a partial quick two-slits run."""

import logging
import os
import shutil
import time

import numpy as np
import pytest
from matplotlib.image import imread

from ngat import plotting
from ngat.cli import main
from ngat.plotting import (
    PlotError,
    draw_bars,
    drawing_processes,
    field_series,
    plot_results,
    read_energies,
)

PICTURES = ["energies.png", "v_final.png", "mesh_final.png", "mesh_zoom.png"]


@pytest.fixture(scope="module")
def run_folder(quick_run):
    """The session's quick two-slits run (tests copy it before changing anything)."""
    return quick_run[2]


def assert_picture(path):
    assert path.exists(), path
    assert path.stat().st_size > 10_000, path
    pixels = imread(path)[..., :3]
    assert pixels.std() > 0.02, f"{path.name} is (nearly) one colour"


def test_plot_command_draws_every_picture(run_folder, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(run_folder, folder)
    assert main(["plot", str(folder), "--quiet"]) == 0
    for name in PICTURES:
        assert_picture(folder / name)
    snapshots = sorted(folder.glob("v_t*.png"))
    assert len(snapshots) == 4
    for path in snapshots:
        assert_picture(path)


def dark_fraction(path):
    """Return the share of pixels left of the colour bar in viridis' colour of v ≈ 0."""
    pixels = imread(path)[..., :3]
    body = pixels[:, : int(0.78 * pixels.shape[1])].reshape(-1, 3)
    return ((body[:, 0] < 0.35) & (body[:, 1] < 0.1) & (body[:, 2] > 0.25)).mean()


def test_v_pictures_show_the_crack_once_it_is_there(run_folder, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(run_folder, folder)
    plot_results(folder, times=[0.3])
    assert dark_fraction(folder / "v_t0.3000.png") == 0
    assert dark_fraction(folder / "v_final.png") > 0.001


def test_chosen_times_and_zoom(run_folder, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(run_folder, folder)
    written = plot_results(folder, times=[0.52, 1.4], zoom=(2.0, 2.0, 0.3))
    names = {p.name for p in written}
    assert {"v_t0.5000.png", "v_t1.4000.png"} <= names
    assert len([n for n in names if n.startswith("v_t")]) == 2


def test_partial_run_is_plotted(run_folder, tmp_path):
    # A crash: the last rows are lost, the last one cut in half, and VTUs named by fields.pvd
    # are missing.
    folder = tmp_path / "partial"
    shutil.copytree(run_folder, folder)
    (folder / "summary.json").unlink()
    lines = (folder / "energies.csv").read_text().splitlines()
    (folder / "energies.csv").write_text("\n".join(lines[:20]) + "\n" + lines[20][:15])
    for step in range(24, 33):
        (folder / "fields" / f"step_{step:04d}.vtu").unlink()
    energies = read_energies(folder / "energies.csv")
    assert len(energies["t"]) == 19
    frames = field_series(folder, energies)
    assert [f.step for f in frames] == list(range(24))
    assert np.isclose(frames[-1].t, 1.15)
    assert main(["plot", str(folder), "--quiet"]) == 0
    for name in PICTURES:
        assert_picture(folder / name)


def test_fields_without_pvd_and_csv_without_rows(run_folder, tmp_path):
    folder = tmp_path / "bare"
    shutil.copytree(run_folder, folder)
    (folder / "fields.pvd").unlink()
    lines = (folder / "energies.csv").read_text().splitlines()
    (folder / "energies.csv").write_text(lines[0] + "\n")
    last = folder / "fields" / "step_0032.vtu"
    last.write_bytes(last.read_bytes()[:100_000])  # a VTU cut short
    written = plot_results(folder, times=[])
    assert [p.name for p in written] == ["v_final.png", "mesh_final.png", "mesh_zoom.png"]


@pytest.mark.skipif(drawing_processes() < 2, reason="draws in one process here")
def test_mesh_pictures_drawn_beside_the_others_are_the_same_pixels(run_folder, tmp_path):
    # Two processes (the default here) against one: the same list and the same pixels.
    folders = [tmp_path / "one", tmp_path / "two"]
    written = []
    for folder, processes in zip(folders, (1, 2), strict=True):
        shutil.copytree(run_folder, folder)
        written.append(
            plot_results(folder, times=[0.5], renderer="matplotlib", processes=processes)
        )
    assert [p.name for p in written[0]] == [p.name for p in written[1]]
    assert [p.name for p in written[1]][-2:] == ["mesh_final.png", "mesh_zoom.png"]
    for path in written[0]:
        assert np.array_equal(imread(path), imread(folders[1] / path.name)), path.name


@pytest.mark.skipif(drawing_processes() < 2, reason="draws in one process here")
def test_mesh_pictures_are_drawn_here_when_the_forked_process_fails(
    run_folder, tmp_path, monkeypatch, caplog
):
    # plot_mesh raises in the forked process only: this process draws the mesh pictures again.
    parent = os.getpid()
    drawn = plotting.plot_mesh

    def fails_in_the_child(*args, **kwargs):
        if os.getpid() != parent:
            raise RuntimeError("the forked drawing fails")
        return drawn(*args, **kwargs)

    monkeypatch.setattr(plotting, "plot_mesh", fails_in_the_child)
    folder = tmp_path / "run"
    shutil.copytree(run_folder, folder)
    with caplog.at_level(logging.DEBUG, logger="ngat.plotting"):
        written = plot_results(folder, times=[], renderer="matplotlib", processes=2)
    assert "the forked drawing failed (exit status 1): drawing here" in caplog.text
    assert [p.name for p in written] == PICTURES
    for name in PICTURES:
        assert_picture(folder / name)


@pytest.mark.skipif(drawing_processes() < 2, reason="draws in one process here")
def test_a_stuck_forked_drawing_is_stopped_and_drawn_here(
    run_folder, tmp_path, monkeypatch, caplog
):
    # plot_mesh waits without end in the forked process only (as on a lock held at the fork).
    parent = os.getpid()
    drawn = plotting.plot_mesh

    def stuck_in_the_child(*args, **kwargs):
        while os.getpid() != parent:
            time.sleep(1)
        return drawn(*args, **kwargs)

    monkeypatch.setattr(plotting, "plot_mesh", stuck_in_the_child)
    monkeypatch.setattr(plotting, "STALL_S", 0.5)
    folder = tmp_path / "run"
    shutil.copytree(run_folder, folder)
    with caplog.at_level(logging.DEBUG, logger="ngat.plotting"):
        written = plot_results(folder, times=[], renderer="matplotlib", processes=2)
    assert "the forked drawing made no progress for 0.5 s: drawing here" in caplog.text
    assert [p.name for p in written] == PICTURES
    for name in PICTURES:
        assert_picture(folder / name)


def test_empty_folder_is_an_input_error(tmp_path):
    with pytest.raises(PlotError):
        plot_results(tmp_path)
    assert main(["plot", str(tmp_path / "nothing")]) == 2


def test_mesh_edges_are_drawn_once_each_with_their_width_rounded_to_a_class():
    from matplotlib.figure import Figure

    from ngat.plotting import MAX_LINEWIDTH, MIN_LINEWIDTH, WIDTH_CLASSES, draw_segments

    rng = np.random.default_rng(0)
    segments = rng.random((500, 2, 2))
    width = MIN_LINEWIDTH * (MAX_LINEWIDTH / MIN_LINEWIDTH) ** rng.random(500)
    ax = Figure().subplots()
    draw_segments(ax, segments, width, "black")
    step = (MAX_LINEWIDTH / MIN_LINEWIDTH) ** (1 / (WIDTH_CLASSES - 1))
    drawn = []
    for line in ax.get_lines():
        xy = line.get_xydata().reshape(-1, 3, 2)
        assert np.isnan(xy[:, 2]).all()  # each segment on its own, between NaNs
        for segment in xy[:, :2]:
            index = np.flatnonzero((segments == segment).all(axis=(1, 2)))
            assert len(index) == 1
            assert step**-0.5 <= line.get_linewidth() / width[index[0]] <= step**0.5
            drawn.append(index[0])
    assert sorted(drawn) == list(range(500))
    assert len(ax.get_lines()) <= WIDTH_CLASSES


def test_bars_as_one_collection_look_as_matplotlibs_bars_on_a_log_axis():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    t = np.round(0.01 * np.arange(161), 10)
    iterations = np.ones(161)
    iterations[120:141] = np.arange(2, 23) ** 1.5
    pictures = []
    for draw in (
        lambda ax: ax.bar(t, iterations, width=0.008, color="C0"),
        lambda ax: draw_bars(ax, t, iterations, 0.008, "C0"),
    ):
        fig = Figure(figsize=(4, 2), dpi=100)
        ax = fig.subplots()
        draw(ax)
        ax.set_yscale("log")
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        pictures.append(np.asarray(canvas.buffer_rgba()))
    assert pictures[0].std() > 10  # bars were drawn
    np.testing.assert_array_equal(pictures[0], pictures[1])
