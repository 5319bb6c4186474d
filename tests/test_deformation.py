"""Pictures of a plane model's run: |u| on the deformed body, forces per component."""

import shutil

import numpy as np
import pytest
from matplotlib.image import imread
from netgen.occ import Y
from ngsolve import CF

import ngat
from ngat.cli import main
from ngat.deformation import (
    DISPLACEMENT_FRACTION,
    deformed_body,
    displacement_scale,
    has_plane_displacement,
)
from ngat.geometry import polygon_face
from ngat.plotting import energies_figure, read_energies
from ngat.scene import Scene


def notched_strip():
    """The rectangle [0, 2] × [0, 1] with a slit from (0, 0.5) to (0.8, 0.5)."""
    outline = [(0, 0), (2, 0), (2, 1), (0, 1), (0, 0.5), (0.8, 0.5), (0, 0.5)]
    body = polygon_face(outline, "body")
    body.edges.Min(Y).name = "bottom"
    body.edges.Max(Y).name = "top"
    return body


PLANE_SCENE = Scene(
    name="notched-strip",
    geometry=notched_strip,
    loads={"bottom": lambda t: CF((0, 0)), "top": lambda t: {"y": t}},
    times=np.array([0.0, 0.05, 0.1]),
    slits=(((0.0, 0.5), (0.8, 0.5)),),
    parameters={"model": "plane_strain", "poisson": 0.3, "nonlinear": "am"},
)


@pytest.fixture(scope="module")
def plane_run(tmp_path_factory):
    """Three load steps of the plane-strain strip on its coarse initial mesh (about 2 s)."""
    out = tmp_path_factory.mktemp("plane") / "run"
    ngat.run(PLANE_SCENE, out=out, maxh=0.25, eps=0.2, adapt="fixed", resolve_eps=False)
    return out


def assert_picture(path):
    assert path.exists(), path
    pixels = imread(path)[..., :3]
    assert pixels.std() > 0.02, f"{path.name} is (nearly) one colour"


def test_plane_run_draws_u_on_the_deformed_body(plane_run):
    for name in ["energies.png", "v_final.png", "u_final.png", "mesh_final.png", "mesh_zoom.png"]:
        assert_picture(plane_run / name)


def test_plot_command_draws_u_final_again(plane_run, tmp_path):
    # ngat plot renders with VTK where it can (else matplotlib, as at the end of a run).
    folder = tmp_path / "run"
    shutil.copytree(plane_run, folder)
    (folder / "u_final.png").unlink()
    assert main(["plot", str(folder), "--quiet"]) == 0
    assert_picture(folder / "u_final.png")


def test_fields_read_back_hold_the_vector_u(plane_run):
    fields = ngat.load_results(plane_run).fields
    u = np.asarray(fields.point_data["u"])
    assert u.shape == (fields.n_points, 2)
    assert has_plane_displacement(fields)
    # The top edge is pulled up by t = 0.1, the bottom edge held.
    y = fields.points[:, 1]
    np.testing.assert_allclose(u[y == 1.0, 1], 0.1, atol=1e-12)
    np.testing.assert_allclose(u[y == 0.0], 0.0, atol=1e-12)


def test_largest_displacement_is_drawn_as_the_stated_fraction(plane_run):
    fields = ngat.load_results(plane_run).fields
    body, scale = deformed_body(fields)
    moved = np.linalg.norm(body.points - fields.points, axis=1)
    assert moved.max() == pytest.approx(DISPLACEMENT_FRACTION * 2.0, rel=1e-6)
    u = np.asarray(fields.point_data["u"])
    np.testing.assert_allclose(body.point_data["|u|"], np.linalg.norm(u, axis=1))
    np.testing.assert_allclose(body.points[:, :2], fields.points[:, :2] + scale * u, atol=1e-6)


def test_no_displacement_no_scale():
    points = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 1.0]])
    assert displacement_scale(points, np.zeros((3, 2))) == 0.0
    u = np.array([[0.0, 0.0], [0.0, 0.6], [0.3, 0.0]])
    assert displacement_scale(points, u, 0.2) == pytest.approx(0.2 * 3.0 / 0.6)


def test_energies_picture_names_the_force_components(plane_run):
    figure = energies_figure(read_energies(plane_run / "energies.csv"))
    labels = figure.axes[1].get_legend_handles_labels()[1]
    assert labels == ["force (dI/dt)", "force_bottom_x", "force_bottom_y", "force_top_y"]


def test_anti_plane_run_keeps_its_pictures(tiny_run, tmp_path):
    scene, parameters = tiny_run
    out = tmp_path / "r"
    ngat.run(scene, out=out, **parameters)
    assert not (out / "u_final.png").exists()
    assert not has_plane_displacement(ngat.load_results(out).fields)
    figure = energies_figure(read_energies(out / "energies.csv"))
    assert figure.axes[1].get_legend() is None
