"""Scripts run in quick mode and write their outputs."""

import csv
import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
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


def test_bench_estimators_on_a_small_mesh(tmp_path):
    subprocess.run(
        [
            sys.executable, str(ROOT / "scripts" / "bench_estimators.py"), "--elements", "2000",
            "--repeats", "1", "--out", str(tmp_path),
        ],
        check=True, capture_output=True,
    )  # fmt: skip
    bench = json.loads((tmp_path / "bench.json").read_text())
    assert bench["elements"] >= 2000
    assert set(bench["median_s"]) == {"u-step + v-step", "edge topology", "μ", "ν"}
    assert all(seconds > 0 for seconds in bench["median_s"].values())
    assert (tmp_path / "bench.png").stat().st_size > 5_000


def test_sample_without_solver_accounts_for_every_second_with_no_solver(tmp_path):
    subprocess.run(
        [
            sys.executable, str(ROOT / "scripts" / "sample_without_solver.py"), "--quick",
            "--until", "1.0", "--interval", "0.001", "--out", str(tmp_path),
        ],
        check=True, capture_output=True,
    )  # fmt: skip
    samples = json.loads((tmp_path / "samples.json").read_text())
    by_timer = samples["without_solver_s"]
    # The samples charge the solver clock's idle seconds: together they are the run's.
    assert samples["sampled_s"] == pytest.approx(sum(by_timer.values()), rel=0.05, abs=0.02)
    assert sum(samples["phases_s"].values()) == pytest.approx(samples["sampled_s"], abs=0.01)
    assert sum(samples["lines_s"].values()) == pytest.approx(samples["sampled_s"], abs=0.01)
    # Every sample knows the run's phase (but the first milliseconds, before the run's timer
    # exists), and the largest phase is found where the timer has it.
    before = samples["phases_s"].pop("before the run's timer", 0.0)
    assert before < 0.05
    assert set(samples["phases_s"]) <= set(by_timer)
    largest = max(by_timer, key=by_timer.get)
    assert samples["phases_s"].get(largest, 0.0) > 0.5 * by_timer[largest]
    outside = samples["lines_s"].pop("outside the package", 0.0)  # the script around the run
    assert outside < 0.05
    assert all(".py:" in line for line in samples["lines_s"])
    assert "| phase | run's timer [s] | sampled [s] |" in (tmp_path / "samples.md").read_text()
    assert (tmp_path / "samples.png").stat().st_size > 5_000


@pytest.mark.skipif(not (ROOT / ".git").exists(), reason="needs a git checkout")
def test_bench_paper_against_the_same_revision(tmp_path):
    # HEAD against HEAD: the same code on both sides, so the deterministic figures agree. The
    # quick history up to t = 1.35, before its break step (47 of its 56 s).
    subprocess.run(
        [
            sys.executable, str(ROOT / "scripts" / "bench_paper.py"), "--quick", "--until", "1.35",
            "--repeats", "1", "--against", "HEAD", "--scaled-to", "10", "--out", str(tmp_path),
        ],
        check=True, capture_output=True,
    )  # fmt: skip
    comparison = json.loads((tmp_path / "compare.json").read_text())
    current, against = comparison["summary"]["current"], comparison["summary"]["against"]
    for key in ("linear_solves", "final_elements", "energy_error_%"):
        assert current[key] is not None and current[key] == against[key]
    assert current["fracture_time"] is None and against["fracture_time"] is None
    # The command's pictures come on top of the load history.
    assert current["with_pictures_median_s"] > current["wall_median_s"]
    # The command adds its start-up (NGSolve's import alone takes some 0.3 s).
    run = comparison["runs"]["current"][0]
    assert run["start_s"] > 0.2
    parts = run["start_s"] + run["wall_s"] + run["pictures_s"]
    assert run["command_s"] == pytest.approx(parts, abs=0.02)  # each part rounded to 0.01 s
    assert current["command_median_s"] == run["command_s"]
    # Its processor time counts every thread's work: more than a small part of the wall even
    # beside other tests, less than the wall on every core the process may use.
    cores = len(os.sched_getaffinity(0))
    assert 0.2 * run["wall_s"] < run["processor_s"] < (cores + 0.05) * run["wall_s"]
    assert current["processor_median_s"] == run["processor_s"]
    # A linear solver runs through the solve phase, and in the background beyond it.
    assert current["phase_share"]["solve"] - 0.005 <= current["solver_share"] <= 1.0
    # The phases' seconds with no solver under way are the rest of the run's wall.
    alone = run["without_solver_s"]
    assert "solve" not in alone and min(alone.values()) >= -0.01
    rest = sum(run["phases_s"].values()) - run["solver_s"]
    assert sum(alone.values()) == pytest.approx(rest, abs=0.01)
    assert current["without_solver_median_s"]["assembly"] == round(alone["assembly"], 2)
    # No break step before t = 1.35: every step's wall is before it.
    stages = current["stage_median_s"]
    assert stages["before the break"] > 0
    assert stages["break step"] is None and stages["after the break"] is None
    assert [r["steps"] for r in comparison["runs"]["current"]] == [28]  # t = 0, 0.05, ..., 1.35
    assert {r["ngat"] for r in comparison["runs"]["current"]} == {str(ROOT / "ngat")}
    markdown = (tmp_path / "compare.md").read_text()
    assert markdown.startswith("two-slits --quick --until 1.35,")
    assert "| fracture time |" in markdown
    assert "| the command: start-up, run, pictures, median [s] |" in markdown
    assert "| processor time of the load history, all threads, median [s] |" in markdown
    assert "| break step, median [s] | – | – |" in markdown
    assert "| share with a linear solver under way, either thread [%] |" in markdown
    assert "| assembly with no solver under way, median [s] |" in markdown
    ratio = comparison["runs"]["current"][0]["wall_s"] / comparison["runs"]["against"][0]["wall_s"]
    assert comparison["pair_ratios"] == [round(ratio, 3)]
    assert f"Pair by pair: {ratio:.3f}" in markdown
    # Scaled to a machine on which HEAD's history took 10 s: HEAD there by construction, the
    # current tree by the ratio of the medians.
    factor = comparison["scale"]["factor"]
    assert factor == pytest.approx(10 / against["wall_median_s"])
    assert f"| wall time median, scaled [s] | {10 * ratio:.1f} | 10.0 |" in markdown
    command = current["command_median_s"] * factor
    assert f"| the command median, scaled [s] | {command:.1f} |" in markdown


def test_stability_judges_the_broken_body_against_the_reference():
    # A two-slits cell that breaks at the reference's time with the right E(1.0) is still
    # wrong if the broken body's I_j at the last load time is more than 3 % off the reference's.
    spec = importlib.util.spec_from_file_location("stability", ROOT / "scripts" / "stability.py")
    stability = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stability)
    steps = stability.REFERENCE["steps"]
    e_1, e_end = (steps["total"][steps["t"].index(t)] for t in (1.0, 1.6))
    row = {"status": "converged", "fracture_time": 1.4, "energy_1.0": e_1, "total": e_end}
    assert stability.judge(row, "Δt=0.05")["verdict"] == "right"
    row["total"] = 1.036 * e_end  # the crack extension's broken body on this row
    judged = stability.judge(row, "Δt=0.05")
    assert judged["verdict"] == "wrong: broken I_j +3.6 %"
    assert judged["broken_energy_error_%"] == 3.6


def bench_break_step(*arguments: str, check: bool = True) -> subprocess.CompletedProcess:
    """Run ``scripts/bench_break_step.py --quick`` (at t = 1.35 unless ``--at`` is given)."""
    at = [] if "--at" in arguments else ["--at", "1.35"]
    script = str(ROOT / "scripts" / "bench_break_step.py")
    return subprocess.run(
        [sys.executable, script, "--quick", *at, *arguments],
        check=check, capture_output=True, text=True, timeout=600,
    )  # fmt: skip


def test_bench_break_step_repeats_the_uninterrupted_step(tmp_path, quick_run):
    # A cheap step of the quick variant (t = 1.35, 19 iterations, two new meshes) stands for
    # the break step: resumed twice from the checkpoint of t = 1.30, it must repeat the
    # uninterrupted run's step to the last bit, and the trace must hold its iterations.
    bench_break_step("--repeats", "2", "--samples", "1", "--out", str(tmp_path))
    bench = json.loads((tmp_path / "bench.json").read_text())
    result, _, _ = quick_run
    (step,) = [r for r in result.records if abs(r["t"] - 1.35) < 1e-9]
    (before,) = [r for r in result.records if abs(r["t"] - 1.30) < 1e-9]
    assert bench["repeatable"]
    assert bench["total_after"] == step["total"] and bench["elements_after"] == step["elements"]
    assert bench["total_before"] == pytest.approx(before["total"], rel=1e-12)
    assert bench["iterations"] == step["am_iterations"] > 1
    trace = list(csv.DictReader(open(tmp_path / "trace.csv")))
    assert len(trace) == step["am_iterations"]
    assert int(trace[-1]["elements"]) == step["elements"]
    assert float(trace[-1]["total"]) == pytest.approx(step["total"], rel=1e-9)
    seconds = [float(row["seconds"]) for row in trace]
    assert seconds == sorted(seconds) and seconds[-1] <= max(bench["wall_s"]["each"])
    assert (tmp_path / "trace.png").stat().st_size > 10_000
    # A draw from v perturbed by at most 1e−9 of itself ends at the same critical point of
    # this stable step; the perturbation moves every v that is not 0 down, and no further.
    unperturbed, perturbed = bench["samples"]["draws"]
    assert unperturbed["total_after"] == step["total"]
    assert perturbed["total_after"] == pytest.approx(step["total"], rel=1e-5)
    spec = importlib.util.spec_from_file_location(
        "bench_break_step", ROOT / "scripts" / "bench_break_step.py"
    )
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    copy = tmp_path / "perturbed"
    shutil.copytree(tmp_path / "checkpoint", copy)
    script.perturb(copy, seed=1)
    v = np.load(tmp_path / "checkpoint" / "checkpoint.npz")["v"]
    moved = v - np.load(copy / "checkpoint.npz")["v"]
    assert np.all(moved[v > 0] > 0) and np.all(moved <= script.PERTURBATION * v)


def test_bench_break_step_to_the_end(tmp_path, quick_run):
    # --to-end resumes the quick variant from the checkpoint of t = 1.30 to its last load time
    # (its break step at 1.40 among them): one record for the steps from t = 1.35 on, their
    # iterations and solves summed, I_j and the elements of the last, to the uninterrupted
    # run's last bit; the trace holds every iteration of those steps.
    bench_break_step("--repeats", "1", "--to-end", "--out", str(tmp_path))
    bench = json.loads((tmp_path / "bench.json").read_text())
    result, _, _ = quick_run
    steps = [r for r in result.records if r["t"] > 1.30 + 1e-9]
    assert len(steps) > 1 and bench["to_end"]
    assert bench["iterations"] == sum(r["am_iterations"] for r in steps)
    assert bench["linear_solves"] == sum(r["linear_solves"] for r in steps)
    assert bench["total_after"] == steps[-1]["total"]
    assert bench["elements_after"] == steps[-1]["elements"]
    trace = list(csv.DictReader(open(tmp_path / "trace.csv")))
    assert len(trace) == bench["iterations"]
    assert int(trace[-1]["elements"]) == steps[-1]["elements"]


def test_bench_break_step_refuses_a_time_that_is_not_a_load_time(tmp_path):
    done = bench_break_step("--at", "1.37", "--out", str(tmp_path), check=False)
    assert done.returncode == 2
    assert "--at 1.37 is not a load time of the scene" in done.stderr


def test_bench_break_step_against_the_same_revision(tmp_path):
    # HEAD against HEAD, draw by draw: the same code on both sides, each from a checkpoint of
    # its own, so every draw's iterations, solves, I_j and elements agree, and the ratios are
    # those of the walls reported.
    bench_break_step("--samples", "1", "--against", "HEAD", "--out", str(tmp_path))
    comparison = json.loads((tmp_path / "compare.json").read_text())
    assert [d["seed"] for d in comparison["draws"]] == [0, 1]
    for draw in comparison["draws"]:
        current, against = draw["current"], draw["against"]
        assert current["iterations"] > 1 and current["elements_after"] > 0
        assert {k: v for k, v in current.items() if k != "wall_s"} == {
            k: v for k, v in against.items() if k != "wall_s"
        }
    ratios = [
        round(d["current"]["wall_s"] / d["against"]["wall_s"], 3) for d in comparison["draws"]
    ]
    assert comparison["draw_ratios"] == ratios
    markdown = (tmp_path / "compare.md").read_text()
    assert markdown.startswith("--scene two-slits --at 1.35 --quick: the break step")
    assert f"Draw by draw: {ratios[0]:.3f}, {ratios[1]:.3f}" in markdown
    worktrees = subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "list"], capture_output=True, text=True, check=True
    )
    assert "bench-against-" not in worktrees.stdout
