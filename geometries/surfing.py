"""Mode-III surfing: a crack driven through a strip by a translating crack-tip field (Griffith).

Ω = (0, L) × (−H/2, H/2) with the pre-crack [0, a₀] × {0}, a true slit that cuts through the
frame Ω_D of thickness d along the outer boundary (docs/design.md, scene 2). On Ω_D

    u = U(x, y, t) = A(t) · sqrt(2r/π) · sin(θ/2),   (r, θ) polar about (a₀ + V t, 0),

θ ∈ (−π, π]; the branch cut θ = ±π lies on y = 0 behind the imposed tip, so on the frame it
coincides with the slit. For the energy density |∇u|² this field has the energy release rate
G = A². A(t) = A · min(1, t / ramp): the amplitude is ramped in, then held.

Griffith's theory for the discrete AT functional: the crack grows when G reaches the effective
toughness of the mesh, G_eff(h) = 1 + h/(4ε) + (h/ε)²/32 (:func:`effective_toughness`), where h
is the spacing of the node lines parallel to the crack (u jumps across a band one element wide
whose nodes all have v = 0). The Griffith checks (``scripts/surfing_griffith.py``,
``tests/test_surfing.py``) therefore use ``make_scene(h_band=h)``: a fixed mesh that is
structured along the crack path, a band |y| ≤ w around y = 0 from a little behind a₀ to past
the crack's end cut into squares of side h (each split by one diagonal, so the node lines
y = jh are straight and the triangles right-angled, Hypothesis A), graded to ``maxh`` away from
the band. The scene itself (``ngat run surfing``) starts from the uniform mesh of squares of
side ``maxh`` (the break points are multiples of 0.1, so h ∈ {0.1, 0.05, 0.025, 0.0125} fit
exactly) and refines it by Algorithm 2, like ``two-slits``; with ``adapt=fixed`` that is a
uniform-mesh run. ``structured=False`` meshes the OCC geometry instead (unstructured).

Sizes: L = 2, H = 1.4, d = 0.1, a₀ = 0.6, so the tip is R = 0.6 from the frame, and ε = 0.01
(ε/R = 1/60). AT2 damages the whole body a little, which biases the Griffith measures by a
relative amount of order ε/R (docs/design.md); measured, A_c²/G_eff = 1.05 at R/ε = 60 and 1.003 at
R/ε = 400, so the checks use a smaller ε with this geometry. The default run: A = 1.1, V = 0.2,
t ∈ [0, 1.5] in steps of 0.025 with the amplitude ramped in over t ∈ [0, 0.25]; the imposed
tip travels from 0.6 to 0.9 and the crack tip runs ahead of it by a steady lead.
"""

from __future__ import annotations

import math

import netgen.meshing as ngm
import numpy as np
from ngsolve import IfPos, Mesh, Parameter, atan2, pi, sin, sqrt, x, y

from ngat.elasticity import AntiPlane, Elasticity
from ngat.geometry import glue, polygon_face
from ngat.scene import Scene

LENGTH = 2.0
"""L: length of the strip."""
HEIGHT = 1.4
"""H: height of the strip."""
FRAME = 0.1
"""d: thickness of the frame Ω_D."""
CRACK_LENGTH = 0.6
"""a₀: length of the pre-crack (and initial x of the imposed tip)."""
EPS = 0.01
"""ε of the scene (η and CRTOL are the package defaults)."""
H_BAND = 0.005
"""Default side of the squares of :func:`structured_mesh`'s band (h/ε = 1/2)."""
BAND_HALF_WIDTH = 0.06
"""w: half width of the structured band around y = 0 (6ε: the profile has decayed to e^-3)."""
SPEED = 0.2
"""V: speed of the imposed tip."""
RAMP = 0.25
"""Time over which the amplitude is ramped in."""
AMPLITUDE = 1.1
"""A of the default (adaptive) run: A² = 1.21 ≈ 1.2 G_eff at the element floor h = 1e-3."""
OVERLOAD = 1.2
"""A² / G_eff(h) on a structured band of side h (the Griffith checks)."""
TIMES = np.round(0.025 * np.arange(61), 10)
"""Load times of the default run: t ∈ [0, 1.5], V Δt = 0.005."""
BAND_END = 1.2
"""x where the structured band ends: beyond the crack tip at t = 1.5."""

# The slit as a segment (mouth, tip), for the crack measures of ngat.crack.
SLITS = (((0.0, 0.0), (CRACK_LENGTH, 0.0)),)


def effective_toughness(h: float, eps: float) -> float:
    """Return G_eff(h) = 1 + h/(4ε) + (h/ε)²/32, the discrete toughness of a band of width h.

    Parameters
    ----------
    h
        Spacing of the node lines parallel to the crack.
    eps
        Regularisation length ε.
    """
    return 1 + h / (4 * eps) + (h / eps) ** 2 / 32


def tip_field(amplitude, tip_x):
    """Return A sqrt(2r/π) sin(θ/2) about (tip_x, 0), θ ∈ (−π, π], as a CoefficientFunction.

    Parameters
    ----------
    amplitude, tip_x
        Numbers or CoefficientFunctions (of the load parameter).
    """
    dx = x - tip_x
    r = sqrt(dx * dx + y * y)
    return amplitude * sqrt(2 * r / pi) * sin(atan2(y, dx) / 2)


def geometry():
    """Return the strip: the frame Ω_D glued to the body, both cut by the pre-crack."""
    half, d, a0 = HEIGHT / 2, FRAME, CRACK_LENGTH
    outer = [(d, 0), (0, 0), (0, -half), (LENGTH, -half), (LENGTH, half), (0, half), (0, 0)]
    inner = [(d, 0), (d, half - d), (LENGTH - d, half - d), (LENGTH - d, -half + d), (d, -half + d)]
    frame = polygon_face(outer + inner, "frame")
    body = polygon_face([(d, 0), (a0, 0), *inner], "body")
    return glue([frame, body])


def _axis(breaks: list[float], size) -> np.ndarray:
    """Return node coordinates through every break point, spaced by ``size(x)`` (graded).

    Each interval between break points gets n = ⌈∫ dx/size⌉ cells whose ends are equally spaced
    in ∫ dx/size, so a constant size that divides the interval gives equal cells.
    """
    nodes = [np.array([breaks[0]])]
    for a, b in zip(breaks[:-1], breaks[1:], strict=True):
        s = np.linspace(a, b, 2001)
        density = 1 / size(s)
        cumulative = np.concatenate(
            [[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(s))]
        )
        n = max(1, math.ceil(cumulative[-1] - 1e-9))
        nodes.append(np.interp(np.linspace(0, cumulative[-1], n + 1)[1:], cumulative, s))
    return np.concatenate(nodes)


def structured_mesh(
    maxh: float,
    h_band: float | None = H_BAND,
    band_end: float = BAND_END,
    half_width: float = BAND_HALF_WIDTH,
    grading: float = 0.3,
    crack_length: float = CRACK_LENGTH,
) -> Mesh:
    """Return a tensor-product triangle mesh of the strip with a true slit and the frame Ω_D.

    Parameters
    ----------
    maxh
        Largest cell side (away from the band).
    h_band
        Cell side in the band (a0 − 10 h, band_end) × (−w, w); ``None``: uniform cells of side
        ``maxh`` everywhere (the break points must then be multiples of ``maxh``).
    band_end
        x where the band ends (rounded to the band's grid).
    half_width
        w, rounded to the band's grid.
    grading
        Growth of the cell side per unit distance from the band (cells grow by about
        1 + grading per cell).
    crack_length
        a₀, the slit's length (a multiple of ``h_band``).

    Returns
    -------
    ngsolve.Mesh
        Materials ``frame`` (Ω_D) and ``body``; boundaries ``outer`` and ``slit``. Each node of
        the slit [0, a₀) × {0}, mouth included, has a twin for the upper face.
    """
    half, d, a0 = HEIGHT / 2, FRAME, crack_length
    if h_band is None:
        h_band = maxh
        x_lo, x_hi, w = a0, a0, 0.0
    else:
        x_lo = a0 - 10 * h_band
        x_hi = a0 + round((band_end - a0) / h_band) * h_band
        w = round(half_width / h_band) * h_band

    def size(lo, hi):
        return lambda s: np.minimum(
            maxh, h_band + grading * np.maximum(0.0, np.maximum(lo - s, s - hi))
        )

    xs = _axis(sorted({0.0, d, x_lo, a0, x_hi, LENGTH - d, LENGTH}), size(x_lo, x_hi))
    ys = _axis(sorted({-half, -half + d, -w, 0.0, w, half - d, half}), size(-w, w))
    nx, ny = len(xs) - 1, len(ys) - 1
    X, Y = np.meshgrid(xs, ys)  # point (i, j) = row j (y), column i (x): number j (nx + 1) + i
    points = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    base = (np.arange(ny)[:, None] * (nx + 1) + np.arange(nx)[None, :]).ravel()
    lower = np.stack([base, base + 1, base + nx + 1], axis=1)
    upper = np.stack([base + 1, base + nx + 2, base + nx + 1], axis=1)
    triangles = np.concatenate([lower, upper])
    # The slit: the upper face's elements get twins of the nodes (x < a0, y = 0).
    j0 = int(np.argmin(np.abs(ys)))
    slit_columns = np.flatnonzero(xs < a0 - 1e-12)
    slit_nodes = j0 * (nx + 1) + slit_columns
    twins = len(points) + np.arange(len(slit_nodes))
    points = np.concatenate([points, points[slit_nodes]])
    above = points[triangles, 1].mean(axis=1) > 0
    renumber = np.arange(len(points))
    renumber[slit_nodes] = twins
    triangles[above] = renumber[triangles[above]]
    centre = points[triangles, :2].mean(axis=1)
    in_frame = (centre[:, 0] < d) | (centre[:, 0] > LENGTH - d) | (np.abs(centre[:, 1]) > half - d)

    ngmesh = ngm.Mesh(dim=2)
    ngmesh.AddPoints(points)
    frame_index = ngmesh.AddRegion("frame", dim=2)
    body_index = ngmesh.AddRegion("body", dim=2)
    outer_index = ngmesh.AddRegion("outer", dim=1)
    slit_index = ngmesh.AddRegion("slit", dim=1)
    ngmesh.AddElements(2, frame_index, triangles[in_frame].astype(np.int32), base=0)
    ngmesh.AddElements(2, body_index, triangles[~in_frame].astype(np.int32), base=0)
    grid = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    ring = np.concatenate([grid[0, :], grid[1:, -1], grid[-1, -2::-1], grid[-2::-1, 0]])
    outer = np.stack([ring[:-1], ring[1:]], axis=1)
    # Above y = 0 the left edge meets the mouth in the upper face's twin.
    upper_left = (outer == slit_nodes[0]).any(axis=1) & (points[outer, 1].max(axis=1) > 0)
    outer[upper_left] = np.where(outer[upper_left] == slit_nodes[0], twins[0], outer[upper_left])
    ends = np.append(slit_nodes, j0 * (nx + 1) + len(slit_columns))
    lower_face = np.stack([ends[1:], ends[:-1]], axis=1)
    upper_ends = np.append(twins, ends[-1])
    upper_face = np.stack([upper_ends[:-1], upper_ends[1:]], axis=1)
    ngmesh.AddElements(1, outer_index, outer.astype(np.int32), base=0)
    ngmesh.AddElements(
        1, slit_index, np.concatenate([lower_face, upper_face]).astype(np.int32), base=0
    )
    return Mesh(ngmesh)


def make_scene(
    amplitude: float | None = None,
    speed: float = SPEED,
    ramp: float = RAMP,
    eps: float = EPS,
    h_band: float | None = None,
    times=TIMES,
    tip_start: float = CRACK_LENGTH,
    structured: bool = True,
    band_end: float = BAND_END,
    half_width: float = BAND_HALF_WIDTH,
    name: str = "surfing",
) -> Scene:
    """Return a surfing scene.

    Parameters
    ----------
    amplitude
        A; default :data:`AMPLITUDE`, or sqrt(1.2 G_eff(h_band)) on a structured band.
    speed
        V, speed of the imposed tip; 0 keeps it where it starts.
    ramp
        A(t) = A · min(1, t / ramp); 0: the full amplitude from the start.
    eps
        ε.
    h_band
        Cell side of a structured band along the crack path, on a fixed mesh (the Griffith
        checks); ``None``: a uniform initial mesh of the run's ``maxh``, refined by Algorithm 2.
    times
        Load times.
    tip_start
        x of the imposed tip at t = 0 (default a₀).
    structured
        Tensor-product mesh (:func:`structured_mesh`); ``False``: Netgen meshes the OCC geometry.
    band_end, half_width
        Extent of the structured band (see :func:`structured_mesh`).
    name
        Scene name.
    """
    if amplitude is None:
        amplitude = (
            AMPLITUDE if h_band is None else math.sqrt(OVERLOAD * effective_toughness(h_band, eps))
        )

    def load(t: Parameter):
        scale = IfPos(t - ramp, 1.0, t / ramp) if ramp > 0 else 1.0
        return tip_field(amplitude * scale, tip_start + speed * t)

    def mesh(maxh: float) -> Mesh:
        return structured_mesh(maxh, h_band, band_end, half_width)

    parameters = {"eps": eps, "maxh": 0.1}
    if h_band is not None:
        parameters["adapt"] = "fixed"
    return Scene(
        name=name,
        description="mode-III surfing: a translating crack-tip field drives the crack (Griffith)",
        geometry=geometry,
        mesh=mesh if structured else None,
        loads={"frame": load},
        times=times,
        slits=SLITS,
        parameters=parameters,
        # --quick: every fourth load step, a looser tolerance and the crack band at 0.35ε (the
        # default 0.18ε made the quick run 112k elements and 220 s; 35k and 48 s at 0.35ε).
        quick={"times": TIMES[::4], "tol": 0.6, "band_h": 0.35},
    )


# -- Griffith measures ----------------------------------------------------------------------
def onset(amplitude_sq, tip_x) -> float:
    """Return A_c², where the crack starts to grow under a ramped amplitude (tip field fixed).

    AT2 has no elastic phase: below A_c² the set {v < 0.1} already creeps ahead of the
    pre-crack's tip (the process zone widens by about ε), and above it the crack grows at the
    rate stable Griffith growth under the fixed field requires, many times faster. A_c² is
    the break point of the continuous two-segment least-squares fit of the tip position
    against A² (the break point is searched on a fine grid).

    Parameters
    ----------
    amplitude_sq
        A² at the load steps.
    tip_x
        x of the crack tip (:func:`ngat.crack.crack_tips`) at the same steps.
    """
    a2, tip = np.asarray(amplitude_sq, dtype=float), np.asarray(tip_x, dtype=float)

    def misfit(b):
        basis = np.stack([np.ones_like(a2), np.minimum(a2 - b, 0), np.maximum(a2 - b, 0)], 1)
        return np.linalg.lstsq(basis, tip, rcond=None)[1].sum()

    candidates = np.linspace(a2[2], a2[-3], 500)
    return float(candidates[np.argmin([misfit(b) for b in candidates])])


def sharp_crack_release_rate(
    crack_length: float,
    tip_x: float,
    amplitude: float = 1.0,
    h: float = 0.0025,
    radii: tuple[float, float] = (0.02, 0.06),
) -> float:
    """Return Griffith's G of the sharp crack [0, a] × {0} in the strip under the tip field.

    The crack is a true slit, v ≡ 1, and u = U (amplitude A, tip field about ``tip_x``) on the
    frame. For the energy ∫|∇u|², G = −dE/da is the domain J-integral

        G = ∫ (2 ∂ₓu ∇u·∇q − |∇u|² ∂ₓq) dx,

    q = 1 within ``radii[0]`` of the crack tip, 0 beyond ``radii[1]``, linear in between. With
    the crack tip at the field's (a = ``tip_x``) the field U solves the problem and G = A².

    Parameters
    ----------
    crack_length
        a (a multiple of ``h``).
    tip_x
        x of the imposed tip field.
    amplitude
        A.
    h
        Cell side of the structured band along the crack (:func:`structured_mesh`).
    radii
        Inner and outer radius of the cut-off q.
    """
    from ngsolve import H1, BilinearForm, BitArray, GridFunction, Integrate, dx, grad

    mesh = structured_mesh(
        0.05, h_band=h, band_end=crack_length + 4 * radii[1], half_width=radii[1] + 2 * h,
        crack_length=crack_length,
    )  # fmt: skip
    fes = H1(mesh, order=1)
    trial, test = fes.TnT()
    stiffness = BilinearForm(grad(trial) * grad(test) * dx).Assemble().mat
    u = GridFunction(fes)
    u.Set(tip_field(amplitude, tip_x), definedon=mesh.Materials("frame"))
    free = BitArray(fes.FreeDofs()) & ~fes.GetDofs(mesh.Materials("frame"))
    u.vec.data += stiffness.Inverse(free, inverse="sparsecholesky") * (-stiffness * u.vec)
    r = sqrt((x - crack_length) ** 2 + y * y)
    inner, outer = radii
    q = GridFunction(fes)
    q.Set(IfPos(r - outer, 0, IfPos(r - inner, (outer - r) / (outer - inner), 1)))
    gu, gq = grad(u), grad(q)
    integrand = 2 * gu[0] * (gu * gq) - (gu * gu) * gq[0]
    return float(Integrate(integrand, mesh, definedon=mesh.Materials("body")))


def griffith_lead(tip_x: float, toughness: float, amplitude: float, h: float = 0.0025) -> float:
    """Return Griffith's steady lead ℓ of the crack tip over the imposed tip at ``tip_x``.

    ℓ solves G(tip_x + ℓ; tip_x) = G_c (:func:`sharp_crack_release_rate`; G decreases with ℓ), by
    the secant method on crack lengths rounded to the band's grid ``h``.

    Parameters
    ----------
    tip_x
        x of the imposed tip.
    toughness
        G_c of the crack.
    amplitude
        A.
    h
        Cell side of the band, and the resolution of ℓ.
    """

    def misfit(lead):
        return sharp_crack_release_rate(tip_x + lead, tip_x, amplitude, h) - toughness

    a, b = 0.0, 0.1
    fa, fb = misfit(a), misfit(b)
    while abs(b - a) > h / 2:
        a, fa, b = b, fb, round((b - fb * (b - a) / (fb - fa)) / h) * h
        if b == a:
            break
        fb = misfit(b)
    return b


def energy_release_rate(
    points,
    cells,
    u,
    v,
    eps: float,
    eta: float,
    centre=(CRACK_LENGTH, 0.0),
    radii=(0.27, 0.48),
    elasticity: Elasticity | None = None,
) -> float:
    """Return J, the energy release rate of a discrete AT2 solution (domain J-integral).

    J = ∫ [−Ψ ∂ₓq + 2 a s(u) : (∂ₓu ⊗ ∇q) + 2ε vₓ ∇v·∇q] dx over the body, with
    a = mean(v²) + η per element (the lumped coefficient), s(u) the flux of the elastic energy
    density W = s(u) : ∇u (:mod:`ngat.elasticity`: s = ∇u for the anti-plane W = |∇u|²,
    s = σ/2 in plane elasticity), Ψ = a W + (1 − v)²/(4ε) + ε|∇v|² the AT2 energy density
    (G_c = 1) and q = 1 inside ``radii[0]``, 0 outside ``radii[1]``, linear in r between. At
    a critical point this is path independent (Eshelby) and is the rate at which the total
    energy is released per unit advance of everything inside the annulus, crack and process
    zone: Griffith's G of the discrete solution. The annulus must enclose the whole crack and
    stay in the body (the default: 0.45R to 0.8R about the slit tip). q is the P1 interpolant
    of that weight (:func:`_weight`): with q evaluated at the element centres instead, the
    elements of an unrefined 10ε mesh across the annulus bias J by +7 % (the K field of G = 1
    with the tip resolved: J = 1.078, against 1.017 with the interpolant, mode I).

    Unlike A², J does not carry the bias of AT2's diffuse damage: the whole body is softened
    by v ≈ 1/(1 + 4ε|∇u|²), so the tip sees less than the imposed G = A² (J/A² ≈ 0.90 at
    R/ε = 100, 0.95 at R/ε = 200 before the crack moves).

    Parameters
    ----------
    points
        (n, 2) or (n, 3) vertex coordinates.
    cells
        (m, 3) vertex numbers of the triangles (a discontinuous numbering is fine: the slit's
        faces then have their own vertices).
    u
        (n,) anti-plane displacement, or (n, k ≥ 2) in-plane displacement (its first two
        columns: a VTU's vector u has three).
    v
        (n,) phase field at the vertices.
    eps, eta
        ε and η of the run.
    centre
        Centre of the annulus.
    radii
        Inner and outer radius of the annulus.
    elasticity
        The model's energy density (:func:`ngat.elasticity.elasticity`); default anti-plane.

    Returns
    -------
    float
        J.
    """
    elasticity = elasticity or AntiPlane()
    corners, area, gradient = _triangles(points, cells)
    columns = np.asarray(u, dtype=float).reshape(len(points), -1)[:, : elasticity.components]
    grad_u = np.stack([gradient(column) for column in columns.T], axis=1)  # (m, k, 2)
    flux = elasticity.flux(grad_u)
    grad_v = gradient(v)
    grad_q = gradient(_weight(points, centre, radii))
    local_v = np.asarray(v, dtype=float)[cells]
    a = (local_v**2).mean(axis=1) + eta
    density = (
        a * (flux * grad_u).sum(axis=(1, 2))
        + (1 - local_v.mean(axis=1)) ** 2 / (4 * eps)
        + eps * (grad_v**2).sum(axis=1)
    )
    integrand = (
        -density * grad_q[:, 0]
        + 2 * a * np.einsum("mi,mij,mj->m", grad_u[:, :, 0], flux, grad_q)
        + 2 * eps * grad_v[:, 0] * (grad_v * grad_q).sum(axis=1)
    )
    return float((area * integrand).sum())


def _weight(points, centre, radii) -> np.ndarray:
    """Return the weight q of the J-integral at the vertices.

    q = 1 within ``radii[0]`` of ``centre``, 0 beyond ``radii[1]`` and on the frame, linear in
    r between.
    """
    points = np.asarray(points, dtype=float)[:, :2]
    r = np.hypot(points[:, 0] - centre[0], points[:, 1] - centre[1])
    q = np.clip((radii[1] - r) / (radii[1] - radii[0]), 0.0, 1.0)
    inside = (np.abs(points[:, 1]) < HEIGHT / 2 - FRAME) & (points[:, 0] > FRAME)
    q[~(inside & (points[:, 0] < LENGTH - FRAME))] = 0.0
    return q


def _triangles(points, cells):
    """Return the corners, the areas and a P1 gradient function of a triangle mesh."""
    cells = np.asarray(cells)
    corners = np.asarray(points, dtype=float)[:, :2][cells]
    edges = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=1)
    area = 0.5 * np.abs(edges[:, 0, 0] * edges[:, 1, 1] - edges[:, 0, 1] * edges[:, 1, 0])

    def gradient(values):
        local = np.asarray(values, dtype=float)[cells]
        rhs = np.stack([local[:, 1] - local[:, 0], local[:, 2] - local[:, 0]], axis=1)
        return np.linalg.solve(edges, rhs[:, :, None])[:, :, 0]

    return corners, area, gradient


def band_surface_energy(points, cells, v, eps: float, x_range=(0.15, 0.3)) -> float:
    """Return Γ, the surface energy per unit length of the crack band along the slit.

    Γ = ∫ (1 − v)²/(4ε) + ε|∇v|² over the strip ``x_range`` × (−H/2 + d, H/2 − d), divided by
    its length (G_c = 1; the lumped (1 − v)² is the element mean of the vertex values).

    With a phase-field pre-crack (v = 0 on the slit, ``surfing_mode_i.make_scene(
    precrack=True)``) the band crosses the annulus of :func:`energy_release_rate` behind the
    tip; translating the inside of the annulus lengthens that band, so J counts its surface
    energy against the release: Griffith's G is J + Γ. The default strip lies where the band
    crosses the default annulus (0.27 to 0.48 behind a₀), away from the tip and the frame.

    Parameters
    ----------
    points, cells, v, eps
        As for :func:`energy_release_rate`.
    x_range
        The strip's ends.
    """
    corners, area, gradient = _triangles(points, cells)
    local_v = np.asarray(v, dtype=float)[np.asarray(cells)]
    density = ((1 - local_v) ** 2).mean(axis=1) / (4 * eps) + eps * (gradient(v) ** 2).sum(axis=1)
    centre = corners.mean(axis=1)
    strip = (centre[:, 0] > x_range[0]) & (centre[:, 0] < x_range[1])
    strip &= np.abs(centre[:, 1]) < HEIGHT / 2 - FRAME
    return float((area * density)[strip].sum() / (x_range[1] - x_range[0]))


def griffith_toughness(release_rates, tip_x, eps: float, grown: float = 10.0, end=None) -> float:
    """Return J_c: the median energy release rate over the steps at which the crack grows.

    Griffith: a crack grows when, and only while, G equals the toughness. Under a ramped
    amplitude the AT2 crack first creeps (its process zone forms, J < J_c) and then grows;
    the steps whose crack tip lies at least ``grown · ε`` beyond the slit's tip (the crack's
    profile formed, 95 % of its surface energy within 3ε) and before ``end`` (where a fixed
    band ends and coarse elements would hold the crack back) are the growth steps.

    Parameters
    ----------
    release_rates
        J at the load steps (:func:`energy_release_rate`).
    tip_x
        x of the crack tip at the same steps.
    eps
        ε.
    grown
        Crack advance, in units of ε, from which a step counts as growth.
    end
        x beyond which steps are left out (``None``: none).

    Returns
    -------
    float
        J_c; NaN when no step counts (the ramp did not reach growth: extend it).
    """
    j, tip = np.asarray(release_rates, dtype=float), np.asarray(tip_x, dtype=float)
    growing = tip >= CRACK_LENGTH + grown * eps
    if end is not None:
        growing &= tip <= end
    return float(np.median(j[growing])) if growing.any() else float("nan")


def steady_rates(times, tip_x, surface) -> dict[str, float]:
    """Return the crack tip's speed, the surface energy per unit advance and the stick–slip.

    Speed and toughness are least-squares slopes over the given steps (choose them after the
    transient): the speed d(tip)/dt, and dS/da = (dS/dt) / (d(tip)/dt), which averages out the
    quantisation of the tip position to the mesh. ``stick_slip`` is the standard deviation of
    the tip's advance per step divided by its mean: 0 for a crack that advances the same in
    every step; a crack that is held and then jumps scatters, and the fitted speed of a short
    window then depends on where the window ends. A tip that does not advance has speed 0 and
    no toughness or stick–slip (NaN).

    Parameters
    ----------
    times, tip_x, surface
        Load times, crack tip x and surface energy S at the steps of the window.
    """
    advance = np.diff(tip_x)
    if not np.any(advance):
        return {"speed": 0.0, "toughness": float("nan"), "stick_slip": float("nan")}
    speed = np.polyfit(times, tip_x, 1)[0]
    return {
        "speed": float(speed),
        "toughness": float(np.polyfit(times, surface, 1)[0] / speed),
        "stick_slip": float(np.std(advance) / np.mean(advance)),
    }


scene = make_scene()
