"""Benchmark: what μ and ν cost against one iteration of alternating minimisation.

Question: are the estimators (Proposition 4) a small part of an iteration? Every iteration of
the adaptive method solves a u-step and a v-step and then evaluates μ and ν on the new mesh
state; the estimators should cost a fraction of the two solves.

Scene: the two-slits geometry at t = 1.0, its mesh of ``maxh=0.25`` refined uniformly until it
has at least ``--elements`` elements (default 80,000). Each of ``--repeats`` rounds times one
u-step and one v-step (the sparse factorisations refactorised), the edge topology of the mesh
built afresh, and μ and ν of the new iterate; the table gives the median per item.

Run ``python scripts/bench_estimators.py``; output in ``--out`` (default
``results/bench_estimators``): ``bench.json`` and ``bench.png``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ngat.estimators import EdgeTopology
from ngat.halfsteps import HalfStepSolvers
from ngat.minimization import estimate
from ngat.parameters import ModelParameters
from ngat.scene import load_scene
from ngat.state import ATState
from ngat.threads import FixedThreads


def timed(function) -> float:
    """Return the seconds ``function()`` takes."""
    start = time.perf_counter()
    function()
    return time.perf_counter() - start


def plot(median: dict[str, float], elements: int, path: Path) -> None:
    """Draw the median time per item as bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(6, 3))
    axes.barh(list(median), [1000 * s for s in median.values()])
    axes.invert_yaxis()
    axes.set_xlabel("median wall time [ms]")
    axes.set_title(f"two-slits, t = 1.0, {elements:,} elements")
    figure.tight_layout()
    figure.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, default=80_000, help="elements at least")
    parser.add_argument("--repeats", type=int, default=3, help="rounds (median taken)")
    parser.add_argument("--out", type=Path, default=Path("results/bench_estimators"))
    args = parser.parse_args()
    threads = FixedThreads()
    scene = load_scene("two-slits")
    mesh = scene.make_mesh(0.25)
    while mesh.ne < args.elements:
        mesh.Refine()
    state = ATState(mesh, ModelParameters(), scene.loads, scene.crack)
    half_steps = HalfStepSolvers(state)
    state.apply_load(1.0)
    crack = state.crack_set()
    rounds: dict[str, list[float]] = {"u-step + v-step": [], "edge topology": [], "μ": [], "ν": []}
    for _ in range(args.repeats + 1):  # the first round factorises: not counted
        rounds["u-step + v-step"].append(
            timed(lambda: (half_steps.solve_u(), half_steps.solve_v(crack)))
        )
        rounds["edge topology"].append(timed(lambda: EdgeTopology(state.arrays)))
        rounds["μ"].append(timed(lambda: estimate(state, "u", crack)))
        rounds["ν"].append(timed(lambda: estimate(state, "v", crack)))
    threads.restore()
    median = {item: float(np.median(times[1:])) for item, times in rounds.items()}
    solve = median["u-step + v-step"]
    print(f"{mesh.ne} elements, median of {args.repeats} rounds:")
    for item, seconds in median.items():
        print(f"  {item:16s} {1000 * seconds:8.1f} ms  ({seconds / solve:6.1%} of the two steps)")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench.json").write_text(
        json.dumps({"elements": mesh.ne, "repeats": args.repeats, "median_s": median}, indent=2)
    )
    plot(median, mesh.ne, args.out / "bench.png")


if __name__ == "__main__":
    main()
