"""Bad input (issue 7, item 4): one line naming the problem and the fix, exit code 2, no traceback
unless ``--debug``, and nothing already written is lost.

Each case runs the real command in a subprocess, pointed at a folder that holds a finished run
and a file of the user's; afterwards every byte of that folder must be as before.
"""

import subprocess
import sys
import textwrap

import pytest

from ngat.cli import main

SCENE_FILES = {
    "syntax.py": "x = (\n",
    "empty.py": "import numpy\n",
    "failing.py": "import no_such_module_here\n",
    "times.py": """
        import dataclasses
        from ngat.geometries.profile_1d import scene as base
        scene = dataclasses.replace(base, name="bad-times", times=[0.0, 0.2, 0.2])
        """,
    "no_region.py": """
        import dataclasses
        from ngat.geometries.profile_1d import scene as base
        scene = dataclasses.replace(base, name="no-region", loads={})
        """,
    "wrong_face.py": """
        import dataclasses
        from ngat.geometries.two_slits import scene as base
        scene = dataclasses.replace(base, name="wrong-face", loads={"bottom": lambda t: t})
        """,
    "wrong_material.py": """
        import dataclasses
        from ngat.geometries.profile_1d import scene as base
        scene = dataclasses.replace(base, name="wrong-material", loads={"nowhere": lambda t: t})
        """,
}

# (arguments after "ngat", words the one-line message must contain)
CASES = {
    "unknown scene": (["run", "no-such-scene"], ["unknown scene 'no-such-scene'", "one of"]),
    "missing file": (["run", "missing.py"], ["'missing.py' does not exist", "check the path"]),
    "syntax error": (["run", "syntax.py"], ["syntax error at line 1", "fix the file"]),
    "failing import": (["run", "failing.py"], ["failed to load", "ModuleNotFoundError"]),
    "no scene": (["run", "empty.py"], ["defines no scene", "scene = Scene(...)"]),
    "eps <= 0": (["run", "profile-1d", "--set", "eps=0"], ["eps must be positive", "eps > 0"]),
    "eta < 0": (["run", "profile-1d", "--set", "eta=-1e-5"], ["eta must be non-negative"]),
    "eta >= eps": (
        ["run", "profile-1d", "--set", "eta=0.05"],
        ["eta must be smaller than eps", "eta < eps"],
    ),
    "crtol 0": (["run", "profile-1d", "--set", "crtol=0"], ["crtol must lie in (0, 1)"]),
    "crtol 1": (["run", "profile-1d", "--set", "crtol=1"], ["0 < crtol < 1"]),
    "tol <= 0": (["run", "profile-1d", "--set", "tol=-0.3"], ["tol must be positive", "tol > 0"]),
    "band_grading < 0": (
        ["run", "profile-1d", "--set", "band_grading=-0.1"],
        ["band_grading must be a non-negative number"],
    ),
    "times": (["run", "times.py"], ["strictly increasing", "t[2] = 0.2 follows t[1] = 0.2"]),
    "unknown --set": (
        ["run", "profile-1d", "--set", "epsilon=0.1"],
        ["unknown parameter 'epsilon'", "did you mean 'eps'"],
    ),
    "--set type": (
        ["run", "profile-1d", "--set", "eps=small"],
        ["'eps' needs a value of type float", "eps=0.05"],
    ),
    "--set syntax": (["run", "profile-1d", "--set", "eps"], ["--set expects NAME=VALUE"]),
    "no Dirichlet region": (["run", "no_region.py"], ["has no Dirichlet region", "'loads'"]),
    "region not a face": (
        ["run", "wrong_face.py"],
        ["['bottom'] are neither faces nor edges of the geometry", "name the OCC faces"],
    ),
    "sweep grid": (
        ["sweep", "profile-1d", "--grid", "eps=0.05", "epsilon=1,2"],
        ["sweep grid: unknown parameter 'epsilon'", "use one of"],
    ),
    "sweep grid syntax": (["sweep", "profile-1d", "--grid", "eps"], ["NAME=V1,V2"]),
    "resume another scene": (
        ["run", "slit-laplace", "--quick", "--resume", "finished"],
        ["cannot resume 'finished'", "scene 'profile-1d', not 'slit-laplace'"],
    ),
    "resume other parameters": (
        ["run", "profile-1d", "--quick", "--set", "eps=0.1", "--resume", "finished"],
        ["cannot resume 'finished'", "eps: 0.05 there, 0.1 here", "--overwrite"],
    ),
    "resume nothing": (["run", "profile-1d", "--resume", "nowhere"], ["holds no run"]),
    "folder of another run": (
        ["run", "slit-laplace", "--quick"],
        ["already holds a run of scene 'profile-1d'", "--overwrite"],
    ),
}


def ngat(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "ngat.cli", *args], cwd=cwd, capture_output=True, text=True
    )


def snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """A folder with the scene files and ``finished/``: a completed run plus a user's file."""
    root = tmp_path_factory.mktemp("errors")
    for name, text in SCENE_FILES.items():
        (root / name).write_text(textwrap.dedent(text))
    finished = root / "finished"
    assert main(["run", "profile-1d", "--quick", "--quiet", "--out", str(finished)]) == 0
    (finished / "notes.txt").write_text("the user's notes")
    return root, finished, snapshot(finished)


def assert_one_clean_line(result, words):
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("ngat: error: ")
    for word in words:
        assert word in lines[0]


@pytest.mark.parametrize("case", CASES)
def test_bad_input_gives_one_line_and_keeps_earlier_output(workspace, case):
    root, finished, before = workspace
    args, words = CASES[case]
    out = [] if "--resume" in args else ["--out", str(finished)]
    result = ngat(*args, *out, cwd=root)
    assert_one_clean_line(result, words)
    assert snapshot(finished) == before


def test_region_missing_from_the_mesh_is_named(workspace, tmp_path):
    # A scene with its own mesh builder is checked on the mesh: the run starts and fails before
    # its first step, which leaves nothing that a second attempt could lose.
    root, _, _ = workspace
    out = tmp_path / "out"
    for _ in range(2):
        result = ngat("run", "wrong_material.py", "--out", str(out), cwd=root)
        assert_one_clean_line(result, ["['nowhere'] are neither materials (faces) nor boundaries"])
    assert not (out / "energies.csv").exists()


def test_unwritable_results_folder(workspace, tmp_path):
    root, _, _ = workspace
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    result = ngat("run", "profile-1d", "--quick", "--out", str(blocker / "out"), cwd=root)
    assert_one_clean_line(result, ["is not writable", "choose another with --out"])
    assert blocker.read_text() == "not a folder"


def test_quiet_run_prints_nothing(workspace, tmp_path):
    root, _, _ = workspace
    result = ngat("run", "profile-1d", "--quick", "--quiet", "--out", str(tmp_path / "q"), cwd=root)
    assert result.returncode == 0
    assert result.stdout == result.stderr == ""
    assert "step 0" in (tmp_path / "q" / "run.log").read_text()


def test_debug_shows_the_traceback(workspace):
    root, _, _ = workspace
    result = ngat("--debug", "run", "syntax.py", cwd=root)
    assert result.returncode != 0
    assert "Traceback" in result.stderr
    assert "SyntaxError" in result.stderr


def test_overwrite_replaces_a_run_and_keeps_other_files(tmp_path):
    out = tmp_path / "out"
    args = ["run", "profile-1d", "--quick", "--quiet", "--out", str(out)]
    assert main(args) == 0
    (out / "notes.txt").write_text("keep me")
    assert main(args) == 2
    assert main([*args, "--overwrite"]) == 0
    assert (out / "notes.txt").read_text() == "keep me"
    assert len((out / "energies.csv").read_text().splitlines()) == 2


def test_an_internal_error_is_reported_as_a_bug_with_its_traceback(monkeypatch, capsys, tmp_path):
    # A ValueError from inside the package is not bad input: traceback, bug-report line, exit 1.
    import ngat.cli

    def broken(*args, **kwargs):
        raise ValueError("an internal invariant failed")

    monkeypatch.setattr(ngat.cli, "run", broken)
    status = ngat.cli.main(
        ["run", "profile-1d", "--quick", "--quiet", "--out", str(tmp_path / "x")]
    )
    err = capsys.readouterr().err
    assert status == 1
    assert "Traceback" in err and "an internal invariant failed" in err
    assert "internal error (a bug in ngat" in err
    # The package's own input errors keep the one-line treatment (exit 2).
    assert ngat.cli.main(["run", "no-such-scene"]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_a_parameter_given_twice_is_refused():
    from ngat.cli import parse_settings
    from ngat.parameters import ParameterError

    assert parse_settings(["eps=0.05", "tol=0.3"]) == {"eps": "0.05", "tol": "0.3"}
    with pytest.raises(ParameterError, match="'eps' twice"):
        parse_settings(["eps=0.05", "eps=0.025"])


def test_the_command_exits_with_the_status_of_main_its_objects_frozen(monkeypatch, capsys):
    # The console script's exit skips the cycle search over what the run left alive.
    import gc

    from ngat.cli import console

    monkeypatch.setattr(sys, "argv", ["ngat", "run", "no-such-scene"])
    try:
        with pytest.raises(SystemExit) as exit_:
            console()
        assert exit_.value.code == 2
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()
    assert "unknown scene 'no-such-scene'" in capsys.readouterr().err
