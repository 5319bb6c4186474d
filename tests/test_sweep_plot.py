"""``ngat sweep --plot``: axes named by parameter, meaning and unit; numeric and categorical x."""

import csv
import json

import matplotlib
import pytest

from ngat.cli import main
from ngat.plotting import sweep_figure
from ngat.sweep import RESULT_COLUMNS

GRID = {"eps": ["0.05", "0.025", "0.0125"], "nonlinear": ["am", "newton"]}


@pytest.fixture
def sweep_folder(tmp_path):
    """A sweep folder as ``ngat sweep`` leaves it, with made-up results and one failed run."""
    rows = []
    for eps in GRID["eps"]:
        for nonlinear in GRID["nonlinear"]:
            failed = eps == "0.0125" and nonlinear == "am"
            rows.append(
                {
                    "run": f"eps={eps}_nonlinear={nonlinear}",
                    "eps": eps,
                    "nonlinear": nonlinear,
                    "status": "failed" if failed else "completed",
                    "wall_s": 10 / float(eps),
                    "total": 1 + float(eps),
                    "fracture_time": "" if eps == "0.05" else 1.4,
                }
            )
    (tmp_path / "sweep.json").write_text(json.dumps({"scene": "two-slits", "grid": GRID}))
    with open(tmp_path / "sweep.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["run", *GRID, *RESULT_COLUMNS], restval="")
        writer.writeheader()
        writer.writerows(rows)
    return tmp_path, rows


def test_axes_name_the_parameter_and_the_units(sweep_folder):
    _, rows = sweep_folder
    done = [{k: str(v) for k, v in row.items()} for row in rows if row["status"] == "completed"]
    fig = sweep_figure(done, GRID, "eps", ["wall_s", "total", "fracture_time"])
    wall, total, fracture = fig.axes
    assert wall.get_xlabel() == "eps: regularisation length ε [length]"
    assert wall.get_xscale() == "linear"  # a factor of four; log from a factor of ten
    assert wall.get_ylabel() == "wall_s: wall time [s]"
    assert total.get_ylabel().startswith("total: total energy")
    assert [line.get_label() for line in total.get_lines()] == ["nonlinear=am", "nonlinear=newton"]
    am, newton = (line.get_xydata() for line in fracture.get_lines())
    assert am.tolist() == [[0.025, 1.4]]  # the empty cell and the failed run are left out
    assert newton.tolist() == [[0.0125, 1.4], [0.025, 1.4]]


def test_categorical_parameter_on_x_in_grid_order(sweep_folder):
    _, rows = sweep_folder
    done = [{k: str(v) for k, v in row.items()} for row in rows if row["status"] == "completed"]
    grid = {"nonlinear": GRID["nonlinear"], "eps": GRID["eps"]}
    fig = sweep_figure(done, grid, "nonlinear", ["total"])
    (ax,) = fig.axes
    assert ax.get_xlabel() == "nonlinear: solver of a load step"
    assert len(ax.get_lines()) == 3  # one per eps


def test_cli_plot_writes_the_picture_and_leaves_pyplot_alone(sweep_folder):
    folder, _ = sweep_folder
    backend = matplotlib.get_backend()
    args = ["sweep", "--plot", str(folder), "--x", "eps", "--y", "wall_s", "total", "--quiet"]
    assert main(args) == 0
    assert (folder / "sweep_wall_s_total_vs_eps.png").stat().st_size > 10_000
    assert main([*args[:5], "--x", "nonlinear", "--y", "total", "--quiet"]) == 0
    assert (folder / "sweep_total_vs_nonlinear.png").exists()
    assert matplotlib.get_backend() == backend
