"""Checkpoint and resume (issue 7, item 3): a run killed with SIGKILL and resumed ends with the
same ``energies.csv`` as an uninterrupted run, and no file of the interrupted run is lost or
left half-written.

The scene is a short two-slits history on a coarse adaptive mesh: it refines during the run,
cracks (CR fills) and keeps lagged factorisations across steps, so each kill lands between
refinements, with a non-empty crack set, or inside the step that breaks the body.
"""

import csv
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from ngat.checkpoint import load_checkpoint
from ngat.cli import main

SCENE = """
    import dataclasses

    import numpy as np

    from ngat.geometries.two_slits import scene as base

    scene = dataclasses.replace(
        base,
        name="two-slits-short",
        quick={"times": np.round(np.arange(0.0, 2.41, 0.05), 10), "eps": 0.2, "maxh": 0.5,
               "floor": 0.2, "band_h": 0.45, "crtol": 0.05, "tol": 0.4,
               "checkpoint_every": 0},  # killed between any two steps: a checkpoint each
    )
    """
TIMING = {"wall_s"}


def read_rows(folder):
    with open(folder / "energies.csv", newline="") as f:
        return list(csv.DictReader(f))


def row_count(folder):
    try:
        with open(folder / "energies.csv", newline="") as f:
            return max(0, sum(1 for _ in f) - 1)
    except FileNotFoundError:
        return 0


def run_and_kill(args, folder, rows):
    """Start ``ngat run``; SIGKILL it as soon as energies.csv has ``rows`` rows."""
    process = subprocess.Popen(
        [sys.executable, "-m", "ngat.cli", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while row_count(folder) < rows and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    if process.poll() is not None:
        pytest.fail(f"the run ended before it could be killed: {process.stderr.read()}")
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    process.stderr.close()
    assert process.returncode == -signal.SIGKILL


def assert_folder_is_whole(folder):
    """Every file the run promises to keep readable is readable and consistent."""
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["scene"] == "two-slits-short"
    checkpoint = load_checkpoint(folder)
    rows = read_rows(folder)
    # Rows are flushed before the checkpoint is written: at most one row ahead of it.
    assert checkpoint.step + 1 <= len(rows) <= checkpoint.step + 2
    assert [int(r["step"]) for r in rows] == list(range(len(rows)))
    datasets = ET.parse(folder / "fields.pvd").getroot().iter("DataSet")
    files = [d.get("file") for d in datasets]
    assert len(files) >= checkpoint.step + 1
    for name in files:
        assert (folder / name).read_bytes().endswith(b"</VTKFile>\n"), name  # complete


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "short.py"
    path.write_text(textwrap.dedent(SCENE))
    return path


def test_killed_and_resumed_run_equals_uninterrupted_run(tmp_path, scene_file):
    reference = tmp_path / "reference"
    assert main(["run", str(scene_file), "--quick", "--quiet", "--out", str(reference)]) == 0
    expected = read_rows(reference)
    cracked = [int(r["cracked_vertices"]) > 0 for r in expected]
    assert len(expected) == 49
    assert int(expected[-1]["elements"]) > int(expected[0]["elements"]), "no refinement"
    assert any(cracked), "CR stays empty"

    folder = tmp_path / "killed"
    start = ["run", str(scene_file), "--quick", "--quiet"]
    # Kill during the uncracked growth, inside the crack-forming step and after CR has filled.
    first_crack = cracked.index(True)
    run_and_kill([*start, "--out", str(folder)], folder, 15)
    assert_folder_is_whole(folder)
    run_and_kill([*start, "--resume", str(folder)], folder, first_crack)
    assert_folder_is_whole(folder)
    run_and_kill([*start, "--resume", str(folder)], folder, first_crack + 6)
    assert_folder_is_whole(folder)
    # Without --resume the interrupted run is not replaced.
    assert main([*start, "--out", str(folder)]) == 2
    assert main([*start, "--resume", str(folder)]) == 0

    resumed = read_rows(folder)
    assert list(resumed[0]) == list(expected[0])
    assert len(resumed) == len(expected)
    for ours, theirs in zip(resumed, expected, strict=True):
        for column, value in theirs.items():
            if column in TIMING:
                continue
            if value in ("True", "False", "") or column == "warnings":
                assert ours[column] == value, (ours["step"], column)
            else:
                a, b = float(ours[column]), float(value)
                assert abs(a - b) <= 1e-12 * max(1.0, abs(b)), (ours["step"], column, a, b)
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert len(summary["resumed_after_step"]) == 3
    reference_summary = json.loads((reference / "summary.json").read_text())
    assert summary["refinement_history"] == reference_summary["refinement_history"]
    assert summary.get("fracture_time") == reference_summary.get("fracture_time")
    series = ET.parse(folder / "fields.pvd").getroot().iter("DataSet")
    assert len(list(series)) == len(expected)


def test_resume_refuses_another_scene_or_other_parameters(tmp_path, scene_file, capsys):
    folder = tmp_path / "run"
    assert main(["run", "profile-1d", "--quick", "--quiet", "--out", str(folder)]) == 0
    before = (folder / "energies.csv").read_bytes()
    assert main(["run", str(scene_file), "--quick", "--quiet", "--resume", str(folder)]) == 2
    assert "it holds a run of scene 'profile-1d', not 'two-slits-short'" in capsys.readouterr().err
    args = ["run", "profile-1d", "--quick", "--quiet", "--set", "eps=0.1", "--resume", str(folder)]
    assert main(args) == 2
    assert "eps: 0.05 there, 0.1 here" in capsys.readouterr().err
    assert main(["run", "profile-1d", "--quiet", "--resume", str(tmp_path / "nothing")]) == 2
    assert "holds no run" in capsys.readouterr().err
    assert (folder / "energies.csv").read_bytes() == before
    # A finished run has nothing left to resume.
    assert main(["run", "profile-1d", "--quick", "--resume", str(folder)]) == 0
    assert "nothing to resume" in capsys.readouterr().err
    checkpoint = load_checkpoint(folder)
    assert checkpoint.step == 0 and np.all(checkpoint.fields["v"] <= 1)


def test_resume_of_a_run_recorded_before_a_parameter_existed(tmp_path):
    # A summary without am_stop or crack_extension: the run stopped on the change (the paper)
    # and had no crack extension, so it resumes with am_stop=change and not with the default.
    from ngat.output import OutputError, check_results_folder, times_summary
    from ngat.parameters import Parameters

    times = [0.0, 0.1, 0.2]
    recorded = Parameters().flat()
    del recorded["am_stop"], recorded["crack_extension"]
    summary = {"scene": "s", "status": "running", "parameters": recorded,
               "times": times_summary(times)}  # fmt: skip
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    now = Parameters().flat()
    with pytest.raises(OutputError, match="am_stop: change there, contraction here") as error:
        check_results_folder(tmp_path, "s", now, times, mode="resume")
    assert "crack_extension" not in str(error.value)
    legacy = {**now, "am_stop": "change"}
    assert check_results_folder(tmp_path, "s", legacy, times, mode="resume") == summary


@pytest.mark.parametrize("recorded", [None, 0.0, 1e9], ids=["before it existed", "0", "1e9"])
def test_a_resumed_run_may_checkpoint_at_another_interval(tmp_path, recorded):
    # checkpoint_every decides when a run writes, not what it computes: neither the summary's
    # nor the checkpoint's parameters refuse a resume that changes it, or a folder without it.
    from types import SimpleNamespace

    from ngat.checkpoint import check_identity
    from ngat.output import OutputError, check_results_folder, times_summary
    from ngat.parameters import Parameters

    times = [0.0, 0.1, 0.2]
    parameters = Parameters().flat()
    if recorded is None:
        del parameters["checkpoint_every"]
    else:
        parameters["checkpoint_every"] = recorded
    identity = {"scene": "s", "parameters": parameters, "times": times_summary(times)}
    summary = {**identity, "status": "running"}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    now = Parameters().flat()
    assert check_results_folder(tmp_path, "s", now, times, mode="resume") == summary
    check_identity(SimpleNamespace(identity=identity), "s", now, times)
    with pytest.raises(OutputError, match="eps: 0.05 there, 0.1 here"):
        check_results_folder(tmp_path, "s", {**now, "eps": 0.1}, times, mode="resume")
