"""Shared fixtures: the quick two-slits run, computed once per test session."""

import pytest

from ngat.driver import run
from ngat.scene import load_scene


class HalfStepLog:
    """Energies and the range of v after every half-step, and CR after every load step."""

    def __init__(self):
        self.state = None
        self.energies = []  # (step, stage, total I_j)
        self.v_ranges = []  # (min v, max v) after each v-step
        self.cracks = []  # CR(t_{k+1}) = {v(t_k) < CRTOL}, one mask per step

    def monitor(self, stage, state):
        self.state = state
        self.energies.append((len(self.cracks), stage, state.energies()["total"]))
        if stage == "v":
            v = state.v_values
            self.v_ranges.append((v.min(), v.max()))

    def on_step(self, record):
        self.cracks.append(self.state.crack_set().copy())


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory):
    """The quick two-slits run (`ngat run two-slits --quick`)."""
    scene = load_scene("two-slits")
    parameters, times = scene.configure(quick=True)
    log = HalfStepLog()
    folder = tmp_path_factory.mktemp("two-slits-quick")
    result = run(scene, parameters, times, folder, on_step=log.on_step, monitor=log.monitor)
    return result, log, folder


@pytest.fixture(scope="session")
def tiny_run():
    """A tiny run of the two-slits geometry, as ``(scene, parameters)`` for ``ngat.run``.

    Five load steps on the coarse initial mesh (adapt=fixed, under-resolved on purpose, so
    ``resolve_eps=false``): about a second.
    """
    import dataclasses

    scene = dataclasses.replace(load_scene("two-slits"), times=[0.0, 0.4, 0.8, 1.2, 1.6])
    return scene, {"maxh": 0.5, "eps": 0.2, "adapt": "fixed", "resolve_eps": False}
