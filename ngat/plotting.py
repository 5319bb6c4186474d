"""Pictures of a results folder, drawn without a GUI from its files alone.

:func:`plot_results` reads ``energies.csv`` and the VTK series (``fields.pvd``, ``fields/*.vtu``)
of a finished or partial run and writes PNGs into the folder:

- ``energies.png``: bulk, surface and total energy, the reaction force (plane models: also the
  ``force_<region>_x`` and ``_y`` columns, labelled), the number of elements and the
  alternating-minimisation iterations against the load time t;
- ``v_final.png`` and ``v_t<t>.png``: the phase field v at the last step and at a few load times,
  rendered off-screen by pyvista (matplotlib ``tripcolor`` where VTK cannot render off-screen);
- ``u_final.png`` (plane models only): |u| at the last step on the body deformed by a scaled u
  (:mod:`ngat.deformation`), the scale written on the picture;
- ``mesh_final.png``: the edges of the last mesh; ``mesh_zoom.png``: a window around a crack tip.

:func:`sweep_figure` draws the result columns of a sweep (``sweep.csv``) against a grid
parameter, with axes labelled by name, meaning and unit.

Whatever is missing (no CSV yet, rows cut short by a crash, VTUs named by ``fields.pvd`` but
absent) is skipped with a log message. Matplotlib figures are built with ``Figure`` objects and
never through ``pyplot``, so the caller's backend is left alone. Where the process may use two
cores and can fork (Linux), the two mesh pictures are drawn in a forked process beside the
others (:func:`drawing_processes`).
"""

from __future__ import annotations

import functools
import json
import logging
import os
import re
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import NamedTuple

import numpy as np
import psutil
import pyvista
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.tri import Triangulation

from ngat.crack import crack_tips, mesh_edges
from ngat.deformation import has_plane_displacement, plot_displacement
from ngat.forms import vertex_size
from ngat.rendering import DPI, PNG, draw_field_matplotlib, draw_field_pyvista, grid_triangles
from ngat.results import Frame, field_series, read_fields, read_records

__all__ = [
    "plot_results",
    "drawing_processes",
    "read_energies",
    "offscreen_rendering_works",
    "energies_figure",
    "sweep_figure",
    "draw_segments",
    "draw_bars",
    "PlotError",
]

log = logging.getLogger(__name__)

CRACK_THRESHOLD = 0.1
"""Vertices with v below this are cracked (as in :mod:`ngat.crack`)."""

ZOOM_FRACTION = 0.05
"""Default zoom radius as a fraction of the diagonal of the body's bounding box."""


class PlotError(ValueError):
    """The folder holds nothing to plot."""


def read_energies(path: Path) -> dict[str, np.ndarray]:
    """Return the numeric columns of ``energies.csv`` as float arrays, complete rows only.

    Rows cut short by a crash are dropped (:func:`ngat.results.read_records`); ``True``/``False``
    become 1/0; text columns (``warnings``) are left out.

    Parameters
    ----------
    path
        The CSV file.
    """
    records = read_records(path)
    columns = {}
    for name in records[0] if records else ():
        values = [record[name] for record in records]
        if all(isinstance(value, bool | int | float) for value in values):
            columns[name] = np.array(values, dtype=float)
    return columns


def drawing_processes() -> int:
    """Return the processes :func:`plot_results` draws with by default: 2 or 1.

    Two where this process may use two cores or more and can fork safely (Linux): a forked
    process inherits the fields already read and matplotlib already imported, and draws the
    two mesh pictures (half of the drawing at the paper's example) beside the others. One
    elsewhere.
    """
    if not sys.platform.startswith("linux"):
        return 1
    return 2 if len(os.sched_getaffinity(0)) > 1 else 1


def _start_beside(draw: Callable[[], object]) -> int:
    """Call ``draw`` in a forked process and return its process id.

    The process leaves at once when ``draw`` returns (status 0) or raises (status 1, without
    a message: :func:`_finish_beside` draws again here and so raises where the caller sees it).
    """
    with warnings.catch_warnings():
        # Python 3.12 and later warn of a fork with other threads running: the child only
        # draws, and one stuck on a lock those threads held is stopped (_finish_beside).
        warnings.filterwarnings("ignore", ".*multi-threaded.*fork", DeprecationWarning)
        pid = os.fork()
    if pid == 0:
        status = 1
        try:
            draw()
            status = 0
        finally:
            os._exit(status)
    return pid


STALL_S = 10.0
"""Seconds in which the forked drawing used no processor time before it counts as stuck.

A fork copies only the thread that forks: a lock another thread of this process held at that
moment (matplotlib's, in a program that draws in two threads) is never released in the child.
"""
POLL_S = 0.01
"""Seconds between two looks at the forked drawing."""


def _finish_beside(pid: int, draw: Callable[[], object]) -> None:
    """Wait for the forked process of :func:`_start_beside`; call ``draw`` here if it failed.

    A process that has used no processor time for :data:`STALL_S` seconds is killed and its
    pictures are drawn here as well.
    """
    child, used, since = psutil.Process(pid), -1.0, time.monotonic()
    while (done := os.waitpid(pid, os.WNOHANG))[0] == 0:
        try:
            now = sum(child.cpu_times()[:2])
        except psutil.Error:  # it has just ended
            now = used + 1
        if now > used:
            used, since = now, time.monotonic()
        elif time.monotonic() - since > STALL_S:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            log.debug("the forked drawing made no progress for %g s: drawing here", STALL_S)
            draw()
            return
        time.sleep(POLL_S)
    code = os.waitstatus_to_exitcode(done[1])
    if code != 0:
        log.debug("the forked drawing failed (exit status %d): drawing here", code)
        draw()


@functools.cache
def offscreen_rendering_works() -> bool:
    """Return whether VTK can render off-screen here, tried once in a child process.

    A VTK without a usable OpenGL context (no display, no EGL or OSMesa) may abort the process
    instead of raising, so the trial runs in a separate interpreter.
    """
    probe = (
        "import pyvista\n"
        "p = pyvista.Plotter(off_screen=True, window_size=(32, 32))\n"
        "p.add_mesh(pyvista.Sphere())\n"
        "assert p.screenshot(return_img=True).std() > 0\n"
    )
    try:
        result = subprocess.run(
            [sys.executable, "-c", probe], capture_output=True, timeout=120, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return result.returncode == 0


def plot_results(
    folder: str | Path,
    times: Sequence[float] | None = None,
    zoom: tuple[float, float, float] | None = None,
    slits: Sequence | None = None,
    renderer: str = "auto",
    processes: int | None = None,
) -> list[Path]:
    """Draw the pictures of a finished or partial results folder.

    The ``v_t*.png`` of an earlier call are removed first, so the folder holds one set of
    snapshots, that of the last call.

    Parameters
    ----------
    folder
        Results folder of ``ngat run``.
    times
        Load times of the ``v_t<t>.png`` pictures (each mapped to the nearest stored step).
        Default: four steps spread evenly over the stored ones, the first excluded.
    zoom
        ``(x, y, r)``: centre and half-width of ``mesh_zoom.png``. Default: centre at the tip of
        the first slit's crack (:func:`ngat.crack.crack_tips`) when the slits are known, else at
        the smallest element with a cracked vertex (v < 0.1; where adaptive refinement is finest),
        else at the smallest element; half-width 5 % of the bounding-box diagonal.
    slits
        Slits as ``((x_mouth, y_mouth), (x_tip, y_tip))`` segments. Default: the ``slits`` of
        the scene named in ``summary.json``, if it has any.
    renderer
        ``"pyvista"``, ``"matplotlib"`` or ``"auto"`` (pyvista if off-screen rendering works).
    processes
        2: the mesh pictures are drawn in a forked process while this one draws the others
        (the same pictures, pixel for pixel); 1: all here. Default :func:`drawing_processes`.

    Returns
    -------
    list of Path
        The pictures written.

    Raises
    ------
    PlotError
        If ``folder`` is not a folder, holds neither energies nor fields, or ``renderer`` is
        unknown.
    """
    if renderer not in ("auto", "pyvista", "matplotlib"):
        raise PlotError(f"renderer must be 'auto', 'pyvista' or 'matplotlib', got '{renderer}'")
    folder = Path(folder)
    if not folder.exists():
        raise PlotError(f"'{folder}' does not exist: give the results folder of a run")
    if not folder.is_dir():
        raise PlotError(
            f"'{folder}' is a file, not a folder: give the results folder of a run (the folder "
            "that holds energies.csv)"
        )
    energies = None
    if (folder / "energies.csv").exists():
        energies = read_energies(folder / "energies.csv")
    rows = energies is not None and len(energies.get("t", ())) > 0
    if energies is not None and not rows:
        log.info("%s: energies.csv has no complete row", folder)
    frames = field_series(folder, energies)
    if not rows and not frames:
        raise PlotError(f"'{folder}' holds no energies.csv rows and no fields to plot")
    for old in folder.glob("v_t*.png"):
        old.unlink()
    while frames and (grid := read_fields(frames[-1])) is None:
        frames.pop()
    meshes = beside = None
    if frames:
        scene_slits = _scene_slits(folder, slits) if zoom is None else ()
        meshes = functools.partial(plot_meshes, grid, frames[-1].t, folder, zoom, scene_slits)
        if (processes or drawing_processes()) > 1:
            beside = _start_beside(meshes)
    try:
        written = [plot_energies(energies, folder / "energies.png")] if rows else []
        if frames:
            written += _plot_fields(grid, frames, times, folder, renderer)
    except BaseException:
        if beside is not None:
            os.waitpid(beside, 0)  # its pictures are whole; this error goes on
        raise
    if beside is not None:
        _finish_beside(beside, meshes)
        written += [folder / name for name in MESH_PICTURES]
    elif meshes is not None:
        written += meshes()
    log.debug("%s: wrote %s", folder, ", ".join(p.name for p in written))
    return written


def _plot_fields(
    grid: pyvista.UnstructuredGrid,
    frames: list[Frame],
    times: Sequence[float] | None,
    folder: Path,
    renderer: str,
) -> list[Path]:
    """Draw ``v_final.png`` (plane models: ``u_final.png``) and v at the chosen earlier frames.

    ``grid`` is the last frame's VTU; ``times`` and ``renderer`` are :func:`plot_results`'s.
    """
    if renderer == "auto":
        renderer = "pyvista" if offscreen_rendering_works() else "matplotlib"
        if renderer == "matplotlib":
            log.warning("VTK cannot render off-screen here: drawing v with matplotlib")
    final = frames[-1]
    written = [plot_field(grid, final.t, folder / "v_final.png", renderer)]
    if has_plane_displacement(grid):
        written.append(plot_displacement(grid, final.t, folder / "u_final.png", renderer))
    for frame in _chosen_frames(frames[:-1], times):
        if (snapshot := read_fields(frame)) is not None:
            path = folder / f"v_t{frame.t:.4f}.png"
            written.append(plot_field(snapshot, frame.t, path, renderer))
    return written


MESH_PICTURES = ("mesh_final.png", "mesh_zoom.png")
"""The pictures of :func:`plot_meshes`."""


def plot_meshes(
    grid: pyvista.UnstructuredGrid,
    t: float,
    folder: Path,
    zoom: tuple[float, float, float] | None,
    slits: Sequence,
) -> list[Path]:
    """Draw :data:`MESH_PICTURES`: the whole mesh, and the window ``zoom`` over v.

    Parameters
    ----------
    grid
        The step's VTU with point data ``v``.
    t
        Load time, for the titles.
    folder
        Folder of the PNGs.
    zoom
        ``(x, y, r)`` of the window; ``None``: :func:`default_zoom` about the first slit's tip.
    slits
        The scene's slits, for the default zoom.
    """
    mesh = MergedMesh.of(*grid_triangles(grid))
    v = np.asarray(grid.point_data["v"])
    whole, window = (folder / name for name in MESH_PICTURES)
    if zoom is None:
        zoom = default_zoom(mesh, v, slits)
    return [plot_mesh(mesh, None, t, whole), plot_mesh(mesh, v, t, window, zoom)]


class MergedMesh(NamedTuple):
    """A VTU's triangles, and the mesh with its coincident points merged, and that mesh's edges.

    The two faces of a slit have points of their own at the same places; merged, the slit's
    edges are drawn once. Built once for the mesh pictures (:func:`plot_meshes`): the merge
    and the edges took 90 ms at 139k elements, three times over before.
    """

    points: np.ndarray
    """(n, 2) points of the VTU."""
    triangles: np.ndarray
    """(ne, 3) the VTU's triangles (point numbers)."""
    coords: np.ndarray
    """(nv, 2) distinct points."""
    elements: np.ndarray
    """(ne, 3) the triangles in numbers of ``coords``."""
    merged: np.ndarray
    """(n,) the number in ``coords`` of every point."""
    edges: np.ndarray
    """(n_edges, 2) the edges of ``elements``, smaller number first."""

    @classmethod
    def of(cls, points: np.ndarray, triangles: np.ndarray) -> MergedMesh:
        """Merge the coincident points of a VTU's mesh (:func:`ngat.rendering.grid_triangles`)."""
        coords, merged = np.unique(points, axis=0, return_inverse=True)
        merged = merged.reshape(-1)
        elements = merged[triangles]
        return cls(points, triangles, coords, elements, merged, mesh_edges(elements))


def _chosen_frames(frames: list[Frame], times: Sequence[float] | None) -> list[Frame]:
    """Return the frames nearest to ``times``, or four spread evenly after the first."""
    if not frames:
        return []
    if times is None:
        index = np.round(np.linspace(0, len(frames), 6)[1:-1]).astype(int)
        index = np.minimum(index, len(frames) - 1)
    else:
        t = np.array([f.t for f in frames])
        index = np.abs(t[None, :] - np.asarray(times, dtype=float)[:, None]).argmin(axis=1)
    return [frames[i] for i in np.unique(index)]


def _scene_slits(folder: Path, slits: Sequence | None) -> Sequence:
    """Return ``slits``, else the slits of the scene named in ``summary.json``, else ()."""
    if slits is not None:
        return slits
    try:
        from ngat.scene import load_scene

        name = json.loads((folder / "summary.json").read_text())["scene"]
        return tuple(getattr(load_scene(name), "slits", None) or ())
    except (OSError, ValueError, KeyError, LookupError):
        return ()


def plot_energies(energies: dict[str, np.ndarray], path: Path) -> Path:
    """Draw energies, reaction forces, elements and iterations against t into ``path``.

    Parameters
    ----------
    energies
        Columns of ``energies.csv`` (:func:`read_energies`).
    path
        PNG file to write.
    """
    energies_figure(energies).savefig(path, dpi=DPI, pil_kwargs=PNG)
    return path


def energies_figure(energies: dict[str, np.ndarray]) -> Figure:
    """Return the figure of ``energies.png``: four panels against the load time t.

    Energies; the reaction force ``force`` (plane models: with the columns ``force_<region>_x``
    and ``_y``, named in a legend); elements; alternating-minimisation iterations.

    Parameters
    ----------
    energies
        Columns of ``energies.csv`` (:func:`read_energies`).
    """
    t = energies["t"]
    fig = Figure(figsize=(7, 9), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True, height_ratios=[3, 2, 1.5, 1.5])
    ax = axes[0]
    for name, style in (("bulk", "-"), ("surface", "-"), ("total", "k-")):
        if name in energies:
            ax.plot(t, energies[name], style, label=name, marker=".", markersize=3)
    ax.set_ylabel("energy")
    ax.legend(loc="upper left", frameon=False)
    ax = axes[1]
    components = [name for name in energies if re.fullmatch(r"force_.+_[xy]", name)]
    if "force" in energies:
        label = "force (dI/dt)" if components else None
        ax.plot(t, energies["force"], "C3.-", markersize=3, label=label)
    for i, name in enumerate(components):
        ax.plot(t, energies[name], "--", color=f"C{4 + i}", label=name)
    if components:
        ax.legend(loc="upper left", frameon=False, fontsize="small")
    ax.set_ylabel("reaction force")
    ax.axhline(0, color="0.7", lw=0.5)
    ax = axes[2]
    if "elements" in energies:
        ax.step(t, energies["elements"], where="mid", color="C2")
        ax.set_yscale("log")
    ax.set_ylabel("elements")
    ax = axes[3]
    if "am_iterations" in energies:
        draw_bars(ax, t, energies["am_iterations"], 0.8 * _spacing(t), "C0")
        ax.set_yscale("log")
        if "converged" in energies and np.any(energies["converged"] == 0):
            failed = energies["converged"] == 0
            ax.plot(t[failed], energies["am_iterations"][failed], "rx", label="not converged")
            ax.legend(loc="upper left", frameon=False)
    ax.set_ylabel("AM iterations")
    ax.set_xlabel("load time t")
    for ax in axes:
        ax.grid(True, lw=0.3, alpha=0.5)
    return fig


def draw_bars(ax, x: np.ndarray, height: np.ndarray, width: float, color) -> None:
    """Draw the bars ``ax.bar`` draws, as one collection instead of a rectangle per bar.

    The 161 load steps' bars of the paper's example took 0.24 s of ``energies.png``'s 0.59 s.
    """
    x, height = np.asarray(x, dtype=float), np.asarray(height, dtype=float)
    left, right, zero = x - width / 2, x + width / 2, np.zeros_like(x)
    corners = [(left, zero), (left, height), (right, height), (right, zero)]
    vertices = np.stack([np.column_stack(corner) for corner in corners], axis=1)
    ax.add_collection(PolyCollection(vertices, facecolors=color, edgecolors="none"))
    ax.autoscale_view()


def _spacing(t: np.ndarray) -> float:
    return float(np.min(np.diff(t))) if len(t) > 1 else 1.0


def plot_field(grid: pyvista.UnstructuredGrid, t: float, path: Path, renderer: str) -> Path:
    """Draw the phase field v of one step, colour range [0, 1], into ``path``.

    Parameters
    ----------
    grid
        The step's VTU with point data ``v``.
    t
        Load time, for the title.
    path
        PNG file to write.
    renderer
        ``"pyvista"`` (off-screen VTK) or ``"matplotlib"`` (``tripcolor``).
    """
    if renderer == "pyvista":
        return draw_field_pyvista(grid, f"t = {t:g}", path)
    return draw_field_matplotlib(grid, f"v at t = {t:g}", path)


def default_zoom(
    mesh: MergedMesh, v: np.ndarray, slits: Sequence = ()
) -> tuple[float, float, float]:
    """Return the default window ``(x, y, r)`` of ``mesh_zoom.png`` (see :func:`plot_results`).

    Parameters
    ----------
    mesh
        The VTU's mesh (points repeated per element, as NGSolve writes them, or per face of a
        slit, as ngat does), merged.
    v
        Phase field at the VTU's points.
    slits
        Slit segments ``(mouth, tip)``; may be empty.
    """
    points, triangles, coords, elements = mesh.points, mesh.triangles, mesh.coords, mesh.elements
    r = ZOOM_FRACTION * float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    xy = coords[elements]
    diameter = np.linalg.norm(xy[:, [1, 2, 0]] - xy, axis=2).max(axis=1)
    if len(slits):
        # Coincident points are merged, so the two faces of a slit are joined here; the tip
        # search only needs the crack set near the slit, where that makes no difference.
        arrays = SimpleNamespace(
            elements=elements,
            coords=coords,
            nv=len(coords),
            ne=len(elements),
            diameter=diameter,
            edges=mesh.edges,
            size_at=lambda point: vertex_size(coords, elements, diameter, point),
        )
        vertex_v = np.zeros(len(coords))
        vertex_v[mesh.merged] = v
        x, y = crack_tips(arrays, vertex_v, [slits[0]], CRACK_THRESHOLD)[0]
        return x, y, r
    cracked = (np.asarray(v)[triangles] < CRACK_THRESHOLD).any(axis=1)
    candidates = np.flatnonzero(cracked) if cracked.any() else np.arange(len(triangles))
    finest = candidates[np.argmin(diameter[candidates])]
    x, y = xy[finest].mean(axis=0)
    return float(x), float(y), r


MIN_LINEWIDTH, MAX_LINEWIDTH = 0.03, 0.4
"""Line widths [pt] of the thinnest and the widest mesh edges (:func:`plot_mesh`)."""
WIDTH_CLASSES = 16
"""Line widths drawn, spaced geometrically between the thinnest and the widest."""


def draw_segments(ax, segments: np.ndarray, linewidth: np.ndarray, color) -> None:
    """Draw line segments (n, 2, 2) with per-segment widths, rounded to :data:`WIDTH_CLASSES`.

    One polyline per width, its segments separated by NaN: a ``LineCollection`` makes a
    ``Path`` per segment, 2.2 of the 3 s the pictures took at 137k elements.

    Parameters
    ----------
    ax
        Matplotlib axes.
    segments
        End points, shape (n, 2, 2).
    linewidth
        Width of each segment [pt], between :data:`MIN_LINEWIDTH` and :data:`MAX_LINEWIDTH`.
    color
        Matplotlib colour of every segment.
    """
    ratio = np.log(linewidth / MIN_LINEWIDTH) / np.log(MAX_LINEWIDTH / MIN_LINEWIDTH)
    classes = np.rint(ratio * (WIDTH_CLASSES - 1)).astype(int)
    for k in np.unique(classes):
        chosen = segments[classes == k]
        lines = np.full((len(chosen), 3, 2), np.nan)
        lines[:, :2] = chosen
        lines = lines.reshape(-1, 2)
        share = k / (WIDTH_CLASSES - 1)
        width = MIN_LINEWIDTH * (MAX_LINEWIDTH / MIN_LINEWIDTH) ** share
        ax.plot(lines[:, 0], lines[:, 1], color=color, linewidth=width, solid_capstyle="butt")


def plot_mesh(
    mesh: MergedMesh,
    v: np.ndarray | None,
    t: float,
    path: Path,
    zoom: tuple[float, float, float] | None = None,
) -> Path:
    """Draw the mesh edges, over v when given, whole or in the window ``zoom = (x, y, r)``.

    Parameters
    ----------
    mesh
        The VTU's mesh, merged.
    v
        Phase field at the points, drawn under the edges; ``None`` for edges only.
    t
        Load time, for the title.
    path
        PNG file to write.
    zoom
        Centre and half-width of the window; ``None`` for the whole body.
    """
    points, triangles = mesh.points, mesh.triangles
    segments = mesh.coords[mesh.edges]
    if zoom is None:
        lo, hi = points.min(axis=0), points.max(axis=0)
    else:
        x, y, r = zoom
        lo, hi = np.array([x - r, y - r]), np.array([x + r, y + r])
        inside = ((segments.max(axis=1) >= lo) & (segments.min(axis=1) <= hi)).all(axis=1)
        segments = segments[inside]
    width, height = hi - lo
    fig = Figure(figsize=(7, 7 * height / width + (0.4 if v is None else 0)), layout="constrained")
    ax = fig.subplots()
    if v is not None:
        image = ax.tripcolor(
            Triangulation(points[:, 0], points[:, 1], triangles),
            v,
            shading="gouraud",
            cmap="viridis",
            vmin=0,
            vmax=1,
        )
        fig.colorbar(image, ax=ax, label="v", shrink=0.9)
    # A line about a twentieth of its edge's length on paper: small elements show as hairlines
    # and leave the colour of v (or the white of the page) visible between them.
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    linewidth = np.clip(20.0 * length / width, MIN_LINEWIDTH, MAX_LINEWIDTH)
    color = (1.0, 1.0, 1.0, 0.5) if v is not None else "black"
    draw_segments(ax, segments, linewidth, color)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    where = "" if zoom is None else f", window ({zoom[0]:.3g}, {zoom[1]:.3g}) ± {zoom[2]:.3g}"
    ax.set_title(f"mesh at t = {t:g}: {len(triangles)} elements{where}")
    fig.savefig(path, dpi=DPI, pil_kwargs=PNG)
    return path


PARAMETER_LABELS = {
    "eps": "regularisation length ε [length]",
    "eta": "residual stiffness η",
    "crtol": "crack-set tolerance CRTOL",
    "am_tol": "AM tolerance on max |Δv|",
    "am_stop": "AM stopping test",
    "am_max_iter": "AM iterations per step at most",
    "max_cg": "CG iterations before refactorising",
    "omega": "over-relaxation factor ω",
    "anderson_depth": "Anderson depth",
    "newton_switch": "Newton switch on max |Δv|",
    "maxh": "initial element size [length]",
    "tol": "estimator tolerance TOL",
    "tol_rel": "relative tolerance (TOL / I^½)",
    "theta": "marking parameter θ",
    "band_h": "crack-band element size [ε]",
    "onset_h": "element size at uncracked slit tips [ε]",
    "band_search": "crack band while searching [band_h]",
    "floor": "element floor [ε]",
    "max_refinements": "refinements per step at most",
    "irreversibility": "irreversibility",
    "lumping": "mass lumping",
    "nonlinear": "solver of a load step",
    "linear_solver": "linear solver",
    "bounded_v": "bounded v-step",
    "adapt": "adaptivity",
    "marking": "marking strategy",
}
"""Meaning and unit of the parameters a sweep varies (lengths in the scene's length unit)."""

SWEEP_COLUMN_LABELS = {
    "wall_s": "wall time [s]",
    "steps": "load steps computed",
    "t": "last load time t",
    "bulk": "bulk energy at the last t",
    "surface": "surface energy at the last t",
    "total": "total energy I at the last t",
    "fracture_time": "fracture time (first t with the body cut)",
}
"""Meaning and unit of the result columns of ``sweep.csv``."""


def _axis_label(name: str, labels: dict[str, str]) -> str:
    return f"{name}: {labels[name]}" if name in labels else name


def sweep_figure(
    rows: Sequence[dict[str, str]],
    grid: dict[str, Sequence[str]],
    x: str,
    columns: Sequence[str],
) -> Figure:
    """Draw ``columns`` of a sweep's rows against the grid parameter ``x``, one panel each.

    Each combination of the other grid parameters is one line. Numeric values of ``x`` are
    placed by value (on a log axis when they span a factor of ten or more), others (``nonlinear``,
    ``adapt``, ...) in grid order; empty cells (no fracture time) are left out.

    Parameters
    ----------
    rows
        Rows of ``sweep.csv`` (strings, as read by :class:`csv.DictReader`) of completed runs.
    grid
        The sweep's grid: parameter name → values.
    x
        Grid parameter on the horizontal axis.
    columns
        Numeric columns of the rows, one panel each.
    """
    try:
        values = [float(v) for v in grid[x]]
    except ValueError:
        values = None
    others = [name for name in grid if name != x]
    groups: dict[str, list[dict[str, str]]] = {}
    for row in rows:
        groups.setdefault(", ".join(f"{n}={row[n]}" for n in others), []).append(row)
    fig = Figure(figsize=(4.5 * len(columns), 3.6), layout="constrained")
    axes = fig.subplots(1, len(columns), squeeze=False)[0]
    for ax, column in zip(axes, columns, strict=True):
        for label, group in groups.items():
            cells = [(row[x], float(row[column])) for row in group if row[column] not in ("", None)]
            if values is None:
                rank = {str(v): i for i, v in enumerate(grid[x])}
                cells.sort(key=lambda cell: rank.get(cell[0], len(rank)))
            else:
                cells = sorted((float(xv), y) for xv, y in cells)
            if cells:
                ax.plot(*zip(*cells, strict=True), "o-", label=label or None)
        if values is not None and min(values) > 0 and max(values) >= 10 * min(values):
            ax.set_xscale("log")
        ax.set_xlabel(_axis_label(x, PARAMETER_LABELS))
        ax.set_ylabel(_axis_label(column, SWEEP_COLUMN_LABELS))
        ax.grid(True, lw=0.3, alpha=0.5)
        if others and groups:
            ax.legend(fontsize="small", frameon=False)
    return fig
