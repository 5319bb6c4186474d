"""Run configuration: model, solver, adaptivity and output parameters as frozen dataclasses.

Every parameter has a default (the paper's computational example where it gives one); a scene
states only what differs. Names are unique across the three groups so that ``--set eps=0.025``
and sweep grids can address them without a prefix.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ngat.crack_density import CRACK_DENSITIES, CrackDensity, crack_density

__all__ = [
    "ModelParameters",
    "SolverParameters",
    "AdaptivityParameters",
    "OutputParameters",
    "Parameters",
    "ParameterError",
]


class ParameterError(ValueError):
    """A parameter has a wrong name, type or value."""


def _convert(kind: type, value: Any) -> Any:
    """Convert ``value`` (often a string from the command line) to ``kind``."""
    if isinstance(value, kind):
        return value
    if kind is bool:
        words = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}
        if str(value).lower() not in words:
            raise ValueError(value)
        return words[str(value).lower()]
    return kind(value)


MODELS = ("antiplane", "plane_strain", "plane_stress")
"""The elastic energy densities W of the functional (:mod:`ngat.elasticity`)."""

SPLITS = ("none", "voldev", "spectral")
"""The energy splits W = W⁺ + W⁻ (only W⁺ degrades; :mod:`ngat.elasticity`)."""


@dataclass(frozen=True)
class ModelParameters:
    """Ambrosio–Tortorelli model (paper, eq. 6–7 and Section 1.2).

    Attributes
    ----------
    eps
        Regularisation length ε.
    eta
        Residual stiffness η, 0 ≤ η ≪ ε.
    crtol
        Crack-set tolerance: CR(t_k) = {v(t_{k-1}) < crtol}.
    irreversibility
        ``"crtol"``: v = 0 on CR(t_k) (the paper's choice); ``"pointwise"``: v ≤ v(t_{k−1})
        (eq. 3), a bound-constrained v-step.
    lumping
        ``True``: the mass-lumped functional I_j of eq. (7); ``False``: the same functional
        with P_j dropped, every term integrated exactly (consistent P1 mass, :mod:`ngat.forms`).
        Without lumping the discrete maximum principle (Proposition 3) can fail even on
        non-obtuse meshes (once h ≳ 5ε); the option exists to show that. The estimators of
        Proposition 4 are unchanged (they are derived for the lumped functional).
    model
        Elastic energy density W (:mod:`ngat.elasticity`): ``"antiplane"`` (W = |∇u|², the
        paper), ``"plane_strain"`` or ``"plane_stress"`` (u = (u_x, u_y)).
    young, poisson
        Young's modulus E (force/length², per unit thickness) and Poisson's ratio ν of the
        plane models; the anti-plane model does not use them.
    gc
        Fracture toughness G_c (energy per unit crack length): I_j's surface term is
        G_c [α P_j((1 − v)²) + ε |∇v|²]. The paper's 1 by default.
    split
        ``"none"``: all of W degrades; ``"voldev"`` (plane models): only the deviatoric and the
        tensile volumetric energy degrade (Amor et al. 2009, :mod:`ngat.elasticity`), for scenes
        with compression; ``"spectral"`` (plane strain): only the energy of the tensile
        principal strains and of a tensile trace (Miehe et al. 2010). With a split the u-step is
        solved by a semismooth Newton method.
    crack_density
        ``"at2"``: the paper's α P_j((1 − v)²) + ε |∇v|²; ``"at1"``: 3/(8ε) (1 − v) +
        (3ε/8) |∇v|², with an elastic phase below W = 3 G_c/(16ε) (:mod:`ngat.crack_density`).
    """

    eps: float = 0.05
    eta: float = 1e-5
    crtol: float = 1e-4
    irreversibility: str = "crtol"
    lumping: bool = True
    model: str = "antiplane"
    young: float = 1.0
    poisson: float = 0.0
    gc: float = 1.0
    split: str = "none"
    crack_density: str = "at2"

    @property
    def alpha(self) -> float:
        """α = 1/(4ε)."""
        return 1 / (4 * self.eps)

    @property
    def surface(self) -> CrackDensity:
        """The crack density γ of the surface term (:func:`ngat.crack_density.crack_density`)."""
        return crack_density(self.crack_density, self.eps)

    def check(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid value."""
        if not self.eps > 0:
            raise ParameterError(f"eps must be positive, got eps={self.eps}: choose eps > 0")
        if not self.eta >= 0:
            raise ParameterError(f"eta must be non-negative, got eta={self.eta}: choose eta >= 0")
        if not self.eta < self.eps:
            raise ParameterError(
                f"eta must be smaller than eps, got eta={self.eta}, eps={self.eps}: "
                "choose eta < eps (eta << eps)"
            )
        if not 0 < self.crtol < 1:
            raise ParameterError(
                f"crtol must lie in (0, 1), got crtol={self.crtol}: choose 0 < crtol < 1"
            )
        if self.irreversibility not in ("crtol", "pointwise"):
            raise ParameterError(
                f"irreversibility must be crtol or pointwise, got {self.irreversibility!r}"
            )
        if self.model not in MODELS:
            raise ParameterError(f"model must be one of {', '.join(MODELS)}, got {self.model!r}")
        if not 0 < self.young < float("inf"):
            raise ParameterError(f"young must be positive and finite, got young={self.young}")
        if not -1 < self.poisson < 0.5:
            raise ParameterError(
                f"poisson must lie in (-1, 0.5), got poisson={self.poisson}: "
                "0.5 is incompressible, which P1 elements lock on"
            )
        if not 0 < self.gc < float("inf"):
            raise ParameterError(f"gc must be positive and finite, got gc={self.gc}")
        if self.split not in SPLITS:
            raise ParameterError(f"split must be one of {', '.join(SPLITS)}, got {self.split!r}")
        if self.split != "none" and self.model == "antiplane":
            raise ParameterError(
                f"split={self.split} splits the in-plane strain tensor: "
                "the antiplane model has no volumetric strain; choose model=plane_strain or "
                "plane_stress, or split=none"
            )
        if self.split == "spectral" and self.model != "plane_strain":
            raise ParameterError(
                "split=spectral splits the strain by its principal values, with ε_zz = 0 the "
                f"third: it needs model=plane_strain, got model={self.model}"
            )
        if self.crack_density not in CRACK_DENSITIES:
            raise ParameterError(
                f"crack_density must be one of {', '.join(CRACK_DENSITIES)}, "
                f"got {self.crack_density!r}"
            )


NONLINEAR_SOLVERS = ("am", "overrelaxed", "anderson", "newton", "anderson-newton")
"""The solvers of one load step, each a strategy of :mod:`ngat.strategies`
(:data:`ngat.strategies.STRATEGIES`)."""

AM_STOPS = ("contraction", "change")
"""Stopping tests of the alternating minimisation (``SolverParameters.am_stop``)."""


@dataclass(frozen=True)
class SolverParameters:
    """Alternating minimisation (paper, Algorithm 1).

    Attributes
    ----------
    am_tol
        Stop when the distance to the fixed point, estimated from ‖v^n − v^{n−1}‖_∞, is below
        am_tol (``am_stop``).
    am_stop
        ``"contraction"`` (default): the change of v outside the crack (v ≥ 0.1; inside, the
        change is scaled by v/0.1, :func:`ngat.minimization.load_bearing_change`) multiplied
        by ρ/(1 − ρ) where the iteration contracts slowly (ρ the ratio of the last two
        changes, :func:`ngat.strategies.estimated_error`), so that a crack front creeping by a
        little less than am_tol per iteration does not stop the step, and v drifting towards
        0 inside an opening crack does not hold it; ``"change"``: ‖v^n − v^{n−1}‖_∞ itself
        (the paper, Algorithm 1).
    am_max_iter
        Iteration limit per load step; 0 (default): ten iterations per ε of the body's diameter,
        at least 1000 (:func:`ngat.minimization.iteration_limit`): a crack that runs through
        the body within one load step moves its tip by 0.1–0.15ε per iteration, so the number
        of iterations such a step needs grows as 1/ε.
    max_cg
        CG iterations accepted with a stale Cholesky factor as preconditioner before the
        factor is refreshed (:class:`ngat.linear.LaggedCholesky`); 0: refactorise every solve.
    linear_solver
        Linear solver of both half-steps (:mod:`ngat.linear`): ``"direct"`` sparse Cholesky
        (with ``max_cg`` above), ``"cg-h1amg"`` conjugate gradients preconditioned by NGSolve's
        algebraic multigrid ``h1amg``, rebuilt for every matrix, to a relative residual of 1e−10
        within 2000 iterations (a solve that stops at the cap is reported as
        ``linear-not-converged``, :mod:`ngat.diagnostics`); for the plane models one h1amg per
        component of u (block Jacobi), not with an energy split. Newton steps solve their
        coupled system directly in either case.
    nonlinear
        Solver of one load step (:mod:`ngat.strategies`): ``"am"`` plain alternating
        minimisation (the paper), ``"overrelaxed"`` v ← v_old + ω(v_new − v_old),
        ``"anderson"`` Anderson acceleration of the alternating-minimisation map; both
        accelerated steps fall back to the plain one whenever it has lower energy;
        ``"newton"``: alternating minimisation until ‖v^n − v^{n−1}‖_∞ < ``newton_switch``,
        then, after each iteration whose rate predicts more than two iterations to go, a
        Newton step on the coupled system with an energy line search, or a step along negative
        curvature where a Lanczos search finds some (:mod:`ngat.newton`); or
        ``"anderson-newton"``: the same with Anderson acceleration of the iterations.
    omega
        Over-relaxation factor ω.
    anderson_depth
        Number of previous iterates Anderson acceleration combines.
    newton_switch
        Change ‖v^n − v^{n−1}‖_∞ of an alternating-minimisation iteration below which Newton
        steps are tried (``nonlinear="newton"``).
    crack_extension
        Let running cracks jump ahead within a load step (:mod:`ngat.extension`): the crack
        profile is translated along the tip's motion and kept where it lowers I_j. Needs the
        scene's slits (the tips are those of their cracks).
    bounded_v
        Minimise the v-step over 0 ≤ v ≤ 1 (see :meth:`ngat.halfsteps.HalfStepSolvers.solve_v`).
    predictor
        Start a load step from v extrapolated linearly from the last two load steps
        (:func:`ngat.minimization.predict_v`; not after a step that moved v by more than
        :data:`ngat.minimization.PREDICTOR_MAX` = 0.025 anywhere: a crack grew); ``False``:
        from v(t_{k−1}) (the paper).
    on_problem
        ``"warn"``: problems found by :mod:`ngat.diagnostics` are logged and recorded;
        ``"error"``: the run stops at the first one.
    """

    am_tol: float = 1e-3
    am_stop: str = "contraction"
    am_max_iter: int = 0
    max_cg: int = 0
    linear_solver: str = "direct"
    nonlinear: str = "newton"
    omega: float = 1.5
    anderson_depth: int = 5
    newton_switch: float = 0.1
    crack_extension: bool = False
    bounded_v: bool = True
    predictor: bool = True
    on_problem: str = "warn"

    def check(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid value."""
        if not self.am_tol > 0:
            raise ParameterError(f"am_tol must be positive, got am_tol={self.am_tol}")
        if self.am_stop not in AM_STOPS:
            raise ParameterError(
                f"am_stop must be one of {', '.join(AM_STOPS)}, got {self.am_stop!r}"
            )
        if not self.am_max_iter >= 0:
            raise ParameterError(
                "am_max_iter must be >= 1 (or 0: scaled with ε), "
                f"got am_max_iter={self.am_max_iter}"
            )
        if self.linear_solver not in ("direct", "cg-h1amg"):
            raise ParameterError(
                f"linear_solver must be direct or cg-h1amg, got {self.linear_solver!r}"
            )
        if self.nonlinear not in NONLINEAR_SOLVERS:
            raise ParameterError(
                f"nonlinear must be one of {', '.join(NONLINEAR_SOLVERS)}, got {self.nonlinear!r}"
            )
        if not self.newton_switch > 0:
            raise ParameterError(f"newton_switch must be positive, got {self.newton_switch}")
        if not 0 < self.omega < 2:
            raise ParameterError(f"omega must lie in (0, 2), got omega={self.omega}")
        if not self.anderson_depth >= 1:
            raise ParameterError(f"anderson_depth must be >= 1, got {self.anderson_depth}")
        if self.on_problem not in ("warn", "error"):
            raise ParameterError(f"on_problem must be warn or error, got {self.on_problem!r}")


ADAPT_VARIANTS = ("band", "paper", "after", "fixed")
"""The adaptivity variants (:func:`ngat.minimization.alternating_minimization`)."""


@dataclass(frozen=True)
class AdaptivityParameters:
    """Mesh: initial size and refinement (paper, Algorithm 2).

    Attributes
    ----------
    maxh
        Initial mesh size.
    adapt
        ``"band"``: Algorithm 2 and, on top of it, the crack band resolved to ``band_h · ε``
        wherever the crack is or is about to be, before each step and after every v-step
        (:mod:`ngat.band`); ``"paper"``: refine inside each half-step until μ ≤ tol and
        ν ≤ tol (Algorithm 2 alone); ``"after"``: refine only after the alternating
        minimisation has converged at a load step, then repeat it;
        ``"fixed"``: no refinement (Algorithm 1).
    tol
        Tolerance TOL_n for μ and ν (``adapt="paper"`` and ``"after"``; the paper's 0.3).
    tol_rel
        Relative tolerance of ``adapt="band"``: TOL_n = tol_rel · I_j(u, v)^{1/2}
        (:func:`ngat.minimization.tolerance`). The default 0.17 was the largest that put the
        paper's example's E(1.0) within 0.1 % of its converged reference with a band of 0.18ε
        (0.18, the paper's absolute 0.3 at t = 1 there, left it 0.145 % off); with the slit
        tips resolved on their own (``onset_h``) it gives +0.091 %.
    theta
        Marking parameter θ.
    marking
        ``"dorfler"`` (bulk) or ``"maximum"``.
    band_h
        Target element diameter in the crack band, in units of ε (``adapt="band"``): a band of
        width h costs G_eff ≈ 1 + h/(4ε) per unit length (:mod:`ngat.band`); with the default
        0.18, the grading and the re-meshing a crack runs within 2 % of its speed on
        ``surfing`` from a coarse unstructured mesh (0.25 with the re-meshing and no grading:
        0.963 V; ``docs/adaptivity.md``, items 12 and 13).
    onset_h
        Target element diameter, in units of ε, within ``ONSET_RADIUS`` · ε (2ε) of a slit tip
        whose crack has not grown yet (``adapt="band"``; :mod:`ngat.band`): the crack's onset
        and the singular field about the slit tip ask for finer elements than the band along a
        crack that runs. 0 (the default): none; the band's discs of 3ε about every crack tip
        resolve the slit tips to ``band_h`` as well.
        The paper's example sets 0.18 with a band of 0.27: E(1.0) +0.091 % off its converged
        reference, against +0.102 % with the slit tips in the band (``docs/paper-example.md``).
    band_search
        Coarsening of the crack band while a load step's iteration searches for its crack
        (``adapt="band"``): until the iteration converges the band is resolved to
        ``band_search · band_h · ε``, then to ``band_h · ε``, and the iteration goes on to
        convergence on that mesh (:meth:`ngat.band.CrackBand.search`). Where a crack runs
        through the body in one step, the hundreds of iterations of its run are spent on a
        band with a quarter of the elements at 2 — but the crack finds its path on that band:
        the default 1 keeps the band at ``band_h`` throughout. The paper's example sets 2 (its
        fracture time and E(1.0) do not move, its run takes 0.48–0.86 of the time, the energy
        after the break +0.3–0.7 %); on ``sent`` the crack ended 12ε off the notch line with
        it against 5ε without (``docs/paper-example.md``).
    band_grading
        Growth of the crack band's target diameter per unit distance beyond the band, about
        running cracks (``adapt="band"``; :mod:`ngat.band`): the default 0.42 grades it like a
        mesh structured along the crack path (the diameter growth of
        ``geometries/surfing.py``'s structured mesh); 0 leaves the body beyond the band to μ
        and ν.
    remesh_radius
        Radius, in units of ε, of the disc about each running crack tip that Netgen re-meshes
        with its own elements of ε before each load step (:mod:`ngat.remesh`;
        ``adapt="band"``): a crack then runs into Netgen's elements rather than into bisected
        initial ones, whose orientation holds it back. 0: no re-meshing.
    floor
        Element floor in units of ε: elements are bisected only while their children stay
        at least ``floor · ε`` wide (:func:`ngat.refinement.refinable`); the default is the
        paper's smallest element, 1e−3 at its ε = 0.05.
    max_refinements
        Limit of refinements per load step.
    resolve_eps
        Refuse, before the first step, a run whose refinement rule cannot make the elements where
        the crack is narrower than ε (the criterion of ``eps-under-resolved``,
        :mod:`ngat.diagnostics`): a ``floor`` of ε/2 or more, a crack band of ``band_h`` ≥ 1 or,
        with ``adapt="fixed"``, an initial mesh at least ε wide where the crack starts.
        ``False`` runs such a mesh anyway (studies of under-resolution).
    """

    maxh: float = 0.25
    adapt: str = "band"
    tol: float = 0.3
    tol_rel: float = 0.17
    theta: float = 0.5
    marking: str = "dorfler"
    band_h: float = 0.18
    onset_h: float = 0.0
    band_search: float = 1.0
    band_grading: float = 0.42
    remesh_radius: float = 10.0
    floor: float = 0.02
    max_refinements: int = 200
    resolve_eps: bool = True

    def check(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid value."""
        if not 0 < self.maxh < math.inf:
            raise ParameterError(f"maxh must be a positive number, got maxh={self.maxh}")
        if self.adapt not in ADAPT_VARIANTS:
            raise ParameterError(
                f"adapt must be one of {', '.join(ADAPT_VARIANTS)}, got adapt={self.adapt}"
            )
        if not self.tol > 0:
            raise ParameterError(f"tol must be positive, got tol={self.tol}: choose tol > 0")
        if not self.tol_rel > 0:
            raise ParameterError(f"tol_rel must be positive, got tol_rel={self.tol_rel}")
        if not 0 < self.theta <= 1:
            raise ParameterError(f"theta must lie in (0, 1], got theta={self.theta}")
        if self.marking not in ("dorfler", "maximum"):
            raise ParameterError(f"marking must be dorfler or maximum, got marking={self.marking}")
        if not self.floor >= 0:
            raise ParameterError(f"floor must be non-negative, got floor={self.floor}")
        if not 0 <= self.onset_h < math.inf:
            raise ParameterError(
                f"onset_h must be a non-negative number (0: band_h), got onset_h={self.onset_h}"
            )
        if not 1 <= self.band_search < math.inf:
            raise ParameterError(
                f"band_search must be a number >= 1 (1: no coarser band while a step searches "
                f"for its crack), got band_search={self.band_search}"
            )
        if not 0 <= self.band_grading < math.inf:
            raise ParameterError(
                f"band_grading must be a non-negative number, got band_grading={self.band_grading}"
            )
        if not 0 <= self.remesh_radius < math.inf:
            raise ParameterError(
                "remesh_radius must be a non-negative number (0: no re-meshing), got "
                f"remesh_radius={self.remesh_radius}"
            )
        if self.resolve_eps:
            self.check_resolution()
        if self.adapt == "band" and not self.band_h > 2 * self.floor:
            raise ParameterError(
                f"band_h must exceed twice the floor, got band_h={self.band_h}, "
                f"floor={self.floor}: the band cannot be refined below the floor (adapt=band)"
            )
        if not self.max_refinements >= 0:
            raise ParameterError(
                f"max_refinements must be >= 0, got max_refinements={self.max_refinements}"
            )

    def check_resolution(self) -> None:
        """Raise :class:`ParameterError` if the refinement rule can never resolve ε.

        Elements are bisected only while wider than 2·floor·ε, and the crack band stops at
        band_h·ε; ε is resolved once the elements at the crack are narrower than ε. The initial
        mesh of ``adapt="fixed"`` is checked on the mesh, by the driver.
        """
        fix = "or set resolve_eps=false to run under-resolved on purpose"
        if self.adapt != "fixed" and not 2 * self.floor < 1:
            raise ParameterError(
                f"floor={self.floor} stops bisection at elements {2 * self.floor:g}ε wide, so "
                f"adapt={self.adapt} never resolves ε: set floor < 0.5 (default 0.02), {fix}"
            )
        if self.adapt == "band" and not self.band_h < 1:
            raise ParameterError(
                f"band_h={self.band_h} leaves the crack band's elements {self.band_h:g}ε wide, "
                f"so the crack is never resolved: set band_h < 1 (default 0.25), {fix}"
            )


@dataclass(frozen=True)
class OutputParameters:
    """What a run writes to its results folder (:class:`ngat.output.ResultsWriter`).

    Attributes
    ----------
    output_every
        Write the fields (a VTU in ``fields.pvd``) of every ``output_every``-th load step
        (steps 0, k, 2k, …) and of the last one; ``energies.csv`` gets every step.
    checkpoint_every
        Seconds of wall time between checkpoints: a load step writes one once this long has
        passed since the last one, and the last step and a step that ends the run with an
        error always do; 0 writes one after every step. A run killed in between resumes from
        its last checkpoint and computes the steps after it again, to the same numbers, so it
        loses at most this long and the step it was in. On small meshes the two fsyncs of a
        checkpoint (the rows, then the state) cost more than the step itself.
    """

    output_every: int = 1
    checkpoint_every: float = 10.0

    def check(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid value."""
        if not self.output_every >= 1:
            raise ParameterError(
                f"output_every must be >= 1, got output_every={self.output_every}: "
                "1 writes the fields of every step"
            )
        if not self.checkpoint_every >= 0:
            raise ParameterError(
                f"checkpoint_every must be >= 0 seconds, got "
                f"checkpoint_every={self.checkpoint_every}: 0 writes a checkpoint after every step"
            )

    def checkpoint_due(self, step: int, steps: int, since: float) -> bool:
        """Return whether load step ``step`` of ``steps`` writes the checkpoint.

        Parameters
        ----------
        step, steps
            The step just finished and the number of steps.
        since
            Seconds since the last checkpoint (or the start of the run).
        """
        return step == steps - 1 or since >= self.checkpoint_every

    def writes_fields(self, step: int, steps: int) -> bool:
        """Return whether load step ``step`` of ``steps`` writes its fields."""
        return step % self.output_every == 0 or step == steps - 1


@dataclass(frozen=True)
class Parameters:
    """All parameters of a run, grouped; :meth:`replace` addresses them by bare name."""

    model: ModelParameters = field(default_factory=ModelParameters)
    solver: SolverParameters = field(default_factory=SolverParameters)
    adaptivity: AdaptivityParameters = field(default_factory=AdaptivityParameters)
    output: OutputParameters = field(default_factory=OutputParameters)

    def _groups(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def names(self) -> dict[str, type]:
        """Return every parameter name with its type."""
        return {
            f.name: type(getattr(group, f.name))
            for group in self._groups().values()
            for f in dataclasses.fields(group)
        }

    def replace(self, **values: Any) -> Parameters:
        """Return a copy with the named parameters changed, converting strings to their type.

        Raises
        ------
        ParameterError
            For an unknown name or a value that does not convert to the parameter's type.
        """
        names = self.names()
        groups = self._groups()
        changes: dict[str, dict[str, Any]] = {}
        for name, value in values.items():
            if name not in names:
                known = ", ".join(sorted(names))
                close = difflib.get_close_matches(name, names, n=1)
                hint = f"did you mean '{close[0]}'? " if close else ""
                raise ParameterError(f"unknown parameter '{name}': {hint}known are {known}")
            kind = names[name]
            try:
                converted = _convert(kind, value)
                if kind is int and isinstance(value, float) and value != int(value):
                    raise ValueError
            except (TypeError, ValueError):
                example = self.flat()[name]
                raise ParameterError(
                    f"parameter '{name}' needs a value of type {kind.__name__}, got {value!r}: "
                    f"give e.g. {name}={example}"
                ) from None
            group = next(g for g, obj in groups.items() if hasattr(obj, name))
            changes.setdefault(group, {})[name] = converted
        new = {g: dataclasses.replace(groups[g], **c) for g, c in changes.items()}
        result = dataclasses.replace(self, **new)
        result.check()
        return result

    def check(self) -> None:
        """Check every group; raise :class:`ParameterError` naming the first invalid value."""
        for name, value in self.flat().items():
            if isinstance(value, float) and not math.isfinite(value):
                raise ParameterError(
                    f"{name} must be a finite number, got {name}={value}: give e.g. "
                    f"{name}={Parameters().flat()[name]}"
                )
        for group in self._groups().values():
            group.check()
        if self.model.split != "none" and self.solver.linear_solver != "direct":
            raise ParameterError(
                f"linear_solver={self.solver.linear_solver} preconditions the u-step with the "
                f"degraded operator, which split={self.model.split} leaves intact in "
                "compression: choose linear_solver=direct with a split"
            )
        if (
            self.model.crack_density == "at1"
            and not self.solver.bounded_v
            and self.model.irreversibility != "pointwise"
        ):
            raise ParameterError(
                "crack_density=at1 needs bounded_v=true: below W = 3 G_c/(16 eps) its v-step "
                "minimiser sits on the bound v = 1, which only the bounded v-step keeps"
            )
        if not self.model.lumping and "newton" in self.solver.nonlinear:
            raise ParameterError(
                f"nonlinear={self.solver.nonlinear} needs lumping=true: its Hessian is that of "
                "the lumped functional (eq. 7); with lumping=false set nonlinear=am, "
                "overrelaxed or anderson"
            )

    def flat(self) -> dict[str, Any]:
        """Return all parameters as one flat dictionary (for summaries and sweep tables)."""
        return {
            f.name: getattr(group, f.name)
            for group in self._groups().values()
            for f in dataclasses.fields(group)
        }


LEGACY_VALUES: dict[str, Any] = {
    "am_stop": "change",
    "band_search": 1.0,
    "crack_extension": False,
    "onset_h": 0.0,
    "predictor": False,
    "remesh_radius": 0.0,
}
"""What the package did in place of a parameter before it existed: a run folder recorded then
(``summary.json``, checkpoint) does not name it, and resuming it compares these values."""


WRITING_ONLY = frozenset({"checkpoint_every"})
"""Parameters that decide when a run writes, not what it computes: a resumed run may change
them (and a run recorded before one existed resumes whatever it is)."""


def with_legacy_values(recorded: Mapping[str, Any]) -> dict[str, Any]:
    """Return the flat parameters of a recorded run with :data:`LEGACY_VALUES` where it names none.

    Parameters
    ----------
    recorded
        Flat parameters as a run folder stores them (:meth:`Parameters.flat`).
    """
    return {**LEGACY_VALUES, **recorded}


def computing(flat: Mapping[str, Any]) -> dict[str, Any]:
    """Return the flat parameters without :data:`WRITING_ONLY`: what a resumed run must share."""
    return {key: value for key, value in flat.items() if key not in WRITING_ONLY}
