"""Benchmark: the cost of a load step against the number of steps before it.

Question: does a step cost more the more steps came before it? A run with very many load times
should take as long for its 800th step as for its 100th. Each step writes a CSV row, the fields
and a checkpoint; if any of these rewrites what earlier steps wrote, the steps slow down as the
run goes on.

Scene: the two-slits geometry on its coarse initial mesh (``maxh=0.5``, ``eps=0.2``,
``adapt=fixed``, ``resolve_eps=false``: deliberately under-resolved, the mesh never changes)
with 10^6 load times in [0, 1], so that the first steps stay elastic and cost the same
computation, and a checkpoint after every step (``checkpoint_every=0``; the default writes one
per 10 s). The run stops after ``--steps`` steps. Steps per second are taken from the time
between the ends of the steps, over 101-step windows around step 100 and at the end.

Run ``python scripts/bench_steps.py`` (800 steps) or ``--quick`` (160 steps); output in
``--out`` (default ``results/bench_steps``): ``bench.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from ngat.driver import run
from ngat.scene import load_scene

WINDOW = 101
"""Steps per measuring window."""


class Stop(Exception):
    """Ends the run after the requested number of steps."""


def steps_per_second(ends: list[float], centre: int) -> float:
    """Return the steps per second over the window of :data:`WINDOW` steps around ``centre``."""
    first = max(1, centre - WINDOW // 2)
    last = min(len(ends) - 1, first + WINDOW - 1)
    return (last - first + 1) / (ends[last] - ends[first - 1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="160 steps instead of 800")
    parser.add_argument("--steps", type=int, default=800, help="load steps to run")
    parser.add_argument("--set", nargs="*", default=[], help="parameter changes, NAME=VALUE")
    parser.add_argument("--out", type=Path, default=Path("results/bench_steps"))
    args = parser.parse_args()
    steps = 160 if args.quick else args.steps
    scene = dataclasses.replace(load_scene("two-slits"), times=np.linspace(0.0, 1.0, 10**6))
    changes = {
        "maxh": 0.5, "eps": 0.2, "adapt": "fixed", "resolve_eps": False, "checkpoint_every": 0
    }  # fmt: skip
    changes.update(item.split("=", 1) for item in args.set)
    parameters, times = scene.configure(overrides=changes)
    ends: list[float] = []

    def on_step(record: dict) -> None:
        ends.append(time.perf_counter())
        if len(ends) == steps:
            raise Stop

    try:
        run(scene, parameters, times, args.out / "run", on_step=on_step)
    except Stop:
        pass
    summary = json.loads((args.out / "run" / "summary.json").read_text())
    bench = {
        "steps": len(ends),
        "changes": changes,
        "steps_per_s_at_100": round(steps_per_second(ends, 100), 1),
        f"steps_per_s_at_{len(ends) - WINDOW // 2 - 1}": round(
            steps_per_second(ends, len(ends) - WINDOW // 2 - 1), 1
        ),
        "phases_s": summary["timing"],
        "checkpoint_bytes": (args.out / "run" / "checkpoint.npz").stat().st_size,
    }
    (args.out / "bench.json").write_text(json.dumps(bench, indent=2))
    print(json.dumps(bench, indent=2))


if __name__ == "__main__":
    main()
