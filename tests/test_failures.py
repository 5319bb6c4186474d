"""Every failure is one line and a recorded status: a damaged checkpoint, a full disk, scene code
that raises, a NaN load, non-finite parameters, SIGINT and SIGTERM, ``ngat plot`` on a wrong path.

Bad input exits with status 2 and at most two lines, no traceback; a signal with 128 + its
number. The folder keeps what it had, says in ``summary.json`` how the run ended, holds no
temporary files, and a run stopped by the disk or a signal continues with ``--resume`` to the
result of an uninterrupted run.
"""

import csv
import errno
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import ngat
from ngat.checkpoint import finished_steps, load_checkpoint
from ngat.cli import main
from ngat.diagnostics import Diagnostics
from ngat.driver import run
from ngat.scene import SceneCodeError, load_scene

ROOT = Path(ngat.__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}

# 40 cheap load steps (about 0.05 s each) on the aligned mesh of profile-1d.
STEPS = """
    import dataclasses

    import numpy as np

    from ngat.geometries.profile_1d import scene as base

    # A checkpoint after every step: the tests below stop the run between any two.
    scene = dataclasses.replace(
        base, name="profile-steps", times=np.linspace(0.0, 1.0, 40),
        quick={"maxh": 0.05, "eps": 0.1}, parameters={**base.parameters, "checkpoint_every": 0},
    )
    """

SCENE_CODE = {
    "geometry": """
        import dataclasses
        from ngat.geometries.two_slits import scene as base

        def geometry():
            return 1 / 0

        scene = dataclasses.replace(base, name="broken", geometry=geometry)
        """,
    "mesh": """
        import dataclasses
        from ngat.geometries.profile_1d import scene as base

        def mesh(maxh):
            raise RuntimeError("no mesher today")

        scene = dataclasses.replace(base, name="broken", mesh=mesh)
        """,
    "load": """
        import dataclasses
        from ngat.geometries.profile_1d import scene as base

        def pull(t):
            raise ValueError("no load today")

        scene = dataclasses.replace(base, name="broken", loads={"lower": pull})
        """,
    "crack": """
        import dataclasses
        from ngat.geometries.profile_1d import scene as base

        def crack(coords):
            return coords[:, 7] > 0

        scene = dataclasses.replace(base, name="broken", crack=crack)
        """,
}
ROLES = {
    "geometry": ("its geometry function", "ZeroDivisionError: division by zero", 6),
    "mesh": ("its mesh function", "RuntimeError: no mesher today", 6),
    "load": ("the load of region 'lower'", "ValueError: no load today", 6),
    "crack": ("its crack function", "IndexError: index 7 is out of bounds", 6),
}


def one_line(capsys):
    """Return the only line on stderr (no traceback, at most two lines: exactly one here)."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


def read_rows(folder):
    with open(folder / "energies.csv", newline="") as f:
        return [{k: v for k, v in row.items() if k != "wall_s"} for row in csv.DictReader(f)]


def summary_of(folder):
    return json.loads((folder / "summary.json").read_text())


def hidden_files(folder):
    return sorted(p.name for p in folder.rglob(".*"))


def snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def steps(tmp_path_factory):
    """The scene file, the command that runs it, and its uninterrupted rows."""
    root = tmp_path_factory.mktemp("steps")
    scene = root / "steps.py"
    scene.write_text(textwrap.dedent(STEPS))
    command = ["run", str(scene), "--quick", "--quiet"]
    assert main([*command, "--out", str(root / "reference")]) == 0
    return scene, command, read_rows(root / "reference")


@pytest.fixture(scope="module")
def interrupted(steps, tmp_path_factory):
    """A run stopped by KeyboardInterrupt after its third step (in the process)."""
    scene_file, _, _ = steps
    folder = tmp_path_factory.mktemp("interrupted") / "D"
    scene = load_scene(str(scene_file))
    parameters, times = scene.configure(quick=True)

    def stop(record):
        if record["step"] == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(scene, parameters, times, folder, on_step=stop)
    return folder


def test_an_interrupted_run_records_its_status_and_last_finished_step(interrupted):
    summary = summary_of(interrupted)
    assert summary["status"] == "interrupted"
    assert summary["steps"] == 3 and summary["final"]["step"] == 2
    assert load_checkpoint(interrupted).step == 2
    assert hidden_files(interrupted) == []


def test_a_run_between_checkpoints_resumes_from_the_last_and_repeats_the_steps_after_it(
    steps, tmp_path
):
    # With checkpoint_every longer than the run only the last step writes a checkpoint: a run
    # stopped after step 5 has rows and fields of six steps and no checkpoint, and resumed it
    # computes every step again, to the same rows and a complete fields.pvd.
    scene_file, _, expected = steps
    scene = load_scene(str(scene_file))
    parameters, times = scene.configure(quick=True, overrides={"checkpoint_every": 1e9})
    folder = tmp_path / "D"
    checkpointed = []

    def stop(record):
        checkpointed.append(finished_steps(folder))
        if record["step"] == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(scene, parameters, times, folder, on_step=stop)
    assert checkpointed == [0] * 6 and row_count(folder) == 6
    assert summary_of(folder)["steps"] == 6
    run(scene, parameters, times, folder, resume=True)
    assert read_rows(folder) == expected
    assert load_checkpoint(folder).step == len(expected) - 1
    series = (folder / "fields.pvd").read_text()
    assert series.count("<DataSet") == len(expected) == len(list((folder / "fields").iterdir()))


def test_an_interrupt_between_checkpoints_says_which_steps_resume_computes_again(
    steps, tmp_path, monkeypatch, capsys
):
    scene, command, expected = steps
    folder = tmp_path / "D"
    finished = []

    def interrupt_after_step_4(self):
        finished.append(len(finished))
        if finished[-1] == 4:
            raise KeyboardInterrupt

    # The end of a step, after its row and fields: where Ctrl-C between two steps lands.
    monkeypatch.setattr(Diagnostics, "raise_if_error", interrupt_after_step_4)
    settings = ["--set", "checkpoint_every=1e9"]
    assert main([*command, *settings, "--out", str(folder)]) == 128 + signal.SIGINT
    monkeypatch.undo()
    assert one_line(capsys) == (
        f"ngat: interrupted by SIGINT after 5 of {len(expected)} load steps (its checkpoint "
        f"holds 0: --resume computes the 5 after it again); continue with ngat run {scene} "
        f"--quick --set checkpoint_every=1e9 --resume {folder}"
    )
    assert main([*command, *settings, "--resume", str(folder)]) == 0
    assert read_rows(folder) == expected


@pytest.mark.parametrize("damage", ["truncated", "bit-flipped"])
def test_a_damaged_checkpoint_is_named_with_the_fix(steps, interrupted, damage, tmp_path, capsys):
    _, command, expected = steps
    folder = tmp_path / "D"
    shutil.copytree(interrupted, folder)
    path = folder / "checkpoint.npz"
    data = bytearray(path.read_bytes())
    if damage == "truncated":
        data = data[: len(data) // 2]
    else:
        data[len(data) // 2] ^= 0x10
    path.write_bytes(data)
    before = snapshot(folder)
    assert main([*command, "--resume", str(folder)]) == 2
    line = one_line(capsys)
    assert line.startswith(f"ngat: error: checkpoint '{path}' is damaged (BadZipFile: ")
    assert line.endswith(
        f"the run cannot continue from it: start it afresh with --out {folder} --overwrite"
    )
    assert snapshot(folder) == before
    assert main([*command, "--out", str(folder), "--overwrite"]) == 0
    assert read_rows(folder) == expected


def fail_third_checkpoint(monkeypatch):
    """Make the third checkpoint write run out of space half-way."""
    real, calls = np.savez, []

    def savez(file, **arrays):
        calls.append(1)
        if len(calls) == 3:
            file.write(b"x" * 4096)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(file, **arrays)

    monkeypatch.setattr(np, "savez", savez)


def test_a_full_disk_is_one_line_a_failed_status_and_resumable(
    steps, tmp_path, monkeypatch, capsys
):
    _, command, expected = steps
    folder = tmp_path / "D"
    fail_third_checkpoint(monkeypatch)
    assert main([*command, "--out", str(folder)]) == 2
    monkeypatch.undo()
    message = (
        f"cannot write to results folder '{folder}' (No space left on device): free space or "
        f"fix the folder, then continue the run with --resume {folder}"
    )
    assert one_line(capsys) == f"ngat: error: {message}"
    summary = summary_of(folder)
    assert summary["status"] == f"failed: OutputError: {message}"
    assert summary["steps"] == 2 and load_checkpoint(folder).step == 1
    assert hidden_files(folder) == []
    # Resumed on a disk still full: the same line, before anything changed.
    import ngat.checkpoint

    def no_space(path, text):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(ngat.checkpoint, "write_atomic", no_space)
    before = snapshot(folder)
    assert main([*command, "--resume", str(folder)]) == 2
    assert one_line(capsys) == f"ngat: error: {message}"
    assert snapshot(folder) == before
    monkeypatch.undo()
    assert main([*command, "--resume", str(folder)]) == 0
    assert read_rows(folder) == expected


def test_a_disk_too_full_for_the_summary_still_records_the_status(steps, tmp_path, monkeypatch):
    # Only a summary without the entries the checkpoint keeps too fits on the disk.
    import ngat.output

    _, command, expected = steps
    folder = tmp_path / "D"
    fail_third_checkpoint(monkeypatch)
    real = ngat.output.write_atomic

    def write_atomic(path, text):
        if path.name == "summary.json" and '"failed' in text and "refinement_history" in text:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(path, text)

    monkeypatch.setattr(ngat.output, "write_atomic", write_atomic)
    assert main([*command, "--out", str(folder)]) == 2
    monkeypatch.undo()
    summary = summary_of(folder)
    assert summary["status"].startswith("failed: OutputError: cannot write")
    assert "refinement_history" not in summary and summary["steps"] == 2
    assert main([*command, "--resume", str(folder)]) == 0
    assert "refinement_history" in summary_of(folder)
    assert read_rows(folder) == expected


def test_an_incomplete_vtu_is_a_write_error_and_is_not_kept(steps, tmp_path, monkeypatch, capsys):
    # VTK's writer does not report a full disk: it leaves the file cut short.
    _, command, _ = steps
    real, calls = ngat.output.write_grid, []

    def cut_short(path, grid, values):
        real(path, grid, values)
        calls.append(1)
        if len(calls) == 2:
            os.truncate(path, 1000)

    monkeypatch.setattr(ngat.output, "write_grid", cut_short)
    folder = tmp_path / "D"
    assert main([*command, "--out", str(folder)]) == 2
    line = one_line(capsys)
    assert "(step_0001.vtu came out incomplete; is the disk full?)" in line
    assert f"--resume {folder}" in line
    assert sorted(p.name for p in (folder / "fields").iterdir()) == ["step_0000.vtu"]
    assert "step_0001" not in (folder / "fields.pvd").read_text()
    assert summary_of(folder)["steps"] == 1


def test_a_full_tmpfs_is_one_line_a_recorded_status_and_resumable(steps, tmp_path):
    scene, command, expected = steps
    if shutil.which("unshare") is None or subprocess.run(["unshare", "-rm", "true"]).returncode:
        pytest.skip("no private mount namespace (unshare -rm) to mount a small tmpfs in")
    disk = tmp_path / "disk"
    disk.mkdir()
    ngat_run = shlex.join([sys.executable, "-m", "ngat.cli", *command])
    q = shlex.quote
    script = f"""
        mount -t tmpfs -o size=1m tmpfs {q(str(disk))} || exit 90
        {ngat_run} --out {q(str(disk / "D"))} 2> {q(str(tmp_path / "full.err"))}
        echo $? > {q(str(tmp_path / "full.rc"))}
        cp -a {q(str(disk / "D"))} {q(str(tmp_path / "full"))}
        mount -o remount,size=64m {q(str(disk))}
        {ngat_run} --resume {q(str(disk / "D"))} 2> {q(str(tmp_path / "resumed.err"))}
        echo $? > {q(str(tmp_path / "resumed.rc"))}
        cp -a {q(str(disk / "D"))} {q(str(tmp_path / "resumed"))}
        """
    result = subprocess.run(["unshare", "-rm", "sh", "-c", script], env=ENV, timeout=300)
    if result.returncode == 90:
        pytest.skip("cannot mount a tmpfs here")
    full = tmp_path / "full"
    assert (tmp_path / "full.rc").read_text() == "2\n"
    lines = (tmp_path / "full.err").read_text().splitlines()
    assert len(lines) == 1 and "Traceback" not in lines[0]
    assert lines[0].startswith(f"ngat: error: cannot write to results folder '{disk / 'D'}' (")
    assert lines[0].endswith(f"then continue the run with --resume {disk / 'D'}")
    assert summary_of(full)["status"].startswith("failed: OutputError: cannot write")
    assert hidden_files(full) == []
    assert all(p.stat().st_size > 0 for p in full.rglob("*") if p.is_file())
    assert (tmp_path / "resumed.rc").read_text() == "0\n", (tmp_path / "resumed.err").read_text()
    assert summary_of(tmp_path / "resumed")["status"] == "completed"
    assert read_rows(tmp_path / "resumed") == expected


@pytest.mark.parametrize("case", SCENE_CODE)
def test_scene_code_that_raises_is_named_in_one_line(case, tmp_path, capsys):
    path = tmp_path / f"broken_{case}.py"
    path.write_text(textwrap.dedent(SCENE_CODE[case]))
    role, error, line_number = ROLES[case]
    folder = tmp_path / "D"
    assert main(["run", str(path), "--quick", "--quiet", "--out", str(folder)]) == 2
    line = one_line(capsys)
    assert line.startswith(f"ngat: error: scene 'broken': {role} raised {error}")
    assert line.endswith(
        f"({path}, line {line_number}); fix the scene (--debug shows the traceback)"
    )
    if case != "geometry":  # the others fail inside the run, which records it
        assert summary_of(folder)["status"].startswith("failed: SceneCodeError: scene 'broken'")
    with pytest.raises(SceneCodeError) as raised:
        main(["--debug", "run", str(path), "--quick", "--quiet", "--out", str(tmp_path / "E")])
    assert f"{type(raised.value.__cause__).__name__}: " in error


def test_a_nan_load_names_its_region(tmp_path, capsys):
    path = tmp_path / "nan_load.py"
    path.write_text(
        textwrap.dedent("""
        import dataclasses
        from ngat.geometries.profile_1d import scene as base

        def pull(t):
            return t * float("nan")

        scene = dataclasses.replace(base, name="nan-load", loads={"lower": pull})
        """)
    )
    folder = tmp_path / "D"
    assert main(["run", str(path), "--quick", "--quiet", "--out", str(folder)]) == 2
    line = one_line(capsys)
    assert line.startswith(
        "ngat: error: the load of region 'lower' is not a finite number at t=0 (NaN or Inf at "
    )
    assert line.endswith("): fix its load function")
    assert summary_of(folder)["status"].startswith("failed: SceneError: the load of region 'lower'")


@pytest.mark.parametrize(
    "setting, default",
    [("eps=inf", "eps=0.05"), ("eps=nan", "eps=0.05"), ("maxh=inf", "maxh=0.25")],
)
def test_non_finite_parameters_are_refused_at_validation(setting, default, tmp_path, capsys):
    folder = tmp_path / "D"
    assert main(["run", "profile-1d", "--set", setting, "--out", str(folder)]) == 2
    name, value = setting.split("=")
    assert one_line(capsys) == (
        f"ngat: error: {name} must be a finite number, got {name}={value}: give e.g. {default}"
    )
    assert not folder.exists()


def test_plot_names_a_missing_path_or_a_file(tmp_path, capsys):
    missing = tmp_path / "nowhere"
    assert main(["plot", str(missing)]) == 2
    assert one_line(capsys) == (
        f"ngat: error: '{missing}' does not exist: give the results folder of a run"
    )
    a_file = tmp_path / "energies.csv"
    a_file.write_text("step,t\n")
    assert main(["plot", str(a_file)]) == 2
    assert one_line(capsys) == (
        f"ngat: error: '{a_file}' is a file, not a folder: give the results folder of a run (the "
        "folder that holds energies.csv)"
    )


def row_count(folder):
    try:
        return max(0, len((folder / "energies.csv").read_text().splitlines()) - 1)
    except FileNotFoundError:
        return 0


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_records_interrupted_and_says_how_to_resume(steps, stop, tmp_path):
    scene, command, expected = steps
    folder = tmp_path / "D"
    process = subprocess.Popen(
        [sys.executable, "-m", "ngat.cli", *command, "--out", str(folder)],
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        # SIGINT may be ignored in a background job; the user's Ctrl-C is not.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while row_count(folder) < 3 and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    assert process.poll() is None, "the run ended before it could be stopped"
    process.send_signal(stop)
    err = process.communicate(timeout=120)[1]
    assert process.returncode == 128 + stop
    summary = summary_of(folder)
    assert summary["status"] == "interrupted"
    done = summary["steps"]
    assert 3 <= done < len(expected) and summary["final"]["step"] == done - 1
    # A step's writes are not cut by a signal: rows, fields and checkpoint agree.
    assert load_checkpoint(folder).step == done - 1
    assert row_count(folder) == done
    assert len(list((folder / "fields").iterdir())) == done
    assert err.splitlines() == [
        f"ngat: interrupted by {stop.name} after {done} of {len(expected)} load steps; continue "
        f"with ngat run {scene} --quick --resume {folder}"
    ]
    assert hidden_files(folder) == []
    assert main([*command, "--resume", str(folder)]) == 0
    assert summary_of(folder)["status"] == "completed"
    assert read_rows(folder) == expected
