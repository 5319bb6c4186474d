"""Runs that cannot work are refused before they compute: one line, exit status 2.

A refinement rule that can never resolve ε (a floor of ε/2 or more, a crack band of ε or more, a
fixed mesh at least ε wide where the crack starts), a slit outside the domain and a ``maxh`` that
asks the mesher for more triangles than any run can use.
"""

import subprocess
import sys
import textwrap

import pytest

from ngat.diagnostics import check_fixed_mesh
from ngat.parameters import ParameterError, Parameters
from ngat.scene import load_scene
from ngat.state import ATState

SLIT_OUTSIDE = """
    import dataclasses
    from ngat.geometries.two_slits import scene as base
    scene = dataclasses.replace(
        base, name="slit-outside", slits=(base.slits[0], ((10.0, 10.0), (10.0, 12.0)))
    )
    """

# (arguments after "ngat", words the one-line message must contain)
CASES = {
    "fixed mesh coarser than eps": (
        ["run", "two-slits", "--quick", "--set", "adapt=fixed", "--set", "maxh=0.25"],
        ["adapt=fixed never refines", "where the crack starts", "maxh below 0.05"],
    ),
    "floor at eps/2": (
        ["run", "two-slits", "--quick", "--set", "adapt=paper", "--set", "floor=0.5"],
        ["floor=0.5 stops bisection at elements 1ε wide", "floor < 0.5", "resolve_eps=false"],
    ),
    "band of eps": (
        ["run", "two-slits", "--quick", "--set", "band_h=1"],
        ["crack band's elements 1ε wide", "band_h < 1"],
    ),
    "slit outside": (
        ["run", "slit_outside.py", "--quick"],
        ["the mouth (10, 10) of slit 2 lies outside the domain", "fix 'slits'"],
    ),
    "maxh tiny": (
        ["run", "two-slits", "--set", "maxh=1e-300"],
        ["maxh=1e-300 is too small for the geometry (area 42)", "choose maxh >= 0.0031"],
    ),
    "maxh infinite": (["run", "two-slits", "--set", "maxh=inf"], ["maxh must be a finite number"]),
}


@pytest.mark.parametrize("case", CASES)
def test_refused_with_one_line(case, tmp_path):
    args, words = CASES[case]
    (tmp_path / "slit_outside.py").write_text(textwrap.dedent(SLIT_OUTSIDE))
    result = subprocess.run(
        [sys.executable, "-m", "ngat.cli", *args, "--out", "out", "--quiet"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert not (tmp_path / "out" / "energies.csv").exists()


def test_resolution_checks_follow_the_rule_and_can_be_switched_off():
    Parameters().replace(adapt="paper", floor=0.49, band_h=0.99)
    Parameters().replace(adapt="fixed", floor=0.5, band_h=1.5)  # fixed: checked on the mesh
    with pytest.raises(ParameterError, match="floor < 0.5"):
        Parameters().replace(adapt="after", floor=0.5)
    with pytest.raises(ParameterError, match="band_h < 1"):
        Parameters().replace(band_h=1.0)
    Parameters().replace(adapt="after", floor=0.5, band_h=1.5, resolve_eps=False)
    Parameters().replace(band_h=1.0, resolve_eps=False)


def test_fixed_mesh_is_checked_where_the_crack_starts():
    scene = load_scene("two-slits")
    for eps, refused in ((0.05, True), (0.4, False)):
        parameters, _ = scene.configure(overrides={"adapt": "fixed", "maxh": 0.25, "eps": eps})
        state = ATState(scene.make_mesh(0.25), parameters.model, scene.loads)
        if refused:
            with pytest.raises(ParameterError, match=r"elements where the crack starts"):
                check_fixed_mesh(state, scene.slits, eps)
        else:
            check_fixed_mesh(state, scene.slits, eps)
