"""A run's results in memory, and read back from its results folder.

:class:`RunResult` is what :func:`ngat.run` (and :func:`ngat.driver.run`) returns and what
:func:`load_results` reads from a results folder: the records (one per load step, the rows of
``energies.csv``) as a list of dictionaries and as columns of numpy arrays, ``summary.json``, the
fields of the last stored step (u and v on its mesh, read from the VTK series with pyvista) and
the folder. A record read back equals the one the run kept in memory: ``energies.csv`` holds each
value as Python prints it, and :func:`read_records` restores ints, floats, booleans and text.
"""

from __future__ import annotations

import csv
import functools
import logging
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ngat.output import OutputError, read_summary

if TYPE_CHECKING:
    import pyvista

    from ngat.state import ATState

__all__ = [
    "RunResult",
    "load_results",
    "read_records",
    "parse_records",
    "field_series",
    "read_fields",
    "Frame",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Frame:
    """One stored step of the VTK series: its step number, load time and VTU file."""

    step: int
    t: float
    path: Path


@dataclass
class RunResult:
    """The results of a run: records, summary, final fields and folder.

    Attributes
    ----------
    records
        One dictionary per load step (the rows of ``energies.csv``).
    summary
        The content of ``summary.json``.
    state
        The final fields and mesh as NGSolve objects (``None`` when read back from a folder).
    folder
        The results folder.
    """

    records: list[dict[str, Any]] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)
    state: ATState | None = None
    folder: Path | None = None

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """The records as columns: name → array over the load steps (int, float, bool or str)."""
        names = dict.fromkeys(name for record in self.records for name in record)
        return {name: np.array([r.get(name) for r in self.records]) for name in names}

    @functools.cached_property
    def fields(self) -> pyvista.UnstructuredGrid | None:
        """The last stored step's mesh with point data ``u`` and ``v``, its t in field data ``t``.

        Read from the folder's VTK series; ``None`` if it holds no readable step. ``u`` has one
        value per point for the anti-plane model and two (u_x, u_y) for the plane models.
        """
        if self.folder is None:
            return None
        frames = field_series(self.folder)
        while frames:
            if (grid := read_fields(frames[-1])) is not None:
                return grid
            frames.pop()
        return None


def load_results(folder: str | Path) -> RunResult:
    """Read a results folder (finished or partial) back into a :class:`RunResult`.

    Parameters
    ----------
    folder
        Results folder of ``ngat run`` or :func:`ngat.run`.

    Raises
    ------
    OutputError
        If the folder holds no run (neither ``energies.csv`` nor ``summary.json``).
    """
    folder = Path(folder)
    summary = read_summary(folder)
    if summary is None:
        raise OutputError(
            f"'{folder}' holds no results of a run (energies.csv, summary.json): give the "
            "results folder of a run"
        )
    csv_path = folder / "energies.csv"
    records = read_records(csv_path) if csv_path.exists() else []
    return RunResult(records=records, summary=summary, folder=folder)


def read_records(path: Path) -> list[dict[str, Any]]:
    """Return the rows of ``energies.csv`` with their types, dropping rows cut short by a crash.

    ``True``/``False`` become booleans, whole numbers ints, other numbers floats; anything else
    (``warnings``) stays text.

    Parameters
    ----------
    path
        The CSV file.
    """
    with open(path, newline="") as f:
        return parse_records(f, path)


def parse_records(lines: Iterable[str], path: Path) -> list[dict[str, Any]]:
    """Return the records of the lines of an ``energies.csv`` (see :func:`read_records`).

    Parameters
    ----------
    lines
        The file's lines, header first, with their line ends.
    path
        The file (named in the log when a row is dropped).
    """
    records = []
    for row in csv.DictReader(lines):
        if None in row or None in row.values():
            log.info("%s: skipping an incomplete row %s", path, row.get("step"))
            continue
        records.append({name: _value(text) for name, text in row.items()})
    return records


def _value(text: str) -> Any:
    if text in ("True", "False"):
        return text == "True"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def field_series(folder: Path, energies: dict[str, np.ndarray] | None = None) -> list[Frame]:
    """Return the stored steps whose VTU exists, in load order.

    ``fields.pvd`` gives the load times; without it (or if it does not parse) the VTUs are
    found by name (``fields/step_XXXX.vtu``) and their times looked up in ``energies`` (the
    step number stands in for t when there is no such row).

    Parameters
    ----------
    folder
        Results folder.
    energies
        Columns of ``energies.csv``, if read.
    """
    folder = Path(folder)
    frames = []
    pvd = folder / "fields.pvd"
    try:
        datasets = list(ET.parse(pvd).getroot().iter("DataSet"))
    except FileNotFoundError:
        datasets = None
    except ET.ParseError as error:
        log.info("%s: unreadable (%s); the VTU files are found by name", pvd, error)
        datasets = None
    if datasets is not None:
        for dataset in datasets:
            path = folder / dataset.get("file")
            frames.append(Frame(_step_of(path), float(dataset.get("timestep")), path))
    else:
        times = {}
        if energies is not None and "step" in energies and "t" in energies:
            times = dict(zip(energies["step"].astype(int).tolist(), energies["t"], strict=True))
        for path in sorted((folder / "fields").glob("step_*.vtu")):
            step = _step_of(path)
            frames.append(Frame(step, float(times.get(step, step)), path))
    missing = [f.path.name for f in frames if not f.path.exists()]
    if missing:
        log.info("%s: %d VTU files named but absent (%s ...)", folder, len(missing), missing[0])
    return [f for f in frames if f.path.exists()]


def _step_of(path: Path) -> int:
    try:
        return int(path.stem.rsplit("_", 1)[-1])
    except ValueError:
        return -1


def read_fields(frame: Frame) -> pyvista.UnstructuredGrid | None:
    """Return the frame's grid with its load time in field data ``t``.

    ``None`` if the VTU is unreadable (cut short by a crash), has no cells or no field v.
    """
    # Imported here: a run needs pyvista only when its fields are read back.
    import pyvista

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            grid = pyvista.read(frame.path)
        except Exception as error:  # VTK readers raise many kinds of errors
            log.info("%s: unreadable (%s)", frame.path, error)
            return None
    if grid.n_cells == 0 or "v" not in grid.point_data:
        log.info("%s: no cells or no field v; skipped", frame.path)
        return None
    grid.field_data["t"] = [frame.t]
    return grid
