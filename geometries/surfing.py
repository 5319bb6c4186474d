"""Mode-III surfing: a crack driven through a strip by a translating crack-tip field (Griffith).

Ω = (0, L) × (−H/2, H/2) with the pre-crack [0, a₀] × {0}, a true slit that cuts through the
frame Ω_D of thickness d along the outer boundary (DESIGN.md, scene 2). On Ω_D

    u = U(x, y, t) = A(t) · sqrt(2r/π) · sin(θ/2),   (r, θ) polar about (a₀ + V t, 0),

θ ∈ (−π, π]; the branch cut θ = ±π lies on y = 0 behind the imposed tip, so on the frame it
coincides with the slit. For the energy density |∇u|² this field has the energy release rate
G = A². A(t) = A · min(1, t / ramp): the amplitude is ramped in, then held.

Griffith's theory for the discrete AT functional: the crack grows when G reaches the effective
toughness of the mesh, G_eff(h) = 1 + h/(4ε) + (h/ε)²/32 (:func:`effective_toughness`), where h
is the spacing of the node lines parallel to the crack (u jumps across a band one element wide
whose nodes all have v = 0). The default mesh is therefore structured along the crack path: a
band |y| ≤ w around y = 0, from a little behind a₀ to the end of the imposed tip's path, is
cut into squares of side ``h_band`` (each split by one diagonal, so the node lines y = jh are
straight and the triangles right-angled, Hypothesis A), and the mesh is graded to ``maxh``
away from the band. With ``h_band=None`` the whole strip is cut into squares of side ``maxh``
(a uniform mesh; the dimensions are multiples of 0.1, so h ∈ {0.1, 0.05, 0.025, 0.0125} fit
exactly). ``structured=False`` meshes the OCC geometry instead (unstructured triangles).

Sizes: L = 2, H = 1.4, d = 0.1, a₀ = 0.6, so the tip is R = 0.6 from the frame and
ε/R = 1/60 for ε = 0.01 (AT2 damages the whole body a little, which shifts the load at which
the crack moves by a relative amount of order ε/R; DESIGN.md). The default run: h = ε/2,
A² = 1.2 G_eff(h), V = 0.4, t ∈ [0, 1.5] with the amplitude ramped in over t ∈ [0, 0.25]; the
imposed tip travels from a₀ = 0.6 to 1.2 and the crack tip runs ahead of it by a fixed lag.
"""

from __future__ import annotations

import math

import netgen.meshing as ngm
import numpy as np
from ngsolve import IfPos, Mesh, Parameter, atan2, pi, sin, sqrt, x, y

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
"""Side of the squares along the crack path (h/ε = 1/2)."""
BAND_HALF_WIDTH = 0.06
"""w: half width of the structured band around y = 0 (6ε: the profile has decayed to e^-3)."""
SPEED = 0.4
"""V: speed of the imposed tip."""
RAMP = 0.25
"""Time over which the amplitude is ramped in."""
OVERLOAD = 1.2
"""A² / G_eff(h) of the default run."""
TIMES = np.round(0.025 * np.arange(61), 10)
"""Load times of the default run: t ∈ [0, 1.5], V Δt = 2 h."""

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
    band_end: float = 1.5,
    half_width: float = BAND_HALF_WIDTH,
    grading: float = 0.3,
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

    Returns
    -------
    ngsolve.Mesh
        Materials ``frame`` (Ω_D) and ``body``; boundaries ``outer`` and ``slit``. Each node of
        the pre-crack [0, a₀) × {0}, mouth included, has a twin for the upper face.
    """
    half, d, a0 = HEIGHT / 2, FRAME, CRACK_LENGTH
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
    h_band: float | None = H_BAND,
    times=TIMES,
    structured: bool = True,
    band_end: float = 1.5,
    half_width: float = BAND_HALF_WIDTH,
    name: str = "surfing",
) -> Scene:
    """Return a surfing scene.

    Parameters
    ----------
    amplitude
        A; default sqrt(1.2 G_eff(h_band)) (``h_band=None``: of h = ε/2).
    speed
        V, speed of the imposed tip; 0 keeps it at the pre-crack's tip.
    ramp
        A(t) = A · min(1, t / ramp); 0: the full amplitude from the start.
    eps
        ε.
    h_band
        Cell side along the crack path; ``None``: uniform mesh of the run's ``maxh``.
    times
        Load times.
    structured
        Tensor-product mesh (:func:`structured_mesh`); ``False``: Netgen meshes the OCC geometry.
    band_end, half_width
        Extent of the structured band (see :func:`structured_mesh`).
    name
        Scene name.
    """
    if amplitude is None:
        amplitude = math.sqrt(OVERLOAD * effective_toughness(h_band or eps / 2, eps))

    def load(t: Parameter):
        scale = IfPos(t - ramp, 1.0, t / ramp) if ramp > 0 else 1.0
        return tip_field(amplitude * scale, CRACK_LENGTH + speed * t)

    def mesh(maxh: float) -> Mesh:
        return structured_mesh(maxh, h_band, band_end, half_width)

    return Scene(
        name=name,
        description="mode-III surfing: a translating crack-tip field drives the crack (Griffith)",
        geometry=geometry,
        mesh=mesh if structured else None,
        loads={"frame": load},
        times=times,
        slits=SLITS,
        parameters={"eps": eps, "maxh": 0.1, "adapt": "fixed"},
        quick={"times": np.round(0.1 * np.arange(16), 10), "maxh": 0.2},
    )


scene = make_scene()
