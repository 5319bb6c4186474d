"""``pip install .`` (not editable) into a fresh venv ships the scenes inside ngat's namespace.

The venv sees the system's packages (ngsolve and the other dependencies are not downloaded
again), but not this source tree: the package is built from a copy of it, as from a fresh clone,
and the commands run outside it with ``PYTHONPATH`` unset. pip builds the wheel in an isolated
environment, as for a user, so the package index must be reachable. Marked ``packaging`` so that
it can be deselected (``-m "not slow and not packaging"``); it takes 10–20 s, most of it
building the wheel.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.packaging


def test_non_editable_install_finds_its_scenes(tmp_path):
    source = tmp_path / "clone"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    for name in ("ngat", "geometries"):
        shutil.copytree(
            ROOT / name, source / name, symlinks=True,
            ignore=shutil.ignore_patterns("__pycache__"),
        )  # fmt: skip
    venv = tmp_path / "venv"
    subprocess.run(
        [sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", str(venv)],
        check=True,
    )
    python, ngat = venv / "bin" / "python", venv / "bin" / "ngat"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    install = subprocess.run(
        [str(python), "-m", "pip", "install", "--quiet", "--no-deps", str(source)],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert install.returncode == 0, install.stderr
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
            env=env, check=True, capture_output=True, text=True,
        ).stdout.strip()
    )  # fmt: skip
    assert (site / "ngat" / "geometries" / "two_slits.py").is_file()
    assert (site / "ngat" / "geometries" / "reference" / "two_slits.json").is_file()
    assert not (site / "geometries").exists(), "scenes installed as a top-level package"

    where = subprocess.run(
        [str(python), "-c", "import ngat.scene; print(ngat.scene.GEOMETRIES)"],
        env=env, cwd=tmp_path, check=True, capture_output=True, text=True,
    )  # fmt: skip
    assert Path(where.stdout.strip()).is_relative_to(site)
    scenes = subprocess.run(
        [str(ngat), "scenes"], env=env, cwd=tmp_path, capture_output=True, text=True
    )
    assert scenes.returncode == 0, scenes.stderr
    for name in ("two-slits", "profile-1d", "surfing"):
        assert name in scenes.stdout + scenes.stderr
