"""The work-precision and reference scripts in quick mode, and the stored references."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / "geometries" / "reference"


def script(name, *args):
    return subprocess.run(
        [sys.executable, str(ROOT / "scripts" / name), *map(str, args)],
        check=True, capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip


@pytest.mark.parametrize("scene", ["two_slits", "surfing"])
def test_stored_reference_is_complete(scene):
    reference = json.loads((REFERENCE / f"{scene}.json").read_text())
    steps = reference["steps"]
    assert {"t", "bulk", "surface", "total", "force", "tip1_x", "tip1_y"} <= set(steps)
    assert len({len(column) for column in steps.values()}) == 1
    np.testing.assert_allclose(
        steps["total"], np.add(steps["bulk"], steps["surface"]), rtol=1e-8, atol=1e-12
    )
    assert reference["command"].startswith("python scripts/reference_two_slits.py")
    assert reference["cost"]["wall_s"] > 0
    if scene == "two_slits":
        assert len(steps["t"]) == 161
        assert 1.35 < reference["fracture_time"] < 1.55


def test_reference_script_quick(tmp_path):
    out = tmp_path / "surfing.json"
    script("reference_two_slits.py", "--scene", "surfing", "--quick", "--out", out,
           "--folder", tmp_path)  # fmt: skip
    reference = json.loads(out.read_text())
    assert reference["scene"] == "surfing"
    assert len(reference["steps"]["t"]) == 16


def test_work_precision_quick(tmp_path):
    script("work_precision.py", "--quick", "--scenes", "surfing", "--out", tmp_path)
    with open(tmp_path / "work_precision.csv") as f:
        rows = list(csv.DictReader(f))
    cases = [(r["method"], float(r["value"])) for r in rows]
    assert cases == [("adaptive", 0.36), ("uniform", 0.2)]
    for r in rows:
        assert float(r["wall_s"]) > 0 and float(r["peak_memory_mb"]) > 50
        assert np.isfinite(float(r["energy_1.0"])) and np.isfinite(float(r["crack_path"]))
    assert (tmp_path / "work_precision.png").stat().st_size > 10_000
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [entry["measure"] for entry in summary["speedups"]] == ["energy_1.0"]
    assert summary["speedups"][0]["uniform_h"] == 0.2
    # Fields of every tenth step and the last (the study reads energies.csv only).
    for folder in filter(Path.is_dir, (tmp_path / "runs").iterdir()):
        assert len(list(folder.glob("fields/*.vtu"))) == 3  # steps 0, 10 and 15 of 16


def test_hausdorff_distance_of_tip_tracks():
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import work_precision
    finally:
        sys.path.pop(0)
    run = {"t": [0, 1], "tip1_x": [0.0, 1.0], "tip1_y": [0.0, 0.0]}
    other = {"t": [0, 1], "tip1_x": [0.0, 1.0], "tip1_y": [0.0, 0.3]}
    # (1, 0.3) lies 0.3 from the segment (0, 0)-(1, 0); the other way, (1, 0) lies only
    # 0.3/sqrt(1.09) from the segment (0, 0)-(1, 0.3): the Hausdorff distance is 0.3.
    assert np.isclose(work_precision.path_distance(run, other), 0.3)
