"""Shared fixtures: the quick two-slits run, computed once per test session."""

import os

import pytest

from ngat.driver import run
from ngat.scene import load_scene

# The test processes run side by side, one per core (pytest-xdist): one factorisation thread
# each, as in a sweep. Two each would oversubscribe the cores: two quick runs at once took 58 s
# each with two MKL threads against 24 s with one.
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    os.environ.setdefault("MKL_NUM_THREADS", "1")


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


@pytest.fixture
def assert_newton_matches_ngsolve():
    """Return a check of Newton's ∇I_j, ∇²I_j and I_j at (u, v) against NGSolve's.

    NGSolve linearises the same energy (:meth:`ngat.functional.LumpedFunctional.energy_form`,
    on the product of the state's space of u and P1); the check asserts agreement to 1e−12
    (1e−13 for I_j) and leaves (u, v) in the state.
    """
    import numpy as np
    import scipy.sparse as sp
    from ngsolve import H1, GridFunction

    from ngat.newton import NewtonSolver

    def check(state, u, v):
        space = state.fes_u * H1(state.mesh, order=1)
        form, w = state.functional.energy_form(space), GridFunction(space)
        w.vec.FV().NumPy()[:] = np.concatenate([u, v])
        gradient = w.vec.CreateVector()
        form.Apply(w.vec, gradient)
        form.AssembleLinearization(w.vec)
        newton = NewtonSolver(state)
        newton._setup()
        size = len(u) + len(v)
        rowptr = np.r_[0, np.cumsum(np.bincount(newton.entry_rows, minlength=size))]
        values = newton.hessian_values(u, v)
        ours = sp.csr_matrix((values, newton.entry_cols, rowptr), (size, size))
        values, cols, rowptr = map(np.asarray, form.mat.CSR())
        theirs = sp.csr_matrix((values, cols, rowptr), (size, size))
        # Newton's matrix holds the upper triangle, all its factorisation reads, with the
        # graph of NGSolve's.
        upper = sp.triu(theirs, format="csr")
        assert abs(ours - upper).max() < 1e-12 * abs(theirs).max()
        assert np.array_equal(newton.indptr, upper.indptr)
        assert np.array_equal(newton.entry_cols, upper.indices)
        g = gradient.FV().NumPy()
        ours = state.functional.gradient(state.arrays, u, v)
        assert np.abs(ours - g).max() < 1e-12 * np.abs(g).max()
        state.u_values[:], state.v_values[:] = u, v
        assert form.Energy(w.vec) == pytest.approx(state.energies()["total"], rel=1e-13)

    return check
