"""Command line: ``ngat run SCENE``, ``ngat scenes``.

Errors in the input (unknown scene, bad parameter, unwritable folder, a scene without Dirichlet
region) print one line naming the problem and exit with status 2; ``--debug`` shows the
traceback instead.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from ngat.driver import run
from ngat.minimization import ConvergenceError
from ngat.output import OutputError
from ngat.parameters import ParameterError
from ngat.scene import SceneNotFound, load_scene, scene_names
from ngat.state import SceneError

__all__ = ["main"]

INPUT_ERRORS = (SceneNotFound, ParameterError, SceneError, OutputError, ValueError)


def parse_settings(items: list[str]) -> dict[str, str]:
    """Turn ``["eps=0.05", ...]`` into a dictionary; reject items without ``=``."""
    settings = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ParameterError(f"--set expects NAME=VALUE, got '{item}'")
        settings[name.strip()] = value.strip()
    return settings


def command_run(args: argparse.Namespace, console: Console) -> int:
    """Run one scene with a progress bar."""
    scene = load_scene(args.scene)
    parameters, times = scene.configure(args.quick, parse_settings(args.set))
    folder = Path(args.out or f"results/{scene.name}{'-quick' if args.quick else ''}")
    columns = [
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
    ]
    with Progress(*columns, console=console, disable=args.quiet) as progress:
        task = progress.add_task(scene.name, total=len(times), info="")

        def on_step(record: dict) -> None:
            info = (
                f"t={record['t']:.3f} elements={record['elements']} "
                f"iterations={record['am_iterations']}"
            )
            progress.update(task, advance=1, info=info)

        result = run(scene, parameters, times, folder, on_step=on_step)
    if not args.quiet:
        final = result.summary["final"]
        console.print(
            f"{scene.name}: {result.summary['steps']} steps, total energy {final['total']:.6g}, "
            f"{result.summary['timing']['wall']:.1f} s → {folder}"
        )
    return 0


def command_scenes(args: argparse.Namespace, console: Console) -> int:
    """List the package's scenes."""
    for name in scene_names():
        console.print(f"{name:14s} {load_scene(name).description}")
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
    p_run.add_argument("--quiet", action="store_true", help="no progress bar")
    p_run.set_defaults(handler=command_run)
    p_scenes = sub.add_parser("scenes", help="list the scenes")
    p_scenes.set_defaults(handler=command_scenes)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``ngat`` command."""
    args = build_parser().parse_args(argv)
    console = Console(stderr=True)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("ngat").setLevel(logging.INFO)
    try:
        return args.handler(args, console)
    except (*INPUT_ERRORS, ConvergenceError) as error:
        if args.debug:
            raise
        console.print(f"ngat: error: {error}", markup=False, highlight=False)
        return 2


if __name__ == "__main__":
    sys.exit(main())
