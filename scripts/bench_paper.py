"""Benchmark: the paper's example end to end, and where the time goes.

Question: how long does ``ngat run two-slits`` (the paper's Section 3 example, 161 load steps,
Algorithm 2, docs/design.md scene 1) take on this machine, how is the wall time split between
assembly, linear solves, estimation, refinement and output, how much memory does it need, and
how many alternating-minimisation iterations does it spend, in total and in the growth phase?

Targets (issue 4): ≤ 60 s wall (stretch ≤ 30 s), ≥ 70 % of the time in the linear solves,
peak memory ≤ 2 GB.

Run ``python scripts/bench_paper.py`` (full) or ``--quick``; output in ``--out`` (default
``results/bench_paper``): ``bench.json`` and ``phases.png``.
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ngat.driver import run  # noqa: E402
from ngat.scene import load_scene  # noqa: E402

PHASES = ["assembly", "solve", "estimate", "refine", "output", "mesh"]


def growth_onset(records: list[dict], slit_tips=((2.0, 2.0), (4.0, 4.0)), distance=0.1):
    """Return the first t at which a crack tip has left its slit tip by more than ``distance``."""
    for r in records:
        for i, (x, y) in enumerate(slit_tips, start=1):
            if ((r[f"tip{i}_x"] - x) ** 2 + (r[f"tip{i}_y"] - y) ** 2) ** 0.5 > distance:
                return r["t"]
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the --quick variant of the scene")
    parser.add_argument("--out", type=Path, default=Path("results/bench_paper"))
    args = parser.parse_args()
    scene = load_scene("two-slits")
    parameters, times = scene.configure(quick=args.quick)
    begin = time.perf_counter()
    result = run(scene, parameters, times, args.out / "run")
    wall = time.perf_counter() - begin
    records, summary = result.records, result.summary
    timing = summary["timing"]
    onset = growth_onset(records)
    fracture = summary.get("fracture_time")
    growth = [r for r in records if onset is not None and onset <= r["t"] <= (fracture or 9e9)]
    bench = {
        "wall_s": round(wall, 2),
        "phases_s": {p: timing.get(p, 0.0) for p in PHASES} | {"other": timing["other"]},
        "solve_fraction": round(timing.get("solve", 0.0) / timing["wall"], 3),
        "peak_memory_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "am_iterations": summary["am_iterations"],
        "am_iterations_growth": sum(r["am_iterations"] for r in growth),
        "growth_window": [onset, fracture],
        "fracture_time": fracture,
        "final_elements": records[-1]["elements"],
        "h_min": min(r["h_min"] for r in records),
        "h_max": records[-1]["h_max"],
        "steps": len(records),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench.json").write_text(json.dumps(bench, indent=2))
    print(json.dumps(bench, indent=2))
    fig, ax = plt.subplots(figsize=(6, 3))
    split = bench["phases_s"]
    ax.barh(list(split), list(split.values()), color="tab:blue")
    ax.set_xlabel("wall time [s]")
    ax.set_title(f"two-slits{' --quick' if args.quick else ''}: {wall:.1f} s wall")
    fig.tight_layout()
    fig.savefig(args.out / "phases.png", dpi=150)


if __name__ == "__main__":
    main()
