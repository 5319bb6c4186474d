"""One point field of a stored step drawn into a PNG, by matplotlib or by off-screen VTK.

:func:`draw_field_matplotlib` draws with ``tripcolor`` (no display needed; what every run uses at
its end), :func:`draw_field_pyvista` renders with VTK off-screen (``ngat plot`` where VTK can).
Both draw the body as seen from above, whole, with a colour bar; :mod:`ngat.plotting` uses them
for the phase field v, :mod:`ngat.deformation` for |u| on the deformed body.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyvista
from matplotlib.figure import Figure
from matplotlib.tri import Triangulation

__all__ = ["DPI", "PNG", "grid_triangles", "draw_field_matplotlib", "draw_field_pyvista"]

DPI = 200
"""Resolution of the PNGs drawn by matplotlib."""
PNG = {"compress_level": 3}
"""Pillow's options for those PNGs: zlib level 3 instead of 6 wrote the final mesh of the paper's
example (1400 × 1200 pixels of hairlines) in 95 instead of 158 ms and in 1.03 instead of 1.57 MB
(its four pictures: 3.2 instead of 3.6 MB)."""


def grid_triangles(grid: pyvista.UnstructuredGrid) -> tuple[np.ndarray, np.ndarray]:
    """Return the (n, 2) points and (ne, 3) triangles of a VTU read by pyvista.

    Parameters
    ----------
    grid
        A step of the VTK series (:func:`ngat.results.read_fields`).
    """
    triangles = grid.cells_dict[pyvista.CellType.TRIANGLE]
    return np.asarray(grid.points)[:, :2], np.asarray(triangles, dtype=np.int64)


def draw_field_matplotlib(
    grid: pyvista.UnstructuredGrid,
    title: str,
    path: Path,
    scalars: str = "v",
    clim: tuple[float, float] = (0.0, 1.0),
) -> Path:
    """Draw a point field with ``tripcolor``, the colour bar labelled by its name.

    Parameters
    ----------
    grid
        The step's VTU (points in the plane) with the point data ``scalars``.
    title
        Title of the picture (may span lines).
    path
        PNG file to write.
    scalars
        Name of the point data drawn.
    clim
        Colour range.
    """
    points, triangles = grid_triangles(grid)
    xmin, ymin = points.min(axis=0)
    xmax, ymax = points.max(axis=0)
    # 0.6 in more than the body for the title and the tick labels (a flat body lost its title),
    # and 0.25 in for each further line of the title.
    height = 7 * (ymax - ymin) / (xmax - xmin) + 0.6 + 0.25 * title.count("\n")
    fig = Figure(figsize=(7, height), layout="constrained")
    ax = fig.subplots()
    image = ax.tripcolor(
        Triangulation(points[:, 0], points[:, 1], triangles),
        np.asarray(grid.point_data[scalars]),
        shading="gouraud",
        cmap="viridis",
        vmin=clim[0],
        vmax=clim[1],
    )
    fig.colorbar(image, ax=ax, label=scalars, shrink=0.9)
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.set_title(title)
    fig.savefig(path, dpi=DPI, pil_kwargs=PNG)
    return path


def draw_field_pyvista(
    grid: pyvista.UnstructuredGrid,
    caption: str,
    path: Path,
    scalars: str = "v",
    clim: tuple[float, float] = (0.0, 1.0),
    title: str = "v",
) -> Path:
    """Render a point field with VTK off-screen, looking down z with parallel projection.

    Parameters
    ----------
    grid
        The step's VTU (points in the plane) with the point data ``scalars``.
    caption
        Short text under the colour bar (the load time; a few lines at most).
    path
        PNG file to write.
    scalars
        Name of the point data drawn.
    clim
        Colour range.
    title
        Title of the colour bar.
    """
    xmin, xmax, ymin, ymax = grid.bounds[:4]
    width, height = xmax - xmin, ymax - ymin
    # The body fills the left BODY of the window (with a 5 % margin); the colour bar the rest.
    body, margin = 0.82, 1.05
    pixels_y = 1200
    pixels_x = int(pixels_y * margin * width / height / body)
    plotter = pyvista.Plotter(off_screen=True, window_size=(pixels_x, pixels_y))
    try:
        plotter.set_background("white")
        plotter.add_mesh(
            grid,
            scalars=scalars,
            cmap="viridis",
            clim=clim,
            lighting=False,
            scalar_bar_args={
                "title": title,
                "vertical": True,
                "position_x": 0.85,
                "position_y": 0.1,
                "width": 0.06,
                "height": 0.8,
                # v keeps its ticks 0.0, 0.2, ..., 1.0; other ranges get three digits.
                "fmt": "%.1f" if clim == (0.0, 1.0) else "%.3g",
                "n_labels": 6,
                "title_font_size": 36,
                "label_font_size": 28,
                "color": "black",
            },
        )
        label = (int(0.83 * pixels_x), int(0.025 * pixels_y))
        plotter.add_text(caption, position=label, font_size=14, color="black")
        plotter.enable_parallel_projection()
        camera = plotter.camera
        window_width = margin * height * pixels_x / pixels_y
        x = 0.5 * (xmin + xmax) + (0.5 - body / 2) * window_width
        y = 0.5 * (ymin + ymax)
        camera.focal_point = (x, y, 0.0)
        camera.position = (x, y, 1.0)
        camera.up = (0.0, 1.0, 0.0)
        camera.parallel_scale = 0.5 * margin * height
        plotter.reset_camera_clipping_range()
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return path
