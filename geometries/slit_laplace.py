"""Laplace's equation on a slit square: the singular function r^{1/2} sin(θ/2).

Ω = (−1, 1)² with the slit [−1, 0] × {0}; Ω_D is the frame of width 0.1 along the outer
boundary (cut by the slit), where u = t · r^{1/2} sin(θ/2), θ ∈ (−π, π]. With v ≡ 1 the
u-step is a Laplace problem whose solution is that singular function: uniform refinement
converges at ndof^(−1/4) in the energy norm, refinement driven by μ at ndof^(−1/2).
"""

from ngsolve import atan2, sin, sqrt, x, y

from ngat.geometry import glue, polygon_face
from ngat.scene import Scene

FRAME = 0.9


def geometry():
    """Return the slit square: the inner body glued to the frame Ω_D, both cut by the slit."""
    f = FRAME
    frame = polygon_face(
        [
            (-f, 0),
            (-1, 0),
            (-1, -1),
            (1, -1),
            (1, 1),
            (-1, 1),
            (-1, 0),
            (-f, 0),
            (-f, f),
            (f, f),
            (f, -f),
            (-f, -f),
        ],
        "frame",
    )
    body = polygon_face([(-f, 0), (0, 0), (-f, 0), (-f, -f), (f, -f), (f, f), (-f, f)], "body")
    return glue([frame, body])


def singular_function():
    """Return r^{1/2} sin(θ/2) as a CoefficientFunction."""
    return sqrt(sqrt(x * x + y * y)) * sin(atan2(y, x) / 2)


scene = Scene(
    name="slit-laplace",
    description="Laplace on a slit square with u = r^(1/2) sin(θ/2) on the frame (estimators)",
    geometry=geometry,
    loads={"frame": lambda t: t * singular_function()},
    times=[1.0],
    parameters={"maxh": 0.2},
)
