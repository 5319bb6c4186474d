"""Scripts run in quick mode and write their outputs."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_stability_quick(tmp_path):
    subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "stability.py"), "--quick", "--out", str(tmp_path)],
        check=True,
        capture_output=True,
    )
    rows = list(csv.DictReader(open(tmp_path / "stability.csv")))
    assert [r["method"] for r in rows] == ["am/paper", "anderson/paper"]
    assert all(r["status"] == "converged" for r in rows)
    # After the break the crack paths of the two solvers may differ slightly (the break is a
    # jump between critical points); the final energies (crack lengths) agree to 1 %.
    totals = [float(r["total"]) for r in rows]
    assert abs(totals[0] / totals[1] - 1) < 1e-2
    assert (tmp_path / "stability.png").stat().st_size > 10_000


def test_stability_cell_with_a_refused_setting_reports_the_error(tmp_path):
    # Newton refuses lumping=false while configuring: the cell must say so, not hang.
    subprocess.run(
        [
            sys.executable, str(ROOT / "scripts" / "stability.py"), "--out", str(tmp_path),
            "--methods", "newton", "--cases", "obtuse mesh (sheared), consistent mass",
            "--limit", "60",
        ],
        check=True, capture_output=True, timeout=120,
    )  # fmt: skip
    (row,) = csv.DictReader(open(tmp_path / "stability.csv"))
    assert row["status"].startswith("failed: ParameterError: nonlinear=newton needs lumping=true")


def test_bench_steps_quick(tmp_path):
    subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "bench_steps.py"),
            "--quick",
            "--out",
            str(tmp_path),
        ],
        check=True,
        capture_output=True,
    )
    bench = json.loads((tmp_path / "bench.json").read_text())
    assert bench["steps"] == 160 and bench["steps_per_s_at_100"] > 0
    assert bench["checkpoint_bytes"] < 100_000  # the state of a 348-element mesh, no records


@pytest.mark.skipif(not (ROOT / ".git").exists(), reason="needs a git checkout")
def test_bench_paper_against_the_same_revision(tmp_path):
    # HEAD against HEAD: the same code on both sides, so the deterministic figures agree.
    subprocess.run(
        [
            sys.executable, str(ROOT / "scripts" / "bench_paper.py"), "--quick",
            "--repeats", "1", "--against", "HEAD", "--out", str(tmp_path),
        ],
        check=True, capture_output=True,
    )  # fmt: skip
    comparison = json.loads((tmp_path / "compare.json").read_text())
    current, against = comparison["summary"]["current"], comparison["summary"]["against"]
    for key in ("fracture_time", "linear_solves", "final_elements", "energy_error_%"):
        assert current[key] is not None and current[key] == against[key]
    assert {r["ngat"] for r in comparison["runs"]["current"]} == {str(ROOT / "ngat")}
    assert "| fracture time |" in (tmp_path / "compare.md").read_text()
