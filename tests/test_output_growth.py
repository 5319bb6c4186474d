"""What a load step writes does not grow with the steps before it, and ``output_every``.

The cost is measured in bytes, which are deterministic, not in seconds (the speed is measured
by ``scripts/bench_steps.py``): the bytes the process writes per step (``wchar`` of
``/proc/self/io``: the CSV row, the VTU, the ``fields.pvd`` entry, the checkpoint, the log
line) and the size of the checkpoint. The scene is the two-slits geometry on its coarse initial
mesh, which never changes (``adapt=fixed``, under-resolved on purpose), with small loads.
"""

import dataclasses
import errno
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from ngat.checkpoint import load_checkpoint
from ngat.driver import run
from ngat.output import OutputError
from ngat.parameters import ParameterError
from ngat.results import read_records
from ngat.scene import load_scene

# A checkpoint after every step: part of what a step writes.
TINY = {"maxh": 0.5, "eps": 0.2, "adapt": "fixed", "resolve_eps": False, "checkpoint_every": 0}


def tiny_scene(steps, **changes):
    scene = dataclasses.replace(load_scene("two-slits"), times=np.linspace(0.0, 0.01, steps))
    return (scene, *scene.configure(overrides={**TINY, **changes}))


def bytes_written():
    for line in Path("/proc/self/io").read_text().splitlines():
        if line.startswith("wchar:"):
            return int(line.split()[1])
    raise AssertionError("no wchar in /proc/self/io")


def rows(folder):
    return [
        {k: v for k, v in r.items() if k != "wall_s"} for r in read_records(folder / "energies.csv")
    ]


def series(folder):
    return [d.get("file") for d in ET.parse(folder / "fields.pvd").getroot().iter("DataSet")]


@pytest.mark.skipif(not Path("/proc/self/io").exists(), reason="needs /proc/self/io (Linux)")
def test_a_late_step_writes_no_more_than_an_early_one(tmp_path):
    scene, parameters, times = tiny_scene(45)
    folder = tmp_path / "run"
    written, checkpoint = [], []

    def measure(record):
        written.append(bytes_written())
        checkpoint.append((folder / "checkpoint.npz").stat().st_size)

    run(scene, parameters, times, folder, on_step=measure)
    per_step = np.diff(written)
    early, late = per_step[4:14].mean(), per_step[-10:].mean()
    # Rewriting the records or the whole fields.pvd each step would add ≥ 100 bytes per step.
    assert abs(late - early) < 100, (early, late)
    # From step 1 on the checkpoint differs only in the digits of its timings.
    assert max(checkpoint[1:]) - min(checkpoint[1:]) < 50, checkpoint
    assert len(series(folder)) == 45


def test_output_every_writes_every_kth_step_and_the_last(tmp_path):
    with pytest.raises(ParameterError, match="output_every must be >= 1"):
        tiny_scene(3, output_every=0)
    scene, parameters, times = tiny_scene(12, output_every=5)
    folder = tmp_path / "run"
    result = run(scene, parameters, times, folder)
    assert len(rows(folder)) == len(result.records) == 12
    expected = [f"fields/step_{k:04d}.vtu" for k in (0, 5, 10, 11)]
    assert series(folder) == expected
    assert sorted(f"fields/{p.name}" for p in (folder / "fields").iterdir()) == expected
    assert result.fields.field_data["t"][0] == times[-1]


def test_a_resumed_run_ends_as_an_uninterrupted_one(tmp_path):
    scene, parameters, times = tiny_scene(12, output_every=5)
    reference = tmp_path / "reference"
    run(scene, parameters, times, reference)
    folder = tmp_path / "run"

    def stop(record):
        if record["step"] == 6:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(scene, parameters, times, folder, on_step=stop)
    assert load_checkpoint(folder).step == 6
    # A crash between a step's row and its checkpoint leaves a row (or part of one) ahead.
    csv = folder / "energies.csv"
    lines = csv.read_bytes().splitlines(keepends=True)
    csv.write_bytes(b"".join(lines) + lines[-1].replace(b"6,", b"7,", 1) + lines[-1][:20])
    result = run(scene, parameters, times, folder, resume=True)
    assert rows(folder) == rows(reference)
    assert [r["step"] for r in result.records] == list(range(12))
    assert (folder / "fields.pvd").read_bytes() == (reference / "fields.pvd").read_bytes()


def test_resume_refuses_a_folder_whose_rows_were_deleted(tmp_path):
    scene, parameters, times = tiny_scene(6)
    folder = tmp_path / "run"

    def stop(record):
        if record["step"] == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run(scene, parameters, times, folder, on_step=stop)
    csv = folder / "energies.csv"
    csv.write_bytes(b"".join(csv.read_bytes().splitlines(keepends=True)[:2]))
    with pytest.raises(OutputError, match="lacks rows of the 3 steps its checkpoint finished"):
        run(scene, parameters, times, folder, resume=True)
    assert len(rows(folder)) == 1


def test_a_failed_fields_entry_leaves_fields_pvd_valid(tmp_path, monkeypatch):
    scene, parameters, times = tiny_scene(6)
    folder = tmp_path / "run"
    real, calls = os.pwrite, []

    def pwrite(fd, data, offset):
        # The first entry is written whole; the second pwrite is step 2's entry.
        calls.append(1)
        if len(calls) == 2:
            real(fd, data[: len(data) // 2], offset)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data, offset)

    monkeypatch.setattr(os, "pwrite", pwrite)
    with pytest.raises(OutputError, match="No space left on device"):
        run(scene, parameters, times, folder)
    monkeypatch.undo()
    assert series(folder) == ["fields/step_0000.vtu", "fields/step_0001.vtu"]
    run(scene, parameters, times, folder, resume=True)
    assert series(folder) == [f"fields/step_{k:04d}.vtu" for k in range(6)]


def test_vtu_holds_the_p1_fields_at_the_mesh_vertices(tmp_path):
    # One point per vertex (shared by its triangles) and the nodal values as point data, a
    # vector field with its two components; pyvista reads it back exactly (binary).
    import ngsolve
    import pyvista
    from netgen.geom2d import unit_square

    from ngat.band import mesh_geometry
    from ngat.output import VTU_END, vtu_grid, write_grid

    mesh = ngsolve.Mesh(unit_square.GenerateMesh(maxh=0.2))
    v = ngsolve.GridFunction(ngsolve.H1(mesh, order=1))
    u = ngsolve.GridFunction(ngsolve.VectorH1(mesh, order=1))
    v.Set(ngsolve.x - 2 * ngsolve.y)
    u.Set(ngsolve.CF((ngsolve.x + 1, 2 * ngsolve.y - 3)))
    path = tmp_path / "step.vtu"
    values = {"u": u.vec.FV().NumPy(), "v": v.vec.FV().NumPy()}
    write_grid(path, vtu_grid(*mesh_geometry(mesh)), values)
    assert path.read_bytes().endswith(VTU_END)
    grid = pyvista.read(path)
    assert (grid.n_points, grid.n_cells) == (mesh.nv, mesh.ne)
    x, y = grid.points[:, 0], grid.points[:, 1]
    np.testing.assert_allclose(grid.point_data["v"], x - 2 * y, atol=1e-14)
    np.testing.assert_allclose(grid.point_data["u"], np.c_[x + 1, 2 * y - 3], atol=1e-14)
    corners = grid.points[grid.cells.reshape(-1, 4)[:, 1:]][..., :2]
    a, b = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    areas = (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) / 2
    assert abs(areas).sum() == pytest.approx(1.0)


def test_a_grid_kept_for_its_mesh_writes_the_bytes_of_a_new_one(tmp_path):
    # The writer builds a mesh's grid once and writes every step's values on it: its files
    # must be those a grid built for the step would give (VTK keeps the points' range on a
    # grid it has written, and would write it into the next file).
    import ngsolve
    from netgen.geom2d import unit_square

    from ngat.forms import MeshArrays
    from ngat.output import vtu_grid, write_grid

    # MeshArrays copies the coordinates: a temporary mesh's own would be freed with it.
    arrays = MeshArrays(ngsolve.Mesh(unit_square.GenerateMesh(maxh=0.2)))
    kept = vtu_grid(arrays.coords, arrays.elements)
    for step in range(3):
        values = {"v": np.linspace(0, step + 1, len(arrays.coords))}
        write_grid(tmp_path / "kept.vtu", kept, values)
        write_grid(tmp_path / "new.vtu", vtu_grid(arrays.coords, arrays.elements), values)
        assert (tmp_path / "kept.vtu").read_bytes() == (tmp_path / "new.vtu").read_bytes()
