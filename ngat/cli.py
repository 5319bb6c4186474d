"""Command line: ``ngat run SCENE``, ``ngat scenes``, ``ngat plot DIR``, ``ngat sweep``.

Errors in the input (unknown scene, bad parameter, unwritable or full folder, a folder in use by
another run, a damaged checkpoint, a scene without Dirichlet region or whose code raises) print
one line naming the problem and exit with status 2; any other exception is a bug in ngat: its
traceback and a request for a bug report, exit status 1. SIGINT (Ctrl-C) and SIGTERM stop a run
with one line saying how to continue it and the shell's status for a signal, 128 + its number
(130, 143), so that scripts tell an interrupted run from bad input. ``--debug`` raises all.
``ngat run`` never replaces a run already in its results folder unless told:
``--overwrite`` starts afresh, ``--resume`` continues it.
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import shlex
import signal
import sys
import traceback
from contextlib import ExitStack
from pathlib import Path

from rich.console import Console
from rich.logging import RichHandler
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from ngat.checkpoint import finished_steps
from ngat.diagnostics import ProblemError
from ngat.driver import run
from ngat.experiment import RunPlan, pictures_on_exit, plan_run
from ngat.minimization import ConvergenceError
from ngat.output import OutputError
from ngat.parameters import ParameterError
from ngat.results import RunResult
from ngat.scene import SceneNotFound, SceneTimesError, load_scene, scene_names
from ngat.state import SceneError

__all__ = ["main", "console"]

INPUT_ERRORS = (
    SceneNotFound,
    SceneTimesError,
    ParameterError,
    SceneError,
    OutputError,
)
"""The package's own input errors: one line and exit status 2. Anything else is a bug."""

BUG_REPORT = (
    "ngat: internal error (a bug in ngat, not in your input): please report it with the "
    "command and the traceback above"
)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like SIGINT's KeyboardInterrupt so that a run stops the same way."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated


def _signal_of(interrupt: KeyboardInterrupt) -> signal.Signals:
    return signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT


def interrupted_steps(folder: Path, steps: int) -> str:
    """Say how far an interrupted run came: its checkpoint's steps, and the steps after them.

    A run writes its checkpoint every ``checkpoint_every`` seconds, so the steps it finished
    (the rows of ``energies.csv``, counted in ``summary.json``) may go beyond its checkpoint;
    ``--resume`` computes those again.
    """
    done = finished_steps(folder)
    try:
        computed = json.loads((folder / "summary.json").read_text())["steps"]
    except (OSError, ValueError, KeyError):
        computed = done
    text = f"after {done} of {steps} load steps"
    if computed > done:
        text = (
            f"after {computed} of {steps} load steps (its checkpoint holds {done}: --resume "
            f"computes the {computed - done} after it again)"
        )
    return text


def parse_settings(items: list[str]) -> dict[str, str]:
    """Turn ``["eps=0.05", ...]`` into a dictionary; reject items without ``=`` or given twice."""
    settings = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ParameterError(f"--set expects NAME=VALUE, got '{item}'")
        if name.strip() in settings:
            raise ParameterError(
                f"--set gives '{name.strip()}' twice ({settings[name.strip()]} and "
                f"{value.strip()}): give it once"
            )
        settings[name.strip()] = value.strip()
    return settings


def command_run(args: argparse.Namespace, console: Console) -> int:
    """Run one scene with a progress bar; draw its pictures when it ends, however it ends."""
    if args.resume and (args.out or args.overwrite):
        raise ParameterError("--resume DIR names the results folder: leave out --out, --overwrite")
    # The folder's lock covers the check too: two runs started together cannot both pass it.
    with ExitStack() as lock:
        plan = plan_run(
            args.scene,
            args.resume or args.out,
            args.quick,
            args.overwrite,
            bool(args.resume),
            parse_settings(args.set),
            lock=lock,
        )
        if plan.finished:
            if not args.quiet:
                console.print(f"nothing to resume: the run in {plan.folder} is complete")
            return 0
        try:
            result = run_with_progress(plan, args, console)
        except KeyboardInterrupt as interrupt:
            if args.debug:
                raise
            command = ["ngat", "run", args.scene, *(["--quick"] if args.quick else [])]
            command += [word for item in args.set for word in ("--set", item)]
            console.print(
                f"ngat: interrupted by {_signal_of(interrupt).name} "
                f"{interrupted_steps(plan.folder, len(plan.times))}; continue with "
                f"{shlex.join([*command, '--resume', str(plan.folder)])}",
                markup=False,
                highlight=False,
                soft_wrap=True,
            )
            return 128 + _signal_of(interrupt)
    if not args.quiet:
        final = result.summary["final"]
        console.print(
            f"{plan.scene.name}: {result.summary['steps']} steps, total energy "
            f"{final['total']:.6g}, {result.summary['timing']['wall']:.1f} s → {plan.folder}"
        )
    return 0


REFRESH_PER_SECOND = 1
"""Redraws of the progress bar per second: its elapsed time counts whole seconds. Each redraw
holds the interpreter for about 2.4 ms, which the run's own thread then waits for: at rich's
default of 10 per second the bar took 0.7 s of the paper's example in a terminal."""


def run_with_progress(plan: RunPlan, args: argparse.Namespace, console: Console) -> RunResult:
    """Run (or resume) the planned run with a progress bar, drawing its pictures at the end."""
    columns = [
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
    ]
    with (
        pictures_on_exit(plan.folder, plan.scene.slits, not args.no_plots),
        Progress(
            *columns,
            console=console,
            disable=args.quiet,
            transient=True,
            refresh_per_second=REFRESH_PER_SECOND,
        ) as progress,
    ):
        task = progress.add_task(
            plan.scene.name, total=len(plan.times), completed=plan.done, info=""
        )

        iterations = 0

        def on_step(record: dict) -> None:
            nonlocal iterations
            iterations = 0
            info = (
                f"t={record['t']:.3f} elements={record['elements']} "
                f"iterations={record['am_iterations']}"
            )
            progress.update(task, advance=1, info=info)

        def on_half_step(stage: str, state) -> None:
            """Show the step under way: its time, iterations so far and elements."""
            nonlocal iterations
            if stage == "v":
                iterations += 1
                info = f"t={state.t.Get():.3f} elements={state.arrays.ne} iteration {iterations}"
                progress.update(task, info=info)

        return run(
            plan.scene,
            plan.parameters,
            plan.times,
            plan.folder,
            on_step,
            on_half_step,
            resume=plan.resume,
        )


def command_sweep(args: argparse.Namespace, console: Console) -> int:
    """Run a parameter sweep on Dask with a progress bar, or draw one (``--plot``).

    Exit status 1 if a run of the sweep failed (its error is in ``sweep.csv``).
    """
    # Imported here: dask is only needed for sweeps.
    from ngat.sweep import parse_grid, plot_sweep, sweep

    if args.plot:
        if not args.x or not args.y:
            raise ParameterError("--plot needs --x PARAMETER and --y COLUMN [COLUMN ...]")
        path = plot_sweep(args.plot, args.x, args.y)
        if not args.quiet:
            console.print(f"→ {path}")
        return 0
    if not args.scene or not args.grid:
        raise ParameterError(
            "ngat sweep needs a scene and --grid NAME=V1,V2 ... (or --plot DIR --x NAME --y COLUMN)"
        )
    grid = parse_grid(args.grid)
    name = load_scene(args.scene).name
    folder = Path(args.out or f"results/sweep-{name}{'-quick' if args.quick else ''}")
    total = 1
    for values in grid.values():
        total *= len(values)
    columns = [
        TextColumn("[bold]sweep {task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
    ]
    with Progress(*columns, console=console, disable=args.quiet, transient=True) as progress:
        task = progress.add_task(name, total=total, info="")

        def on_result(row: dict) -> None:
            progress.update(task, advance=1, info=f"{row['run']}: {row['status']}")

        rows = sweep(
            args.scene,
            grid,
            folder,
            scheduler=args.scheduler,
            quick=args.quick,
            overrides=parse_settings(args.set),
            workers=args.workers,
            on_result=on_result,
        )
    failed = [row for row in rows if row["status"] != "completed"]
    if not args.quiet:
        skipped = sum(bool(row["skipped"]) for row in rows)
        console.print(
            f"sweep {name}: {len(rows) - len(failed)} of {len(rows)} runs completed "
            f"({skipped} by an earlier sweep), {len(failed)} failed → {folder / 'sweep.csv'}"
        )
        for row in failed:
            console.print(f"  {row['run']}: {row['error']}", markup=False, highlight=False)
    return 1 if failed else 0


def command_scenes(args: argparse.Namespace, console: Console) -> int:
    """List the package's scenes."""
    for name in scene_names():
        console.print(f"{name:14s} {load_scene(name).description}")
    return 0


def command_plot(args: argparse.Namespace, console: Console) -> int:
    """Draw the pictures of a results folder."""
    # Imported here: matplotlib and pyvista are only needed for pictures.
    from ngat.plotting import PlotError, plot_results

    zoom = tuple(args.zoom) if args.zoom else None
    try:
        written = plot_results(args.folder, times=args.times, zoom=zoom)
    except PlotError as error:
        raise OutputError(str(error)) from None
    if not args.quiet:
        names = ", ".join(p.name for p in written)
        console.print(f"{len(written)} pictures → {args.folder}: {names}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of the ``ngat`` command."""
    parser = argparse.ArgumentParser(prog="ngat", description=__doc__.splitlines()[0])
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run", help="run a scene's load history")
    p_run.add_argument("scene", help="scene name (see 'ngat scenes') or path to a scene file")
    p_run.add_argument("--out", help="results folder (default results/SCENE)")
    p_run.add_argument("--quick", action="store_true", help="coarse, shortened variant")
    p_run.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE", help="change a parameter"
    )
    p_run.add_argument(
        "--overwrite", action="store_true", help="replace the run already in the results folder"
    )
    p_run.add_argument("--resume", metavar="DIR", help="continue the interrupted run in DIR")
    p_run.add_argument("--quiet", action="store_true", help="no progress bar")
    p_run.add_argument(
        "--no-plots", action="store_true", help="no pictures when the run ends (see 'ngat plot')"
    )
    p_run.set_defaults(handler=command_run)
    p_scenes = sub.add_parser("scenes", help="list the scenes")
    p_scenes.set_defaults(handler=command_scenes)
    p_sweep = sub.add_parser("sweep", help="run every combination of a parameter grid on Dask")
    p_sweep.add_argument("scene", nargs="?", help="scene name or path to a scene file")
    p_sweep.add_argument(
        "--grid", nargs="+", metavar="NAME=V1,V2", help="parameter values, e.g. eps=0.05,0.025"
    )
    p_sweep.add_argument("--out", help="sweep folder (default results/sweep-SCENE)")
    p_sweep.add_argument("--quick", action="store_true", help="quick variant of every run")
    p_sweep.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE", help="change a parameter"
    )
    p_sweep.add_argument("--scheduler", metavar="ADDRESS", help="address of a Dask scheduler")
    p_sweep.add_argument(
        "--workers", type=int, help="local worker processes (default: one per core)"
    )
    p_sweep.add_argument("--plot", metavar="DIR", help="draw the sweep in DIR instead of running")
    p_sweep.add_argument("--x", metavar="NAME", help="grid parameter on the x axis (--plot)")
    p_sweep.add_argument(
        "--y", nargs="+", metavar="COLUMN", help="sweep.csv columns to draw (--plot)"
    )
    p_sweep.add_argument("--quiet", action="store_true", help="no progress bar, no log lines")
    p_sweep.set_defaults(handler=command_sweep)
    p_plot = sub.add_parser("plot", help="draw the pictures of a (finished or partial) run")
    p_plot.add_argument("folder", help="results folder")
    p_plot.add_argument(
        "--times", type=float, nargs="+", metavar="T", help="load times of the v pictures"
    )
    p_plot.add_argument(
        "--zoom", type=float, nargs=3, metavar=("X", "Y", "R"), help="window of mesh_zoom.png"
    )
    p_plot.add_argument("--quiet", action="store_true", help="no list of the pictures")
    p_plot.set_defaults(handler=command_plot)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``ngat`` command."""
    args = build_parser().parse_args(argv)
    console = Console(stderr=True)
    # ngat's INFO lines go to the terminal unless --quiet (run.log keeps them either way);
    # other libraries' (dask's) only from WARNING up.
    handler = RichHandler(console=console, show_time=False, show_path=False, markup=False)
    handler.setLevel(logging.WARNING if getattr(args, "quiet", False) else logging.INFO)
    handler.addFilter(lambda record: record.name.startswith("ngat") or record.levelno >= 30)
    logging.getLogger().addHandler(handler)
    logging.getLogger("ngat").setLevel(logging.INFO)
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        return args.handler(args, console)
    except KeyboardInterrupt as interrupt:
        if args.debug:
            raise
        console.print(f"ngat: interrupted by {_signal_of(interrupt).name}")
        return 128 + _signal_of(interrupt)
    except (*INPUT_ERRORS, ConvergenceError, ProblemError) as error:
        if args.debug:
            raise
        console.print(f"ngat: error: {error}", markup=False, highlight=False, soft_wrap=True)
        return 2
    except Exception:
        if args.debug:
            raise
        traceback.print_exc()
        console.print(BUG_REPORT, markup=False, highlight=False, soft_wrap=True)
        return 1
    finally:
        signal.signal(signal.SIGTERM, previous if previous is not None else signal.SIG_DFL)
        logging.getLogger().removeHandler(handler)


def console() -> None:
    """Run the ``ngat`` command (:func:`main`) and end the process with its status.

    The process ends with the command, so its objects are first frozen out of the cycle
    collector (``gc.freeze``): the interpreter's exit otherwise searches every object still
    alive (the libraries' modules, the last mesh and fields) for cycles, 0.2–0.4 s after the
    paper's example, against 0.06–0.2 s frozen. :func:`main` itself leaves the collector
    alone: tests and scripts call it many times in one process.
    """
    status = main()
    gc.freeze()
    sys.exit(status)


if __name__ == "__main__":
    console()
