"""Results that repeat whatever the environment: ngat fixes its thread pools.

``ngat run`` in an environment that asks OpenBLAS, OpenMP and MKL for two threads and the same
run inside ``ngat sweep`` (whose Dask worker sets them to 1) write the same ``energies.csv``.
Without the fixed pools the quick two-slits run differs from the first step on (in the last bits
of the energies) and by 1e-3 in the final energy. MKL PARDISO keeps the threads it is given:
its factorisations give the same bits with one or two (``tests/test_pardiso.py``).
"""

import csv
import json
import os
import subprocess
import sys
import textwrap
import time
from types import SimpleNamespace

import numpy as np
import psutil
import pytest

from ngat import pardiso
from ngat.threads import SPIN_MS, CoreUse, FixedThreads, _intel_openmp, refinement_threads

SCENE = """
    import dataclasses

    from ngat.geometries.two_slits import scene as base

    scene = dataclasses.replace(
        base, name="two-slits-start", quick={**base.quick, "times": [0.0, 0.05]}
    )
    """


def ngat(*args, env=None):
    result = subprocess.run(
        [sys.executable, "-m", "ngat.cli", *args],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
    )
    assert result.returncode == 0, result.stderr
    return result


def rows_without_timing(folder):
    with open(folder / "energies.csv", newline="") as f:
        return [{k: v for k, v in row.items() if k != "wall_s"} for row in csv.DictReader(f)]


def test_run_and_one_run_sweep_give_identical_energies(tmp_path):
    scene = tmp_path / "start.py"
    scene.write_text(textwrap.dedent(SCENE))
    threads = {"OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2", "MKL_NUM_THREADS": "2"}
    ngat("run", str(scene), "--quick", "--quiet", "--out", str(tmp_path / "run"), env=threads)
    sweep = ["sweep", str(scene), "--quick", "--quiet", "--grid", "eps=0.05", "--workers", "1"]
    ngat(*sweep, "--out", str(tmp_path / "sweep"))
    alone = rows_without_timing(tmp_path / "run")
    swept = rows_without_timing(tmp_path / "sweep" / "eps=0.05")
    assert len(alone) == 2
    assert alone == swept
    for folder, factorisation in ((tmp_path / "run", 2), (tmp_path / "sweep" / "eps=0.05", 1)):
        recorded = json.loads((folder / "summary.json").read_text())["threads"]
        assert recorded["ngsolve"] == 1 and recorded["blas"] == 1
        assert recorded["factorisation"] == factorisation
        assert_pools(recorded)


def assert_pools(recorded):
    """Every pool but MKL's has one thread; MKL's has the factorisation's."""
    assert recorded["libraries"]
    for lib in recorded["libraries"]:
        expected = recorded["factorisation"] if lib["api"] == "mkl" else 1
        assert lib["threads"] == expected, lib


def test_fixed_threads_are_restored(monkeypatch):
    from threadpoolctl import threadpool_info

    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    before = [pool["num_threads"] for pool in threadpool_info()]
    threads = FixedThreads()
    assert threads.summary()["factorisation"] == 2
    assert_pools(threads.summary())
    threads.restore()
    assert [pool["num_threads"] for pool in threadpool_info()] == before


@pytest.mark.parametrize("setting", ["0", "two", "-1"])
def test_a_bad_thread_count_is_named(monkeypatch, setting):
    monkeypatch.setenv("MKL_NUM_THREADS", setting)
    with pytest.raises(ValueError, match="MKL_NUM_THREADS"):
        FixedThreads()


class _Machine:
    """Processor times that a test sets: each core's busy seconds, this process's own."""

    times = type(psutil.cpu_times())

    def __init__(self, cores):
        self.busy, self.own = dict.fromkeys(range(max(cores) + 1), 0.0), 0.0

    def cpu_times(self, percpu):
        zero = dict.fromkeys(self.times._fields, 0.0)
        return [self.times(**{**zero, "user": busy, "idle": 1e6}) for busy in self.busy.values()]

    def process(self):
        return SimpleNamespace(cpu_times=lambda: SimpleNamespace(user=self.own, system=0.0))


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="two threads need two cores")
def test_a_busy_machine_is_named_when_the_factorisation_has_several_threads(monkeypatch):
    import ngat.threads

    cores = sorted(os.sched_getaffinity(0))
    machine = _Machine(cores)
    monkeypatch.setattr(ngat.threads.psutil, "cpu_times", machine.cpu_times)
    monkeypatch.setattr(ngat.threads.psutil, "Process", machine.process)

    def sampled(other, own):
        """Return the warning after every core ran ``other`` and this process ``own`` more."""
        use = CoreUse(min_interval=0.0)
        begin = time.perf_counter()
        time.sleep(0.05)
        wall = time.perf_counter() - begin
        for core in machine.busy:
            machine.busy[core] += (other + own / len(cores)) * wall
        machine.own += own * wall
        return use.warning(2), use

    message, use = sampled(other=1.0, own=0.0)  # every core busy with other work
    assert message is not None and "MKL_NUM_THREADS=1" in message
    assert use.warning(1) is None  # one thread waits for nobody
    # This process's own threads keep the cores as busy: no other work.
    assert sampled(other=0.0, own=len(cores))[0] is None
    assert sampled(other=0.0, own=0.0)[0] is None
    # Half of every core: beyond the half core the second factorisation thread may lose.
    assert sampled(other=0.5, own=1.0)[0] is not None


def test_the_cores_use_is_sampled_for_at_least_its_interval():
    begin = time.perf_counter()
    other = CoreUse(min_interval=0.1).other_work()
    assert time.perf_counter() - begin >= 0.1
    assert 0.0 <= other <= len(os.sched_getaffinity(0)) + 0.1


def _refined(threads):
    """Return the vertices, triangles and a prolongated P1 field after six bisection rounds."""
    from netgen.geom2d import unit_square
    from ngsolve import H1, GridFunction, Mesh, x, y

    mesh = Mesh(unit_square.GenerateMesh(maxh=0.05))
    field = GridFunction(H1(mesh, order=1, autoupdate=True), autoupdate=True)
    field.Set(x * x + 3 * y)
    for round in range(6):
        # The elements about a point moving along the diagonal, as about a running crack tip.
        coords = mesh.ngmesh.Coordinates()
        triangles = mesh.ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(int) - 1
        centres = coords[triangles].mean(axis=1)
        tip = 0.2 + 0.1 * round
        mesh.SetRefinementFlags((np.linalg.norm(centres - tip, axis=1) < 0.15).tolist())
        with refinement_threads(threads):
            mesh.Refine()
    return (
        mesh.ngmesh.Coordinates().copy(),
        mesh.ngmesh.Elements2D().NumPy()["nodes"][:, :3].copy(),
        field.vec.FV().NumPy().copy(),
    )


def test_refinement_on_two_threads_gives_the_mesh_and_fields_of_one():
    one, two = _refined(1), _refined(2)
    assert len(one[1]) > 4000  # from about 1,000: six rounds refined a good part of the square
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.skipif(not pardiso.AVAILABLE, reason="MKL PARDISO is not installed")
def test_factorisation_threads_sleep_between_factorisations_during_a_run(monkeypatch):
    monkeypatch.setenv("MKL_NUM_THREADS", "2")
    monkeypatch.delenv("KMP_BLOCKTIME", raising=False)
    openmp = _intel_openmp()
    before = openmp.kmp_get_blocktime()
    threads = FixedThreads()
    assert openmp.kmp_get_blocktime() == SPIN_MS
    # The setting is the calling thread's: the background worker, whose METIS orderings run on
    # MKL's threads, gets it as well.
    assert pardiso.in_background(openmp.kmp_get_blocktime).result() == SPIN_MS
    threads.restore()
    assert openmp.kmp_get_blocktime() == before
    assert pardiso.in_background(openmp.kmp_get_blocktime).result() == before
    # A setting of the user's stays.
    monkeypatch.setenv("KMP_BLOCKTIME", "50")
    threads = FixedThreads()
    assert openmp.kmp_get_blocktime() == before
    threads.restore()
