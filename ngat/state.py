"""The discrete state: the mesh, the P1 fields u, v and the previous step's v, and their data.

:class:`ATState` owns the mesh, the P1 spaces and the GridFunctions (all ``autoupdate=True``, so
``mesh.Refine()`` prolongates them exactly), and what fixes the fields' admissible sets: the
Dirichlet regions with their loads g(t) and the crack DOF masks (the initial crack, and CR(t_k)
of the paper's Section 1.2). It evaluates I_j (eq. 7) at its fields through the model's
:class:`ngat.functional.LumpedFunctional` and reports the mesh measures. The matrices of the two
half-steps are :mod:`ngat.operators`, how the half-steps are solved is :mod:`ngat.halfsteps`, and
the nonlinear solvers of a load step are :mod:`ngat.strategies`.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Hashable, Mapping
from concurrent.futures import Future
from typing import TypeVar

import ngsolve
import numpy as np
from ngsolve import H1, TRIG, CoefficientFunction, GridFunction, IntegrationRule, Parameter

from ngat import pardiso
from ngat.elasticity import elasticity
from ngat.estimators import EdgeTopology
from ngat.forms import MeshArrays, same_values, upper_graph
from ngat.functional import LumpedFunctional
from ngat.parameters import ModelParameters
from ngat.pardiso import in_background
from ngat.timing import PhaseTimer

__all__ = ["ATState", "SceneError"]

log = logging.getLogger(__name__)

Load = Callable[[Parameter], ngsolve.CoefficientFunction]
T = TypeVar("T")


class SceneError(ValueError):
    """The scene or its mesh cannot define a valid problem (e.g. no Dirichlet region)."""


class ATState:
    """Mesh and fields of the Ambrosio–Tortorelli problem, with their Dirichlet and crack data.

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
        self.materials = set(mesh.GetMaterials())
        boundaries = set(mesh.GetBoundaries())
        missing = [name for name in loads if name not in self.materials | boundaries]
        if missing:
            raise SceneError(
                f"Dirichlet region(s) {missing} are neither materials (faces) nor boundaries "
                f"(edges) of the mesh (materials: {sorted(self.materials)}, boundaries: "
                f"{sorted(boundaries)}); name the OCC faces or edges accordingly"
            )
        self.model = model
        self.timer = timer or PhaseTimer()
        self.t = Parameter(0.0)
        self.crack = crack
        self.elasticity = elasticity(model.model, model.young, model.poisson, model.split)
        self.functional = LumpedFunctional(model, self.elasticity)
        self.loads, self.load_components = {}, {}
        for name, g in loads.items():
            self.load_components[name], self.loads[name] = self._load(name, g(self.t))
        self.load_rates = {name: g.Diff(self.t) for name, g in self.loads.items()}
        self._set_mesh(mesh)
        # Every change of the mesh, in order: the marked elements of a mesh.Refine() or a
        # re-meshed region (ngat.remesh.Patch); a checkpoint replays them.
        self.refinements: list = []
        self.v.vec[:] = 1.0
        self.v_prev.vec[:] = 1.0
        self._ordering: Future | None = None
        self.mesh_changed()

    def _set_mesh(self, mesh: ngsolve.Mesh) -> None:
        """Make the P1 spaces and the fields u, v, v(t_{k−1}) and the iterate on ``mesh``."""
        self.mesh = mesh
        self.fes = H1(mesh, order=1, autoupdate=True)
        self.fes_u = self.fes if self.elasticity.components == 1 else self.elasticity.space(mesh)
        self.u = GridFunction(self.fes_u, autoupdate=True)
        self.v = GridFunction(self.fes, autoupdate=True)
        self.v_prev = GridFunction(self.fes, autoupdate=True)
        self.v_iter = GridFunction(self.fes, autoupdate=True)
        self.v_change = GridFunction(self.fes, autoupdate=True)

    def replace_mesh(self, mesh: ngsolve.Mesh, values: Mapping[str, np.ndarray]) -> None:
        """Move to another mesh of the same domain (:mod:`ngat.remesh`).

        Parameters
        ----------
        mesh
            The new mesh, with the same materials and boundary names.
        values
            Nodal values on ``mesh`` of ``u``, ``v`` and ``v_prev``; the Dirichlet data g(t_k)
            is set anew.
        """
        self._set_mesh(mesh)
        for name, array in values.items():
            getattr(self, name).vec.FV().NumPy()[:] = array
        self.v_iter.vec.data = self.v.vec
        self.mesh_changed()
        self.apply_load(self.t.Get())

    @property
    def patches(self) -> list:
        """The re-meshed regions among the mesh's changes (:class:`ngat.remesh.Patch`)."""
        return [change for change in self.refinements if not isinstance(change, np.ndarray)]

    # -- set-up per mesh --------------------------------------------------------------------
    def mesh_changed(self, order: bool = True) -> None:
        """Rebuild everything that depends on the mesh (call after ``mesh.Refine()``).

        ``order``: start METIS's ordering of the new mesh first (:meth:`start_ordering`), for
        a mesh that will be solved on; an intermediate mesh (the re-mesher's rounds) leaves it
        to the first use.
        """
        if self._ordering is not None:
            self._ordering.cancel()  # the ordering of a mesh gone, if it has not started
        self._ordering = None
        if order:
            self.start_ordering()
        with self.timer("assembly"):
            self.arrays = arrays = MeshArrays(self.mesh)
            count = self.elasticity.components
            self.region_vertices = {}
            self.region_dofs = {}
            segments = self.mesh.ngmesh.Elements1D().NumPy()
            self._segments = segments["nodes"][:, :2].astype(np.int64) - 1
            self._segment_boundary = segments["index"].astype(np.int64) - 1
            for name, components in self.load_components.items():
                vertices = self._region_vertices(name)
                dofs = np.zeros((count, arrays.nv), dtype=bool)
                dofs[components] = vertices
                self.region_vertices[name], self.region_dofs[name] = vertices, dofs.ravel()
            dirichlet = np.logical_or.reduce(list(self.region_dofs.values()))
            if not dirichlet.any():
                raise SceneError("the Dirichlet regions contain no DOFs of the mesh")
            self.dirichlet = dirichlet
            self.boundary_vertices = np.zeros(arrays.nv, dtype=bool)
            self.boundary_vertices[self._segments.ravel()] = True
            # Ω_D of the paper: the Dirichlet faces (μ is 0 on the elements meeting them).
            self.dirichlet_vertices = np.zeros(arrays.nv, dtype=bool)
            for name in self.materials.intersection(self.loads):
                self.dirichlet_vertices |= self.region_vertices[name]
            self._load_points = {name: self._load_points_of(name) for name in self.loads}
            self.initial_crack = np.zeros(self.fes.ndof, dtype=bool)
            if callable(self.crack):
                self.initial_crack = np.asarray(self.crack(self.arrays.coords), dtype=bool)
            elif self.crack is not None:
                self.initial_crack = self._region_vertices(self.crack)
            self._edges = None
            self._of_v: dict = {}
            self._energies: tuple | None = None

    def _region_vertices(self, name: str) -> np.ndarray:
        """Return the vertices of the material or boundary ``name`` (its DOFs, ``fes.GetDofs``).

        From the mesh's element arrays and the region's mask of material or boundary numbers:
        numpy converts the BitArray of ``GetDofs`` entry by entry (25–50 ms per region at 150k
        elements, for every new mesh).
        """
        if name in self.materials:
            chosen = np.array(self.mesh.Materials(name).Mask(), dtype=bool)
            cells = self.arrays.elements[chosen[self.arrays.material]]
        else:
            chosen = np.array(self.mesh.Boundaries(name).Mask(), dtype=bool)
            cells = self._segments[chosen[self._segment_boundary]]
        vertices = np.zeros(self.arrays.nv, dtype=bool)
        vertices[cells.ravel()] = True
        return vertices

    def _load(self, name: str, value) -> tuple[list[int], ngsolve.CoefficientFunction]:
        """Return the components a region's load fixes and the load as one CoefficientFunction.

        ``value`` is g(t): a number or CoefficientFunction with all components of u, or (plane
        models) a dict naming the components it fixes, e.g. ``{"y": t}`` (u_x stays free).
        """
        components = self.elasticity.components
        if isinstance(value, Mapping):
            names = "xy" if components > 1 else ""
            unknown = sorted(set(value) - set(names))
            if unknown:
                raise SceneError(
                    f"the load of region '{name}' names the component(s) {unknown}: the "
                    f"{self.model.model} model's u has "
                    + (f"the components {', '.join(names)}" if names else "none, give g itself")
                )
            fixed = sorted(value)
            indices = [names.index(c) for c in fixed]
            return indices, CoefficientFunction(tuple(value[c] for c in fixed))
        g = CoefficientFunction(value)
        if g.dim != components:
            raise SceneError(
                f"the load of region '{name}' has {g.dim} component(s), the "
                f"{self.model.model} model's u has {components}: give "
                + ("a number" if components == 1 else 'CF((gx, gy)) or {"x": gx, "y": gy}')
            )
        return list(range(components)), g

    def _load_points_of(self, region: str):
        """Return where a region's load is evaluated and the vertex of each point.

        A face (Ω_D): :meth:`_pulled_vertices`. An edge: its vertices themselves (Dirichlet data
        on a slit face would need the side; take edges on the outer boundary).
        """
        if region in self.materials:
            return self._pulled_vertices(region)
        vertices = np.flatnonzero(self.region_vertices[region])
        xy = self.arrays.coords[vertices]
        return self.mesh(xy[:, 0], xy[:, 1]), vertices

    def _pulled_vertices(self, region: str, shift: float = 1e-9):
        """Return mapped points next to each vertex inside each element of ``region``.

        The reference points (1 − 2δ, δ), (δ, 1 − 2δ), (δ, δ) lie next to the reference vertices,
        which NGSolve maps to the element's netgen nodes in order.
        """
        rule = IntegrationRule(
            points=[(1 - 2 * shift, shift), (shift, 1 - 2 * shift), (shift, shift)],
            weights=[1, 1, 1],
        )
        faces = self.mesh.Materials(region)
        points = self.mesh.MapToAllElements({TRIG: rule}, faces)
        chosen = np.array(faces.Mask(), dtype=bool)
        return points, self.arrays.elements[chosen[self.arrays.material]].ravel()

    @property
    def edges(self) -> EdgeTopology:
        """Edge topology of the mesh for the estimators, built on first use per mesh."""
        if self._edges is None:
            self._edges = EdgeTopology(self.arrays)
        elif isinstance(self._edges, Future):
            self._edges = self._edges.result()
        return self._edges

    def start_ordering(self) -> None:
        """Start METIS's fill-reducing ordering of the mesh's vertices in the background.

        From the triangles alone (:func:`ngat.forms.upper_graph`), before the mesh's arrays
        and operators are built: the first factorisation on the mesh waits for it
        (:attr:`vertex_ordering`). None without MKL PARDISO (NGSolve's Cholesky orders itself).
        """
        if self._ordering is None and pardiso.AVAILABLE:
            elements = self.mesh.ngmesh.Elements2D().NumPy()["nodes"][:, :3].astype(np.int64) - 1
            graph = functools.partial(upper_graph, elements, self.mesh.nv)
            self._ordering = pardiso.background_ordering(graph)

    @property
    def vertex_ordering(self) -> Future | None:
        """The future of the mesh's ordering (:meth:`start_ordering`, started if it was not)."""
        self.start_ordering()
        return self._ordering

    def start_edges(self) -> None:
        """Start building :attr:`edges` in the background (:func:`ngat.pardiso.in_background`).

        A new mesh's operators are built meanwhile; the first use waits for it.
        """
        if self._edges is None:
            self._edges = in_background(EdgeTopology, self.arrays)

    def of_v(self, key: Hashable, compute: Callable[[], T]) -> T:
        """Return ``compute()``, computed once per mesh and nodal values of v.

        A memo for measures of v alone (:func:`ngat.crack.crack_tips`): the crack band, the
        re-mesher and a step's record ask for the tips of the same v up to five times per load
        step, at 45 ms each at 180k elements. ``key`` names the measure; a change of the mesh
        or of any value of v computes it anew.
        """
        return self.of_values(key, (self.v_values,), compute)

    def of_values(
        self, key: Hashable, inputs: tuple[np.ndarray, ...], compute: Callable[[], T]
    ) -> T:
        """Return ``compute()``, computed once per mesh and values of the arrays ``inputs``.

        The memo of :meth:`of_v` for measures of several arrays (the estimators of u and v):
        ``key`` names the measure, and a change of the mesh or of any value of an input
        computes it anew.
        """
        stored = self._of_v.get(key)
        if stored is not None and all(map(same_values, stored[0], inputs)):
            return stored[1]
        value = compute()
        self._of_v[key] = (tuple(np.array(array) for array in inputs), value)
        return value

    # -- views ------------------------------------------------------------------------------
    @property
    def u_values(self) -> np.ndarray:
        """Nodal values of u (a writable view)."""
        return self.u.vec.FV().NumPy()

    @property
    def v_values(self) -> np.ndarray:
        """Nodal values of v (a writable view)."""
        return self.v.vec.FV().NumPy()

    def crack_set(self, previous: np.ndarray | None = None) -> np.ndarray:
        """Return the DOFs where v = 0 is imposed: CR(t_k) and the scene's crack.

        With ``irreversibility="crtol"`` CR(t_k) = {v(t_{k-1}) < CRTOL} (paper, Section 1.2);
        with ``"pointwise"`` irreversibility is the bound v ≤ v(t_{k−1}) of eq. (3) instead
        (:meth:`ngat.halfsteps.HalfStepSolvers.solve_v`) and only the scene's crack is fixed.
        ``previous``: the nodal values of v(t_{k−1}) if not ``v_prev``'s (the next step's CR).
        """
        if self.model.irreversibility == "pointwise":
            return self.initial_crack.copy()
        previous = self.v_prev.vec.FV().NumPy() if previous is None else previous
        return (previous < self.model.crtol) | self.initial_crack

    # -- load -------------------------------------------------------------------------------
    def apply_load(self, t: float) -> None:
        """Set the load parameter to ``t`` and u = g(t) on every Dirichlet region's components.

        Raises
        ------
        SceneError
            If g(t) is NaN or infinite somewhere, naming the region and a point.
        """
        self.t.Set(t)
        self._interpolate(self.loads, self.u_values)
        for name, dofs in self.region_dofs.items():
            bad = dofs & ~np.isfinite(self.u_values)
            if bad.any():
                x, y = self.arrays.coords[np.flatnonzero(bad)[0] % self.arrays.nv]
                raise SceneError(
                    f"the load of region '{name}' is not a finite number at t={t:g} (NaN or Inf "
                    f"at {bad.sum()} of its {dofs.sum()} DOFs, e.g. at ({x:.4g}, {y:.4g})): "
                    "fix its load function"
                )

    def _interpolate(self, functions: Mapping[str, ngsolve.CoefficientFunction], out: np.ndarray):
        """Write each region's function into ``out`` at that region's vertices (interpolation).

        Each element of the region evaluates the function at points pulled a relative 1e-9
        from its vertices into its interior, and a vertex takes the mean over its elements. On
        a slit face this picks the value of the face's own side (the twin nodes have equal
        coordinates, so evaluating at the vertex itself could not tell the sides apart, and
        ``GridFunction.Set`` does exactly that). Only the components the region fixes are written.
        """
        nv = self.arrays.nv
        for name, g in functions.items():
            points, vertices = self._load_points[name]
            values = np.asarray(g(points)).reshape(len(vertices), -1)
            count = np.bincount(vertices, minlength=nv)
            dofs = count > 0
            for i, component in zip(self.load_components[name], values.T, strict=True):
                total = np.bincount(vertices, weights=component, minlength=nv)
                out[i * nv : (i + 1) * nv][dofs] = total[dofs] / count[dofs]

    # -- records ----------------------------------------------------------------------------
    def energies(self) -> dict[str, float]:
        """Return bulk, surface and total energy of I_j (paper, eq. 7).

        With ``lumping=False`` the P_j in eq. (7) are dropped and the integrals are exact.
        Computed once per mesh and values of (u, v): an iteration asks for the energy of the
        same pair up to three times (its record, the tolerance of the refinement after the
        v-step, the nonlinear solver), at 4 ms each at 180k elements.
        """
        u, v = self.u_values, self.v_values
        stored = self._energies
        if stored is not None and same_values(stored[0], u) and same_values(stored[1], v):
            return dict(stored[2])
        energies = self.functional.energies(self.arrays, u, v)
        self._energies = (u.copy(), v.copy(), energies)
        return dict(energies)

    def load_rate_values(self) -> np.ndarray:
        """Return ∂g/∂t at the current t on every Dirichlet DOF (0 elsewhere)."""
        rate = np.zeros(self.fes_u.ndof)
        self._interpolate(self.load_rates, rate)
        return rate

    def mesh_measures(self) -> dict[str, float]:
        """Return element and vertex counts, element diameters, the range of v and ``h_crack``.

        ``h_crack`` is the size of the elements meeting the crack {v < 0.1}: sqrt(2 |T|) of their
        mean area (the leg of a right isosceles triangle of that area, the spacing of its node
        lines), the h of the crack's discrete toughness G_eff(h); 0 without a crack.
        """
        v = self.v_values
        cracked = self.arrays.touching(v < 0.1)
        h_crack = np.sqrt(2 * self.arrays.area[cracked].mean()) if cracked.any() else 0.0
        return {
            "h_crack": float(h_crack),
            "elements": self.arrays.ne,
            "vertices": self.arrays.nv,
            "h_min": float(self.arrays.diameter.min()),
            "h_max": float(self.arrays.diameter.max()),
            "v_min": float(v.min()),
            "v_max": float(v.max()),
        }
