"""The 1-D optimal profile: v = 0 imposed on the line y = 0 of a strip, u ≡ 0.

With no elastic energy the v-step minimises ∫ α(1 − v)² + ε|∇v|² with v = 0 on the line; the
minimiser is v = 1 − exp(−|y|/(2ε)) and the surface energy per unit length of line tends to 1 as
h/ε → 0 (docs/design.md, scene 4). The mesh is structured and aligned with the line, so a v that
depends only on y reduces the discrete problem exactly to 1-D. Ω_D is the lower half, g = 0.
"""

import numpy as np
from ngsolve import CoefficientFunction, Mesh
from ngsolve.meshes import MakeStructured2DMesh

from ngat.scene import Scene

LENGTH, HALF_HEIGHT = 1.0, 1.0


def aligned_mesh(maxh: float):
    """Return a structured triangle mesh of (0, L) × (−H, H) with a node line at y = 0.

    Elements below the line form the material ``lower`` (Ω_D), the others ``upper``.
    """
    ny = 2 * max(1, round(HALF_HEIGHT / maxh))
    nx = max(1, round(LENGTH / maxh))
    mesh = MakeStructured2DMesh(
        quads=False, nx=nx, ny=ny, mapping=lambda x, y: (LENGTH * x, HALF_HEIGHT * (2 * y - 1))
    )
    ngmesh = mesh.ngmesh
    elements = ngmesh.Elements2D().NumPy()
    centroid_y = ngmesh.Coordinates()[elements["nodes"][:, :3] - 1][:, :, 1].mean(axis=1)
    elements["index"] = np.where(centroid_y < 0, 1, 2)
    ngmesh.SetMaterial(1, "lower")
    ngmesh.SetMaterial(2, "upper")
    return Mesh(ngmesh)


def on_line(coords: np.ndarray) -> np.ndarray:
    """Return the mask of vertices on the line y = 0."""
    return np.abs(coords[:, 1]) < 1e-12


scene = Scene(
    name="profile-1d",
    description="v = 0 on the centre line of a strip: the optimal profile 1 − exp(−d/(2ε))",
    geometry=None,
    mesh=aligned_mesh,
    loads={"lower": lambda t: CoefficientFunction(0.0) * t},
    times=[0.0],
    crack=on_line,
    # Element diameters (√2·maxh) below ε = 0.05, so the crack band is resolved; the aligned
    # mesh is the point of the scene, so the band must not bisect it (adapt=paper: μ = ν = 0).
    parameters={"maxh": 0.025, "adapt": "paper"},
    quick={"maxh": 0.03},
)
