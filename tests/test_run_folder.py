"""The results folder across restarts: a fresh run.log and fields with --overwrite, the wall
time of a resumed run, a resume that works after summary.json was deleted, and the diagnostics
of the interrupted part."""

import dataclasses
import json
import textwrap
import time

import pytest

from ngat.cli import main
from ngat.driver import run
from ngat.scene import load_scene
from ngat.timing import SOLVER_KEY

# profile-1d with four load times: a few cheap steps to interrupt and resume.
SCENE = """
    import dataclasses
    from ngat.geometries.profile_1d import scene as base
    scene = dataclasses.replace(
        base, name="profile-steps", times=[0.0, 0.1, 0.2, 0.3],
        parameters={**base.parameters, "checkpoint_every": 0},
    )
    """
PAUSE = 0.5


class Stop(Exception):
    pass


def test_overwrite_starts_a_fresh_run_log(tmp_path):
    folder = tmp_path / "run"
    args = ["run", "profile-1d", "--quick", "--quiet", "--out", str(folder)]
    assert main(args) == 0
    assert main([*args, "--overwrite"]) == 0
    assert (folder / "run.log").read_text().count("scene profile-1d:") == 1


def test_a_fresh_run_leaves_no_vtu_of_an_earlier_longer_run(tmp_path):
    # Scripts read fields/step_*.vtu: a shorter run into the same folder must not leave the
    # longer run's last steps behind.
    scene = dataclasses.replace(load_scene("profile-1d"), times=[0.0, 0.1, 0.2, 0.3])
    parameters, times = scene.configure()
    run(scene, parameters, times, tmp_path)
    longer = {p.name for p in (tmp_path / "fields").glob("*.vtu")}
    run(scene, parameters, times[:2], tmp_path)
    left = {p.name for p in (tmp_path / "fields").glob("*.vtu")}
    assert any(int(name[5:9]) >= 2 for name in longer)
    assert left and all(int(name[5:9]) < 2 for name in left)
    assert all(name in (tmp_path / "fields.pvd").read_text() for name in left)


def test_resume_without_summary_counts_the_whole_wall_time(tmp_path, capsys):
    scene_file = tmp_path / "steps.py"
    scene_file.write_text(textwrap.dedent(SCENE))
    scene = load_scene(str(scene_file))
    parameters, times = scene.configure()
    folder = tmp_path / "run"

    def pause_then_stop(record):
        # The pauses before step 2's checkpoint count; the run stops after step 2.
        time.sleep(PAUSE)
        if record["step"] == 2:
            raise Stop

    with pytest.raises(Stop):
        run(scene, parameters, times, folder, on_step=pause_then_stop)
    (folder / "summary.json").unlink()

    args = ["run", str(scene_file), "--quiet", "--no-plots"]
    assert main([*args, "--out", str(folder)]) == 2
    assert "--resume to continue it" in capsys.readouterr().err
    begin = time.perf_counter()
    assert main([*args, "--resume", str(folder)]) == 0
    resumed_part = time.perf_counter() - begin

    summary = json.loads((folder / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["steps"] == 4 and summary["resumed_after_step"] == [2]
    wall = summary["timing"]["wall"]
    assert wall >= 2 * PAUSE
    assert wall > resumed_part
    phases = sum(v for k, v in summary["timing"].items() if k not in ("wall", SOLVER_KEY))
    assert phases == pytest.approx(wall, abs=1e-3)
    solver = summary["timing"][SOLVER_KEY]  # the solve phase, or more: solves on either thread
    assert summary["timing"]["solve"] - 1e-3 <= solver <= wall
    # Each phase's seconds with no solver under way are a part of it, and they are the rest.
    alone = summary["timing_without_solver"]
    assert all(0 <= seconds <= summary["timing"][phase] + 1e-3 for phase, seconds in alone.items())
    assert sum(alone.values()) == pytest.approx(wall - solver, abs=1e-3)


def test_resumed_run_keeps_the_diagnostics_of_the_interrupted_part(tiny_run, tmp_path):
    # The tiny run is under-resolved on purpose: eps-under-resolved at steps 2, 3 and 4.
    import ngat

    scene, parameters = tiny_run
    whole = ngat.run(scene, out=tmp_path / "whole", plots=False, **parameters).summary

    def stop_after_step_3(record):
        if record["step"] == 3:
            raise Stop

    with pytest.raises(Stop):
        ngat.run(scene, out=tmp_path / "cut", plots=False, on_step=stop_after_step_3, **parameters)
    resumed = ngat.run(scene, out=tmp_path / "cut", resume=True, plots=False, **parameters)
    assert [d["step"] for d in whole["diagnostics"]] == [2, 3, 4]
    assert resumed.summary["diagnostics"] == whole["diagnostics"]
