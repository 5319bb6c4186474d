"""A process of its own for the mesh pictures, started with the run and drawing at its end.

The pictures a run leaves take about 2 s after the paper's example has finished (matplotlib's
import 0.5 s, ``energies.png`` and ``v_final.png`` 0.7 s, ``mesh_final.png`` and
``mesh_zoom.png`` of 137k elements 1.0 s), on a machine whose second core is then idle.
:class:`PictureProcess` starts a Python process when the run starts; it imports
:mod:`ngat.plotting` while the run computes and waits. At the run's end it draws the two mesh
pictures (:func:`ngat.plotting.plot_mesh_pictures`, from the folder's files) while the run's
own process draws the others: about 1.3 s instead of 2.2 s.

The process is a new interpreter (:data:`START`), not a fork of the run, at the lowest priority,
and runs in a session of its own: Ctrl-C in the terminal stops the run, whose pictures of what
it has are then still drawn. It reads one request from its standard input (a JSON line with
the folder and the slits) and answers with one JSON line; it ends when its input closes, so a
run that dies leaves no process behind. Whatever goes wrong there (no Python, a failed import,
an error while drawing, no answer within :data:`TIMEOUT`) returns ``None``, and the caller
draws the mesh pictures itself.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["PictureProcess", "TIMEOUT"]

log = logging.getLogger(__name__)

TIMEOUT = 120.0
"""Seconds the run waits for the mesh pictures before it draws them itself."""
START = (
    "import os, sys\n"
    "if hasattr(os, 'nice'):\n"
    "    os.nice(19)\n"
    "from ngat.picture_process import serve\n"
    "sys.exit(serve())\n"
)
"""The process's program: its imports at the lowest priority, before ngat's own. On a core
that the run's threads need (Netgen's bisection, PARDISO's factorisations and METIS run on two)
they would hold back all of the run's threads: the refinements of the paper's example took 0.8 s
longer with the import at normal priority."""


class PictureProcess:
    """The mesh pictures of a results folder, drawn by a process started in advance."""

    def __init__(self) -> None:
        package_root = str(Path(__file__).resolve().parent.parent)
        path = os.environ.get("PYTHONPATH")
        environment = {
            **os.environ,
            # The process imports the ngat the run imported, installed or not.
            "PYTHONPATH": package_root if not path else os.pathsep.join([package_root, path]),
        }
        try:
            self._process: subprocess.Popen | None = subprocess.Popen(
                [sys.executable, "-c", START],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
                env=environment,
                start_new_session=True,
            )
        except OSError as error:
            log.debug("no picture process: %s", error)
            self._process = None

    def draw(self, folder: Path, slits: Sequence = ()) -> bool:
        """Ask for the mesh pictures of ``folder``; return at once (``False``: cannot be asked)."""
        if self._process is None:
            return False
        request = {"folder": str(folder), "slits": [[list(p) for p in slit] for slit in slits]}
        try:
            self._process.stdin.write(json.dumps(request) + "\n")
            self._process.stdin.flush()
        except OSError as error:  # the process has ended
            log.debug("picture process gone: %s", error)
            self.close()
            return False
        return True

    def result(self, timeout: float = TIMEOUT) -> list[Path] | None:
        """Return the pictures the process wrote, or ``None`` if it failed (then draw them)."""
        process, self._process = self._process, None
        if process is None:
            return None
        try:
            answer, _ = process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            log.debug("picture process: no answer within %g s", timeout)
            process.kill()
            process.communicate()
            return None
        try:
            reply = json.loads(answer.strip().splitlines()[-1])
        except (ValueError, IndexError):
            log.debug("picture process ended without an answer")
            return None
        if "error" in reply:
            log.debug("picture process: %s", reply["error"])
            return None
        return [Path(path) for path in reply["written"]]

    def close(self) -> None:
        """End the process (nothing asked, or no longer waited for)."""
        if self._process is None:
            return
        if self._process.poll() is None:
            self._process.kill()
        self._process.communicate()
        self._process = None


def serve() -> int:
    """Import the plotting, answer one request from standard input, return the exit status."""
    from ngat.plotting import plot_mesh_pictures

    line = sys.stdin.readline()
    if not line:
        return 0
    request = json.loads(line)
    try:
        written = plot_mesh_pictures(Path(request["folder"]), slits=request["slits"])
        reply = {"written": [str(path) for path in written]}
    except Exception as error:  # reported to the run, which then draws them itself
        reply = {"error": f"{type(error).__name__}: {error}"}
    print(json.dumps(reply), flush=True)
    return 0
