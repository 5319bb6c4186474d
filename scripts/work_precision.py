"""Work against precision: error against wall time, adaptive (Algorithm 2) against uniform meshes.

Question: for the same accuracy, how much cheaper is the adaptive method (the package's
defaults: Algorithm 2 with the crack band) than a uniform mesh — at equal accuracy of the total
energy at t = 1.0, and at equal accuracy of the fracture time?

Scenes: ``two-slits`` (the paper's example, docs/design.md scene 1) and ``surfing`` (scene 2, its
default: ε = 0.01, A = 1.1, V = 0.2, from the uniform mesh of squares of side 0.1). Methods,
each with the scene's full load history (no fewer steps for either):

- adaptive: the default ``adapt=band`` (Algorithm 2 and the scene's crack band, graded and
  re-meshed about running cracks: 0.18ε on surfing; 0.27ε on two-slits, whose slit tips are
  resolved to 0.18ε until their cracks grow) at the relative tolerance
  ``tol_rel`` ∈ {0.36, 0.18, 0.09, 0.045} (0.17 is the default), all else default
  (floor ε/50, am_tol = 1e-3); ``--paper`` runs Algorithm 2 alone (``adapt=paper``) at the
  absolute TOL = tol_rel / 0.6 instead (0.3 for tol_rel 0.18);
- uniform: ``adapt=fixed`` on the scene's initial mesh with ``maxh = h``, h ∈ {0.1, 0.05,
  0.025, 0.0125}; for two-slits h = 0.0125 (620 000 elements for all 161 steps, ~2 GB, est.
  1.5–2 h against 14 min at h = 0.025) is left out by default (``--hs`` chooses other sizes).

Each case runs in its own process (``ProcessPoolExecutor(max_workers=1,
max_tasks_per_child=1)``), one after the other; it reports the wall time of ``ngat.driver.run``,
its peak resident memory (``ru_maxrss`` of that process: ~150 MB of it is Python and NGSolve),
the largest and the final number of elements. The errors are measured against the stored
reference (``geometries/reference/<scene>.json``, ``scripts/reference_two_slits.py``):

- ``energy_1.0``: |E − E_ref| / |E_ref| of the total energy at t = 1.0 (before any crack grows:
  the elastic field's accuracy);
- ``fracture_time``: |t_f − t_f,ref|, t_f the first load time at which {v ≥ 0.1} no longer
  connects the Dirichlet regions (two-slits only: nothing breaks in surfing);
- ``crack_path``: the largest distance between the two runs' crack centre lines, taken as the
  Hausdorff distance between the polylines traced by each crack tip over the load steps with
  t ≤ 1.4 before either run breaks (once the cracks have joined, a slit's tip is measured on
  the other slit's side), the larger over the slits;
- ``toughness`` (surfing): |dS/da − 1|, dS/da the surface energy per unit crack advance while
  the crack runs (t ≥ 0.5, :func:`ngat.geometries.surfing.steady_rates`) and 1 = G_c, the toughness
  of the continuous AT functional; a crack that does not run (tip speed < V/2) has no value.

Each scene shows the measures it has (:data:`MEASURES`). Output in ``--out`` (default
``results/work_precision``): ``work_precision.csv`` (one row per case), ``work_precision.png``
(log–log error against wall time, one row of panels per scene, one panel per error measure, one
curve per method, points labelled by tol_rel or h), ``summary.json`` (per scene and measure,
for each uniform run the cheapest adaptive run at least as accurate and the ratio of their wall
times, :func:`speedups`), and each case's raw measures in ``runs/`` (``--reuse`` takes them
instead of running the case again). ``--nonlinear am anderson-newton`` runs the adaptive
cases once per nonlinear solver, side by side, for a before/after of the solver. ``--quick``
runs the scenes' quick variants at one TOL and one h (the tests use it).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import resource
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ["two-slits", "surfing"]
TOLS = [0.36, 0.18, 0.09, 0.045]
"""tol_rel of the adaptive cases."""
HS = {"two-slits": [0.1, 0.05, 0.025], "surfing": [0.1, 0.05, 0.025, 0.0125]}
MEASURES = {
    "two-slits": ["energy_1.0", "fracture_time", "crack_path"],
    "surfing": ["energy_1.0", "crack_path", "toughness"],
}
"""The error measures each scene has (nothing breaks in surfing; two-slits has no steady run)."""
PAPER_TOL = 1 / 0.6
"""TOL of ``adapt=paper`` per unit tol_rel: tol_rel 0.18 is the paper's TOL 0.3."""
OUTPUT_EVERY = 10
"""Fields (VTU) of every tenth load step and the last: the study reads energies.csv only."""
SURFING_WINDOW = 0.5
"""Surfing: the toughness is fitted over t ≥ this (after the ramp and the first jump)."""


def overrides(method: str, value: float) -> dict:
    """Return the parameter changes of a case: ``tol_rel`` (adaptive) or ``maxh`` (uniform).

    ``method`` is ``"uniform"``, ``"adaptive"`` (``adapt=band``), ``"paper"`` (``adapt=paper``
    at TOL = :data:`PAPER_TOL` · value) or either followed by a nonlinear solver's name.
    """
    kind, *solver = method.split()
    common = {"output_every": OUTPUT_EVERY}
    nonlinear = {"nonlinear": solver[0]} if solver else {}
    if kind == "adaptive":
        return {"adapt": "band", "tol_rel": value, **nonlinear, **common}
    if kind == "paper":
        return {"adapt": "paper", "tol": round(PAPER_TOL * value, 6), **nonlinear, **common}
    # Uniform meshes coarser than ε are part of the comparison.
    return {"adapt": "fixed", "maxh": value, "resolve_eps": False, **common}


def run_case(scene_name: str, method: str, value: float, folder: str, quick: bool) -> dict:
    """Run one case (in a fresh process) and return its cost and per-step measures."""
    from ngat.driver import run
    from ngat.scene import load_scene

    scene = load_scene(scene_name)
    parameters, times = scene.configure(quick=quick, overrides=overrides(method, value))
    begin = time.perf_counter()
    result = run(scene, parameters, times, Path(folder))
    wall = time.perf_counter() - begin
    keys = ["t", "total", "surface", "elements"] + [
        k for k in result.records[0] if k.startswith("tip")
    ]
    return {
        "wall_s": wall,
        "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "steps": {k: [r[k] for r in result.records] for k in keys},
        "fracture_time": result.summary.get("fracture_time"),
    }


def at_time(steps: dict, key: str, t: float) -> float:
    """Return ``steps[key]`` at load time ``t`` (NaN if the run has no such step)."""
    times = np.asarray(steps["t"])
    hit = np.flatnonzero(np.isclose(times, t, atol=1e-9))
    return float(np.asarray(steps[key])[hit[0]]) if len(hit) else math.nan


def polyline_distance(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Return the distance of each point to the polyline through ``line`` (in order)."""
    if len(line) == 1:
        return np.linalg.norm(points - line[0], axis=1)
    a, b = line[:-1], line[1:]
    ab = b - a
    length = np.maximum((ab**2).sum(axis=1), 1e-300)
    s = np.clip(((points[:, None, :] - a) * ab).sum(axis=2) / length, 0, 1)
    nearest = a + s[..., None] * ab
    return np.linalg.norm(points[:, None, :] - nearest, axis=2).min(axis=1)


def path_distance(steps: dict, reference: dict, until: float = 1.4) -> float:
    """Return the Hausdorff distance between the two runs' tip trajectories (t ≤ ``until``)."""
    worst = 0.0
    for i in (1, 2):
        if f"tip{i}_x" not in steps:
            continue
        tracks = []
        for s in (steps, reference):
            keep = np.asarray(s["t"]) <= until + 1e-9
            xy = np.stack([np.asarray(s[f"tip{i}_x"]), np.asarray(s[f"tip{i}_y"])], axis=1)
            tracks.append(xy[keep])
        worst = max(
            worst,
            polyline_distance(tracks[0], tracks[1]).max(),
            polyline_distance(tracks[1], tracks[0]).max(),
        )
    return float(worst)


def toughness(steps: dict, speed: float) -> float:
    """Return dS/da over t ≥ :data:`SURFING_WINDOW`, NaN if the crack does not run."""
    from ngat.geometries.surfing import steady_rates

    t = np.asarray(steps["t"])
    keep = t >= SURFING_WINDOW - 1e-9
    tip, surface = np.asarray(steps["tip1_x"]), np.asarray(steps["surface"])
    rates = steady_rates(t[keep], tip[keep], surface[keep])
    return rates["toughness"] if rates["speed"] > speed / 2 else math.nan


def errors(scene_name: str, case: dict, reference: dict) -> dict:
    """Return the error measures of a case against the reference."""
    steps, ref = case["steps"], reference["steps"]
    result = {}
    e, e_ref = at_time(steps, "total", 1.0), at_time(ref, "total", 1.0)
    result["energy_1.0"] = abs(e - e_ref) / abs(e_ref)
    if scene_name == "two-slits":
        t_f, t_ref = case["fracture_time"], reference["fracture_time"]
        result["fracture_time"] = abs(t_f - t_ref) if t_f is not None else math.nan
    # Once the cracks have joined, each slit's tip lies on the other slit's side: compare the
    # tracks only before either run breaks.
    breaks = [t for t in (case["fracture_time"], reference["fracture_time"]) if t is not None]
    result["crack_path"] = path_distance(steps, ref, until=min([1.4] + breaks) - 1e-6)
    if scene_name == "surfing":
        from ngat.geometries.surfing import SPEED

        result["toughness"] = abs(toughness(steps, SPEED) - 1)
    return result


def case_label(method: str, value: float) -> str:
    """Return the label of a point: its tol_rel, TOL or h."""
    if method.startswith("adaptive"):
        return f"tol_rel {value:g}"
    if method.startswith("paper"):
        return f"TOL {PAPER_TOL * value:g}"
    return f"h {value:g}"


def plot(rows: list[dict], path: Path) -> None:
    """Draw error against wall time, log–log: a row of panels per scene, a curve per method."""
    scenes = sorted({r["scene"] for r in rows}, key=SCENES.index)
    columns = max(len(MEASURES[scene]) for scene in scenes)
    fig, axes = plt.subplots(
        len(scenes), columns, figsize=(3.4 * columns, 3.0 * len(scenes)), squeeze=False
    )
    for i, scene in enumerate(scenes):
        for ax in axes[i, len(MEASURES[scene]) :]:
            ax.set_axis_off()
        for j, measure in enumerate(MEASURES[scene]):
            ax = axes[i, j]
            for method in dict.fromkeys(r["method"] for r in rows):
                style = "s--" if method == "uniform" else "o-"
                # A fracture time equal to the reference's is exact to the load step 0.01:
                # drawn at 0.005.
                floor = 0.005 if measure == "fracture_time" else 0.0
                pts = [
                    (r["wall_s"], max(r[measure], floor), r["value"])
                    for r in rows
                    if r["scene"] == scene and r["method"] == method
                    and np.isfinite(r[measure]) and max(r[measure], floor) > 0
                ]  # fmt: skip
                if not pts:
                    continue
                wall, err, value = zip(*sorted(pts), strict=True)
                ax.loglog(wall, err, style, label=method)
                for w, e, v in pts:
                    ax.annotate(
                        case_label(method, v), (w, e), fontsize=6, xytext=(3, 3),
                        textcoords="offset points",
                    )  # fmt: skip
            # Walls labelled 1, 2, 5, 10, …: a panel whose runs span less than a decade still
            # reads off its times.
            ax.xaxis.set_minor_locator(LogLocator(subs=(2, 5)))
            for axis_formatter in (ax.xaxis.set_major_formatter, ax.xaxis.set_minor_formatter):
                axis_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
            ax.tick_params(axis="x", which="both", labelsize=7)
            ax.set_title(f"{scene}: {measure}", fontsize=9)
            ax.set_xlabel("wall time [s]", fontsize=8)
            if ax.has_data():
                ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def speedups(rows: list[dict], method: str = "adaptive") -> list[dict]:
    """Return, per uniform run and measure, the cheapest ``method`` run at least as accurate.

    The speed-up is the ratio of the two wall times, both measured in this run of the script.
    Measures: the energy at t = 1.0 and the fracture time (two-slits).
    """
    found = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for measure in ("energy_1.0", "fracture_time"):
            if measure not in MEASURES[scene]:
                continue
            for uniform in (r for r in rows if r["scene"] == scene and r["method"] == "uniform"):
                better = [
                    r for r in rows if r["scene"] == scene and r["method"] == method
                    and r[measure] <= uniform[measure]
                ]  # fmt: skip
                entry = {
                    "scene": scene, "measure": measure, "uniform_h": uniform["value"],
                    "uniform_wall_s": uniform["wall_s"], "uniform_error": uniform[measure],
                }  # fmt: skip
                if better:
                    best = min(better, key=lambda r: r["wall_s"])
                    entry.update(
                        adaptive=case_label(method, best["value"]),
                        adaptive_wall_s=best["wall_s"], adaptive_error=best[measure],
                        speedup=round(uniform["wall_s"] / best["wall_s"], 2),
                    )  # fmt: skip
                found.append(entry)
    return found


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="quick variants, one TOL, one h")
    parser.add_argument("--scenes", nargs="+", default=SCENES, choices=SCENES)
    parser.add_argument("--tols", nargs="+", type=float, default=None)
    parser.add_argument("--hs", nargs="*", type=float, default=None, help="none: no uniform")
    parser.add_argument(
        "--nonlinear", nargs="+", default=None,
        help="run the adaptive cases once per nonlinear solver (e.g. am anderson-newton)",
    )  # fmt: skip
    parser.add_argument(
        "--paper", action="store_true", help="also Algorithm 2 alone (adapt=paper) at each TOL"
    )
    parser.add_argument("--out", type=Path, default=Path("results/work_precision"))
    parser.add_argument("--reuse", action="store_true", help="reuse the cases already run")
    parser.add_argument("--reference", type=Path, default=ROOT / "geometries" / "reference")
    args = parser.parse_args(argv)
    tols = args.tols or ([0.36] if args.quick else TOLS)
    if args.hs is not None:
        hs = {scene: args.hs for scene in args.scenes}
    else:
        hs = {scene: [0.2] if args.quick else HS[scene] for scene in args.scenes}
    kinds = ["adaptive", "paper"] if args.paper else ["adaptive"]
    solvers = [f" {s}" for s in args.nonlinear] if args.nonlinear else [""]
    adaptive = [kind + solver for kind in kinds for solver in solvers]
    (args.out / "runs").mkdir(parents=True, exist_ok=True)
    cases = []
    for scene in args.scenes:
        # Solvers alternate at each TOL, so that a change in the machine's load hits both.
        runs = [(m, tol) for tol in tols for m in adaptive] + [("uniform", h) for h in hs[scene]]
        for method, value in runs:
            label = method.replace(" ", "_")
            name = f"{scene}_{label}_{value:g}{'_quick' if args.quick else ''}"
            raw = args.out / "runs" / f"{name}.json"
            if args.reuse and raw.exists():
                case = json.loads(raw.read_text())
            else:
                with ProcessPoolExecutor(max_workers=1, max_tasks_per_child=1) as pool:
                    case = pool.submit(
                        run_case, scene, method, value, str(args.out / "runs" / name), args.quick
                    ).result()
                raw.write_text(json.dumps(case))
            print(f"{name}: {case['wall_s']:.1f} s", flush=True)
            cases.append((scene, method, value, case))
    rows = []
    for scene, method, value, case in cases:
        reference = json.loads((args.reference / f"{scene.replace('-', '_')}.json").read_text())
        row = {
            "scene": scene, "method": method, "value": value,
            "wall_s": round(case["wall_s"], 2), "peak_memory_mb": round(case["peak_memory_mb"]),
            "max_elements": max(case["steps"]["elements"]),
            "final_elements": case["steps"]["elements"][-1],
            "t_fracture": case["fracture_time"],
        }  # fmt: skip
        row.update(errors(scene, case, reference))
        rows.append(row)
    with open(args.out / "work_precision.csv", "w", newline="") as f:
        # Each scene has its own measures: the columns are their union, blank where absent.
        writer = csv.DictWriter(f, fieldnames=list(dict.fromkeys(k for r in rows for k in r)))
        writer.writeheader()
        writer.writerows(rows)
    plot(rows, args.out / "work_precision.png")
    summary = {"speedups": speedups(rows)}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
