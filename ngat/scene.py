"""Scenes: geometry, Dirichlet regions with their load g(x, t), load times, parameter changes.

A scene is one Python file that defines ``scene = Scene(...)``. The package's scenes live in the
``geometries`` folder and are found by name (``two-slits`` → ``geometries/two_slits.py``); any
other file is found by its path. A scene states only what differs from the defaults.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import ngsolve
import numpy as np

from ngat.geometry import generate_mesh
from ngat.parameters import Parameters

__all__ = ["Scene", "load_scene", "scene_names", "SceneNotFound"]

GEOMETRIES = Path(__file__).resolve().parent.parent / "geometries"


class SceneNotFound(LookupError):
    """No scene of that name or path, or the file defines no scene."""


@dataclass(frozen=True)
class Scene:
    """One experiment's setting.

    Attributes
    ----------
    name
        Scene name (used in results and for ``--resume`` checks).
    geometry
        Returns the OCC shape; faces named after the Dirichlet regions.
    loads
        Dirichlet region name → ``g(t)`` returning a CoefficientFunction of x, y and the load
        parameter ``t`` (an NGSolve ``Parameter``).
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

    def make_mesh(self, maxh: float) -> ngsolve.Mesh:
        """Return the initial mesh with element size ``maxh``."""
        if self.mesh is not None:
            return self.mesh(maxh)
        return generate_mesh(self.geometry(), maxh)

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
        """
        changes = dict(self.parameters)
        times = self.times
        if quick:
            quick_changes = dict(self.quick)
            times = quick_changes.pop("times", times)
            changes.update(quick_changes)
        changes.update(overrides or {})
        times = np.asarray(times, dtype=float)
        if times.ndim != 1 or len(times) == 0 or np.any(np.diff(times) <= 0):
            raise ValueError(f"scene '{self.name}': load times must be increasing, got {times}")
        return Parameters().replace(**changes), times


def scene_names() -> list[str]:
    """Return the names of the package's scenes."""
    return sorted(
        p.stem.replace("_", "-") for p in GEOMETRIES.glob("*.py") if not p.stem.startswith("_")
    )


def load_scene(name_or_path: str) -> Scene:
    """Return the scene of a package scene name or of a scene file's path.

    Raises
    ------
    SceneNotFound
        If there is no such scene or the file defines no ``scene``.
    """
    path = Path(name_or_path)
    if not (path.suffix == ".py" and path.exists()):
        path = GEOMETRIES / f"{name_or_path.replace('-', '_')}.py"
    if not path.exists():
        raise SceneNotFound(
            f"unknown scene '{name_or_path}': give a scene file path or one of "
            f"{', '.join(scene_names())}"
        )
    spec = importlib.util.spec_from_file_location(f"ngat_scene_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    scene = getattr(module, "scene", None)
    if not isinstance(scene, Scene):
        raise SceneNotFound(f"{path} defines no 'scene = Scene(...)'")
    return scene
