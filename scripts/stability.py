"""Stability where methods fail: the failure matrix of nonlinear solvers × stress cases.

Question: which nonlinear solver for one load step (plain alternating minimisation ``am``, the
paper's; ``overrelaxed``; ``anderson``; ``newton`` and ``anderson-newton``, which add Newton
steps on the coupled system) survives which stress — the rapid-growth window of
two-slits, large load increments, η → 0, an under-resolved ε, obtuse meshes with and without the
bounded v-step, coarse and fine TOL — and at what cost? And how does the iterative linear solver
(CG with NGSolve's h1amg, ``linear_solver=cg-h1amg``) degrade against the direct one as η → 0?

Scene: ``two-slits`` in its ``--quick`` setting (every fifth load step, element floor 0.004),
changed per case as listed in ``CASES``; the cases in ``CASE_SCENES`` use their own scene
instead (``obtuse-line``: a fixed sheared mesh, every triangle with a 161.6° angle, sheared
anti-plane between two slanted grips until it breaks, with the lumped and with the consistent
mass, ``lumping=false``; ``sent`` and ``sens``: the plane-strain benchmarks at ε = 0.02 mm,
``sens`` with the volumetric–deviatoric split, without a split and with the spectral
split, judged by their crack paths).
Each cell runs in its own process with a time limit and records:
status (converged, not converged, failed with the error, timeout and the load time reached), AM
iterations, linear solves, Newton steps, steps along negative curvature and the extra solves
that found it, rejected accelerated or Newton steps, CG iterations
(total and most per solve; 0 with the direct solver), final total energy, min/max v, fracture
time, the diagnostics, the wall time and the time in linear solves. Every finished cell is
also judged against the reference (:func:`judge`): a run that converged to the wrong fracture
time or energy is a failure and is coloured so. Columns are the solvers with the default
adaptivity (``band``) and ``newton/paper``, the default solver with Algorithm 2 alone.

Output in ``--out`` (default ``results/stability``): ``stability.csv`` and ``stability.png``
(a colour table). ``--quick`` runs two cells only (used by the tests).
"""

from __future__ import annotations

import argparse
import csv
import json
import multiprocessing
import tempfile
import time
from pathlib import Path

import numpy as np

from ngat.parameters import NONLINEAR_SOLVERS

QUICK_TIMES = np.round(np.arange(0.0, 1.61, 0.05), 10)
LONG_TIMES = np.round(np.arange(0.0, 2.01, 0.05), 10)  # coarse meshes break late
GROWTH_TIMES = np.round(np.r_[0.0, 0.6, 1.0, 1.2, np.arange(1.3, 1.501, 0.01)], 10)
SHEARED_TIMES = np.round(np.arange(0.0, 0.801, 0.02), 10)
SENT_TIMES = np.round(np.r_[np.arange(0.0, 0.0051, 1e-3), np.arange(0.0055, 0.0081, 5e-4)], 10)
SENS_TIMES = np.round(np.r_[np.arange(0.0, 0.0081, 2e-3), np.arange(0.009, 0.0201, 1e-3)], 10)
SURFING_TIMES = np.round(0.05 * np.arange(31), 10)
PLANE = {"eps": 0.02, "floor": 0.1, "band_h": 0.35}
"""The plane benchmarks at ε = 0.02 mm (ℓ = 0.04 mm, 5× the published): cells within minutes."""
CASES = {
    # name: (parameter changes, load times)
    "growth window Δt=0.01": ({}, GROWTH_TIMES),
    "Δt=0.05": ({}, QUICK_TIMES),
    "Δt=0.1": ({}, np.round(np.arange(0.0, 1.61, 0.1), 10)),
    "η=1e-3": ({"eta": 1e-3}, QUICK_TIMES),
    "η=1e-8": ({"eta": 1e-8}, QUICK_TIMES),
    "ε under-resolved (fixed h=0.25)":
        ({"adapt": "fixed", "maxh": 0.25, "resolve_eps": False}, QUICK_TIMES),
    # Algorithm 2's TOL: absolute for adapt=paper, relative for adapt=band (tol_rel = 0.6 tol,
    # 0.18 being the paper's 0.3 at t = 1 of its example).
    "TOL=1.0": ({"tol": 1.0, "tol_rel": 0.6}, LONG_TIMES),
    "TOL=0.15": ({"tol": 0.15, "tol_rel": 0.09}, QUICK_TIMES),
    "TOL=0.05": ({"tol": 0.05, "tol_rel": 0.03}, QUICK_TIMES),
    "no v bounds (obtuse bisection)": ({"bounded_v": False}, QUICK_TIMES),
    "CG+h1amg η=1e-3": ({"linear_solver": "cg-h1amg", "eta": 1e-3}, QUICK_TIMES),
    "CG+h1amg η=1e-5": ({"linear_solver": "cg-h1amg"}, QUICK_TIMES),
    "CG+h1amg η=1e-8": ({"linear_solver": "cg-h1amg", "eta": 1e-8}, QUICK_TIMES),
    "ε=0.025 (defaults)": ({"eps": 0.025}, QUICK_TIMES),
    "coarse start maxh=1.0": ({"maxh": 1.0}, QUICK_TIMES),
    "obtuse mesh (sheared)": ({}, SHEARED_TIMES),
    "obtuse mesh (sheared), no v bounds": ({"bounded_v": False}, SHEARED_TIMES),
    "obtuse mesh (sheared), no v bounds, consistent mass":
        ({"bounded_v": False, "lumping": False}, SHEARED_TIMES),
    "obtuse mesh (sheared), consistent mass": ({"lumping": False}, SHEARED_TIMES),
    "running crack (surfing, unstructured maxh=10ε)": ({"eps": 0.02, "maxh": 0.2}, SURFING_TIMES),
    "sent (plane strain, ε=0.02)": (PLANE, SENT_TIMES),
    "sens (plane strain, ε=0.02, split)": (PLANE, SENS_TIMES),
    "sens (plane strain, ε=0.02, no split)": ({**PLANE, "split": "none"}, SENS_TIMES),
    "sens (plane strain, ε=0.02, spectral split)": ({**PLANE, "split": "spectral"}, SENS_TIMES),
}  # fmt: skip
# Cases with their own scene (the others run two-slits).
CASE_SCENES = {
    case: "obtuse-line" if case.startswith("obtuse") else case.split(" ")[0]
    for case in CASES
    if case.startswith(("obtuse mesh (sheared)", "sent", "sens"))
}
CASE_SCENES["running crack (surfing, unstructured maxh=10ε)"] = "surfing"
STEADY_FROM = 0.5
"""surfing: the tip speed and toughness are fitted over t ≥ 0.5 (after the ramp to 0.25)."""


def load_case_scene(case: str):
    """Return the scene of a case (surfing: meshed by Netgen, no band along the path)."""
    from ngat.geometries import surfing
    from ngat.scene import load_scene

    name = CASE_SCENES.get(case, "two-slits")
    if name == "surfing":
        return surfing.make_scene(eps=CASES[case][0]["eps"], structured=False)
    return load_scene(name)


def steady_measures(records: list[dict], eps: float) -> dict:
    """Return the surfing crack's tip speed / V and toughness dS/da / G_eff(h_crack)."""
    from ngat.geometries import surfing

    steady = [r for r in records if r["t"] >= STEADY_FROM - 1e-9]
    if len(steady) < 3 or "tip1_x" not in steady[0]:
        return {}
    rates = surfing.steady_rates(
        [r["t"] for r in steady], [r["tip1_x"] for r in steady], [r["surface"] for r in steady]
    )
    h = float(np.median([r["h_crack"] for r in records if r["h_crack"] > 0]))
    return {
        "speed_ratio": round(rates["speed"] / surfing.SPEED, 4),
        "toughness_ratio": round(rates["toughness"] / surfing.effective_toughness(h, eps), 4),
        "h_crack_over_eps": round(h / eps, 3),
    }


METHODS = [*NONLINEAR_SOLVERS, "newton/paper", "newton+extension"]
"""Columns: every solver with the default adaptivity (``band``), the default solver with the
paper's Algorithm 2 alone (``adapt=paper``) and with the crack extension
(``crack_extension=true``, :mod:`ngat.extension`)."""


def method_overrides(method: str) -> dict:
    """Return the parameters of a column: ``solver[+extension][/adapt]``.

    Examples: ``newton``, ``newton/paper`` (Algorithm 2 alone), ``newton+extension``.
    """
    solver, _, adapt = method.partition("/")
    solver, _, extension = solver.partition("+")
    return {
        "nonlinear": solver,
        **({"adapt": adapt} if adapt else {}),
        **({"crack_extension": True} if extension == "extension" else {}),
    }


def cell(method: str, case: str, queue: multiprocessing.Queue, progress) -> None:
    """Run one cell and put its row on the queue (runs in a child process).

    ``progress`` (a shared double) holds the load time of the last finished step, so that a
    cell stopped at the time limit can say how far it got.
    """
    from ngat.driver import run

    changes, times = CASES[case]
    scene = load_case_scene(case)
    begin = time.perf_counter()

    def on_step(record: dict) -> None:
        progress.value = record["t"]

    try:
        overrides = {**method_overrides(method), **changes}
        parameters, _ = scene.configure(quick=True, overrides=overrides)
        result = run(scene, parameters, times, Path(tempfile.mkdtemp()) / "run", on_step=on_step)
        records = result.records
        status = "converged" if all(r["converged"] for r in records) else "not converged"
        row = {
            "status": status,
            "am_iterations": sum(r["am_iterations"] for r in records),
            "linear_solves": sum(r["linear_solves"] for r in records),
            "newton_steps": sum(r["newton_steps"] for r in records),
            "escapes": sum(r["escapes"] for r in records),
            "curvature_solves": sum(r["curvature_solves"] for r in records),
            "fallbacks": sum(r["fallbacks"] for r in records),
            "cg_iterations": sum(r["cg_iterations"] for r in records),
            "cg_max_iterations": max(r["cg_max_iterations"] for r in records),
            "total": records[-1]["total"],
            "v_min": min(r["v_min"] for r in records),
            "v_max": max(r["v_max"] for r in records),
            "fracture_time": result.summary.get("fracture_time", ""),
            "energy_1.0": next((r["total"] for r in records if np.isclose(r["t"], 1.0)), ""),
            "diagnostics": " ".join(sorted({p["kind"] for p in result.summary["diagnostics"]})),
            "peak_force": max(r["force"] for r in records),
            "tip_x": records[-1].get("tip1_x", ""),
            "tip_y": records[-1].get("tip1_y", ""),
            **(
                steady_measures(records, parameters.model.eps)
                if CASE_SCENES.get(case) == "surfing"
                else {}
            ),
            "solve_s": result.summary["timing"].get("solve", 0.0),
        }
    except Exception as error:  # noqa: BLE001 - a failed cell is a result of the study
        row = {"status": f"failed: {type(error).__name__}: {error}"}
    row["wall_s"] = round(time.perf_counter() - begin, 2)
    queue.put(row)


def run_cell(method: str, case: str, limit: float) -> dict:
    """Run a cell in a child process; a cell over the time limit is recorded as a timeout."""
    queue: multiprocessing.Queue = multiprocessing.Queue()
    progress = multiprocessing.Value("d", -1.0)
    process = multiprocessing.Process(target=cell, args=(method, case, queue, progress))
    process.start()
    process.join(limit)
    if process.is_alive():
        process.kill()
        return {
            "method": method, "case": case, "status": "timeout", "wall_s": limit,
            "reached_t": progress.value,
        }  # fmt: skip
    row = {"method": method, "case": case, **queue.get()}
    return {**row, **judge(row, case)}


REFERENCE = json.loads(
    (Path(__file__).resolve().parent.parent / "geometries/reference/two_slits.json").read_text()
)
OBTUSE_BREAK = 0.50
"""obtuse-line's break time with converged alternating minimisation (am_tol 1e−4 to 1e−6)."""
BROKEN_ENERGY_TOL = 3.0
"""two-slits: I_j of the broken body at the last load time within this many % of the
reference's. The broken state is a local minimiser that the step's path decides; the cells of
``newton`` and ``am`` that break at the right time end within 0.05–2.0 % of the reference."""


def judge(row: dict, case: str) -> dict:
    """Score a finished cell against the reference: a converged run can still be wrong.

    two-slits cells: the fracture time within the load step at the reference (at least 0.02) of the
    converged reference (1.39), E(1.0) within 0.5 % of it and I_j at the last load time (the
    broken body) within :data:`BROKEN_ENERGY_TOL` % of it; obtuse-line cells: the break
    within one load step of 0.50; ``sent`` and ``sens``: the crack path (:func:`judge_path`).
    Returns ``fracture_error``, ``energy_error_%``, ``broken_energy_error_%`` (where they
    apply) and ``verdict``:
    ``right``, ``wrong: …`` or empty for cells that did not finish.
    """
    if row.get("status") not in ("converged", "not converged"):
        return {"verdict": ""}
    if CASE_SCENES.get(case) in ("sent", "sens"):
        return judge_path(row, CASE_SCENES[case])
    if CASE_SCENES.get(case) == "surfing":
        return judge_running_crack(row)
    times = CASES[case][1]
    obtuse = CASE_SCENES.get(case) == "obtuse-line"
    reference = OBTUSE_BREAK if obtuse else REFERENCE["fracture_time"]
    # One load step where the reference breaks (the growth window's 0.6-wide early steps do
    # not count), and at least 0.02.
    later = times[times > reference - 1e-9]
    step = later[0] - times[times < later[0]][-1] if len(later) else np.max(np.diff(times))
    tolerance = max(float(step), 0.02)
    fracture = row.get("fracture_time")
    scores, wrong = {}, []
    if fracture in ("", None):
        wrong.append("never breaks")
    else:
        scores["fracture_error"] = round(fracture - reference, 4)
        if abs(fracture - reference) > tolerance + 1e-9:
            wrong.append(f"breaks at {fracture:g}")
    if "eps" in CASES[case][0] and CASE_SCENES.get(case) is None:
        # Another ε is another model: no reference; the crack must be resolved.
        resolved = "eps-under-resolved" not in row.get("diagnostics", "")
        return {"verdict": "right" if resolved else "wrong: ε under-resolved"}
    if not obtuse and row.get("energy_1.0", "") != "":
        e_ref = REFERENCE["steps"]["total"][REFERENCE["steps"]["t"].index(1.0)]
        error = 100 * (row["energy_1.0"] / e_ref - 1)
        scores["energy_error_%"] = round(error, 3)
        if abs(error) > 0.5:
            wrong.append(f"E(1.0) {error:+.2f} %")
    end = round(float(times[-1]), 10)
    steps = REFERENCE["steps"]
    if not obtuse and fracture not in ("", None) and end in steps["t"]:
        error = 100 * (row["total"] / steps["total"][steps["t"].index(end)] - 1)
        scores["broken_energy_error_%"] = round(error, 2)
        if abs(error) > BROKEN_ENERGY_TOL:
            wrong.append(f"broken I_j {error:+.1f} %")
    return {**scores, "verdict": "wrong: " + ", ".join(wrong) if wrong else "right"}


def judge_running_crack(row: dict) -> dict:
    """Score the surfing cell: tip speed within 2 % of V, dS/da within 3 % of G_eff(h_crack)."""
    if "speed_ratio" not in row:
        return {"verdict": "wrong: the crack does not run"}
    wrong = []
    if abs(row["speed_ratio"] - 1) > 0.02:
        wrong.append(f"tip speed {row['speed_ratio']:.3f} V")
    if abs(row["toughness_ratio"] - 1) > 0.03:
        wrong.append(f"dS/da {row['toughness_ratio']:.3f} G_eff")
    return {"verdict": "wrong: " + ", ".join(wrong) if wrong else "right"}


def judge_path(row: dict, scene: str) -> dict:
    """Score a plane benchmark by its crack path: the plate must break along the right path.

    ``sent``: the crack runs straight, its tip ends within 0.05 of y = 0.5 at the right edge
    (x > 0.9). ``sens``: the crack curves down towards the lower right corner, its tip ends
    below y = 0.35 (Miehe et al. 2010; straight on would end at 0.5). A run whose crack lies in
    elements coarser than ε (``eps-under-resolved``) is wrong whatever its path.
    """
    x, y = row.get("tip_x", ""), row.get("tip_y", "")
    if row.get("fracture_time", "") in ("", None) or x == "":
        return {"verdict": "wrong: never breaks"}
    if "eps-under-resolved" in row.get("diagnostics", ""):
        # A path through elements coarser than ε is the mesh's, right or not.
        return {"verdict": "wrong: ε under-resolved"}
    if scene == "sent":
        right = x > 0.9 and abs(y - 0.5) < 0.05
    else:
        right = y < 0.35
    return {"verdict": "right" if right else f"wrong: crack ends at ({x:.2f}, {y:.2f})"}


def convert(row: dict) -> dict:
    """Return a row read back from the CSV with its numbers as numbers (empty cells dropped)."""
    converted = {}
    for key, value in row.items():
        if value == "":
            continue
        try:
            converted[key] = float(value) if "." in value or "e" in value else int(value)
        except ValueError:
            converted[key] = value
    return converted


def draw(rows: list[dict], path: Path) -> None:
    """Draw the colour table of the cells.

    Green converged with the right answer, orange converged with a wrong one (fracture time
    or E(1.0) off the reference, :func:`judge`), yellow not converged, red failed or timeout,
    grey refused (a parameter combination the solver rejects, such as Newton without lumping).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(r["case"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    colour = {"converged": "#7fc97f", "not converged": "#fdc086"}
    fig, ax = plt.subplots(figsize=(2.4 * len(methods) + 2.5, 0.55 * len(cases) + 1))
    for i, case in enumerate(cases):
        for j, method in enumerate(methods):
            row = next((r for r in rows if r["case"] == case and r["method"] == method), None)
            if row is None:
                continue
            status = row["status"]
            face = colour.get(status, "#f0027f")
            text = status if not status.startswith("failed") else "failed"
            if status == "converged" and str(row.get("verdict", "")).startswith("wrong"):
                face, text = "#fb6a4a", row["verdict"].replace(": ", "\n", 1)
            if status.startswith("failed: ParameterError"):
                face, text = "#cccccc", "refused\n(invalid setting)"
            if "linear_solves" in row:
                text += f"\n{row['linear_solves']} solves, {row['wall_s']:.0f} s"
            elif status == "timeout" and row.get("reached_t", -1) >= 0:
                text += f" at t = {row['reached_t']:g}"
            if row.get("cg_iterations"):
                text += f"\n{row['cg_iterations']} CG its (≤ {row['cg_max_iterations']}/solve)"
            ax.add_patch(plt.Rectangle((j, i), 1, 1, facecolor=face, edgecolor="white"))
            ax.text(j + 0.5, i + 0.5, text, ha="center", va="center", fontsize=7)
    ax.set_xlim(0, len(methods))
    ax.set_ylim(len(cases), 0)
    ax.set_xticks(np.arange(len(methods)) + 0.5, methods)
    ax.set_yticks(np.arange(len(cases)) + 0.5, cases, fontsize=8)
    ax.set_title("failure matrix (two-slits --quick unless the row names its scene)")
    fig.tight_layout()
    fig.savefig(path, dpi=150)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/stability"))
    parser.add_argument("--limit", type=float, default=300.0, help="seconds per cell")
    parser.add_argument("--quick", action="store_true", help="two cells only")
    parser.add_argument(
        "--resume", action="store_true", help="keep the cells already in stability.csv"
    )
    parser.add_argument(
        "--methods",
        nargs="+",
        default=METHODS,
        help="solver[+extension][/adapt] (e.g. am/paper, newton+extension)",
    )
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    args = parser.parse_args()
    cells = [(m, c) for c in args.cases for m in args.methods]
    if args.quick:
        cells = [("am/paper", "Δt=0.1"), ("anderson/paper", "Δt=0.1")]
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    if args.resume and (args.out / "stability.csv").exists():
        with open(args.out / "stability.csv", newline="") as f:
            rows = [convert(row) for row in csv.DictReader(f)]
    done = {(r["method"], r["case"]) for r in rows}
    for method, case in cells:
        if (method, case) in done:
            continue
        rows.append(run_cell(method, case, args.limit))
        print(json.dumps(rows[-1]), flush=True)
        columns = list(dict.fromkeys(k for r in rows for k in r))
        with open(args.out / "stability.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=columns)
            writer.writeheader()
            writer.writerows(rows)
    draw(rows, args.out / "stability.png")


if __name__ == "__main__":
    main()
