"""One run per results folder: two runs started on one folder give one refusal and an intact
run; the lock follows its holder's life (a killed holder frees it), is re-entrant within a
thread and guards sweeps too; atomic writes use temporary names of their own.
"""

import json
import os
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

import ngat
from ngat.lock import LOCK_FILE, FolderInUse, folder_lock
from ngat.output import atomic_file
from ngat.sweep import run_combination, sweep

ROOT = Path(ngat.__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}

# The mesh builder waits for the file $NGAT_TEST_GATE: the run that wins the folder holds it,
# locked, until the test opens the gate.
GATED = """
    import dataclasses
    import os
    import time

    import numpy as np

    from ngat.geometries.profile_1d import aligned_mesh
    from ngat.geometries.profile_1d import scene as base


    def gated_mesh(maxh):
        deadline = time.monotonic() + 120
        while not os.path.exists(os.environ["NGAT_TEST_GATE"]) and time.monotonic() < deadline:
            time.sleep(0.01)
        return aligned_mesh(maxh)


    scene = dataclasses.replace(
        base, name="gated", mesh=gated_mesh, times=np.linspace(0.0, 1.0, 4),
        quick={"maxh": 0.1, "eps": 0.2},
    )
    """

HOLDER = (
    "import sys\n"
    "from ngat.lock import folder_lock\n"
    "with folder_lock(sys.argv[1]):\n"
    "    print('locked', flush=True)\n"
    "    sys.stdin.read()\n"
)


@pytest.fixture
def holder(tmp_path):
    """Start a process that holds the lock of a folder until its stdin closes."""
    started = []

    def hold(folder):
        process = subprocess.Popen(
            [sys.executable, "-c", HOLDER, str(folder)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=ENV,
        )
        started.append(process)
        assert process.stdout.readline() == "locked\n"
        return process

    yield hold
    for process in started:
        process.stdin.close()
        process.wait()
        process.stdout.close()


def test_two_runs_started_together_give_one_refusal_and_one_intact_run(tmp_path):
    scene = tmp_path / "gated.py"
    scene.write_text(textwrap.dedent(GATED))
    gate = tmp_path / "gate"
    folder = tmp_path / "D"
    args = [sys.executable, "-m", "ngat.cli", "run", str(scene), "--quick", "--quiet"]
    processes = [
        subprocess.Popen(
            [*args, "--out", str(folder)],
            stderr=subprocess.PIPE,
            text=True,
            env={**ENV, "NGAT_TEST_GATE": str(gate)},
        )
        for _ in range(2)
    ]
    deadline = time.monotonic() + 120
    while all(p.poll() is None for p in processes) and time.monotonic() < deadline:
        time.sleep(0.01)
    refused = next(p for p in processes if p.poll() is not None)
    winner = next(p for p in processes if p is not refused)
    error = refused.stderr.read()
    gate.touch()
    assert winner.wait(timeout=120) == 0, winner.stderr.read()
    winner.stderr.close()
    refused.stderr.close()

    assert refused.returncode == 2
    assert error.splitlines() == [
        f"ngat: error: results folder '{folder}' is already in use by process {winner.pid}: "
        "wait until that run ends or choose another folder"
    ]
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["steps"] == 4
    assert len((folder / "energies.csv").read_text().splitlines()) == 5
    assert "resumed_after_step" not in summary
    assert sorted(p.name for p in folder.iterdir() if p.name.startswith(".")) == []


def test_the_lock_is_held_by_a_process_and_freed_when_it_dies(tmp_path, holder):
    folder = tmp_path / "D"
    process = holder(folder)
    assert (folder / LOCK_FILE).read_text() == f"{process.pid}\n"
    with pytest.raises(FolderInUse, match=f"already in use by process {process.pid}"):
        with folder_lock(folder):
            pass
    process.kill()  # SIGKILL: no clean-up, the lock file stays behind
    process.wait()
    assert (folder / LOCK_FILE).exists()
    with folder_lock(folder):
        assert (folder / LOCK_FILE).read_text() == f"{os.getpid()}\n"
    assert not (folder / LOCK_FILE).exists()


def test_the_lock_is_reentrant_in_its_thread_and_refused_to_others(tmp_path):
    folder = tmp_path / "D"
    seen = []

    def other_thread():
        try:
            with folder_lock(folder):
                seen.append("locked")
        except FolderInUse as error:
            seen.append(str(error))

    with folder_lock(folder):
        with folder_lock(folder):
            thread = threading.Thread(target=other_thread)
            thread.start()
            thread.join()
        assert (folder / LOCK_FILE).exists()  # still held by the outer block
    assert seen == [
        f"results folder '{folder}' is already in use by process {os.getpid()}: wait until that "
        "run ends or choose another folder"
    ]
    assert not (folder / LOCK_FILE).exists()
    thread = threading.Thread(target=other_thread)
    thread.start()
    thread.join()
    assert seen[-1] == "locked"


def test_a_sweep_run_whose_folder_is_in_use_fails_and_a_locked_sweep_is_refused(tmp_path, holder):
    run_folder = tmp_path / "sweep" / "eps=0.05"
    process = holder(run_folder)
    row = run_combination("profile-1d", {"eps": 0.05}, str(run_folder), quick=True)
    assert row["status"] == "failed"
    assert row["error"].startswith(
        f"FolderInUse: results folder '{run_folder}' is already in use by process {process.pid}"
    )
    assert sorted(p.name for p in run_folder.iterdir()) == [LOCK_FILE]  # nothing written

    sweep_folder = tmp_path / "other-sweep"
    process = holder(sweep_folder)
    with pytest.raises(FolderInUse, match=f"in use by process {process.pid}"):
        sweep("profile-1d", {"eps": [0.05]}, sweep_folder, quick=True)
    assert sorted(p.name for p in sweep_folder.iterdir()) == [LOCK_FILE]


def test_atomic_writes_use_temporary_names_of_their_own_and_leave_none_behind(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text("old")
    with atomic_file(path) as first, atomic_file(path) as second:
        assert first.name != second.name
        first.write(b"first")
        second.write(b"second")
    assert path.read_text() == "first"  # the outer block ends last
    with pytest.raises(OSError, match="No space left"):
        with atomic_file(path) as f:
            f.write(b"half")
            raise OSError(28, "No space left on device")
    with pytest.raises(KeyboardInterrupt):
        with atomic_file(path) as f:
            f.write(b"half")
            raise KeyboardInterrupt
    assert path.read_text() == "first"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]


def test_a_refused_process_waits_for_the_winner_to_write_its_id(tmp_path):
    # The winner writes its id just after it wins the lock: a process refused in between
    # must not report "another process" for want of waiting.
    from ngat.lock import _holder

    path = tmp_path / LOCK_FILE
    path.write_text("")
    fd = os.open(path, os.O_RDONLY)
    writer = threading.Timer(0.05, lambda: path.write_text("4242\n"))
    writer.start()
    try:
        assert _holder(fd) == "4242"
    finally:
        writer.join()
        os.close(fd)
