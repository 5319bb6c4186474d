"""Reference solution: the paper's two-slits example with a much finer adaptive resolution.

Question: what are the energies, reaction force, crack tips and fracture time of ``two-slits``
(docs/design.md scene 1, the paper's Section 3) once the discretisation error is far below that of
the runs we compare (``scripts/work_precision.py``)? The scene is run with Algorithm 2 at a
smaller TOL, a smaller element floor and a tighter stopping tolerance of the alternating
minimisation than the defaults (TOL = 0.3, floor 1e-3, am_tol = 1e-3); everything else
(ε = 0.05, η = 1e-5, CRTOL = 1e-4, the 161 load steps) is the scene's.

The result is stored compactly, one JSON file with one row per load step (t, bulk, surface,
total, force, tips, elements, smallest element) plus the fracture time, the parameters, the
command line that made it and its cost (wall time, peak memory, machine). The default output
is ``geometries/reference/two_slits.json``; ``--scene surfing`` makes the surfing reference.

Run ``python scripts/reference_two_slits.py`` (about 25 min on a shared 2-core machine) or
``--quick`` (the scene's quick variant at the default resolution, for the tests).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shlex
import time
from pathlib import Path

from ngat.driver import run
from ngat.scene import load_scene

ROOT = Path(__file__).resolve().parent.parent
COLUMNS = ["t", "bulk", "surface", "total", "force", "elements", "h_min", "am_iterations"]
TIPS = ["tip1_x", "tip1_y", "tip2_x", "tip2_y"]


def compact(records: list[dict], digits: int = 10) -> dict[str, list]:
    """Return the records as columns, floats rounded to ``digits`` significant digits."""
    columns = {}
    for key in COLUMNS + TIPS:
        if key in records[0]:
            columns[key] = [
                float(f"{r[key]:.{digits}g}") if isinstance(r[key], float) else r[key]
                for r in records
            ]
    return columns


def command(args: argparse.Namespace) -> str:
    """Return the command line that makes this reference (the results folder aside)."""
    words = ["python", "scripts/reference_two_slits.py", "--scene", args.scene]
    if args.quick:
        words.append("--quick")
    else:
        words += ["--tol", f"{args.tol:g}", "--floor", f"{args.floor:g}"]
        words += ["--am-tol", f"{args.am_tol:g}"]
    return shlex.join(words + ["--max-cg", str(args.max_cg)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="two-slits")
    parser.add_argument("--tol", type=float, default=0.075, help="TOL (default 0.075)")
    parser.add_argument(
        "--floor", type=float, default=0.005, help="element floor in units of eps (2.5e-4 at 0.05)"
    )
    parser.add_argument("--am-tol", type=float, default=1e-4, help="stopping tolerance")
    parser.add_argument("--max-cg", type=int, default=0, help="lagged Cholesky (ngat.linear)")
    parser.add_argument("--quick", action="store_true", help="quick variant, default resolution")
    parser.add_argument("--out", type=Path, default=None, help="JSON file to write")
    parser.add_argument("--folder", type=Path, default=Path("results/reference"))
    args = parser.parse_args()
    scene = load_scene(args.scene)
    # The references are Algorithm 2 alone (adapt=paper) at a fine TOL and floor.
    overrides = {"max_cg": args.max_cg, "adapt": "paper"}
    if not args.quick:
        overrides.update(tol=args.tol, floor=args.floor, am_tol=args.am_tol)
    parameters, times = scene.configure(quick=args.quick, overrides=overrides)
    out = args.out or ROOT / "geometries" / "reference" / f"{args.scene.replace('-', '_')}.json"
    begin = time.perf_counter()
    result = run(scene, parameters, times, args.folder / args.scene)
    wall = time.perf_counter() - begin
    records, summary = result.records, result.summary
    reference = {
        "scene": args.scene,
        "command": command(args),
        "parameters": summary["parameters"],
        "fracture_time": summary.get("fracture_time"),
        "cost": {
            "wall_s": round(wall, 1),
            "peak_memory_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
            "am_iterations": summary["am_iterations"],
            "final_elements": records[-1]["elements"],
            "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}",
            "timing_s": summary["timing"],
        },
        "versions": summary["versions"],
        "steps": compact(records),
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(reference, separators=(",", ":")) + "\n")
    print(
        f"{out}: {len(records)} steps, fracture time {reference['fracture_time']}, "
        f"{wall:.0f} s, {reference['cost']['peak_memory_mb']} MB"
    )


if __name__ == "__main__":
    main()
