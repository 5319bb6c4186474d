"""The deformed body of a plane model and its picture: |u| on the mesh moved by a scaled u.

The plane models (``model=plane_strain`` or ``plane_stress``, docs/plane-elasticity.md) store u
as a 2-vector in the VTK series; the anti-plane model's u is a scalar (the displacement out of
the plane) and moves no point of the plane. Elastic displacements are small against the body,
so :func:`deformed_body` moves the points by s u with the scale s chosen so that the largest
displacement becomes :data:`DISPLACEMENT_FRACTION` of the body's size (the longer side of its
bounding box); :func:`plot_displacement` draws |u| on that body (``u_final.png`` of
:func:`ngat.plotting.plot_results`) and writes s on the picture.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyvista

from ngat.rendering import draw_field_matplotlib, draw_field_pyvista

__all__ = [
    "DISPLACEMENT_FRACTION",
    "has_plane_displacement",
    "displacement_scale",
    "deformed_body",
    "plot_displacement",
]

DISPLACEMENT_FRACTION = 0.1
"""The largest displacement drawn, as a fraction of the body's size."""


def has_plane_displacement(grid: pyvista.UnstructuredGrid) -> bool:
    """Return whether the grid's point data ``u`` is a vector (a plane model's displacement).

    Parameters
    ----------
    grid
        A step of the VTK series (:func:`ngat.results.read_fields`).
    """
    return "u" in grid.point_data and np.ndim(grid.point_data["u"]) == 2


def displacement_scale(
    points: np.ndarray, u: np.ndarray, fraction: float = DISPLACEMENT_FRACTION
) -> float:
    """Return s such that max |s u| is ``fraction`` of the longer side of the bounding box.

    Parameters
    ----------
    points
        Points of the undeformed mesh, ``(n, 2)`` or ``(n, 3)``.
    u
        Displacement at the points, ``(n, 2)`` or ``(n, 3)``.
    fraction
        The largest displacement drawn, as a fraction of the body's size.

    Returns
    -------
    float
        The scale s; 0 when u vanishes.
    """
    size = float(np.ptp(np.asarray(points)[:, :2], axis=0).max())
    largest = float(np.linalg.norm(u, axis=1).max())
    return fraction * size / largest if largest > 0 else 0.0


def deformed_body(
    grid: pyvista.UnstructuredGrid, fraction: float = DISPLACEMENT_FRACTION
) -> tuple[pyvista.UnstructuredGrid, float]:
    """Return a copy of the grid moved by s u, with point data ``|u|``, and the scale s.

    Parameters
    ----------
    grid
        A step of a plane model's VTK series (:func:`has_plane_displacement`).
    fraction
        The largest displacement drawn, as a fraction of the body's size
        (:func:`displacement_scale`).
    """
    u = np.zeros((grid.n_points, 3))
    stored = np.asarray(grid.point_data["u"], dtype=float)
    u[:, : stored.shape[1]] = stored
    scale = displacement_scale(grid.points, u, fraction)
    body = grid.copy()
    body.points = np.asarray(grid.points, dtype=float) + scale * u
    body.point_data["|u|"] = np.linalg.norm(u, axis=1)
    return body, scale


def plot_displacement(grid: pyvista.UnstructuredGrid, t: float, path: Path, renderer: str) -> Path:
    """Draw |u| of a plane model's step on its deformed body (:func:`deformed_body`) into ``path``.

    Parameters
    ----------
    grid
        The step's VTU with the vector point data ``u``.
    t
        Load time, for the title.
    path
        PNG file to write.
    renderer
        ``"pyvista"`` (off-screen VTK) or ``"matplotlib"`` (``tripcolor``).
    """
    body, scale = deformed_body(grid)
    clim = (0.0, float(body.point_data["|u|"].max()) or 1.0)
    if renderer == "pyvista":
        # VTK's fonts draw no "|": the colour bar's title is in words.
        caption = f"t = {t:g}\nshape: u × {scale:.3g}"
        return draw_field_pyvista(body, caption, path, "|u|", clim, "u magnitude")
    title = (
        f"|u| at t = {t:g} on the body moved by {scale:.3g} u\n"
        f"(the largest displacement drawn as {DISPLACEMENT_FRACTION:.0%} of the body's size)"
    )
    return draw_field_matplotlib(body, title, path, "|u|", clim)
