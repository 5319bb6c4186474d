"""The results folder: energies.csv, fields.pvd with one VTU per step, summary.json, run.log.

Every file is usable while the run goes on and after a crash: each CSV row is flushed when its
step ends, the VTU of a step is complete before ``fields.pvd`` names it, and ``fields.pvd`` and
``summary.json`` are replaced atomically (write a temporary file, then rename).
"""

from __future__ import annotations

import contextlib
import csv
import json
import logging
import os
import secrets
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, Any
from xml.sax.saxutils import quoteattr

import ngsolve

__all__ = [
    "ResultsWriter",
    "atomic_file",
    "write_atomic",
    "read_summary",
    "check_results_folder",
    "times_summary",
    "REQUIRED_COLUMNS",
    "OutputError",
]

REQUIRED_COLUMNS = [
    "step", "t", "bulk", "surface", "total", "force", "am_iterations", "elements", "vertices",
    "h_min", "h_max", "v_min", "v_max", "wall_s",
]  # fmt: skip


class OutputError(OSError):
    """The results folder cannot be created or written."""


def read_summary(folder: Path) -> dict[str, Any] | None:
    """Return the ``summary.json`` of the run in ``folder``.

    Returns
    -------
    dict or None
        The summary; ``{}`` if the folder holds rows of a run (``energies.csv``) but no readable
        summary; ``None`` if it holds no run.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return None
    try:
        return json.loads((folder / "summary.json").read_text())
    except FileNotFoundError:
        return {} if (folder / "energies.csv").exists() else None
    except (OSError, ValueError):
        return {}


def times_summary(times: Sequence[float]) -> dict[str, Any]:
    """Return the load times as ``summary.json`` records them: first, last and count."""
    return {"first": float(times[0]), "last": float(times[-1]), "count": len(times)}


def _identity(parameters: dict[str, Any], times: dict[str, Any]) -> dict[str, Any]:
    """Return what a resumed run must share with the interrupted one, as one flat dict."""
    return {**parameters, **{f"times.{key}": value for key, value in times.items()}}


def check_results_folder(
    folder: Path,
    scene: str,
    parameters: dict[str, Any],
    times: Sequence[float],
    mode: str = "new",
) -> dict[str, Any] | None:
    """Refuse a results folder that would lose or mix up another run's files.

    ``mode="new"``: the folder must hold no run (a fresh run would replace its files), or only
    one that failed before its first step;
    ``"overwrite"``: anything goes; ``"resume"``: the folder must hold a run of the same scene
    with the same parameters and load times.

    Parameters
    ----------
    folder
        Results folder.
    scene
        Scene name of the new run.
    parameters
        Flat parameters of the new run (:meth:`ngat.parameters.Parameters.flat`).
    times
        Load times of the new run (compared by first, last and count, as in the summary).
    mode
        ``"new"``, ``"overwrite"`` or ``"resume"``.

    Returns
    -------
    dict or None
        The existing summary (see :func:`read_summary`).

    Raises
    ------
    OutputError
        Naming the conflict and the options.
    """
    summary = read_summary(folder)
    if mode == "overwrite":
        return summary
    if mode == "new":
        nothing_to_lose = (
            summary is not None
            and summary.get("steps") == 0
            and not (Path(folder) / "energies.csv").exists()
        )
        if summary is not None and not nothing_to_lose:
            what = (
                f"a run of scene '{summary['scene']}' (status {summary.get('status')})"
                if "scene" in summary
                else "a run"
            )
            raise OutputError(
                f"results folder '{folder}' already holds {what}: choose another folder with "
                "--out, pass --overwrite to replace it or --resume to continue it"
            )
        return summary
    if not summary or "scene" not in summary:
        raise OutputError(
            f"cannot resume '{folder}': it holds no run with a summary.json; start the run "
            "without --resume"
        )
    if summary["scene"] != scene:
        raise OutputError(
            f"cannot resume '{folder}': it holds a run of scene '{summary['scene']}', not "
            f"'{scene}'; give the same scene or another folder"
        )
    theirs = _identity(summary.get("parameters", {}), summary.get("times", {}))
    ours = _identity(parameters, times_summary(times))
    differ = [
        f"{key}: {theirs.get(key)} there, {ours.get(key)} here"
        for key in sorted(theirs.keys() | ours.keys())
        if theirs.get(key) != ours.get(key)
    ]
    if differ:
        raise OutputError(
            f"cannot resume '{folder}': its parameters differ ({'; '.join(differ)}); resume "
            "with the same --quick and --set values, or start afresh with --overwrite"
        )
    return summary


TEMPORARY = ".*.*-*.tmp"
"""Glob pattern of the temporary files of :func:`atomic_file`."""


@contextlib.contextmanager
def atomic_file(path: Path) -> Iterator[IO[bytes]]:
    """Open a temporary file that replaces ``path`` atomically when the block ends.

    The temporary file, ``.NAME.PID-RANDOM.tmp`` next to ``path``, has a name of its own for
    every writer, so two writers never share one; it is fsynced before the rename, and removed
    if the block or the write fails (an exception, a full disk, an interrupt), so that ``path``
    keeps its old content and no partial file stays behind. (``tempfile`` would create it with
    mode 0600 instead of the umask's.)
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, "xb") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and an atomic rename."""
    with atomic_file(path) as f:
        f.write(text.encode())


class ResultsWriter:
    """Write one run's results folder step by step.

    The run must hold the folder's lock (:func:`ngat.lock.folder_lock`): temporary files found
    in the folder are then left over from a killed run, and are removed.

    Parameters
    ----------
    folder
        Results folder; created if missing.
    append
        Keep the rows and fields already written (resuming a run).
    """

    def __init__(self, folder: Path, append: bool = False):
        self.folder = Path(folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            (self.folder / "fields").mkdir(exist_ok=True)
            probe = self.folder / ".write-test"
            probe.write_text("")
            probe.unlink()
            for stale in self.folder.glob(TEMPORARY):
                stale.unlink()
        except OSError as error:
            raise OutputError(
                f"results folder '{self.folder}' is not writable ({error.strerror}); "
                "choose another with --out"
            ) from None
        self.csv_path = self.folder / "energies.csv"
        self.pvd_entries: list[tuple[float, str]] = []
        self.columns: list[str] | None = None
        if append and self.csv_path.exists():
            with open(self.csv_path) as f:
                reader = csv.DictReader(f)
                self.columns = reader.fieldnames
                self.pvd_entries = [
                    (float(row["t"]), f"fields/step_{int(row['step']):04d}.vtu") for row in reader
                ]
        elif self.csv_path.exists():
            self.csv_path.unlink()
        self.log_handler = logging.FileHandler(self.folder / "run.log")
        self.log_handler.setFormatter(
            logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
        )
        self.log_handler.setLevel(logging.INFO)
        logger = logging.getLogger("ngat")
        logger.addHandler(self.log_handler)
        if logger.getEffectiveLevel() > logging.INFO:
            logger.setLevel(logging.INFO)

    def write_step(self, record: dict[str, Any], mesh: ngsolve.Mesh, fields: dict) -> None:
        """Append one row to ``energies.csv`` and write the step's VTU.

        Parameters
        ----------
        record
            The step's values; its keys fix the columns at the first step.
        mesh
            Current mesh.
        fields
            Name → GridFunction written to the VTU (u and v).
        """
        name = f"fields/step_{int(record['step']):04d}"
        ngsolve.VTKOutput(
            ma=mesh,
            coefs=list(fields.values()),
            names=list(fields),
            filename=str(self.folder / name),
            subdivision=0,
        ).Do()
        self.pvd_entries.append((float(record["t"]), f"{name}.vtu"))
        datasets = "\n".join(
            f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(f)}/>'
            for t, f in self.pvd_entries
        )
        write_atomic(
            self.folder / "fields.pvd",
            '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
            f"  <Collection>\n{datasets}\n  </Collection>\n</VTKFile>\n",
        )
        new_file = self.columns is None
        if new_file:
            self.columns = list(record)
        with open(self.csv_path, "a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns, extrasaction="ignore")
            if new_file:
                writer.writeheader()
            writer.writerow(record)

    def write_summary(self, summary: dict[str, Any]) -> None:
        """Replace ``summary.json`` atomically."""
        write_atomic(self.folder / "summary.json", json.dumps(summary, indent=2, default=str))

    def close(self) -> None:
        """Detach the log file."""
        logging.getLogger("ngat").removeHandler(self.log_handler)
        self.log_handler.close()
