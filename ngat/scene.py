"""Scenes: geometry, Dirichlet regions with their load g(x, t), load times, parameter changes.

A scene is one Python file that defines ``scene = Scene(...)``. The package's scenes are the
subpackage :mod:`ngat.geometries` (the repository's ``geometries`` folder) and are found by name
(``two-slits`` → ``geometries/two_slits.py``); any other file is found by its path. A scene
states only what differs from the defaults. The functions of a scene loaded by
:func:`load_scene` raise :class:`SceneCodeError`, naming the function and its line, instead of
whatever they raise: that is the scene's bug, not ngat's.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import ngsolve
import numpy as np

from ngat import geometries
from ngat.geometry import check_mesh_size, generate_mesh, without_face_table
from ngat.parameters import Parameters
from ngat.state import SceneError

__all__ = [
    "Scene",
    "load_scene",
    "scene_names",
    "check_times",
    "SceneNotFound",
    "SceneFileError",
    "SceneTimesError",
    "SceneCodeError",
]

GEOMETRIES = Path(geometries.__file__).resolve().parent


class SceneNotFound(LookupError):
    """No scene of that name or path, or the file defines no scene."""


class SceneFileError(SceneNotFound):
    """A scene file that cannot be executed (syntax error, failing import, ...)."""


class SceneTimesError(ValueError):
    """A scene's load times are not a strictly increasing sequence."""


class SceneCodeError(SceneError):
    """A function of a scene (geometry, mesh, load or crack) raised an exception."""


@dataclass(frozen=True)
class Scene:
    """One experiment's setting.

    Attributes
    ----------
    name
        Scene name (used in results and for ``--resume`` checks).
    geometry
        Returns the OCC shape; faces (or edges) named after the Dirichlet regions.
    loads
        Dirichlet region name → ``g(t)`` returning a CoefficientFunction of x, y and the load
        parameter ``t`` (an NGSolve ``Parameter``). A region is a face (Ω_D, the paper's
        setting) or an edge of the boundary. For the plane models g has two components, or is a
        dict naming the components it holds, e.g. ``{"y": t}`` (u_x free).
    times
        Load times t_0 < t_1 < … .
    parameters
        Parameters that differ from the defaults (``eps``, ``maxh``, …).
    crack
        Optional set where v = 0 from the start: a boundary or material name, or a function of
        the vertex coordinates returning a boolean mask.
    quick
        Changes for ``--quick``: parameter names and optionally ``times``.
    description
        One line for ``ngat scenes``.
    mesh
        Optional mesh builder ``mesh(maxh)`` replacing the OCC meshing of ``geometry``.
    slits
        Slits as segments ``((x_mouth, y_mouth), (x_tip, y_tip))``: the crack tips grown from
        them are recorded per step (:func:`ngat.crack.crack_tips`).
    """

    name: str
    geometry: Callable[[], Any] | None
    loads: Mapping[str, Callable[[ngsolve.Parameter], ngsolve.CoefficientFunction]]
    times: Sequence[float]
    parameters: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    crack: str | Callable[[np.ndarray], np.ndarray] | None = None
    quick: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    description: str = ""
    mesh: Callable[[float], ngsolve.Mesh] | None = None
    slits: Sequence[tuple[tuple[float, float], tuple[float, float]]] = ()

    def make_mesh(self, maxh: float) -> ngsolve.Mesh:
        """Return the initial mesh with element size ``maxh`` (:func:`without_face_table`)."""
        with without_face_table():
            if self.mesh is not None:
                return self.mesh(maxh)
            return generate_mesh(self.geometry(), maxh)

    def check(self, maxh: float | None = None) -> None:
        """Raise :class:`~ngat.state.SceneError` if a Dirichlet region is missing.

        That is: the scene has no Dirichlet region, or its geometry has no face or edge of a
        Dirichlet region's name, or ``maxh`` (if given) asks for too many triangles
        (:func:`~ngat.geometry.check_mesh_size`). Scenes with their own ``mesh`` builder are
        checked on the mesh, by :class:`~ngat.state.ATState`.
        """
        if not self.loads:
            raise SceneError(
                f"scene '{self.name}' has no Dirichlet region: give at least one entry in 'loads'"
            )
        if self.mesh is not None or self.geometry is None:
            return
        shape = self.geometry()
        faces = {face.name for face in shape.faces}
        edges = {edge.name for edge in shape.edges} - {None}
        missing = sorted(set(self.loads) - faces - edges)
        if missing:
            raise SceneError(
                f"scene '{self.name}': Dirichlet region(s) {missing} are neither faces nor "
                f"edges of the geometry (faces: {sorted(faces)}, edges: {sorted(edges)}); name "
                "the OCC faces or edges accordingly"
            )
        if maxh is not None:
            check_mesh_size(shape, maxh)

    def configure(
        self, quick: bool = False, overrides: Mapping[str, Any] | None = None
    ) -> tuple[Parameters, np.ndarray]:
        """Return the run's parameters and load times.

        Parameters
        ----------
        quick
            Apply the scene's ``quick`` changes.
        overrides
            Further changes by name (from ``--set``), applied last.

        Raises
        ------
        ParameterError
            For an unknown parameter or an invalid value.
        SceneTimesError
            Unless the load times increase strictly.
        SceneError
            See :meth:`check`.
        """
        changes = dict(self.parameters)
        times = self.times
        if quick:
            quick_changes = dict(self.quick)
            times = quick_changes.pop("times", times)
            changes.update(quick_changes)
        changes.update(overrides or {})
        times = np.asarray(times, dtype=float)
        check_times(self.name, times)
        parameters = Parameters().replace(**changes)
        self.check(parameters.adaptivity.maxh)
        return parameters, times


def check_times(name: str, times: np.ndarray) -> None:
    """Raise :class:`SceneTimesError` unless ``times`` is a non-empty increasing 1-D sequence."""
    fix = f"fix 'times' (or the 'times' of 'quick') in scene '{name}'"
    if times.ndim != 1 or len(times) == 0:
        raise SceneTimesError(f"scene '{name}' has no load times: {fix}")
    if not np.all(np.isfinite(times)):
        raise SceneTimesError(f"scene '{name}': load times must be finite numbers; {fix}")
    bad = np.flatnonzero(np.diff(times) <= 0)
    if len(bad):
        k = int(bad[0]) + 1
        raise SceneTimesError(
            f"scene '{name}': load times must be strictly increasing, but t[{k}] = "
            f"{times[k]:g} follows t[{k - 1}] = {times[k - 1]:g}; {fix}"
        )


def _guarded(scene: str, role: str, function: Callable) -> Callable:
    """Return ``function`` raising :class:`SceneCodeError` for any exception of its own."""

    @functools.wraps(function)
    def call(*args):
        try:
            return function(*args)
        except Exception as error:
            code = getattr(function, "__code__", None)
            lines = [
                f"{frame.filename}, line {frame.lineno}"
                for frame in traceback.extract_tb(error.__traceback__)
                if code is not None and frame.filename == code.co_filename
            ]
            where = f" ({lines[-1]})" if lines else ""
            raise SceneCodeError(
                f"scene '{scene}': {role} raised {type(error).__name__}: {error}{where}; fix the "
                "scene (--debug shows the traceback)"
            ) from error

    return call


def guarded(scene: Scene) -> Scene:
    """Return ``scene`` with every function of it wrapped to raise :class:`SceneCodeError`."""
    return dataclasses.replace(
        scene,
        geometry=scene.geometry and _guarded(scene.name, "its geometry function", scene.geometry),
        mesh=scene.mesh and _guarded(scene.name, "its mesh function", scene.mesh),
        loads={
            name: _guarded(scene.name, f"the load of region '{name}'", load)
            for name, load in scene.loads.items()
        },
        crack=_guarded(scene.name, "its crack function", scene.crack)
        if callable(scene.crack)
        else scene.crack,
    )


def scene_names() -> list[str]:
    """Return the names of the package's scenes."""
    return sorted(
        p.stem.replace("_", "-") for p in GEOMETRIES.glob("*.py") if not p.stem.startswith("_")
    )


def load_scene(name_or_path: str) -> Scene:
    """Return the scene of a package scene name or of a scene file's path.

    The scene's functions raise :class:`SceneCodeError` (see :func:`guarded`).

    Raises
    ------
    SceneNotFound
        If there is no such scene or the file defines no ``scene``.
    SceneFileError
        If executing the scene file raises (a syntax error, a failing import, ...).
    """
    path = Path(name_or_path)
    if path.suffix == ".py" or len(path.parts) > 1:
        if not path.is_file():
            raise SceneNotFound(f"scene file '{name_or_path}' does not exist: check the path")
        if path.suffix != ".py":
            raise SceneNotFound(f"scene file '{name_or_path}' is not a Python file (.py)")
    else:
        path = GEOMETRIES / f"{name_or_path.replace('-', '_')}.py"
        if not path.is_file():
            raise SceneNotFound(
                f"unknown scene '{name_or_path}': give a scene file path or one of "
                f"{', '.join(scene_names())}"
            )
    spec = importlib.util.spec_from_file_location(f"ngat_scene_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except SyntaxError as error:
        raise SceneFileError(
            f"scene file '{path}' has a syntax error at line {error.lineno}: {error.msg}; "
            "fix the file"
        ) from error
    except Exception as error:
        raise SceneFileError(
            f"scene file '{path}' failed to load ({type(error).__name__}: {error}); fix the "
            "file (run with --debug for the traceback)"
        ) from error
    scene = getattr(module, "scene", None)
    if not isinstance(scene, Scene):
        raise SceneNotFound(
            f"scene file '{path}' defines no scene: add 'scene = Scene(...)' (ngat.scene.Scene)"
        )
    return guarded(scene)
