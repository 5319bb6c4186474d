"""Adaptivity that lets cracks run: neither the initial mesh nor ε decides when they run.

Question: with the crack band (``adapt=band``, the default) the elements where the crack is or
is about to be are tied to ε. Does the paper's example then break at the same time from any
initial mesh, at the converged reference's time, with the crack resolved for every ε, and
what does that cost against the paper's Algorithm 2 alone (``adapt=paper``, the old default)?

Three studies on ``two-slits`` (the paper's example, Section 3), defaults otherwise:

- ``meshes``: initial meshes maxh ∈ {0.5, 0.25, 0.125}: fracture time and E(1.0) against the
  reference (``geometries/reference/two_slits.json``, fracture 1.39);
- ``eps``: ε ∈ {0.05, 0.025, 0.0125} on the quick load steps (Δt = 0.05): fracture time,
  ``eps-under-resolved`` warnings, elements, the crack's element size against ε;
- ``cost``: ``adapt=paper``, the crack band as it was before the grading and the re-meshing
  about running cracks (``band_h=0.25 band_grading=0 remesh_radius=0``) and the default
  ``adapt=band``, on the full load history, run in turn in this one script run: wall,
  elements, fracture time, E(1.0) error.

Run ``python scripts/adaptivity_study.py`` (all three; ``--studies meshes cost`` for some) or
``--quick`` (the coarse variant the tests use). Output in ``--out`` (default
``results/adaptivity_study``): ``adaptivity.csv`` and one results folder per run.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import numpy as np

from ngat.driver import run
from ngat.scene import load_scene

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "geometries" / "reference" / "two_slits.json"


def reference() -> dict:
    """Return the stored reference of two-slits: fracture time and E(t) per load time."""
    data = json.loads(REFERENCE.read_text())
    return {"fracture_time": data["fracture_time"], **data["steps"]}


def energy_at(records: list[dict], t: float) -> float:
    """Return the total energy of the step at load time ``t`` (NaN if there is none)."""
    hits = [r["total"] for r in records if np.isclose(r["t"], t)]
    return hits[0] if hits else float("nan")


BAND_BEFORE = {"band_h": 0.25, "band_grading": 0.0, "remesh_radius": 0.0}
"""The crack band's parameters before the grading and the re-meshing about running cracks."""


def run_case(study: str, overrides: dict, folder: Path, quick_times: bool) -> dict:
    """Run two-slits with ``overrides`` and return its measures."""
    scene = load_scene("two-slits")
    parameters, times = scene.configure(overrides=overrides)
    if quick_times:
        times = scene.configure(quick=True)[1]
    begin = time.perf_counter()
    result = run(scene, parameters, times, folder)
    wall = time.perf_counter() - begin
    records, ref = result.records, reference()
    e_ref = ref["total"][int(np.argmin(np.abs(np.asarray(ref["t"]) - 1.0)))]
    fracture = result.summary.get("fracture_time", np.nan)
    warnings = [p["kind"] for p in result.summary["diagnostics"]]
    cracked = [r["h_crack"] for r in records if r["h_crack"] > 0]
    return {
        "study": study,
        **{k: overrides.get(k, "") for k in ("adapt", "maxh", "eps", *BAND_BEFORE)},
        "fracture_time": fracture,
        "fracture_error": round(fracture - ref["fracture_time"], 4),
        "E(1.0)": round(energy_at(records, 1.0), 6),
        "E(1.0)_error_%": round(100 * (energy_at(records, 1.0) / e_ref - 1), 4),
        "eps_under_resolved": warnings.count("eps-under-resolved"),
        "h_crack_over_eps": round(max(cracked) / parameters.model.eps, 3) if cracked else "",
        "elements": records[-1]["elements"],
        "linear_solves": sum(r["linear_solves"] for r in records),
        "wall_s": round(wall, 1),
    }


def cases(studies: list[str], quick: bool) -> list[tuple[str, dict, bool]]:
    """Return the runs (study, overrides, quick load steps) of the chosen studies."""
    runs = []
    if "meshes" in studies:
        sizes = [0.5, 0.25] if quick else [0.5, 0.25, 0.125]
        runs += [("meshes", {"adapt": "band", "maxh": h}, quick) for h in sizes]
    if "eps" in studies:
        values = [0.1, 0.05] if quick else [0.05, 0.025, 0.0125]
        runs += [("eps", {"adapt": "band", "eps": e, "maxh": 0.5}, True) for e in values]
    if "cost" in studies:
        variants = [{"adapt": "paper"}, {"adapt": "band", **BAND_BEFORE}, {"adapt": "band"}]
        runs += [("cost", variant, quick) for variant in variants]
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="coarse variant (tests)")
    parser.add_argument("--out", type=Path, default=Path("results/adaptivity_study"))
    parser.add_argument(
        "--studies", nargs="+", default=["meshes", "eps", "cost"], choices=["meshes", "eps", "cost"]
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for study, overrides, quick_times in cases(args.studies, args.quick):
        tag = "_".join(f"{k}={v}" for k, v in overrides.items())
        rows.append(run_case(study, overrides, args.out / f"{study}_{tag}", quick_times))
        print(rows[-1], flush=True)
        with open(args.out / "adaptivity.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
