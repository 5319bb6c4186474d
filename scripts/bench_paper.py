"""Benchmark: the paper's example end to end, where the time goes, and against another revision.

Question: how long does ``ngat run two-slits`` (the paper's Section 3 example, 161 load steps,
docs/design.md scene 1) take on this machine, the load history and the pictures the command
draws at its end, how is the wall time split between assembly,
linear solves, estimation, refinement and output, how much memory does it need, and how many
alternating-minimisation iterations does it spend, in total and in the growth phase? And is
the current tree faster or slower than a given git revision, measured side by side?

Targets (issue 4): ≤ 60 s wall (stretch ≤ 30 s), ≥ 70 % of the time in the linear solves,
peak memory ≤ 2 GB.

One run: ``python scripts/bench_paper.py`` (full) or ``--quick`` (the scene's quick variant);
``--until T`` stops the load history at t = T (e.g. 1.35: the pre-break steps alone);
output in ``--out`` (default ``results/bench_paper``): ``bench.json`` (wall time of the load
history and of the pictures, drawn as ``ngat run`` draws them
(``ngat.experiment.pictures_on_exit``), the start-up before the run (importing ngat, NGSolve
and SciPy and loading the scene, counted from the script's start) and the command's total,
start-up + run + pictures: what ``ngat run two-slits`` takes, less the interpreter's own start
of some 20 ms; the processor time of the load history, all threads, user and system; seconds
per timed phase and with a linear solver under way on either thread (the factorisations that
run in the background, behind the estimators, count there), each phase's seconds with no
linear solver under way (the work no solve hides), peak memory, AM iterations in
total and in the growth window, linear solves, fracture time, E(1.0), final elements, element
sizes, the wall of the steps before the break step, of it and after it) and ``phases.png``;
the run's results folder in ``run/``.

Comparison: ``--against REV`` (e.g. ``HEAD~5``) checks REV out in a temporary git worktree
(removed at the end, also on an error or Ctrl-C) and runs the benchmark ``--repeats`` times
(default 3) for each checkout, alternating current/REV so that machine noise hits both alike,
current first in odd pairs and second in even ones (the second run of a pair tended to be the
faster).
Each run is this script's one-run mode in a process of its own with ``PYTHONPATH`` set to the
checkout's root: the two versions never share a process and are measured by the same code,
through ``ngat.driver.run`` and ``ngat.scene.load_scene``, which every revision has. A figure
an older revision cannot give is reported as "–". Output in ``--out``: ``compare.md`` (also
printed) and ``compare.json`` with, per checkout, the wall time (median, min, max) of the load
history, with the pictures and of the whole command, the median processor time, the share
of the wall time per phase ("–" where a checkout does not time a phase) and with a linear
solver under way on either thread, each phase's median seconds with none under way, the median
walls
before, of and after the break step, linear solves, final elements, fracture time, the error
of E(1.0) against ``geometries/reference/two_slits.json``, peak memory, the ratio
current/REV of the median wall times and that of each pair (less sensitive to the machine's
drift from one pair to the next).

Another machine: ``--scaled-to S`` with ``--against REV`` states the seconds REV's load history
took on a machine where a target was set (e.g. ``--against 6c4392c --scaled-to 47``: the
default when the 30 s target of ``ngat run two-slits`` was set, whose history took 47 s alone
there). Both checkouts' median wall and command are then also shown multiplied by S / REV's
median wall here, the factor by which that machine was faster than this one on REV's code:
what each would take there, as far as the two checkouts' work slows down alike.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

STARTED = time.perf_counter()
"""When this script began (after the standard library's imports): start-up counts from here."""
ROOT = Path(__file__).resolve().parent.parent
SCRIPT = Path(__file__).resolve()
REFERENCE = json.loads((ROOT / "geometries/reference/two_slits.json").read_text())
MISSING = "–"
"""Shown for a figure a checkout cannot give."""
SOLVER_KEY = "linear_solver"
"""``ngat.timing.SOLVER_KEY``, spelt out: an older checkout's ngat has no such name."""
WITHOUT_SOLVER_KEY = "timing_without_solver"
"""``ngat.timing.WITHOUT_SOLVER_KEY``, spelt out for the same reason."""


def growth_onset(records: list[dict], slit_tips=((2.0, 2.0), (4.0, 4.0)), distance=0.1):
    """Return the first t at which a crack tip has left its slit tip by more than ``distance``."""
    for r in records:
        for i, (x, y) in enumerate(slit_tips, start=1):
            if ((r[f"tip{i}_x"] - x) ** 2 + (r[f"tip{i}_y"] - y) ** 2) ** 0.5 > distance:
                return r["t"]
    return None


def optional(value: Callable[[], Any]) -> Any:
    """Return ``value()``, or ``None`` where an older revision's records or summary lack a key."""
    try:
        return value()
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None


def variant(quick: bool, until: float | None) -> list[str]:
    """Return the command-line words that choose the run: ``--quick``, ``--until T``."""
    words = ["--quick"] if quick else []
    return words if until is None else [*words, "--until", f"{until:g}"]


STAGES = ("before the break", "break step", "after the break")
"""The parts of a load history whose wall times the table shows (:func:`stage_walls`)."""


def stage_walls(records: list[dict], fracture: float | None) -> dict[str, float | None]:
    """Return the wall seconds of the steps before the break step, of it and after it.

    The break step is the load step at the fracture time; without one every step is before
    it and the other two are ``None``.
    """
    if fracture is None:
        return {STAGES[0]: round(sum(r["wall_s"] for r in records), 2), **dict.fromkeys(STAGES[1:])}
    walls = dict.fromkeys(STAGES, 0.0)
    for r in records:
        before, at = r["t"] < fracture - 1e-9, abs(r["t"] - fracture) <= 1e-9
        walls[STAGES[0] if before else STAGES[1] if at else STAGES[2]] += r["wall_s"]
    return {stage: round(wall, 2) for stage, wall in walls.items()}


def processor_time() -> float:
    """Return the processor seconds this process has used so far, all threads, user and system."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def measure(quick: bool, until: float | None, folder: Path) -> dict:
    """Run two-slits with the ngat on the path and return its figures (``None``: not given)."""
    import ngat
    from ngat.driver import run
    from ngat.scene import load_scene

    scene = load_scene("two-slits")
    parameters, times = scene.configure(quick=quick)
    if until is not None:
        times = times[times <= until + 1e-12]
    drawing = pictures_on_exit(folder, scene)
    used = processor_time()
    begin = time.perf_counter()
    with drawing or contextlib.nullcontext():
        result = run(scene, parameters, times, folder)
        end = time.perf_counter()
        processor = processor_time() - used
    wall = end - begin
    pictures = None if drawing is None else round(time.perf_counter() - end, 2)
    start = begin - STARTED
    records, summary = result.records, result.summary
    timing = summary.get("timing", {})
    onset = optional(lambda: growth_onset(records))
    fracture = summary.get("fracture_time")
    end = fracture if fracture is not None else float("inf")
    return {
        "wall_s": round(wall, 2),
        "processor_s": round(processor, 2),
        "pictures_s": pictures,
        "start_s": round(start, 2),
        "command_s": optional(lambda: round(start + wall + pictures, 2)),
        "phases_s": {
            phase: seconds for phase, seconds in timing.items() if phase not in ("wall", SOLVER_KEY)
        },
        "solve_fraction": optional(lambda: round(timing["solve"] / timing["wall"], 3)),
        "solver_s": timing.get(SOLVER_KEY),
        "solver_fraction": optional(lambda: round(timing[SOLVER_KEY] / timing["wall"], 3)),
        "without_solver_s": summary.get(WITHOUT_SOLVER_KEY),
        "peak_memory_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "am_iterations": optional(lambda: sum(r["am_iterations"] for r in records)),
        "am_iterations_growth": optional(
            lambda: sum(r["am_iterations"] for r in records if onset <= r["t"] <= end)
        ),
        "growth_window": [onset, fracture],
        "stages_s": optional(lambda: stage_walls(records, fracture)),
        "linear_solves": optional(lambda: sum(r["linear_solves"] for r in records)),
        "fracture_time": fracture,
        "energy_1.0": next((r.get("total") for r in records if abs(r["t"] - 1.0) < 1e-9), None),
        "final_elements": optional(lambda: records[-1]["elements"]),
        "h_min": optional(lambda: min(r["h_min"] for r in records)),
        "h_max": optional(lambda: records[-1]["h_max"]),
        "steps": len(records),
        "ngat": str(Path(ngat.__file__).resolve().parent),
    }


def pictures_on_exit(folder: Path, scene) -> contextlib.AbstractContextManager | None:
    """Return the block that draws a run's pictures at its end as ``ngat run`` does.

    That is :func:`ngat.experiment.pictures_on_exit`; ``None`` for a revision without it.
    """
    try:
        from ngat.experiment import pictures_on_exit as drawn_on_exit
    except ImportError:
        return None
    return drawn_on_exit(folder, scene.slits)


def plot_phases(bench: dict, title: str, path: Path) -> None:
    """Draw the seconds per phase of one run as bars, and the solver's on either thread."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.5))
    split = bench["phases_s"]
    ax.barh(list(split), list(split.values()), color="tab:blue", label="phase")
    alone = bench.get("without_solver_s")
    if alone is not None:
        # The part of each phase that no solve hides, in front of the phase's bar.
        seconds = [alone.get(phase, 0.0) for phase in split]
        ax.barh(list(split), seconds, color="tab:red", label="no solver under way")
        ax.legend(loc="lower right", fontsize="small")
    if bench.get("solver_s") is not None:
        # Overlaps the phases: the background factorisations run behind the others.
        label = f"solver, either thread\n({100 * bench['solver_fraction']:.0f} % of the wall)"
        ax.barh([label], [bench["solver_s"]], color="tab:orange")
    ax.set_xlabel("wall time [s]")
    ax.set_title(f"{title}: {bench['wall_s']:.1f} s wall")
    fig.tight_layout()
    fig.savefig(path, dpi=150)


def bench_one(quick: bool, until: float | None, out: Path) -> None:
    """Run the benchmark once in this process; write ``bench.json`` and ``phases.png``."""
    bench = measure(quick, until, out / "run")
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(bench, indent=2))
    print(json.dumps(bench, indent=2))
    plot_phases(bench, " ".join(["two-slits", *variant(quick, until)]), out / "phases.png")


def git(*arguments: str) -> str:
    """Run git in this script's repository and return its output; exit with git's message."""
    done = subprocess.run(
        ["git", "-C", str(ROOT), *arguments], capture_output=True, text=True, check=False
    )
    if done.returncode:
        raise SystemExit(f"git {' '.join(arguments)} failed: {done.stderr.strip()}")
    return done.stdout.strip()


@contextlib.contextmanager
def worktree(revision: str) -> Iterator[Path]:
    """Yield a temporary detached git worktree of ``revision``; remove it on exit."""
    with tempfile.TemporaryDirectory(prefix="bench-against-") as tmp:
        path = Path(tmp) / "checkout"
        git("worktree", "add", "--detach", str(path), revision)
        try:
            yield path
        finally:
            git("worktree", "remove", "--force", str(path))


def describe(revision: str | None) -> str:
    """Return the short commit of ``revision``, or of the current tree (``+ changes`` if edited)."""
    if revision is not None:
        short = git("rev-parse", "--short", revision)
        return short if revision.startswith(short) else f"{revision} ({short})"
    edited = subprocess.run(["git", "-C", str(ROOT), "diff", "--quiet", "HEAD"]).returncode
    return f"current ({git('rev-parse', '--short', 'HEAD')}{' + changes' if edited else ''})"


def bench_child(root: Path, words: list[str]) -> dict:
    """Return the figures of one run in a process of its own, only ``root`` on PYTHONPATH."""
    with tempfile.TemporaryDirectory(prefix="bench-run-") as tmp:
        command = [sys.executable, str(SCRIPT), "--out", tmp, *words]
        environment = {**os.environ, "PYTHONPATH": str(root)}
        done = subprocess.run(command, env=environment, stdout=subprocess.DEVNULL, check=False)
        if done.returncode:
            raise SystemExit(f"the run in {root} failed with exit status {done.returncode}")
        bench = json.loads((Path(tmp) / "bench.json").read_text())
    if not Path(bench["ngat"]).is_relative_to(root.resolve()):
        raise SystemExit(f"the run for {root} imported ngat from {bench['ngat']}")
    return bench


def energy_error(bench: dict) -> float | None:
    """Return the error of E(1.0) against the reference in %, or ``None`` without E(1.0)."""
    steps = REFERENCE["steps"]
    reference = steps["total"][steps["t"].index(1.0)]
    energy = bench.get("energy_1.0")
    return None if energy is None else round(100 * (energy / reference - 1), 4)


def agreed(values: list) -> Any:
    """Return the one value all runs gave, or all distinct values if the runs disagree."""
    distinct = list(dict.fromkeys(values))
    return distinct[0] if len(distinct) == 1 else distinct


def summarise(benches: list[dict], phases: list[str]) -> dict:
    """Return one checkout's row of the table from its runs."""
    walls = [b["wall_s"] for b in benches]
    return {
        "runs": len(benches),
        "wall_median_s": round(statistics.median(walls), 2),
        "wall_min_s": min(walls),
        "wall_max_s": max(walls),
        "with_pictures_median_s": optional(
            lambda: round(statistics.median(b["wall_s"] + b["pictures_s"] for b in benches), 2)
        ),
        "command_median_s": optional(
            lambda: round(statistics.median(b["command_s"] for b in benches), 2)
        ),
        "processor_median_s": optional(
            lambda: round(statistics.median(b["processor_s"] for b in benches), 2)
        ),
        "phase_share": {
            p: round(statistics.median(b["phases_s"][p] / b["wall_s"] for b in benches), 3)
            if all(p in (b.get("phases_s") or {}) for b in benches)
            else None
            for p in phases
        },
        "solver_share": optional(
            lambda: round(statistics.median(b["solver_s"] / b["wall_s"] for b in benches), 3)
        ),
        "without_solver_median_s": {
            p: round(statistics.median(b["without_solver_s"][p] for b in benches), 2)
            if all(p in (b.get("without_solver_s") or {}) for b in benches)
            else None
            for p in phases
        },
        "stage_median_s": {
            stage: round(statistics.median(b["stages_s"][stage] for b in benches), 2)
            if all((b.get("stages_s") or {}).get(stage) is not None for b in benches)
            else None
            for stage in STAGES
        },
        "linear_solves": agreed([b.get("linear_solves") for b in benches]),
        "final_elements": agreed([b.get("final_elements") for b in benches]),
        "fracture_time": agreed([b.get("fracture_time") for b in benches]),
        "energy_error_%": agreed([energy_error(b) for b in benches]),
        "peak_memory_mb": max(b["peak_memory_mb"] for b in benches),
    }


def timed_phases(runs: dict[str, list[dict]]) -> list[str]:
    """Return the phases any run times, in the order they first appear.

    A checkout that does not time a phase (an older one) shows ``–`` there; its time is in
    its ``other``.
    """
    phases: dict[str, None] = {}
    for benches in runs.values():
        for bench in benches:
            phases.update(dict.fromkeys(bench.get("phases_s") or {}))
    return list(phases)


def cell(value: Any, digits: int | None = None) -> str:
    """Format a table cell: ``–`` for a missing figure, ``a / b`` where runs disagree."""
    if isinstance(value, list):
        return " / ".join(cell(v, digits) for v in value)
    if value is None:
        return MISSING
    if digits is not None:
        return f"{value:.{digits}f}"
    return f"{value:,}" if isinstance(value, int) else f"{value:g}"


def percent(share: float | None) -> float | None:
    """Return a share in per cent (``None`` stays ``None``)."""
    return None if share is None else 100 * share


def table(comparison: dict) -> str:
    """Return the comparison as a markdown table, the ratio of the median walls below it."""
    labels, rows = comparison["labels"], comparison["summary"]
    current, against = rows["current"], rows["against"]
    lines = [
        f"| measure | {labels['current']} | {labels['against']} |",
        "|---|---|---|",
    ]

    def line(name: str, key: Callable[[dict], str]) -> None:
        lines.append(f"| {name} | {key(current)} | {key(against)} |")

    line("wall time median [s]", lambda r: cell(r["wall_median_s"], 1))
    line("wall time min – max [s]", lambda r: f"{r['wall_min_s']:.1f} – {r['wall_max_s']:.1f}")
    line("with the pictures, median [s]", lambda r: cell(r.get("with_pictures_median_s"), 1))
    line(
        "the command: start-up, run, pictures, median [s]",
        lambda r: cell(r.get("command_median_s"), 1),
    )
    line(
        "processor time of the load history, all threads, median [s]",
        lambda r: cell(r.get("processor_median_s"), 1),
    )
    for stage in STAGES:
        line(f"{stage}, median [s]", lambda r, s=stage: cell(r["stage_median_s"][s], 1))
    for phase in comparison["phases"]:
        line(f"share {phase} [%]", lambda r, p=phase: cell(percent(r["phase_share"][p]), 1))
    line(
        "share with a linear solver under way, either thread [%]",
        lambda r: cell(percent(r.get("solver_share")), 1),
    )
    for phase in comparison["phases"]:
        if phase != "solve":
            line(
                f"{phase} with no solver under way, median [s]",
                lambda r, p=phase: cell(r["without_solver_median_s"][p], 2),
            )
    line("linear solves", lambda r: cell(r["linear_solves"]))
    line("final elements", lambda r: cell(r["final_elements"]))
    line("fracture time", lambda r: cell(r["fracture_time"]))
    line("E(1.0) error [%]", lambda r: cell(r["energy_error_%"], 3))
    line("peak memory [MB]", lambda r: cell(r["peak_memory_mb"], 0))
    scale = comparison.get("scale")
    if scale is not None:
        factor = scale["factor"]
        line("wall time median, scaled [s]", lambda r: cell(r["wall_median_s"] * factor, 1))
        line(
            "the command median, scaled [s]",
            lambda r: cell(optional(lambda: r["command_median_s"] * factor), 1),
        )
        lines += [
            "",
            f"Scaled: × {factor:.3f} = {scale['against_wall_s']:g} s / {comparison['against']}'s "
            "median wall here, the machine on which its load history took "
            f"{scale['against_wall_s']:g} s.",
        ]
    mode = " ".join(["two-slits", *comparison["variant"]])
    return "\n".join(
        [
            f"{mode}, {comparison['repeats']} run(s) per checkout, alternating (current first "
            "in odd pairs, second in even ones).",
            "",
            *lines,
            "",
            f"Median wall time current / {comparison['against']}: {comparison['wall_ratio']:.3f}",
            "Pair by pair: " + ", ".join(f"{r:.3f}" for r in comparison["pair_ratios"]),
        ]
    )


def stop(signum: int, frame: Any) -> None:
    """Leave by an exception on SIGTERM, so that the runs end and the worktree goes."""
    raise SystemExit(128 + signum)


def compare(
    revision: str, repeats: int, words: list[str], out: Path, scaled_to: float | None = None
) -> None:
    """Benchmark the current tree against ``revision``, alternating; write the table.

    ``scaled_to``: the seconds ``revision``'s load history took on another machine; the
    table then also shows the median walls and commands scaled to that machine.
    """
    signal.signal(signal.SIGTERM, stop)
    labels = {"current": describe(None), "against": describe(revision)}
    runs: dict[str, list[dict]] = {"current": [], "against": []}
    with worktree(revision) as checkout:
        roots = {"current": ROOT, "against": checkout}
        for k in range(repeats):
            # ABBA: the order flips from pair to pair, since the second run of a pair was
            # faster on our machines whatever the code (by up to 1 s in 14).
            for name in ("current", "against")[:: 1 if k % 2 == 0 else -1]:
                runs[name].append(bench_child(roots[name], words))
                print(f"run {k + 1}/{repeats} {labels[name]}: {runs[name][-1]['wall_s']} s")
    phases = timed_phases(runs)
    summary = {name: summarise(benches, phases) for name, benches in runs.items()}
    comparison = {
        "against": revision,
        "variant": words,
        "repeats": repeats,
        "labels": labels,
        "phases": phases,
        "summary": summary,
        "wall_ratio": round(
            summary["current"]["wall_median_s"] / summary["against"]["wall_median_s"], 3
        ),
        "pair_ratios": [
            round(c["wall_s"] / a["wall_s"], 3)
            for c, a in zip(runs["current"], runs["against"], strict=True)
        ],
        "scale": None
        if scaled_to is None
        else {
            "against_wall_s": scaled_to,
            "factor": scaled_to / summary["against"]["wall_median_s"],
        },
        "runs": runs,
    }
    markdown = table(comparison)
    out.mkdir(parents=True, exist_ok=True)
    (out / "compare.json").write_text(json.dumps(comparison, indent=2))
    (out / "compare.md").write_text(markdown + "\n")
    print(markdown)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the --quick variant of the scene")
    parser.add_argument("--out", type=Path, default=Path("results/bench_paper"))
    parser.add_argument(
        "--against", metavar="REV", help="compare with this git revision (e.g. HEAD~5)"
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="runs per checkout with --against (default 3)"
    )
    parser.add_argument(
        "--until", type=float, metavar="T", help="stop the load history at t = T (default: all)"
    )
    parser.add_argument(
        "--scaled-to",
        type=float,
        metavar="S",
        help="with --against: REV's load history took S seconds on another machine; "
        "also show both checkouts' times scaled to that machine",
    )
    args = parser.parse_args()
    if args.scaled_to is not None and (args.against is None or not args.scaled_to > 0):
        parser.error("--scaled-to takes positive seconds and needs --against")
    if args.against is None:
        bench_one(args.quick, args.until, args.out)
    else:
        words = variant(args.quick, args.until)
        compare(args.against, args.repeats, words, args.out, args.scaled_to)


if __name__ == "__main__":
    main()
