"""Parameter sweeps on Dask (issue 7, item 2): one run per combination, failures recorded, reruns
skip finished runs, ``sweep.csv`` and ``ngat sweep --plot``."""

import csv
import textwrap

import pytest
from dask.distributed import LocalCluster

from ngat.cli import main
from ngat.sweep import RESULT_COLUMNS, run_name, sweep

# eta = 0.03 is only valid with eps = 0.05: exactly one combination fails (eta >= eps).
GRID = {"eps": [0.05, 0.025], "eta": [1e-5, 0.03]}


@pytest.fixture(scope="module")
def scheduler():
    """A local cluster of two single-threaded worker processes, shared by the tests."""
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        yield cluster.scheduler_address


def read_table(folder):
    with open(folder / "sweep.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_two_by_two_sweep_records_a_failure_and_reruns_skip(tmp_path, scheduler):
    folder = tmp_path / "sweep"
    seen = []
    rows = sweep("profile-1d", GRID, folder, scheduler=scheduler, quick=True, on_result=seen.append)
    assert len(seen) == 4
    assert [r["run"] for r in rows] == [
        "eps=0.05_eta=1e-05", "eps=0.05_eta=0.03", "eps=0.025_eta=1e-05", "eps=0.025_eta=0.03",
    ]  # fmt: skip
    table = read_table(folder)
    assert list(table[0]) == ["run", "eps", "eta", *RESULT_COLUMNS]
    assert [r["run"] for r in table] == [r["run"] for r in rows]
    assert [r["status"] for r in table] == ["completed", "completed", "completed", "failed"]
    failed = table[3]
    assert "eta must be smaller than eps" in failed["error"]
    assert failed["total"] == ""
    for row in table[:3]:
        assert row["error"] == ""
        assert row["skipped"] == "False"
        assert float(row["wall_s"]) > 0
        assert row["steps"] == "1"
        assert float(row["total"]) == pytest.approx(float(row["bulk"]) + float(row["surface"]))
        assert row["fracture_time"] == ""  # profile-1d has no fracture time
        assert (folder / row["run"] / "energies.csv").exists()
    # Surface energy per unit length ≈ 1 + (h/ε)²/32 grows as ε shrinks at fixed h.
    assert float(table[2]["surface"]) > float(table[0]["surface"])

    stamps = {r["run"]: (folder / r["run"] / "summary.json").stat().st_mtime_ns for r in table[:3]}
    again = sweep("profile-1d", GRID, folder, scheduler=scheduler, quick=True)
    assert [r["skipped"] for r in again] == [True, True, True, False]
    assert [r["status"] for r in again] == ["completed", "completed", "completed", "failed"]
    for name, stamp in stamps.items():
        assert (folder / name / "summary.json").stat().st_mtime_ns == stamp
    assert read_table(folder)[:3] == [{**r, "skipped": "True"} for r in table[:3]]


def test_a_run_failing_at_run_time_does_not_stop_the_others(tmp_path, scheduler):
    scene = tmp_path / "fragile.py"
    scene.write_text(
        textwrap.dedent(
            """
            import dataclasses
            from ngat.geometries.profile_1d import aligned_mesh, scene as base

            def mesh(maxh):
                if maxh < 0.07:
                    raise RuntimeError("mesher gave up")
                return aligned_mesh(maxh)

            scene = dataclasses.replace(base, name="fragile", mesh=mesh)
            """
        )
    )
    rows = sweep(str(scene), {"maxh": [0.1, 0.05]}, tmp_path / "sweep", scheduler=scheduler)
    assert [r["status"] for r in rows] == ["completed", "failed"]
    assert rows[1]["error"].startswith(
        "SceneCodeError: scene 'fragile': its mesh function raised RuntimeError: mesher gave up ("
    )
    assert rows[1]["run"] == run_name({"maxh": "0.050"}) == "maxh=0.05"


def test_cli_sweep_on_a_local_cluster_and_plot(tmp_path):
    folder = tmp_path / "sweep"
    args = ["sweep", "profile-1d", "--quick", "--grid", "eps=0.05,0.025", "--workers", "2"]
    assert main([*args, "--out", str(folder), "--quiet"]) == 0
    assert [r["status"] for r in read_table(folder)] == ["completed", "completed"]
    plot = ["sweep", "--plot", str(folder), "--x", "eps", "--y", "surface", "total", "--quiet"]
    assert main(plot) == 0
    assert (folder / "sweep_surface_total_vs_eps.png").stat().st_size > 0
    assert main([*plot[:5], "--y", "energy"]) == 2
