"""Parameter sweeps on Dask: every combination of a grid is one independent run.

:func:`sweep` submits one task per combination to a Dask cluster — a local cluster of processes
(one single-threaded worker per core) by default, or an existing scheduler by address, so a sweep
outgrows one machine without code changes. Each run writes its own results folder inside the
sweep folder, named after its grid values (``eps=0.05_tol=0.3``); a failed run is recorded with
its error and does not stop the others. ``sweep.csv`` collects one row per run (parameters,
status, wall time, final energies, fracture time) and is rewritten atomically whenever a run
ends. Re-running a sweep skips the runs whose ``summary.json`` says ``completed`` (same scene and
parameters) and resumes interrupted ones from their checkpoint. A sweep holds the lock of its
folder and each run that of its own (:mod:`ngat.lock`): a second sweep of the same folder is
refused, and a run whose folder is in use fails with that error. :func:`plot_sweep` draws
columns of ``sweep.csv`` against a grid parameter (:func:`ngat.plotting.sweep_figure`).

With a remote scheduler, the workers need ngat installed and the sweep folder (and a scene file
given by path) at the same path, e.g. on a shared file system.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ngat.lock import folder_lock
from ngat.output import check_results_folder, read_summary, write_atomic
from ngat.parameters import ParameterError, Parameters

__all__ = ["sweep", "run_combination", "plot_sweep", "parse_grid", "run_name", "RESULT_COLUMNS"]

log = logging.getLogger(__name__)

RESULT_COLUMNS = [
    "status",
    "skipped",
    "wall_s",
    "steps",
    "t",
    "bulk",
    "surface",
    "total",
    "fracture_time",
    "error",
    "folder",
]

RowCallback = Callable[[dict[str, Any]], None]


def parse_grid(items: Sequence[str]) -> dict[str, list[str]]:
    """Turn ``["eps=0.05,0.025", "tol=0.3"]`` into ``{"eps": ["0.05", "0.025"], "tol": ["0.3"]}``.

    Raises
    ------
    ParameterError
        For an item without ``=`` or without values.
    """
    grid: dict[str, list[str]] = {}
    for item in items:
        name, sep, values = item.partition("=")
        listed = [v.strip() for v in values.split(",") if v.strip()]
        if not sep or not name.strip() or not listed:
            raise ParameterError(f"--grid expects NAME=V1,V2,..., got '{item}'")
        grid[name.strip()] = listed
    return grid


def check_grid(grid: Mapping[str, Sequence[Any]]) -> None:
    """Raise :class:`ParameterError` for an empty grid or one naming an unknown parameter."""
    if not grid:
        raise ParameterError("the sweep grid is empty: give e.g. --grid eps=0.05,0.025")
    names = Parameters().names()
    for name, values in grid.items():
        if name not in names:
            raise ParameterError(
                f"sweep grid: unknown parameter '{name}': use one of {', '.join(sorted(names))}"
            )
        if isinstance(values, str) or not len(values):
            raise ParameterError(f"sweep grid: give a list of values for '{name}'")


def _format(name: str, value: Any) -> str:
    """Return ``value`` as its parameter's type would print it (``"0.050"`` → ``0.05``)."""
    kind = Parameters().names()[name]
    try:
        return str(kind(value))
    except (TypeError, ValueError):
        return str(value)


def run_name(values: Mapping[str, Any]) -> str:
    """Return the folder name of one combination, e.g. ``eps=0.05_tol=0.3``."""
    return "_".join(f"{name}={_format(name, value)}" for name, value in values.items())


def _result_row(summary: dict[str, Any] | None) -> dict[str, Any]:
    """Return the result columns read from a run's summary."""
    if not summary:
        return {}
    final = summary.get("final", {})
    fracture_time = summary.get("fracture_time")
    return {
        "wall_s": summary.get("timing", {}).get("wall", ""),
        "steps": summary.get("steps", ""),
        **{key: final.get(key, "") for key in ("t", "bulk", "surface", "total")},
        "fracture_time": "" if fracture_time is None else fracture_time,
    }


def run_combination(
    scene: str,
    values: Mapping[str, Any],
    folder: str,
    quick: bool = False,
    overrides: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Run one combination of a sweep (a Dask task) and return its ``sweep.csv`` row.

    Never raises for a failing run: the error goes into the row's ``error`` column.

    Parameters
    ----------
    scene
        Scene name or absolute path of a scene file.
    values
        The combination's grid values, by parameter name.
    folder
        The run's results folder.
    quick
        Use the scene's quick variant.
    overrides
        Parameter changes common to the whole sweep, applied before ``values``.

    Returns
    -------
    dict
        ``run``, the grid values and the :data:`RESULT_COLUMNS`.
    """
    from ngat.driver import run
    from ngat.scene import load_scene

    row: dict[str, Any] = {
        "run": Path(folder).name,
        **values,
        "status": "failed",
        "skipped": False,
        "folder": folder,
    }
    begin = time.perf_counter()
    try:
        loaded = load_scene(scene)
        parameters, times = loaded.configure(quick, {**(overrides or {}), **values})
        with folder_lock(folder):
            existing = read_summary(Path(folder))
            if existing and existing.get("status") == "completed":
                # Same scene and parameters, or an error naming the difference.
                check_results_folder(Path(folder), loaded.name, parameters.flat(), times, "resume")
                row.update(status="completed", skipped=True, **_result_row(existing))
                return row
            # An interrupted run of the same combination continues from its checkpoint.
            resume = bool(existing) and existing.get("scene") == loaded.name
            run(loaded, parameters, times, Path(folder), resume=resume)
        row.update(status="completed", **_result_row(read_summary(Path(folder))))
    except Exception as error:  # a failed run is a result of the sweep, not its end
        row.update(error=f"{type(error).__name__}: {error}".replace("\n", " "))
        row.update(_result_row(read_summary(Path(folder))))
        row.setdefault("wall_s", round(time.perf_counter() - begin, 4))
    return row


def _write_table(path: Path, rows: list[dict[str, Any]], parameters: list[str]) -> None:
    """Rewrite ``sweep.csv`` atomically with ``rows``."""
    columns = ["run", *parameters, *RESULT_COLUMNS]
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, extrasaction="ignore", restval="")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(path, text.getvalue())


def sweep(
    scene: str,
    grid: Mapping[str, Sequence[Any]],
    folder: str | Path,
    scheduler: str | None = None,
    quick: bool = False,
    overrides: Mapping[str, Any] | None = None,
    workers: int | None = None,
    on_result: RowCallback | None = None,
) -> list[dict[str, Any]]:
    """Run every combination of ``grid`` as an independent run on a Dask cluster.

    Parameters
    ----------
    scene
        Scene name (see ``ngat scenes``) or path of a scene file.
    grid
        Parameter name → list of values; every combination is one run.
    folder
        Sweep folder: one results folder per run, ``sweep.csv`` and ``sweep.json``.
    scheduler
        Address of a running Dask scheduler (``tcp://host:8786``); by default a local cluster of
        ``workers`` single-threaded processes is started and closed again.
    quick
        Use the scene's quick variant for every run.
    overrides
        Parameter changes common to all runs (like ``--set``).
    workers
        Number of local worker processes (default: one per core).
    on_result
        Called in the calling process with each row as its run ends (progress display).

    Returns
    -------
    list of dict
        One row per run, in grid order: ``run``, the grid values and :data:`RESULT_COLUMNS`.

    Raises
    ------
    ParameterError
        For an empty grid or an unknown parameter (before anything runs).
    SceneNotFound
        For an unknown scene.
    """
    from ngat.output import OutputError
    from ngat.scene import load_scene

    check_grid(grid)
    Parameters().replace(**(overrides or {}))
    scene_path = Path(scene)
    if scene_path.suffix == ".py" or len(scene_path.parts) > 1:
        scene = str(scene_path.resolve())
    load_scene(scene)
    names = list(grid)
    combinations = [dict(zip(names, c, strict=True)) for c in itertools.product(*grid.values())]
    order = [run_name(values) for values in combinations]
    if len(set(order)) != len(order):
        raise ParameterError("sweep grid: two values of a parameter give the same run name")
    folder = Path(folder).resolve()
    with folder_lock(folder):
        try:
            write_atomic(
                folder / "sweep.json",
                json.dumps(
                    {
                        "scene": scene,
                        "grid": {k: list(v) for k, v in grid.items()},
                        "overrides": dict(overrides or {}),
                        "quick": quick,
                    },
                    indent=2,
                    default=str,
                ),
            )
        except OSError as error:
            raise OutputError(
                f"sweep folder '{folder}' is not writable ({error.strerror}); choose another "
                "with --out"
            ) from None
        return _run_on_dask(
            scene, combinations, order, folder, scheduler, quick, overrides, workers, on_result
        )


def _run_on_dask(
    scene: str,
    combinations: list[dict[str, Any]],
    order: list[str],
    folder: Path,
    scheduler: str | None,
    quick: bool,
    overrides: Mapping[str, Any] | None,
    workers: int | None,
    on_result: RowCallback | None,
) -> list[dict[str, Any]]:
    """Run the combinations (named ``order``) on a Dask cluster: :func:`sweep` after its checks."""
    from dask.distributed import Client, LocalCluster, as_completed

    names = list(combinations[0])
    rows: dict[str, dict[str, Any]] = {}
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",  # a free port: sweeps may run side by side
        )
    client = Client(scheduler or cluster)
    log.info(
        "sweep of %s: %d runs on %s (dashboard %s)",
        scene,
        len(combinations),
        client.scheduler.address,
        client.dashboard_link,
    )
    try:
        futures = {
            client.submit(
                run_combination,
                scene,
                values,
                str(folder / name),
                quick,
                dict(overrides or {}),
                pure=False,
            ): (name, values)
            for name, values in zip(order, combinations, strict=True)
        }
        for future in as_completed(futures):
            name, values = futures[future]
            try:
                row = future.result()
            except Exception as error:  # the worker died (KilledWorker, ...)
                row = {
                    "run": name,
                    **values,
                    "status": "failed",
                    "skipped": False,
                    "error": f"{type(error).__name__}: {error}",
                    "folder": str(folder / name),
                }
            rows[name] = row
            log.info("sweep run %s: %s", name, row["status"])
            _write_table(folder / "sweep.csv", [rows[n] for n in order if n in rows], names)
            if on_result:
                on_result(row)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return [rows[name] for name in order]


def plot_sweep(
    folder: str | Path, x: str, columns: Sequence[str], path: str | Path | None = None
) -> Path:
    """Draw columns of ``sweep.csv`` against a grid parameter, one line per other combination.

    Parameters
    ----------
    folder
        Sweep folder holding ``sweep.csv`` and ``sweep.json``.
    x
        Grid parameter on the horizontal axis.
    columns
        Numeric columns of ``sweep.csv`` to draw, one panel each.
    path
        Picture to write (default ``FOLDER/sweep_<columns>_vs_<x>.png``).

    Returns
    -------
    Path
        The picture written.

    Raises
    ------
    ParameterError
        If ``x`` is not a grid parameter or a column is not in ``sweep.csv``.
    """
    from ngat.output import OutputError
    from ngat.plotting import sweep_figure

    folder = Path(folder)
    try:
        grid = json.loads((folder / "sweep.json").read_text())["grid"]
        with open(folder / "sweep.csv", newline="") as f:
            table = list(csv.DictReader(f))
    except (OSError, ValueError, KeyError):
        raise OutputError(
            f"'{folder}' holds no sweep (sweep.json and sweep.csv): give the folder of a sweep"
        ) from None
    if x not in grid:
        raise ParameterError(f"--x '{x}' is not a parameter of the sweep: use one of {list(grid)}")
    known = ["wall_s", "steps", "t", "bulk", "surface", "total", "fracture_time"]
    for column in columns:
        if column not in known:
            raise ParameterError(f"--y '{column}' is not a column of sweep.csv: use one of {known}")
    done = [row for row in table if row["status"] == "completed"]
    path = Path(path) if path else folder / f"sweep_{'_'.join(columns)}_vs_{x}.png"
    sweep_figure(done, grid, x, columns).savefig(path, dpi=120)
    return path
