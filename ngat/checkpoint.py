"""Checkpoints: after a load step, everything a resumed run needs to continue exactly.

A run writes one once ``checkpoint_every`` seconds have passed since the last, after its last
step and before an error ends it (:class:`ngat.parameters.OutputParameters`).

A checkpoint is one file, ``checkpoint.npz`` in the results folder, written to a temporary file
and renamed over the old one, so a run killed at any moment leaves either the previous or the new
checkpoint, complete. It holds the state after the step it was written at, and nothing that grows
with the number of steps: the step, the summary entries a resumed run carries on
(:data:`CARRIED`), the nodal values of u, v and the previous step's v (which defines CR), the
lagged Cholesky factorisations' matrix values (they outlive a load step, see
:meth:`ngat.halfsteps.HalfStepSolvers.solver_state`) and the mesh. The records of the finished
steps are the rows of ``energies.csv``, written (and synced) before the checkpoint: a resumed
run reads them back from there (:func:`restore_energies`).

The mesh is stored as the list of its changes — the marked elements of every ``mesh.Refine()``
and every re-meshed region (:class:`ngat.remesh.Patch`, replayed by :func:`ngat.remesh.splice`
without Netgen) — plus its vertex coordinates as a check. A resumed run meshes the scene again
and replays the changes: Netgen's bisection keeps, per element, the edge to bisect next
(newest-vertex bisection), which a mesh file (``ngmesh.Save``) does not store, so a reloaded
mesh would be refined differently from then on (and the ``.vol`` file rounds the coordinates in
the last bit). Replaying gives the identical mesh, numbering and bisection state, which the
coordinates check.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import ngsolve
import numpy as np

from ngat.halfsteps import HalfStepSolvers
from ngat.output import (
    CHECKPOINT,
    OutputError,
    atomic_file,
    check_results_folder,
    times_summary,
    write_atomic,
    writing,
)
from ngat.parameters import computing, with_legacy_values
from ngat.remesh import Patch, splice
from ngat.results import parse_records
from ngat.state import ATState
from ngat.timing import WITHOUT_SOLVER_KEY

__all__ = [
    "Checkpoint",
    "save_checkpoint",
    "load_checkpoint",
    "finished_steps",
    "prepare_resume",
    "remove_checkpoint",
    "replay_refinements",
    "restore_state",
    "restore_energies",
    "CHECKPOINT",
    "CARRIED",
]

log = logging.getLogger(__name__)

FIELDS = ("u", "v", "v_prev", "v_change")
"""The fields a checkpoint keeps: u, v, v(t_{k−1}) and v(t_{k−1}) − v(t_{k−2}) (the
predictor's, :func:`ngat.minimization.predict_v`; older checkpoints have no ``v_change``)."""

CARRIED = (
    "timing",
    WITHOUT_SOLVER_KEY,
    "fracture_time",
    "refinement_history",
    "resumed_after_step",
    "diagnostics",
)
"""The summary entries gathered during the steps that the checkpoint keeps for a resumed run.

The refinement history has one entry per mesh refinement, as the refinement list of the mesh
itself: on a fixed mesh it does not grow. The diagnostics have one entry per problem found
(a step and kind each), which a healthy run does not have.
"""


@dataclass
class Checkpoint:
    """The content of ``checkpoint.npz``.

    Attributes
    ----------
    step
        Index of the last finished load step.
    identity
        ``scene``, ``parameters`` and ``times`` of the run, as in ``summary.json``.
    summary
        The summary entries of :data:`CARRIED` the run has.
    fields
        ``u``, ``v``, ``v_prev``, ``v_change``: nodal values (:data:`FIELDS`).
    refinements
        The mesh's changes in order: marked element indices of a refinement, or a re-meshed
        region (:class:`ngat.remesh.Patch`).
    coords
        Vertex coordinates of the mesh (checked after the replay).
    solvers
        :meth:`ngat.halfsteps.HalfStepSolvers.solver_state`.
    """

    step: int
    identity: dict[str, Any]
    summary: dict[str, Any]
    fields: dict[str, np.ndarray]
    refinements: list
    coords: np.ndarray
    solvers: dict[str, np.ndarray] = field(default_factory=dict)


def _plain(value: Any) -> Any:
    """JSON encoder fallback: numpy scalars and arrays to Python values."""
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot store {type(value).__name__} in a checkpoint")


def save_checkpoint(
    folder: Path,
    state: ATState,
    half_steps: HalfStepSolvers,
    step: int,
    summary: dict[str, Any],
) -> None:
    """Write ``folder/checkpoint.npz`` atomically (:func:`ngat.output.atomic_file`).

    Parameters
    ----------
    folder
        Results folder.
    state
        Fields, mesh and refinement list after the step.
    half_steps
        The half-steps' solvers after the step.
    step
        Index of the step just finished (its row is already in ``energies.csv``).
    summary
        The run's summary so far (its ``scene``, ``parameters`` and ``times`` identify the run;
        the entries of :data:`CARRIED` are kept).

    Raises
    ------
    OutputError
        If the write fails (:func:`ngat.output.writing`); the previous checkpoint is then kept.
    """
    meta = {
        "version": 2,
        "step": int(step),
        "identity": {key: summary[key] for key in ("scene", "parameters", "times")},
        "summary": {key: summary[key] for key in CARRIED if key in summary},
    }
    marks = [c for c in state.refinements if isinstance(c, np.ndarray)]
    arrays = {
        "meta": np.array(json.dumps(meta, default=_plain)),
        "u": state.u_values,
        "v": state.v_values,
        "v_prev": state.v_prev.vec.FV().NumPy(),
        "v_change": state.v_change.vec.FV().NumPy(),
        "coords": state.mesh.ngmesh.Coordinates(),
        "marks": np.concatenate(marks) if marks else np.zeros(0, dtype=np.int64),
        "mark_offsets": np.cumsum([0, *(len(m) for m in marks)]),
        **patch_arrays(state.refinements),
        **{f"solver_{key}": value for key, value in half_steps.solver_state().items()},
    }
    with writing(folder), atomic_file(Path(folder) / CHECKPOINT) as f:
        np.savez(f, **arrays)


def patch_arrays(changes: Sequence) -> dict[str, np.ndarray]:
    """Return the re-meshed regions among the mesh's changes as arrays, and where they fall.

    ``patch_after[i]`` is the number of refinements before the i-th patch; each patch's
    removed elements, points and elements are concatenated with their offsets.
    """
    patches = [c for c in changes if isinstance(c, Patch)]
    if not patches:
        return {}
    after = np.cumsum([isinstance(c, np.ndarray) for c in changes])
    position = [int(after[i]) for i, c in enumerate(changes) if isinstance(c, Patch)]
    arrays = {
        "patch_after": np.array(position),
        "patch_material": np.array([p.material for p in patches]),
        "patch_disc": np.array([[*p.centre, p.radius] for p in patches]),
    }
    for name in ("removed", "points", "elements"):
        parts = [getattr(p, name) for p in patches]
        arrays[f"patch_{name}"] = np.concatenate(parts)
        arrays[f"patch_{name}_offsets"] = np.cumsum([0, *(len(x) for x in parts)])
    return arrays


def with_patches(refinements: list[np.ndarray], data) -> list:
    """Insert the checkpoint's patches (:func:`patch_arrays`) among its refinements."""
    if "patch_after" not in data.files:
        return refinements
    changes: list = list(refinements)

    def parts(name: str) -> list[np.ndarray]:
        offsets = data[f"patch_{name}_offsets"]
        values = data[f"patch_{name}"]
        return [values[a:b] for a, b in zip(offsets[:-1], offsets[1:], strict=True)]

    removed, points, elements = parts("removed"), parts("points"), parts("elements")
    entries = zip(
        data["patch_after"], data["patch_material"], data["patch_disc"], removed, points,
        elements, strict=True,
    )  # fmt: skip
    for shift, (after, material, disc, *fields) in enumerate(entries):
        patch = Patch(
            removed=fields[0].astype(np.int64),
            points=fields[1].reshape(-1, 2),
            elements=fields[2].reshape(-1, 3).astype(np.int64),
            material=int(material),
            centre=disc[:2],
            radius=float(disc[2]),
        )
        changes.insert(int(after) + shift, patch)
    return changes


def load_checkpoint(folder: Path) -> Checkpoint | None:
    """Return the checkpoint of ``folder``, or ``None`` if it has none.

    Raises
    ------
    OutputError
        If the file cannot be read (it is only ever replaced whole, so this means it was
        truncated or damaged by something else).
    """
    path = Path(folder) / CHECKPOINT
    if not path.exists():
        return None
    # A damaged file makes zipfile, numpy or json raise almost anything (BadZipFile on a bad
    # CRC or a cut-off end, ValueError on a bad array header, KeyError on a renamed member).
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            offsets = data["mark_offsets"]
            marks = data["marks"]
            solvers = {
                key.removeprefix("solver_"): data[key]
                for key in data.files
                if key.startswith("solver_")
            }
            refinements = [marks[a:b] for a, b in zip(offsets[:-1], offsets[1:], strict=True)]
            return Checkpoint(
                step=meta["step"],
                identity=meta["identity"],
                summary={key: meta["summary"][key] for key in CARRIED if key in meta["summary"]},
                fields={key: data[key] for key in FIELDS if key in data.files},
                refinements=with_patches(refinements, data),
                coords=data["coords"],
                solvers=solvers,
            )
    except Exception as error:
        raise OutputError(
            f"checkpoint '{path}' is damaged ({type(error).__name__}: {error}), the run cannot "
            f"continue from it: start it afresh with --out {folder} --overwrite"
        ) from None


def finished_steps(folder: Path) -> int:
    """Return the number of load steps the checkpoint of ``folder`` holds.

    0 without a checkpoint or with a damaged one (:func:`load_checkpoint` says so).
    """
    path = Path(folder) / CHECKPOINT
    if not path.exists():
        return 0
    try:
        with np.load(path, allow_pickle=False) as data:
            return json.loads(str(data["meta"]))["step"] + 1
    except Exception:  # damaged: see load_checkpoint
        return 0


def remove_checkpoint(folder: Path) -> None:
    """Delete the checkpoint of ``folder`` (a fresh run must not leave a stale one)."""
    (Path(folder) / CHECKPOINT).unlink(missing_ok=True)


def check_identity(
    checkpoint: Checkpoint, scene: str, parameters: dict[str, Any], times: Sequence[float]
) -> None:
    """Raise :class:`OutputError` unless the checkpoint belongs to this scene and parameters."""
    ours = {"scene": scene, "parameters": computing(parameters), "times": times_summary(times)}
    theirs = dict(checkpoint.identity)
    theirs["parameters"] = computing(with_legacy_values(theirs.get("parameters", {})))
    differ = [key for key in ours if theirs.get(key) != ours[key]]
    if differ:
        raise OutputError(
            f"cannot resume: the checkpoint belongs to a run with another {' and '.join(differ)}; "
            "resume with the same scene, --quick and --set values, or start afresh with --overwrite"
        )


def prepare_resume(
    folder: Path, scene: str, parameters: dict[str, Any], times: Sequence[float]
) -> tuple[Checkpoint | None, list[dict[str, Any]]]:
    """Check that ``folder`` holds this run; cut ``energies.csv`` back to its checkpoint.

    Parameters
    ----------
    folder
        Results folder of the interrupted run.
    scene, parameters, times
        Scene name, flat parameters and load times of the run to resume.

    Returns
    -------
    checkpoint : Checkpoint or None
        The checkpoint; ``None`` if the run was interrupted before its first step ended.
    records : list of dict
        The records of the steps the checkpoint finished (:func:`restore_energies`).

    Raises
    ------
    OutputError
        If the folder holds no run, one of another scene, parameters or times, or fewer rows
        than its checkpoint finished steps.
    """
    check_results_folder(folder, scene, parameters, times, mode="resume")
    checkpoint = load_checkpoint(folder)
    if checkpoint is None:
        return None, []
    check_identity(checkpoint, scene, parameters, times)
    records = restore_energies(folder, checkpoint.step)
    log.info("resuming %s after step %d", folder, checkpoint.step)
    return checkpoint, records


def replay_refinements(mesh: ngsolve.Mesh, checkpoint: Checkpoint) -> ngsolve.Mesh:
    """Refine and re-mesh the scene's initial mesh as the interrupted run did; check it.

    Returns
    -------
    ngsolve.Mesh
        The mesh of the checkpoint (a new one if a region was re-meshed).

    Raises
    ------
    OutputError
        If the replayed mesh differs from the checkpoint's (the scene or Netgen changed).
    """
    for marked in checkpoint.refinements:
        if isinstance(marked, Patch):
            mesh, _ = splice(mesh, marked)
            continue
        flags = np.zeros(mesh.ne, dtype=bool)
        flags[marked] = True
        mesh.SetRefinementFlags(flags.tolist())
        mesh.Refine()
    coords = mesh.ngmesh.Coordinates()
    if coords.shape != checkpoint.coords.shape or not np.array_equal(coords, checkpoint.coords):
        raise OutputError(
            "cannot resume: meshing the scene and replaying its refinements does not give the "
            "checkpoint's mesh (was the scene or Netgen changed?); start afresh with --overwrite"
        )
    return mesh


def restore_state(state: ATState, half_steps: HalfStepSolvers, checkpoint: Checkpoint) -> None:
    """Set u, v, v(t_{k−1}), its last change, the refinement list and the factorisations.

    A checkpoint written before the predictor (:func:`ngat.minimization.predict_v`) has no
    ``v_change``: 0, so the next step starts from v(t_{k−1}).
    """
    state.u_values[:] = checkpoint.fields["u"]
    state.v_values[:] = checkpoint.fields["v"]
    state.v_prev.vec.FV().NumPy()[:] = checkpoint.fields["v_prev"]
    if "v_change" in checkpoint.fields:
        state.v_change.vec.FV().NumPy()[:] = checkpoint.fields["v_change"]
    state.refinements[:] = [
        m if isinstance(m, Patch) else np.asarray(m) for m in checkpoint.refinements
    ]
    half_steps.restore_solver_state(checkpoint.solvers)


def restore_energies(folder: Path, step: int) -> list[dict[str, Any]]:
    """Cut ``energies.csv`` back to the rows of steps 0, …, ``step``; return their records.

    A run writes a step's row before its checkpoint, and checkpoints every
    ``checkpoint_every`` seconds, so the file may hold rows of the steps after the checkpoint
    (the last one whole or cut short by a crash), which are dropped and computed again; the
    rows kept are the file's own bytes.

    Raises
    ------
    OutputError
        If the file lacks rows of the checkpoint's steps (it was deleted or changed), or the
        write fails (:func:`ngat.output.writing`).
    """
    path = Path(folder) / "energies.csv"
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        data = b""
    lines = data.splitlines(keepends=True)
    kept = b"".join(lines[: step + 2])
    text = kept.decode(errors="replace")
    records = parse_records(text.splitlines(keepends=True), path)
    if [r.get("step") for r in records] != list(range(step + 1)) or not kept.endswith(b"\n"):
        raise OutputError(
            f"cannot resume '{folder}': its energies.csv lacks rows of the {step + 1} steps its "
            f"checkpoint finished (was it deleted or changed?); start afresh with --out {folder} "
            "--overwrite"
        )
    if kept != data:
        with writing(folder):
            write_atomic(path, text)
    return records
