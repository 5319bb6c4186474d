"""Laplace's equation on the unit square with a smooth harmonic solution (estimator rates).

Ω = (0, 1)²; Ω_D is the two strips (0, 0.1) × (0, 1) ("left") and (0.9, 1) × (0, 1) ("right"),
where u = t · cos(πy) cosh(π(x − 1/2)) / cosh(π/2); the edges y = 0 and y = 1 are Neumann
edges. That function is harmonic with ∂_y u = 0 on y = 0, 1, so with v ≡ 1 (and any η) it is
the exact solution of the u-step: P1 converges at h in the energy norm and μ decays like h.
"""

import math

from ngsolve import CF, cos, cosh, pi, sin, sinh, x, y

from ngat.geometry import glue, rectangle
from ngat.scene import Scene

SCALE = 1 / math.cosh(math.pi / 2)


def geometry():
    """Return the body glued to the two loaded strips."""
    return glue(
        [
            rectangle(0, 0, 0.1, 1, "left"),
            rectangle(0.1, 0, 0.9, 1, "body"),
            rectangle(0.9, 0, 1, 1, "right"),
        ]
    )


def exact_solution():
    """Return cos(πy) cosh(π(x − 1/2)) / cosh(π/2) as a CoefficientFunction."""
    return SCALE * cos(pi * y) * cosh(pi * (x - 0.5))


def exact_gradient():
    """Return the gradient of :func:`exact_solution` as a vector CoefficientFunction."""
    s = pi * (x - 0.5)
    return SCALE * pi * CF((cos(pi * y) * sinh(s), -sin(pi * y) * cosh(s)))


scene = Scene(
    name="smooth-laplace",
    description="Laplace on a square with a smooth harmonic solution (estimator rates)",
    geometry=geometry,
    loads={"left": lambda t: t * exact_solution(), "right": lambda t: t * exact_solution()},
    times=[1.0],
    parameters={"maxh": 0.2},
)
