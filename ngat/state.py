"""The discrete state on one mesh: P1 fields u, v, the previous step's v, and the two half-steps.

:class:`ATState` owns the mesh, the P1 space and the GridFunctions (all ``autoupdate=True``, so
``mesh.Refine()`` prolongates them exactly), the Dirichlet and crack DOF masks and the two
sparse Cholesky factorisations. The u-step solves a_j(v; u, φ) = 0 with u = g(t_k) on Ω_D, the
v-step solves b_j(u; v, ψ) = 0 with v = 0 on CR(t_k) (paper, Algorithm 1, steps 2.1 and 2.2).
Per mesh, the matrix graph is built once; per solve only the values are rewritten and the
factorisation is refreshed with ``Inverse.Update()``, which keeps the symbolic analysis.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping

import ngsolve
import numpy as np
from ngsolve import H1, BitArray, GridFunction, Parameter

from ngat.forms import LumpedAssembler, MeshArrays, a_form, b_form
from ngat.parameters import ModelParameters
from ngat.timing import PhaseTimer

__all__ = ["ATState", "SceneError"]

log = logging.getLogger(__name__)

Load = Callable[[Parameter], ngsolve.CoefficientFunction]


class SceneError(ValueError):
    """The scene or its mesh cannot define a valid problem (e.g. no Dirichlet region)."""


class ATState:
    """Fields and lumped operators of the Ambrosio–Tortorelli problem on one mesh.

    Parameters
    ----------
    mesh
        Triangle mesh with named materials; refined in place by the adaptive loop.
    model
        Model parameters ε, η, CRTOL.
    loads
        Dirichlet region name → function of the load parameter ``t`` giving g(x, t).
    crack
        Optional set where v = 0 from the start: a boundary or material name, or a function
        of the vertex coordinates (nv, 2) returning a boolean mask.
    timer
        Accumulates wall time per phase.
    """

    def __init__(
        self,
        mesh: ngsolve.Mesh,
        model: ModelParameters,
        loads: Mapping[str, Load],
        crack: str | Callable[[np.ndarray], np.ndarray] | None = None,
        timer: PhaseTimer | None = None,
    ):
        if not loads:
            raise SceneError("the scene has no Dirichlet region: give at least one load")
        materials = set(mesh.GetMaterials())
        missing = [name for name in loads if name not in materials]
        if missing:
            raise SceneError(
                f"Dirichlet region(s) {missing} are not materials of the mesh "
                f"(materials: {sorted(materials)}); name the OCC faces accordingly"
            )
        self.mesh = mesh
        self.model = model
        self.timer = timer or PhaseTimer()
        self.t = Parameter(0.0)
        self.loads = {name: g(self.t) for name, g in loads.items()}
        self.load_rates = {name: g.Diff(self.t) for name, g in self.loads.items()}
        self.crack = crack
        self.fes = H1(mesh, order=1, autoupdate=True)
        self.u = GridFunction(self.fes, autoupdate=True)
        self.v = GridFunction(self.fes, autoupdate=True)
        self.v_prev = GridFunction(self.fes, autoupdate=True)
        self.v.vec[:] = 1.0
        self.v_prev.vec[:] = 1.0
        self.mesh_changed()

    # -- set-up per mesh --------------------------------------------------------------------
    def mesh_changed(self) -> None:
        """Rebuild everything that depends on the mesh (call after ``mesh.Refine()``)."""
        with self.timer("assembly"):
            self.arrays = MeshArrays(self.mesh)
            self.a = a_form(self.fes, self.v, self.model.eta)
            self.b = b_form(self.fes, self.u, self.model.eps)
            self.a.Assemble()
            self.b.Assemble()
            self.assembler = LumpedAssembler(self.arrays, self.a.mat)
            self.region_dofs = {
                name: np.array(self.fes.GetDofs(self.mesh.Materials(name)), dtype=bool)
                for name in self.loads
            }
            dirichlet = np.logical_or.reduce(list(self.region_dofs.values()))
            if not dirichlet.any():
                raise SceneError("the Dirichlet regions contain no DOFs of the mesh")
            self.dirichlet = dirichlet
            self._load_points = {name: self._pulled_vertices(name) for name in self.loads}
            self.initial_crack = np.zeros(self.fes.ndof, dtype=bool)
            if callable(self.crack):
                self.initial_crack = np.asarray(self.crack(self.arrays.coords), dtype=bool)
            elif self.crack is not None:
                region = (
                    self.mesh.Materials(self.crack)
                    if self.crack in self.mesh.GetMaterials()
                    else self.mesh.Boundaries(self.crack)
                )
                self.initial_crack = np.array(self.fes.GetDofs(region), dtype=bool)
            self._a_inverse = None
            self._b_inverse = None
            self._b_free: np.ndarray | None = None
            self._residual = self.a.mat.CreateColVector()

    def _pulled_vertices(self, region: str, shift: float = 1e-9):
        """Return mesh points next to each vertex inside each element of ``region``."""
        index = self.mesh.ngmesh.Elements2D().NumPy()["index"]
        material = list(self.mesh.GetMaterials()).index(region) + 1
        elements = self.arrays.elements[index == material]
        xy = self.arrays.coords[elements]
        pulled = (1 - 3 * shift) * xy + shift * xy.sum(axis=1, keepdims=True)
        pulled = pulled.reshape(-1, 2)
        return self.mesh(pulled[:, 0], pulled[:, 1]), elements.ravel()

    # -- views ------------------------------------------------------------------------------
    @property
    def u_values(self) -> np.ndarray:
        """Nodal values of u (a writable view)."""
        return self.u.vec.FV().NumPy()

    @property
    def v_values(self) -> np.ndarray:
        """Nodal values of v (a writable view)."""
        return self.v.vec.FV().NumPy()

    def crack_set(self) -> np.ndarray:
        """Return CR(t_k) = {v(t_{k-1}) < CRTOL} (paper, Section 1.2) plus the scene's crack."""
        return (self.v_prev.vec.FV().NumPy() < self.model.crtol) | self.initial_crack

    # -- load -------------------------------------------------------------------------------
    def apply_load(self, t: float) -> None:
        """Set the load parameter to ``t`` and u = g(t) on every Dirichlet region."""
        self.t.Set(t)
        self._interpolate(self.loads, self.u_values)

    def _interpolate(self, functions: Mapping[str, ngsolve.CoefficientFunction], out: np.ndarray):
        """Write each region's function into ``out`` at that region's vertices (interpolation).

        Each element of the region evaluates the function at points pulled a relative 1e-9
        from its vertices into its interior, and a vertex takes the mean over its elements. On
        a slit face this picks the value of the face's own side (the twin nodes have equal
        coordinates, so evaluating at the vertex itself could not tell the sides apart, and
        ``GridFunction.Set`` does exactly that).
        """
        for name, g in functions.items():
            points, vertices = self._load_points[name]
            values = g(points).ravel()
            total = np.bincount(vertices, weights=values, minlength=len(out))
            count = np.bincount(vertices, minlength=len(out))
            dofs = count > 0
            out[dofs] = total[dofs] / count[dofs]

    # -- half-steps -------------------------------------------------------------------------
    def solve_u(self) -> None:
        """u-step: minimise I_j(·, v) over g(t_k) + X_{j,D} (Algorithm 1, step 2.1)."""
        with self.timer("assembly"):
            self.a.mat.AsVector().FV().NumPy()[:] = self.assembler.a_values(
                self.v_values, self.model.eta
            )
        with self.timer("solve"):
            if self._a_inverse is None:
                self._a_inverse = self.a.mat.Inverse(
                    BitArray(~self.dirichlet), inverse="sparsecholesky"
                )
            else:
                self._a_inverse.Update()
            self._residual.data = -1 * (self.a.mat * self.u.vec)
            self.u.vec.data += self._a_inverse * self._residual

    def solve_v(self, crack: np.ndarray) -> None:
        """v-step: minimise I_j(u, ·) over X_{j,CR} (Algorithm 1, step 2.2).

        Parameters
        ----------
        crack
            Boolean DOF mask of CR(t_k), where v is fixed to 0.
        """
        arrays = self.arrays
        with self.timer("assembly"):
            grad_u = arrays.gradient(self.u_values)
            values = self.assembler.b_values((grad_u**2).sum(axis=1), self.model.eps)
            self.b.mat.AsVector().FV().NumPy()[:] = values
            rhs = self._residual.FV().NumPy()
            rhs[:] = self.model.alpha * arrays.mass
        with self.timer("solve"):
            free = ~crack
            if self._b_inverse is None or not np.array_equal(free, self._b_free):
                self._b_inverse = self.b.mat.Inverse(BitArray(free), inverse="sparsecholesky")
                self._b_free = free
            else:
                self._b_inverse.Update()
            self.v.vec.data = self._b_inverse * self._residual

    # -- records ----------------------------------------------------------------------------
    def energies(self) -> dict[str, float]:
        """Return bulk, surface and total energy of the lumped functional I_j (paper, eq. 7)."""
        arrays = self.arrays
        v = self.v_values
        grad_u = arrays.gradient(self.u_values)
        grad_v = arrays.gradient(v)
        bulk = np.sum(
            arrays.area * (arrays.vertex_mean(v * v) + self.model.eta) * (grad_u**2).sum(1)
        )
        surface = self.model.alpha * np.dot(arrays.mass, (1 - v) ** 2) + self.model.eps * np.sum(
            arrays.area * (grad_v**2).sum(1)
        )
        return {"bulk": float(bulk), "surface": float(surface), "total": float(bulk + surface)}

    def reaction_forces(self) -> dict[str, float]:
        """Return the reaction force on each Dirichlet region and the load's conjugate force.

        The residual r = A u of the u-equation vanishes at free DOFs; at a DOF of Ω_D it is the
        nodal reaction. ``force_<region>`` = 2 Σ_{i∈Ω_D} r_i is the derivative of the bulk
        energy with respect to a uniform shift of u on that region; ``force`` = 2 r·∂g/∂t is the
        derivative of the bulk energy with respect to the load parameter t.
        """
        self.a.mat.AsVector().FV().NumPy()[:] = self.assembler.a_values(
            self.v_values, self.model.eta
        )
        self._residual.data = self.a.mat * self.u.vec
        residual = 2 * self._residual.FV().NumPy()
        forces = {
            f"force_{name}": float(residual[dofs].sum()) for name, dofs in self.region_dofs.items()
        }
        rate = np.zeros_like(residual)
        self._interpolate(self.load_rates, rate)
        forces["force"] = float(np.dot(residual[self.dirichlet], rate[self.dirichlet]))
        return forces

    def mesh_measures(self) -> dict[str, float]:
        """Return element and vertex counts, element diameters and the range of v."""
        v = self.v_values
        return {
            "elements": self.arrays.ne,
            "vertices": self.arrays.nv,
            "h_min": float(self.arrays.diameter.min()),
            "h_max": float(self.arrays.diameter.max()),
            "v_min": float(v.min()),
            "v_max": float(v.max()),
        }
