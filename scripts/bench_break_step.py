"""Benchmark: the break step of the paper's example alone, iteration by iteration.

Question: where does the load step in which the cracks run through the body (two thirds of
the wall of ``ngat run two-slits``) spend its iterations and its seconds: how many iterations
while the cracks creep, how many on a new mesh while they run, how many while the broken body
settles, and does a change of the code or of a parameter shorten it without changing the
answer?

The load history is run once up to the step before ``--at`` (default t = 1.40, the default
run's fracture time) with a checkpoint after every step, into ``--out``/``checkpoint`` (kept
and reused while the scene, ``--quick`` and ``--set`` are the same: a study of the code can
resume every variant from one state). Each of ``--repeats`` runs (default 3) copies that
folder and resumes it (``ngat.driver.run(..., resume=True)``) for the one step at ``--at``;
a resumed step is the uninterrupted run's to the last bit, so the repeats must agree exactly
(``repeatable``), and their wall times measure the machine's noise.

The step is chaotic: a change at round-off level sends the cracks along another path, with
other iteration counts (the paper's break step: 132–142 iterations over six such draws). One
draw therefore says little about a change of the code; ``--samples K`` resumes K more copies
whose v is multiplied by 1 − 1e−9 r (r uniform in [0, 1), seeds 1 … K: a perturbation at
round-off level that keeps 0 ≤ v ≤ 1 and the crack set), and reports each draw and their
median, so that two versions compare by their distributions.

Output in ``--out`` (default ``results/bench_break_step``): ``bench.json`` (iterations, linear
solves, Newton steps and escapes, refinements, elements and I_j before and after, the step's
wall median/min/max, the iterations that started on a new mesh and their seconds),
``trace.csv`` (per iteration of the first repeat: seconds since the step began, elements,
‖v^n − v^{n−1}‖_∞, I_j after the v-step) and ``trace.png`` (the trace against the
iteration). Run ``python scripts/bench_break_step.py`` (the paper's example, about 11 s for the
checkpoint and 20 s per repeat on two cores) or ``--quick`` (the scene's quick variant).
``--seed S`` perturbs every repeat's copy with seed S (0: none).

``--to-end`` resumes the rest of the load history too, from the step at ``--at`` to the last
load time, and reports it as one: iterations, solves, Newton steps, escapes, refinements and
wall summed over its steps, I_j and the elements of the last. A variant that shortens the
break step may leave the broken body less settled, and the steps after it pay that back
(stop 65's deferred estimators: the break step 0.849 times main's over five draws, the rest of
the history 1.055): a change of the solver is judged on this, not on the break step alone.

Comparison: the machine's speed drifts by a third or more within an hour, so two versions
measured one script run after the other differ by the hour as much as by the code.
``--against REV`` resumes the step for every draw (the unperturbed one and ``--samples``
perturbed ones) with the current tree and with REV, one after the other, the order flipping
from draw to draw (a worktree of REV, removed at the end, as in ``bench_paper.py``). Each run
is this script's one-draw mode (``--repeats 1 --seed S``) in a process of its own with
``PYTHONPATH`` at the checkout's root, with a checkpoint of that checkout's own history, made
anew, in ``--out``/current or ``--out``/against. Output: ``compare.md`` (also printed) and
``compare.json``: each draw's iterations, linear solves, I_j after, elements and wall on both
sides, their medians, and the ratio current/REV of the median walls and of each draw's.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import ngat
from ngat.driver import run
from ngat.experiment import plan_run
from ngat.output import OutputError
from ngat.rendering import DPI, PNG
from ngat.results import read_records


class Stop(Exception):
    """Ends a run after the step it was started for."""


def step_index(times: np.ndarray, at: float) -> int:
    """Return the index of the load time ``at``; ``ValueError`` unless it is one after the first."""
    matches = np.flatnonzero(np.isclose(times, at, rtol=0, atol=1e-9))
    if len(matches) == 0 or matches[0] == 0:
        raise ValueError(f"--at {at} is not a load time of the scene after its first")
    return int(matches[0])


def stop_after(step: int):
    """Return an ``on_step`` callback that raises :class:`Stop` after load step ``step``."""

    def on_step(record: dict) -> None:
        if record["step"] >= step:
            raise Stop

    return on_step


def checkpoint_before(scene: str, quick: bool, changes: dict, at: float, folder: Path) -> int:
    """Make (or reuse) the run in ``folder`` stopped after the step before ``at``.

    Returns the index of the step at ``at``.
    """
    try:
        plan = plan_run(scene, out=folder, quick=quick, resume=True, changes=changes)
        k = step_index(plan.times, at)
        if plan.done == k:
            return k
    except OutputError:
        pass  # another scene, --quick or --set: made afresh
    plan = plan_run(scene, out=folder, quick=quick, overwrite=True, changes=changes)
    k = step_index(plan.times, at)
    try:
        run(plan.scene, plan.parameters, plan.times, plan.folder, on_step=stop_after(k - 1))
    except Stop:
        pass
    return k


PERTURBATION = 1e-9
"""Relative size of the perturbation of v in a sample (``--samples``)."""


def perturb(folder: Path, seed: int) -> None:
    """Multiply v in the checkpoint of ``folder`` by 1 − :data:`PERTURBATION` · r, r ~ U[0, 1)."""
    path = folder / "checkpoint.npz"
    with np.load(path, allow_pickle=False) as stored:
        arrays = dict(stored)
    r = np.random.default_rng(seed).random(len(arrays["v"]))
    arrays["v"] = arrays["v"] * (1 - PERTURBATION * r)
    np.savez(path, **arrays)


SUMMED = ("am_iterations", "linear_solves", "newton_steps", "escapes", "refinements", "wall_s")
"""The columns of a step's record that :func:`combined` sums over the steps."""


def combined(records: list[dict]) -> dict:
    """Return the steps' records as one: the last step's record with the :data:`SUMMED` summed."""
    return records[-1] | {key: round(sum(r[key] for r in records), 4) for key in SUMMED}


def break_step(
    scene: str,
    quick: bool,
    changes: dict,
    source: Path,
    work: Path,
    k: int,
    seed: int = 0,
    to_end: bool = False,
):
    """Resume a copy of ``source`` for step ``k``; return its record and the per-iteration trace.

    With ``seed`` > 0 the copy's v is perturbed first (:func:`perturb`). With ``to_end`` the
    run goes on to the last load time, and the record is that of the steps from ``k`` on
    (:func:`combined`).
    """
    shutil.rmtree(work, ignore_errors=True)
    shutil.copytree(source, work)
    if seed:
        perturb(work, seed)
    plan = plan_run(scene, out=work, quick=quick, resume=True, changes=changes)
    trace: list[dict] = []
    begin = None

    def monitor(stage: str, state) -> None:
        nonlocal begin
        now = time.perf_counter()
        if begin is None:
            begin = now  # the step's first half-step has ended: close enough
        if stage != "v":
            return
        change = float(np.max(np.abs(state.v_values - state.v_iter.vec.FV().NumPy())))
        trace.append(
            {"iteration": len(trace) + 1, "seconds": now - begin,
             "elements": state.arrays.ne, "change": change,
             "total": state.energies()["total"]}
        )  # fmt: skip

    records: list[dict] = []

    def on_step(record: dict) -> None:
        records.append(record)
        if not to_end:
            raise Stop

    try:
        run(plan.scene, plan.parameters, plan.times, plan.folder, on_step, monitor, resume=True)
    except Stop:
        pass
    return combined(records), trace


def new_mesh_iterations(trace: list[dict]) -> tuple[int, float]:
    """Return the iterations that ended on another mesh than the one before, and their seconds."""
    count, seconds = 0, 0.0
    for before, now in zip(trace, trace[1:], strict=False):
        if now["elements"] != before["elements"]:
            count += 1
            seconds += now["seconds"] - before["seconds"]
    return count, seconds


OUTCOME = {"iterations": "am_iterations", "linear_solves": "linear_solves",
           "total_after": "total", "elements_after": "elements"}  # fmt: skip
"""What a step computed, by the names of ``bench.json`` (the wall aside)."""


def outcome(record: dict) -> dict:
    """Return the :data:`OUTCOME` of a step's record."""
    return {name: record[key] for name, key in OUTCOME.items()}


def sample_summary(records: list[dict]) -> dict:
    """Return the draws (the unperturbed step first) and the median of each measure."""
    each = [outcome(r) | {"wall_s": r["wall_s"]} for r in records]
    return {
        "draws": each,
        "median": {name: statistics.median(d[name] for d in each) for name in each[0]},
    }


def draw_trace(trace: list[dict], path: Path, to_end: bool = False) -> None:
    """Draw ‖Δv‖∞, elements and seconds per iteration against the iteration into ``path``.

    ``to_end``: the trace runs on through the steps after the break step (``--to-end``).
    """
    from matplotlib.figure import Figure

    iteration = np.array([r["iteration"] for r in trace])
    seconds = np.diff(np.concatenate([[0.0], [r["seconds"] for r in trace]]))
    fig = Figure(figsize=(7, 7), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    axes[0].semilogy(iteration, [r["change"] for r in trace], "k.-", markersize=3)
    axes[0].set_ylabel(r"$\|v^n - v^{n-1}\|_\infty$")
    axes[1].step(iteration, [r["elements"] for r in trace], where="mid", color="C2")
    axes[1].set_ylabel("elements")
    axes[2].bar(iteration, seconds, width=0.8, color="C0")
    axes[2].set_ylabel("seconds")
    axes[2].set_xlabel(
        "iteration from the break step to the end" if to_end else "iteration of the break step"
    )
    for ax in axes:
        ax.grid(True, lw=0.3, alpha=0.5)
    fig.savefig(path, dpi=DPI, pil_kwargs=PNG)


def _bench_paper():
    """Return ``bench_paper.py`` (its worktree, description and signal helpers), by its path."""
    spec = importlib.util.spec_from_file_location(
        "bench_paper", Path(__file__).with_name("bench_paper.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def draw_child(root: Path, words: list[str], out: Path) -> dict:
    """Return one draw run by this script in a process with only ``root`` on PYTHONPATH."""
    command = [sys.executable, str(Path(__file__).resolve()), "--repeats", "1", "--out", str(out)]
    environment = {**os.environ, "PYTHONPATH": str(root)}
    done = subprocess.run(
        [*command, *words], env=environment, stdout=subprocess.DEVNULL, check=False
    )
    if done.returncode:
        raise SystemExit(f"the break step in {root} failed with exit status {done.returncode}")
    bench = json.loads((out / "bench.json").read_text())
    if not Path(bench["ngat"]).is_relative_to(root.resolve()):
        raise SystemExit(f"the run for {root} imported ngat from {bench['ngat']}")
    return {name: bench[name] for name in [*OUTCOME, "iterations_on_a_new_mesh"]} | {
        "wall_s": bench["wall_s"]["each"][0]
    }


def compare(revision: str, samples: int, words: list[str], out: Path) -> dict:
    """Resume the step for each draw with the current tree and with ``revision``, alternating."""
    checkouts = _bench_paper()
    signal.signal(signal.SIGTERM, checkouts.stop)
    labels = {"current": checkouts.describe(None), "against": checkouts.describe(revision)}
    draws = []
    for name in labels:  # each side's checkpoint made anew by its own code
        shutil.rmtree(out / name, ignore_errors=True)
    with checkouts.worktree(revision) as checkout:
        roots = {"current": checkouts.ROOT, "against": checkout}
        for seed in range(samples + 1):
            draw: dict = {"seed": seed}
            for name in ("current", "against")[:: 1 if seed % 2 == 0 else -1]:
                draw[name] = draw_child(roots[name], [*words, "--seed", str(seed)], out / name)
                print(f"draw {seed} {labels[name]}: {draw[name]['wall_s']} s")
            draws.append(draw)
    median = {  # the middle draw's figure (the lower of two: a value some draw had)
        name: {key: statistics.median_low(d[name][key] for d in draws) for key in draws[0][name]}
        for name in ("current", "against")
    }
    comparison = {
        "against": revision, "variant": words, "labels": labels, "draws": draws,
        "median": median,
        "wall_ratio": round(median["current"]["wall_s"] / median["against"]["wall_s"], 3),
        "draw_ratios": [round(d["current"]["wall_s"] / d["against"]["wall_s"], 3) for d in draws],
    }  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    (out / "compare.json").write_text(json.dumps(comparison, indent=2))
    markdown = compare_table(comparison)
    (out / "compare.md").write_text(markdown + "\n")
    print(markdown)
    return comparison


COLUMNS = {
    "iterations": "{}",
    "linear_solves": "{}",
    "total_after": "{:.6f}",
    "elements_after": "{:,}",
    "iterations_on_a_new_mesh": "{}",
    "wall_s": "{:.1f}",
}
"""The figures of a draw in :func:`compare_table`, with their format."""


def compare_table(comparison: dict) -> str:
    """Return the Markdown table of :func:`compare`: current / REV in every cell."""

    def cells(row: dict) -> str:
        return " | ".join(
            f"{form.format(row['current'][key])} / {form.format(row['against'][key])}"
            for key, form in COLUMNS.items()
        )

    labels = comparison["labels"]
    words = comparison["variant"]
    what = "the load history from the break step on" if "--to-end" in words else "the break step"
    lines = [
        f"{' '.join(words)}: {what}, {labels['current']} / "
        f"{labels['against']} in each cell, alternating draw by draw (draw 0 unperturbed).",
        "",
        "| draw | iterations | linear solves | I_j after | elements | iterations on a new "
        "mesh | wall [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += [f"| {d['seed']} | {cells(d)} |" for d in comparison["draws"]]
    median = comparison["median"]
    lines.append(f"| median | {cells(median)} |")
    ratios = ", ".join(f"{r:.3f}" for r in comparison["draw_ratios"])
    lines += ["", f"Median wall current / {comparison['against']}: {comparison['wall_ratio']:.3f}",
              f"Draw by draw: {ratios}"]  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="two-slits")
    parser.add_argument("--quick", action="store_true", help="the scene's quick variant")
    parser.add_argument("--at", type=float, default=1.40, help="load time of the break step")
    parser.add_argument("--repeats", type=int, default=3, help="resumed runs of the step")
    parser.add_argument(
        "--samples", type=int, default=0, help="resumed runs with v perturbed at round-off level"
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="perturb every repeat's v with this seed (0: none)"
    )
    parser.add_argument("--set", nargs="*", default=[], help="parameter changes, NAME=VALUE")
    parser.add_argument(
        "--to-end",
        action="store_true",
        help="resume the load history to its end, not only the step at --at",
    )
    parser.add_argument(
        "--against", metavar="REV", help="compare with this git revision, draw by draw"
    )
    parser.add_argument("--out", type=Path, default=Path("results/bench_break_step"))
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be at least 1, got {args.repeats}")
    if args.samples < 0 or args.seed < 0:
        parser.error("--samples and --seed must be 0 or more")
    if args.against is not None:
        words = ["--scene", args.scene, "--at", str(args.at), *(["--quick"] * args.quick)]
        words += ["--to-end"] if args.to_end else []
        words += ["--set", *args.set] if args.set else []
        compare(args.against, args.samples, words, args.out)
        return
    changes = dict(item.split("=", 1) for item in args.set) | {"checkpoint_every": "0"}
    source = args.out / "checkpoint"
    try:
        k = checkpoint_before(args.scene, args.quick, changes, args.at, source)
    except ValueError as error:
        parser.error(str(error))
    before = read_records(source / "energies.csv")[-1]
    work = args.out / "resumed"
    results = [
        break_step(args.scene, args.quick, changes, source, work, k, args.seed, args.to_end)
        for _ in range(args.repeats)
    ]
    draws = [
        break_step(args.scene, args.quick, changes, source, work, k, seed, args.to_end)[0]
        for seed in range(1, args.samples + 1)
    ]
    record, trace = results[0]
    walls = [r["wall_s"] for r, _ in results]
    on_new_mesh, new_mesh_seconds = new_mesh_iterations(trace)
    bench = {
        "scene": args.scene, "quick": args.quick, "at": args.at, "to_end": args.to_end,
        "changes": changes,
        "seed": args.seed, "ngat": str(Path(ngat.__file__).parent),
        **outcome(record),
        "newton_steps": record["newton_steps"], "escapes": record["escapes"],
        "refinements": record["refinements"],
        "elements_before": before["elements"], "total_before": before["total"],
        "wall_s": {"median": statistics.median(walls), "min": min(walls), "max": max(walls),
                   "each": walls},
        "iterations_on_a_new_mesh": on_new_mesh,
        "their_seconds": round(new_mesh_seconds, 3),
        "repeatable": all(outcome(r) == outcome(record) for r, _ in results),
    }  # fmt: skip
    if draws:
        bench["samples"] = sample_summary([record, *draws])
    with open(args.out / "trace.csv", "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(trace[0]))
        writer.writeheader()
        writer.writerows(trace)
    draw_trace(trace, args.out / "trace.png", args.to_end)
    (args.out / "bench.json").write_text(json.dumps(bench, indent=2))
    print(json.dumps(bench, indent=2))


if __name__ == "__main__":
    main()
