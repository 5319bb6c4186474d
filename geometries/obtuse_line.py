"""An obtuse mesh that violates Hypothesis A: v = 0 on a line of a sheared structured mesh.

The unit square's structured triangle mesh is sheared by x → x + 4y into the parallelogram with
corners (0, 0), (1, 0), (5, 1), (4, 1); every triangle then has an angle of 161.6°, and the
stiffness matrix has positive off-diagonals (Hypothesis A fails, paper, Section 2.2). v = 0 is
imposed on the line y = 1/2. The strip x − 4y < 0.1 is Ω_D with g = −t (``grip``), the strip
x − 4y > 0.9 is Ω_D with g = t (``pull``), so the body is sheared anti-plane between the two
slanted strips as t grows. At t = 0 (u ≡ 0) the unconstrained v-step overshoots 1 next to the
line; the bounded v-step does not (``tests/test_diagnostics.py``, ``scripts/stability.py``).
The mesh is fixed (``adapt="fixed"``): bisection would change the angles under study.
"""

import numpy as np
from ngsolve import Mesh
from ngsolve.meshes import MakeStructured2DMesh

from ngat.scene import Scene

SHEAR = 4.0


def sheared_mesh(maxh: float, shear: float = SHEAR):
    """Return the structured mesh of the unit square sheared by x → x + shear·y.

    ``maxh`` is the cell size before shearing. Elements with x − shear·y < 0.1 form the material
    ``grip``, those with x − shear·y > 0.9 the material ``pull``, the rest ``body``.
    """
    n = round(1 / maxh)
    mesh = MakeStructured2DMesh(quads=False, nx=n, ny=n, mapping=lambda a, b: (a + shear * b, b))
    ngmesh = mesh.ngmesh
    elements = ngmesh.Elements2D().NumPy()
    xy = ngmesh.Coordinates()[elements["nodes"][:, :3] - 1].mean(axis=1)
    across = xy[:, 0] - shear * xy[:, 1]
    elements["index"] = np.select([across < 0.1, across > 0.9], [1, 3], 2)
    ngmesh.SetMaterial(1, "grip")
    ngmesh.SetMaterial(2, "body")
    ngmesh.SetMaterial(3, "pull")
    return Mesh(ngmesh)


def on_line(coords: np.ndarray) -> np.ndarray:
    """Return the mask of vertices on the line y = 1/2."""
    return np.abs(coords[:, 1] - 0.5) < 1e-9


scene = Scene(
    name="obtuse-line",
    description="v = 0 on a line of a sheared (obtuse) mesh: Hypothesis A fails",
    geometry=None,
    mesh=sheared_mesh,
    loads={"grip": lambda t: -1 * t, "pull": lambda t: 1 * t},
    times=[0.0],
    crack=on_line,
    # The sheared elements are 0.21 long, wider than ε: the angles, not ε, are under study.
    parameters={"maxh": 0.05, "adapt": "fixed", "resolve_eps": False},
)
