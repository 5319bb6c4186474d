"""One experiment in one call: a scene and its parameters in, a results folder and its pictures out.

``ngat.run("two-slits", out="results/x", eps=0.025)`` does in Python what ``ngat run two-slits
--out results/x --set eps=0.025`` does on the command line, and both go the same way:
:func:`plan_run` finds the scene, applies the parameter changes (checked as ``--set`` checks
them) and checks the results folder; :func:`ngat.driver.run` computes the load history;
:func:`pictures_on_exit` draws ``energies.png``, ``v_final.png``, ``mesh_final.png`` and
``mesh_zoom.png`` (plane models: also ``u_final.png``) when the run ends, however it ends.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ngat.checkpoint import finished_steps
from ngat.driver import StepCallback
from ngat.driver import run as run_history
from ngat.lock import folder_lock
from ngat.output import OutputError, check_results_folder
from ngat.parameters import ParameterError, Parameters
from ngat.results import RunResult, load_results
from ngat.scene import Scene, load_scene

__all__ = ["run", "plan_run", "RunPlan", "pictures_on_exit", "draw_pictures"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunPlan:
    """A run checked and ready to start.

    Attributes
    ----------
    scene
        The scene.
    parameters
        The scene's parameters with the changes applied.
    times
        Load times.
    folder
        Results folder.
    resume
        Continue the interrupted run in ``folder``.
    done
        Load steps already finished (when resuming).
    finished
        Resuming a run that is complete: nothing to compute.
    """

    scene: Scene
    parameters: Parameters
    times: np.ndarray
    folder: Path
    resume: bool = False
    done: int = 0
    finished: bool = False


def plan_run(
    scene: str | Path | Scene,
    out: str | Path | None = None,
    quick: bool = False,
    overwrite: bool = False,
    resume: bool = False,
    changes: Mapping[str, Any] | None = None,
    lock: ExitStack | None = None,
) -> RunPlan:
    """Find the scene, apply the parameter changes and check the results folder.

    Parameters
    ----------
    scene
        A scene name (``ngat scenes``), the path of a scene file or a :class:`Scene`.
    out
        Results folder; default ``results/<scene name>`` (``-quick`` appended with ``quick``).
    quick
        Use the scene's coarse, shortened variant.
    overwrite
        Replace a run already in the folder (other files in it are kept).
    resume
        Continue the interrupted run in the folder.
    changes
        Parameter name → value, strings (``--set``) or values of the parameter's type.
    lock
        Enter the folder's lock (:func:`ngat.lock.folder_lock`) into this stack before the
        folder is checked, so that the check and the run that follows are one step for other
        processes; without it the folder is checked unlocked (the run takes the lock itself).

    Raises
    ------
    SceneNotFound, SceneTimesError, SceneError, ParameterError, OutputError
        For bad input, naming the problem and the fix; nothing is written.
    """
    if overwrite and resume:
        raise ParameterError("overwrite and resume exclude each other: give one of them")
    if not isinstance(scene, Scene):
        scene = load_scene(str(scene))
    parameters, times = scene.configure(quick, changes)
    folder = Path(out or f"results/{scene.name}{'-quick' if quick else ''}")
    if resume and not folder.is_dir():
        raise OutputError(
            f"cannot resume '{folder}': it holds no run (there is no such folder); check the path"
        )
    if lock is not None:
        lock.enter_context(folder_lock(folder))
    mode = "resume" if resume else "overwrite" if overwrite else "new"
    existing = check_results_folder(folder, scene.name, parameters.flat(), times, mode)
    finished = resume and (existing or {}).get("status") == "completed"
    done = finished_steps(folder) if resume else 0
    return RunPlan(scene, parameters, times, folder, resume, done, finished)


def draw_pictures(folder: Path, slits: Sequence = ()) -> list[Path]:
    """Draw the pictures a run leaves: energies, final v, the final mesh, whole and zoomed.

    Plane models add |u| on the deformed body (``u_final.png``).

    v is drawn with matplotlib (no VTK window, nothing printed); ``ngat plot`` draws the same
    set and more (snapshots of v) with VTK where it can.

    Parameters
    ----------
    folder
        Results folder.
    slits
        The scene's slits (the zoom centres on the first one's crack tip).

    Returns
    -------
    list of Path
        The pictures written; none if the folder holds no finished step yet.
    """
    from ngat.plotting import PlotError, plot_results

    begin = time.perf_counter()
    try:
        written = plot_results(folder, times=[], slits=slits, renderer="matplotlib")
    except PlotError:
        log.debug("%s: no finished step, no pictures", folder)
        return []
    names = ", ".join(path.name for path in written)
    log.info("pictures in %.1f s: %s", time.perf_counter() - begin, names)
    return written


def _energies_stamp(folder: Path) -> tuple[int, int] | None:
    """Return size and modification time of the folder's ``energies.csv`` (None: none)."""
    try:
        stat = (Path(folder) / "energies.csv").stat()
    except OSError:
        return None
    return stat.st_size, stat.st_mtime_ns


@contextmanager
def pictures_on_exit(folder: Path, slits: Sequence = (), enabled: bool = True) -> Iterator[None]:
    """Draw the run's pictures (:func:`draw_pictures`) when the block ends, however it ends.

    A block that raises (a failed or interrupted run) still gets the pictures of what its
    folder holds, and its own exception goes on: a failure to draw is then only logged. A block
    that raises before it wrote a load step (bad input found on the way in, e.g. a damaged
    checkpoint) draws nothing: the folder stays as it was.

    Parameters
    ----------
    folder
        Results folder.
    slits
        The scene's slits.
    enabled
        ``False``: draw nothing (``--no-plots``).
    """
    before = _energies_stamp(folder)
    try:
        yield
    except BaseException:
        if enabled and _energies_stamp(folder) != before:
            try:
                draw_pictures(folder, slits)
            except Exception as error:  # the run's own error matters, not the pictures'
                log.info("pictures not drawn: %s: %s", type(error).__name__, error)
        raise
    if enabled:
        draw_pictures(folder, slits)


def run(
    scene: str | Path | Scene,
    out: str | Path | None = None,
    *,
    quick: bool = False,
    overwrite: bool = False,
    resume: bool = False,
    plots: bool = True,
    on_step: StepCallback | None = None,
    **parameters: Any,
) -> RunResult:
    """Run a scene's load history, write its results folder and pictures, return its results.

    ``ngat.run(scene, out, quick=..., eps=0.025)`` is ``ngat run SCENE --out OUT [--quick]
    --set eps=0.025``.

    Parameters
    ----------
    scene
        A scene name (``ngat scenes``), the path of a scene file or a :class:`Scene`.
    out
        Results folder; default ``results/<scene name>`` (``-quick`` appended with ``quick``).
    quick
        Use the scene's coarse, shortened variant.
    overwrite
        Replace a run already in the folder (other files in it are kept); without it, a folder
        that holds a run is refused.
    resume
        Continue the interrupted run in the folder (same scene, parameters and times).
    plots
        Draw ``energies.png``, ``v_final.png``, ``mesh_final.png`` and ``mesh_zoom.png`` (plane
        models: also ``u_final.png``) when the run ends (:func:`draw_pictures`); also after a
        failure, for the steps it finished.
    on_step
        Called with each load step's record as the step ends.
    **parameters
        Parameter changes by name (``eps=0.025``, ``adapt="paper"``; see
        :class:`ngat.parameters.Parameters`), checked as ``--set`` checks them.

    Returns
    -------
    RunResult
        Records (also as :attr:`~RunResult.columns`), summary, final fields and state, folder.

    Raises
    ------
    SceneNotFound, SceneTimesError, SceneError, ParameterError, OutputError
        For bad input (before anything is written).
    """
    plan = plan_run(scene, out, quick, overwrite, resume, parameters)
    if plan.finished:
        log.info("nothing to resume: the run in %s is complete", plan.folder)
        return load_results(plan.folder)
    with pictures_on_exit(plan.folder, plan.scene.slits, plots):
        return run_history(
            plan.scene, plan.parameters, plan.times, plan.folder, on_step, resume=plan.resume
        )
