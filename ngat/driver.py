"""The load-history driver: for each t_k update CR, solve the step, record, write.

For k = 0, 1, …: CR(t_k) = {v(t_{k−1}) < CRTOL} (paper, Section 1.2), u = g(t_k) on Ω_D, the
alternating minimisation from v(t_{k−1}) (Algorithm 1), then the energies (eq. 7), reaction
forces, mesh measures and timings go to ``energies.csv``, the fields (every ``output_every``-th
step and the last) to ``fields.pvd``, and the state to the checkpoint (every
``checkpoint_every`` seconds, after the last step and before an error ends the run); what a
step writes does not grow with the steps before it.
A run holds its folder's lock throughout (:mod:`ngat.lock`), and however it ends its
``summary.json`` records how: ``completed``, ``interrupted`` (KeyboardInterrupt: SIGINT, or
SIGTERM by the command line) or ``failed: ERROR`` — unless the disk is too full even for that.
"""

from __future__ import annotations

import contextlib
import logging
import platform
import signal
import threading
import time
from collections.abc import Callable, Iterator
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np

from ngat import __version__, pardiso
from ngat.band import CrackBand
from ngat.checkpoint import (
    prepare_resume,
    remove_checkpoint,
    replay_refinements,
    restore_state,
    save_checkpoint,
)
from ngat.crack import check_slits, connects, tips_of
from ngat.diagnostics import Diagnostics, check_fixed_mesh
from ngat.extension import CrackExtension
from ngat.halfsteps import HalfStepSolvers
from ngat.lock import folder_lock
from ngat.minimization import (
    ConvergenceError,
    HalfStepMonitor,
    alternating_minimization,
    estimate,
    predict_v,
    predicted_v,
)
from ngat.output import OutputError, ResultsWriter, vtu_name
from ngat.parameters import Parameters
from ngat.remesh import TipRemesher
from ngat.results import RunResult
from ngat.scene import Scene
from ngat.state import ATState
from ngat.strategies import nonlinear_strategy
from ngat.threads import CoreUse, FixedThreads
from ngat.timing import WITHOUT_SOLVER_KEY, PhaseTimer

__all__ = ["run"]

log = logging.getLogger(__name__)

StepCallback = Callable[[dict[str, Any]], None]


def versions() -> dict[str, str]:
    """Return the versions of Python and the packages a run depends on.

    ``mkl`` is MKL PARDISO's version, or ``"none"`` where ngat factorises with NGSolve's sparse
    Cholesky (:mod:`ngat.pardiso`).
    """
    result = {"python": platform.python_version(), "ngat": __version__}
    for package in ("ngsolve", "numpy", "scipy"):
        result[package] = version(package)
    result["mkl"] = version("mkl") if pardiso.AVAILABLE else "none"
    return result


def crack_measures(state: ATState, scene: Scene) -> dict[str, Any]:
    """Return the tip of each slit's crack and whether {v ≥ 0.1} connects the Ω_D regions."""
    measures: dict[str, Any] = {}
    tips = tips_of(state, scene.slits)
    for i, (x, y) in enumerate(tips, start=1):
        measures[f"tip{i}_x"], measures[f"tip{i}_y"] = x, y
    regions = list(state.region_vertices.values())
    if len(regions) >= 2:
        measures["connected"] = connects(state.arrays, state.v_values, regions[0], regions[1])
    return measures


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back until the block ends, then deliver the first one.

    Around the writes of a load step: its row, fields and checkpoint are written whole or not
    at all.
    Python handles signals in the main thread only; elsewhere (a sweep's worker) this does
    nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = {
        number: signal.signal(number, lambda number, frame: held.append(number))
        for number in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, signal.SIG_DFL if handler is None else handler)
        if held:
            signal.raise_signal(held[0])


def crack_band(scene: Scene, parameters: Parameters) -> CrackBand | None:
    """Return the crack band of ``adapt="band"`` (:mod:`ngat.band`), else ``None``."""
    adaptivity, eps = parameters.adaptivity, parameters.model.eps
    if adaptivity.adapt != "band":
        return None
    return CrackBand(
        eps, adaptivity.band_h, scene.slits, adaptivity.floor * eps,
        grading=adaptivity.band_grading, search=adaptivity.band_search,
        onset_h=adaptivity.onset_h,
    )  # fmt: skip


def tip_remesher(scene: Scene, parameters: Parameters) -> TipRemesher | None:
    """Return the re-meshing about crack tips of ``remesh_radius`` > 0 (:mod:`ngat.remesh`)."""
    adaptivity = parameters.adaptivity
    if adaptivity.adapt != "band" or adaptivity.remesh_radius == 0 or not scene.slits:
        return None
    return TipRemesher(parameters.model.eps, scene.slits, adaptivity.remesh_radius)


def step_ratio(times: np.ndarray, k: int) -> float:
    """Return (t_k − t_{k−1}) / (t_{k−1} − t_{k−2}), the predictor's ratio (k ≥ 2)."""
    return float((times[k] - times[k - 1]) / (times[k - 1] - times[k - 2]))


def prepare_next_step(
    state: ATState,
    half_steps: HalfStepSolvers,
    predictor: bool,
    times: np.ndarray,
    k: int,
) -> None:
    """Start factorising the first a_j of load step ``k`` as soon as step k − 1 has converged.

    Step k's alternating minimisation starts from v(t_{k−1}), or from its prediction
    (:func:`ngat.minimization.predicted_v`), with v = 0 on CR(t_k): known once v(t_{k−1}) is, so
    its a_j factorises in the background (:meth:`ngat.halfsteps.HalfStepSolvers.prepare_u`)
    while step k − 1's estimators, measures, fields and checkpoint are computed and written.
    A refinement at the start of step k makes it a waste of the idle core, never a wrong
    number. Call before ``state.v_prev`` becomes v(t_{k−1}).
    """
    v = state.v_values
    pointwise = state.model.irreversibility == "pointwise"
    predicted = None
    if predictor and k >= 2:
        change = v - state.v_prev.vec.FV().NumPy()
        predicted = predicted_v(v, change, step_ratio(times, k), v if pointwise else 1.0)
    start = v.copy() if predicted is None else predicted
    start[state.crack_set(previous=v)] = 0.0
    half_steps.prepare_u(start)


def run(
    scene: Scene,
    parameters: Parameters,
    times: np.ndarray,
    folder: Path,
    on_step: StepCallback | None = None,
    monitor: HalfStepMonitor | None = None,
    resume: bool = False,
) -> RunResult:
    """Run the load history of ``scene`` and write its results folder.

    Parameters
    ----------
    scene
        Geometry, loads and crack of the experiment.
    parameters
        Model, solver and adaptivity parameters.
    times
        Load times t_0 < t_1 < ….
    folder
        Results folder.
    on_step
        Called with each step's record (progress display).
    monitor
        Called after every half-step of the alternating minimisation (tests, diagnostics, the
        progress display of ``ngat run``).
    resume
        Continue the interrupted run in ``folder`` from its checkpoint (same scene, parameters
        and times, else :class:`~ngat.output.OutputError`); the result is the same as that of
        an uninterrupted run. Without a checkpoint the run starts from the first step.

    Returns
    -------
    RunResult
        Records, summary, the final state and the folder.

    Raises
    ------
    FolderInUse
        If another run holds the folder (:mod:`ngat.lock`).
    """
    with folder_lock(folder):
        return _run_locked(scene, parameters, times, Path(folder), on_step, monitor, resume)


def _run_locked(
    scene: Scene,
    parameters: Parameters,
    times: np.ndarray,
    folder: Path,
    on_step: StepCallback | None,
    monitor: HalfStepMonitor | None,
    resume: bool,
) -> RunResult:
    """:func:`run`, with the folder locked."""
    checkpoint, records = (
        prepare_resume(folder, scene.name, parameters.flat(), times) if resume else (None, [])
    )
    earlier = checkpoint.summary if checkpoint else {}
    timer = PhaseTimer(earlier.get("timing"), earlier.get(WITHOUT_SOLVER_KEY))
    output = parameters.output
    stored = [
        (r["t"], vtu_name(r["step"]))
        for r in records
        if output.writes_fields(r["step"], len(times))
    ]
    writer = ResultsWriter(folder, append=checkpoint is not None, stored=stored)
    result = RunResult(records=records, folder=Path(folder))
    summary = result.summary
    summary.update(
        scene=scene.name,
        parameters=parameters.flat(),
        times={"first": float(times[0]), "last": float(times[-1]), "count": len(times)},
        versions=versions(),
        status="running",
        refinement_history=[],
    )
    # -- checkpoints: a fresh run drops a stale one, a resumed run continues from it -----------
    if checkpoint is None:
        remove_checkpoint(folder)
    else:
        summary.update({**checkpoint.summary, "status": "running", "versions": versions()})
        summary.setdefault("resumed_after_step", []).append(checkpoint.step)
    diagnostics = Diagnostics(parameters.solver.on_problem)
    diagnostics.problems.extend(summary.get("diagnostics", []))
    threads, cores = FixedThreads(), CoreUse()
    try:
        summary["threads"] = threads.summary()
        writer.write_summary(summary)
        with timer("mesh"):
            mesh = scene.make_mesh(parameters.adaptivity.maxh)
            if checkpoint is not None:
                mesh = replay_refinements(mesh, checkpoint)
        solver = parameters.solver
        state = ATState(mesh, parameters.model, scene.loads, scene.crack, timer)
        # One set of solvers for the run: their factorisations outlive a load step.
        half_steps = HalfStepSolvers.from_parameters(state, solver)
        strategy = nonlinear_strategy(solver)
        check_slits(mesh, scene.slits, scene.name)
        if parameters.adaptivity.adapt == "fixed" and parameters.adaptivity.resolve_eps:
            check_fixed_mesh(state, scene.slits, parameters.model.eps)
        if checkpoint is not None:
            restore_state(state, half_steps, checkpoint)
        result.state = state
        band = crack_band(scene, parameters)
        extension = (
            CrackExtension(parameters.model.eps, scene.slits, band)
            if solver.crack_extension and scene.slits
            else None
        )
        remesher = tip_remesher(scene, parameters)
        if warning := cores.warning(threads.factorisation):  # sampled while the run set up
            log.warning(warning)
        log.info("scene %s: %d elements, %d load steps", scene.name, mesh.ne, len(times))
        checkpointed = time.perf_counter()
        for k, t in enumerate(times):
            if k < len(result.records):
                continue
            begin = time.perf_counter()
            state.apply_load(float(t))
            remeshed = remesher.remesh(state) if remesher else 0
            predicted = band.refine(state) if band else 0
            if solver.predictor and k >= 2:
                predict_v(state, step_ratio(times, k))
            try:
                step = alternating_minimization(
                    state,
                    solver,
                    parameters.adaptivity,
                    monitor,
                    band,
                    half_steps,
                    strategy,
                    extension,
                )
            except ConvergenceError as error:
                diagnostics.report("nan", str(error), k, float(t), raise_now=False)
                raise
            crack = state.crack_set()
            forces = half_steps.operators.reaction_forces()
            if k + 1 < len(times):
                prepare_next_step(state, half_steps, solver.predictor, times, k + 1)
            mu = step.mu  # the last u-step's, Algorithm 2's test; ν is the final pair's
            if mu is None:  # an iteration that does not estimate: μ of the final pair
                mu = float(np.sqrt(estimate(state, "u", crack).sum()))
            record = {"step": k, "t": float(t), **state.energies(), **forces}
            record.update(
                am_iterations=step.iterations,
                converged=step.converged,
                refinements=step.refinements + predicted,
                band_refinements=step.band_refinements + predicted,
                remeshed=remeshed,
                mu=mu,
                nu=float(np.sqrt(estimate(state, "v", crack).sum())),
                **state.mesh_measures(),
                cracked_vertices=int(crack.sum()),
                v_bound_active=step.bound_active,
                linear_solves=step.linear_solves,
                cg_iterations=step.cg_iterations,
                cg_max_iterations=step.cg_max_iterations,
                fallbacks=step.fallbacks,
                newton_steps=step.newton_steps,
                escapes=step.escapes,
                extensions=step.extensions,
                curvature_solves=step.curvature_solves,
            )
            record.update(crack_measures(state, scene))
            if "fracture_time" not in summary and record.get("connected") is False:
                summary["fracture_time"] = float(t)
            summary["refinement_history"].extend({"step": k, **h} for h in step.history)
            problems = diagnostics.check_step(
                state, step, parameters.model.eps, k, float(t), raise_now=False
            )
            record["warnings"] = " ".join(problems)
            state.v_change.vec.data = state.v.vec - state.v_prev.vec
            state.v_prev.vec.data = state.v.vec
            record["wall_s"] = round(time.perf_counter() - begin, 4)
            fields = {"u": state.u, "v": state.v} if output.writes_fields(k, len(times)) else None
            with signals_held():
                with timer("output"):
                    writer.write_step(record, state.arrays, fields)
                if diagnostics.pending or output.checkpoint_due(
                    k, len(times), time.perf_counter() - checkpointed
                ):
                    summary["timing"] = timer.summary()
                    summary[WITHOUT_SOLVER_KEY] = timer.without_solver()
                    summary["diagnostics"] = diagnostics.summary()
                    with timer("checkpoint"):
                        writer.sync()  # the rows before the checkpoint that counts them
                        save_checkpoint(folder, state, half_steps, k, summary)
                    checkpointed = time.perf_counter()
                # The records of a failed write do not hold the step; --resume goes on from
                # the last checkpoint and computes the steps after it again.
                result.records.append(record)
            log.info(
                "step %d t=%.4g: %d iterations, total %.6g, %d elements",
                k,
                t,
                step.iterations,
                record["total"],
                record["elements"],
            )
            if on_step:
                on_step(record)
            diagnostics.raise_if_error()
        summary["status"] = "completed"
    except KeyboardInterrupt:
        summary["status"] = "interrupted"
        raise
    except BaseException as error:
        summary["status"] = f"failed: {type(error).__name__}: {error}"
        raise
    finally:
        writer.close()
        summary["steps"] = len(result.records)
        summary["am_iterations"] = int(sum(r["am_iterations"] for r in result.records))
        if result.records:
            last = result.records[-1]
            summary["final"] = {key: last[key] for key in ("step", "t", "bulk", "surface", "total")}
            summary["final"].update(elements=last["elements"], h_min=last["h_min"])
        summary["timing"] = timer.summary()
        summary[WITHOUT_SOLVER_KEY] = timer.without_solver()
        summary["diagnostics"] = diagnostics.summary()
        threads.restore()
        try:
            writer.write_summary(summary)
        except OutputError:
            if summary["status"] == "completed":
                raise
            # The run's own error, often the same full disk, is the one to report. The space
            # the writer reserved holds the summary without the entries the checkpoint keeps
            # too (--resume restores them).
            kept = {"refinement_history", "diagnostics"}
            try:
                writer.write_summary({k: v for k, v in summary.items() if k not in kept})
            except OutputError:
                log.warning("summary.json could not record how the run ended")
    return result
