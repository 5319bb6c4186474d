"""The results folder: energies.csv, fields.pvd with one VTU per step, summary.json, run.log.

Every file is usable while the run goes on and after a crash: each CSV row is written and
synced when its step ends, the VTU of a step is complete before ``fields.pvd`` names it, and
``summary.json`` is replaced atomically (write a temporary file, then rename). A step costs the
same however many came before it: the row is appended, and the step's entry is written over the
closing tags of ``fields.pvd`` together with new closing tags (one write of a few hundred
bytes), so that the collection is valid XML after every step. A write that fails (a full disk)
leaves no partial file behind — no temporary file, no half VTU, no half CSV row, no half entry —
and raises :class:`OutputError` saying how to continue.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import json
import logging
import os
import secrets
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import IO, Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ngat.forms import MeshArrays
from ngat.parameters import computing, with_legacy_values

__all__ = [
    "ResultsWriter",
    "vtu_name",
    "write_grid",
    "vtu_grid",
    "atomic_file",
    "write_atomic",
    "writing",
    "read_summary",
    "check_results_folder",
    "times_summary",
    "REQUIRED_COLUMNS",
    "OutputError",
    "CHECKPOINT",
]

REQUIRED_COLUMNS = [
    "step", "t", "bulk", "surface", "total", "force", "am_iterations", "elements", "vertices",
    "h_min", "h_max", "v_min", "v_max", "wall_s",
]  # fmt: skip


CHECKPOINT = "checkpoint.npz"
"""The checkpoint's file name in a results folder (:mod:`ngat.checkpoint`)."""


class OutputError(OSError):
    """The results folder cannot be created or written."""


def read_summary(folder: Path) -> dict[str, Any] | None:
    """Return the ``summary.json`` of the run in ``folder``.

    Returns
    -------
    dict or None
        The summary; ``{}`` if the folder holds rows of a run (``energies.csv``) or its
        checkpoint but no readable summary; ``None`` if it holds no run.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return None
    try:
        return json.loads((folder / "summary.json").read_text())
    except FileNotFoundError:
        return {} if (folder / "energies.csv").exists() or (folder / CHECKPOINT).exists() else None
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
    with the same parameters and load times (or, without a readable summary, a checkpoint, whose
    identity :func:`ngat.checkpoint.prepare_resume` checks).

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
    if (not summary or "scene" not in summary) and (Path(folder) / CHECKPOINT).exists():
        return summary or {}  # the checkpoint names the run (checked by prepare_resume)
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
    recorded = with_legacy_values(summary.get("parameters", {}))
    theirs = _identity(computing(recorded), summary.get("times", {}))
    ours = _identity(computing(parameters), times_summary(times))
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

VTU_END = b"</VTKFile>\n"
"""The last bytes of a complete VTU file."""

RESERVE = 64 * 1024
"""Bytes a run holds in ``.ngat-reserve`` until it ends, so that on a full disk the final
``summary.json`` still fits (at least without the entries the checkpoint keeps too)."""


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


@contextlib.contextmanager
def writing(folder: Path) -> Iterator[None]:
    """Turn a failed write into an :class:`OutputError` naming the folder and how to go on.

    A run's writes fail for reasons outside ngat — a full disk, a quota, a folder removed or
    made read-only meanwhile; the run can continue from its last checkpoint once that is fixed.
    """
    try:
        yield
    except OutputError:
        raise
    except OSError as error:
        raise OutputError(
            f"cannot write to results folder '{folder}' ({error.strerror or error}): free space "
            f"or fix the folder, then continue the run with --resume {folder}"
        ) from error


def _ends_with(path: Path, end: bytes) -> bool:
    """Return whether the file ``path`` ends with the bytes ``end``."""
    with open(path, "rb") as f:
        size = f.seek(0, os.SEEK_END)
        f.seek(max(0, size - len(end)))
        return f.read() == end


class _RunLog(logging.FileHandler):
    """``run.log``: a line that cannot be written (a full disk) is dropped without a traceback.

    The run's own writes report the full disk (:func:`writing`); logging's default would print
    a traceback for every log line until then.
    """

    def handleError(self, record: logging.LogRecord) -> None:
        """Drop the record if writing it failed; report any other error as logging does."""
        if not isinstance(sys.exc_info()[1], OSError):
            super().handleError(record)


def vtu_name(step: int) -> str:
    """Return the VTU file of load step ``step``, relative to the results folder."""
    return f"fields/step_{step:04d}.vtu"


def vtu_grid(points: np.ndarray, triangles: np.ndarray):
    """Return the pyvista ``UnstructuredGrid`` of a triangle mesh, without data.

    One point per mesh vertex, shared by its triangles (NGSolve's ``VTKOutput`` writes ASCII
    with three points per triangle). Built once per mesh by :class:`ResultsWriter`.

    Parameters
    ----------
    points, triangles
        (nv, 2) vertex coordinates and (ne, 3) vertex numbers of the triangles.
    """
    # Only the VTU writer needs it; keep `import ngat` light.
    import pyvista

    cells = np.hstack([np.full((len(triangles), 1), 3, dtype=np.int64), triangles]).ravel()
    types = np.full(len(triangles), pyvista.CellType.TRIANGLE, dtype=np.uint8)
    return pyvista.UnstructuredGrid(cells, types, np.c_[points, np.zeros(len(points))])


def write_grid(path: Path, grid, values: dict[str, np.ndarray]) -> None:
    """Write nodal values on the grid of :func:`vtu_grid` to the VTU file ``path`` (raw binary).

    The values become point data (a plane model's u with its two components). Uncompressed,
    so that a step's file has the same size on the same mesh whatever the values
    (``tests/test_output_growth.py``). The arrays are appended raw after the XML (VTK's
    appended mode without encoding): pyvista's ``save`` encodes them in base64, which took
    0.14 s instead of 0.01 s for a file of 180k elements, a third more bytes.

    Parameters
    ----------
    path
        The file to write.
    grid
        The mesh's grid; its point data are replaced.
    values
        Name → nodal values, component-major (a vector field's nv x-values, then its y-values).
    """
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

    # The writer keeps the points' range in their information, and a later file of the same
    # grid would carry it (276 bytes more than the first): every file is written as the first.
    grid.GetPoints().GetData().GetInformation().Clear()
    grid.point_data.clear()
    for name, nodal in values.items():
        dim = len(nodal) // grid.n_points
        grid.point_data[name] = nodal.reshape(dim, -1).T.copy() if dim > 1 else nodal.copy()
    writer = vtkXMLUnstructuredGridWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(grid)
    writer.SetDataModeToAppended()
    writer.EncodeAppendedDataOff()
    writer.SetCompressorTypeToNone()
    if not writer.Write():
        raise OSError(f"VTK could not write {path}")


PVD_HEAD = b'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
PVD_TAIL = b"  </Collection>\n</VTKFile>\n"
"""The bytes of ``fields.pvd`` before and after its entries."""


def _dataset(t: float, file: str) -> bytes:
    """Return the ``fields.pvd`` entry of the VTU ``file`` at load time ``t``."""
    return f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(file)}/>\n'.encode()


class _Series:
    """``fields.pvd``, the collection of the VTU files, valid XML after every entry.

    The first entry of a run (or of a resumed run) writes the file whole and atomically, with
    the entries of the steps before; each further entry is written, followed by the closing
    tags, over the old closing tags in one ``pwrite`` of a few hundred bytes. A write that
    fails puts the closing tags back; a run killed at any moment leaves the file with or
    without its last entry.
    """

    def __init__(self, path: Path, stored: Sequence[tuple[float, str]]):
        self.path = path
        self.stored = list(stored)
        self.end: int | None = None  # offset of the closing tags, once written

    def append(self, t: float, file: str) -> None:
        """Add the VTU ``file`` at load time ``t``; raise :class:`OSError` if that fails."""
        entry = _dataset(t, file)
        if self.end is None:
            head = PVD_HEAD + b"".join(_dataset(*item) for item in self.stored)
            with atomic_file(self.path) as f:
                f.write(head + entry + PVD_TAIL)
            self.stored.clear()
            self.end = len(head) + len(entry)
            return
        fd = os.open(self.path, os.O_WRONLY)
        try:
            data = entry + PVD_TAIL
            if os.pwrite(fd, data, self.end) != len(data):
                raise OSError(errno.ENOSPC, f"{self.path.name}: {os.strerror(errno.ENOSPC)}")
        except BaseException:
            # The old closing tags' bytes are allocated: writing them back needs no space.
            with contextlib.suppress(OSError):
                os.pwrite(fd, PVD_TAIL, self.end)
                os.ftruncate(fd, self.end + len(PVD_TAIL))
            raise
        finally:
            os.close(fd)
        self.end += len(entry)


class ResultsWriter:
    """Write one run's results folder step by step.

    The run must hold the folder's lock (:func:`ngat.lock.folder_lock`): temporary files found
    in the folder are then left over from a killed run, and are removed. Until :meth:`close`
    the writer holds :data:`RESERVE` bytes of disk space for the final summary.

    Parameters
    ----------
    folder
        Results folder; created if missing.
    append
        Keep the rows and fields already written (resuming a run).
    stored
        When appending: load time and VTU file of every step whose fields were written.
    """

    def __init__(
        self, folder: Path, append: bool = False, stored: Sequence[tuple[float, str]] = ()
    ):
        self.folder = Path(folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            (self.folder / "fields").mkdir(exist_ok=True)
            probe = self.folder / ".write-test"
            probe.write_text("")
            probe.unlink()
            for stale in self.folder.glob(TEMPORARY):
                stale.unlink()
            if not append:
                # A fresh run's steps replace an earlier run's: none of its VTUs may stay behind.
                for stale in (self.folder / "fields").glob("step_*.vtu"):
                    stale.unlink()
            self.reserve = self.folder / ".ngat-reserve"
            # Random bytes: a compressing file system would store zeros in no space at all.
            self.reserve.write_bytes(os.urandom(RESERVE))
        except OSError as error:
            raise OutputError(
                f"results folder '{self.folder}' is not writable ({error.strerror}); "
                "choose another with --out"
            ) from None
        self.csv_path = self.folder / "energies.csv"
        self.columns: list[str] | None = None
        if append and self.csv_path.exists():
            with open(self.csv_path, newline="") as f:
                self.columns = next(csv.reader(f), None)
        elif self.csv_path.exists():
            self.csv_path.unlink()
        self.series = _Series(self.folder / "fields.pvd", stored)
        self.log_handler = _RunLog(self.folder / "run.log", "a" if append else "w")
        self.log_handler.setFormatter(
            logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
        )
        self.log_handler.setLevel(logging.INFO)
        self._grid: tuple[Any, Any] = (None, None)  # (mesh arrays, their VTU grid)
        logger = logging.getLogger("ngat")
        logger.addHandler(self.log_handler)
        if logger.getEffectiveLevel() > logging.INFO:
            logger.setLevel(logging.INFO)

    def write_step(
        self, record: dict[str, Any], arrays: MeshArrays, fields: dict | None = None
    ) -> None:
        """Append one row to ``energies.csv``; write the step's VTU and add it to ``fields.pvd``.

        Parameters
        ----------
        record
            The step's values; its keys fix the columns at the first step.
        arrays
            The current mesh's arrays (:class:`ngat.forms.MeshArrays`, one object per mesh:
            the VTU's grid is built once per mesh, :func:`vtu_grid`).
        fields
            Name → GridFunction written to the VTU (u and v); ``None``: no VTU for this step
            (``output_every``).

        Raises
        ------
        OutputError
            If a write fails (see :func:`writing`); the step's VTU and row are then not kept.
        """
        with writing(self.folder):
            if fields is not None:
                name = vtu_name(int(record["step"]))
                values = {key: field.vec.FV().NumPy() for key, field in fields.items()}
                self._write_vtu(name, arrays, values)
                self.series.append(float(record["t"]), name)
            self._append_row(record)

    def _write_vtu(self, name: str, arrays: MeshArrays, values: dict[str, np.ndarray]) -> None:
        """Write the VTU ``name``; raise :class:`OSError` and remove it unless it is complete."""
        path = self.folder / name
        if self._grid[0] is not arrays:
            self._grid = (arrays, vtu_grid(arrays.coords, arrays.elements))
        try:
            write_grid(path, self._grid[1], values)
            # VTK's writer does not raise on a failed write (it leaves the file cut short).
            if not _ends_with(path, VTU_END):
                raise OSError(errno.EIO, f"{path.name} came out incomplete; is the disk full?")
        except BaseException:
            path.unlink(missing_ok=True)
            raise

    def _append_row(self, record: dict[str, Any]) -> None:
        """Append the row of ``record`` to ``energies.csv``, or leave the file as it was."""
        new_file = self.columns is None
        if new_file:
            self.columns = list(record)
        size = self.csv_path.stat().st_size if self.csv_path.exists() else 0
        try:
            with open(self.csv_path, "a", newline="") as f:
                writer = csv.DictWriter(f, fieldnames=self.columns, extrasaction="ignore")
                if new_file:
                    writer.writeheader()
                writer.writerow(record)
        except BaseException:
            with contextlib.suppress(OSError):
                if size:
                    os.truncate(self.csv_path, size)
                else:
                    self.csv_path.unlink()
            raise

    def sync(self) -> None:
        """Force the rows of ``energies.csv`` to the disk (before a checkpoint that counts them).

        A checkpoint must never be ahead of the rows, not even after a power failure: a
        resumed run reads them back (:func:`ngat.checkpoint.restore_energies`).

        Raises
        ------
        OutputError
            If the sync fails (see :func:`writing`).
        """
        with writing(self.folder), open(self.csv_path, "rb") as f:
            os.fsync(f.fileno())

    def write_summary(self, summary: dict[str, Any]) -> None:
        """Replace ``summary.json`` atomically.

        Raises
        ------
        OutputError
            If the write fails (see :func:`writing`); the old summary is then kept.
        """
        with writing(self.folder):
            write_atomic(self.folder / "summary.json", json.dumps(summary, indent=2, default=str))

    def close(self) -> None:
        """Detach the log file and free the reserved space (before the final summary)."""
        logging.getLogger("ngat").removeHandler(self.log_handler)
        self.log_handler.close()
        self.reserve.unlink(missing_ok=True)
