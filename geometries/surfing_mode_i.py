"""Mode-I surfing in plane strain: a translating K_I crack-tip field drives the crack.

The strip, frame Ω_D and pre-crack of ``surfing`` (Ω = (0, 2) × (−0.7, 0.7), the slit
[0, 0.6] × {0} cutting through the frame of thickness 0.1), meshed unstructured by Netgen, with
the plane-strain model (E = 1, ν = 0.3, G_c = 1) and, on Ω_D, Williams' mode-I field about the
imposed tip (a₀ + V t, 0):

    u = K/(2μ) sqrt(r/(2π)) (cos(θ/2) (κ − cos θ), sin(θ/2) (κ − cos θ)),   κ = 3 − 4ν,

θ ∈ (−π, π], whose branch cut lies on the slit (traction free on both faces). Its energy
release rate is G = K² (1 − ν²)/E; the scene is driven by A = sqrt(G) (so that, as in
``surfing``, the crack grows once A² reaches the effective toughness G_eff of the crack band),
A(t) = A · min(1, t/ramp).

``make_scene(precrack=True)`` also holds v = 0 on the slit's faces (the scene's ``crack``): a
phase-field pre-crack on top of the geometric one, whose tip profile is formed before the load
comes. From the bare slit the mode-I crack needs A² ≈ 1.2 G_eff to form its tip, because W is
largest off the crack line there (``docs/plane-elasticity.md``).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from ngsolve import CF, IfPos, Parameter, atan2, cos, pi, sin, sqrt, x, y

from ngat.elasticity import lame
from ngat.geometries.surfing import (
    AMPLITUDE,
    CRACK_LENGTH,
    EPS,
    RAMP,
    SLITS,
    SPEED,
    TIMES,
    geometry,
)
from ngat.scene import Scene

YOUNG = 1.0
"""E of the scene."""
POISSON = 0.3
"""ν of the scene."""
# ε, A = sqrt(G), V, the ramp and the load times are those of ``surfing``.


def stress_intensity(amplitude, young: float = YOUNG, poisson: float = POISSON):
    """Return K_I = A sqrt(E/(1 − ν²)), the K of the energy release rate G = A² (plane strain)."""
    return amplitude * math.sqrt(young / (1 - poisson**2))


def tip_field(amplitude, tip_x, young: float = YOUNG, poisson: float = POISSON):
    """Return Williams' plane-strain mode-I displacement with G = A² about (tip_x, 0).

    Parameters
    ----------
    amplitude
        A = sqrt(G): a number or a CoefficientFunction (of the load parameter).
    tip_x
        x of the tip: a number or a CoefficientFunction.
    young, poisson
        E and ν.
    """
    _, mu = lame(young, poisson)
    kappa = 3 - 4 * poisson
    dx = x - tip_x
    r = sqrt(dx * dx + y * y)
    theta = atan2(y, dx)
    scale = stress_intensity(1.0, young, poisson) * amplitude / (2 * mu) * sqrt(r / (2 * pi))
    return CF(
        (
            scale * cos(theta / 2) * (kappa - cos(theta)),
            scale * sin(theta / 2) * (kappa - cos(theta)),
        )
    )


def on_slit(coords: np.ndarray, length: float = CRACK_LENGTH) -> np.ndarray:
    """Return the vertices on the last ``length`` of the slit's faces, [a₀ − length, a₀] × {0}.

    The default ``length`` a₀ is the whole slit (its tip included).
    """
    on_line = (np.abs(coords[:, 1]) < 1e-12) & (coords[:, 0] <= CRACK_LENGTH + 1e-12)
    return on_line & (coords[:, 0] >= CRACK_LENGTH - length - 1e-12)


def _pre_crack(precrack: bool | float):
    """Return the scene's crack function for ``precrack`` (:func:`make_scene`), or None."""
    if precrack is True:
        return on_slit
    if precrack:
        return functools.partial(on_slit, length=float(precrack))
    return None


def make_scene(
    amplitude: float = AMPLITUDE,
    speed: float = SPEED,
    ramp: float = RAMP,
    eps: float = EPS,
    times=TIMES,
    tip_start: float = CRACK_LENGTH,
    name: str = "surfing-mode-i",
    precrack: bool | float = False,
) -> Scene:
    """Return a mode-I surfing scene (see the module docstring for the parameters).

    Parameters
    ----------
    amplitude
        A = sqrt(G).
    speed
        V, speed of the imposed tip; 0 keeps it where it starts.
    ramp
        A(t) = A · min(1, t / ramp); 0: the full amplitude from the start.
    eps
        ε.
    times
        Load times.
    tip_start
        x of the imposed tip at t = 0 (default a₀).
    name
        Scene name.
    precrack
        ``True``: hold v = 0 on the slit's faces, [0, a₀] × {0} (:func:`on_slit`); a length ℓ:
        on its last ℓ only, [a₀ − ℓ, a₀] × {0} (the crack band then follows the tip alone, not
        the whole slit: at R/ε = 1000 a pre-crack over the slit's 1000ε would be resolved to
        ε/4 everywhere along it).
    """

    def load(t: Parameter):
        scale = IfPos(t - ramp, 1.0, t / ramp) if ramp > 0 else 1.0
        return tip_field(amplitude * scale, tip_start + speed * t)

    return Scene(
        name=name,
        description="mode-I surfing in plane strain: a translating K_I field drives the crack",
        geometry=geometry,
        loads={"frame": load},
        times=times,
        slits=SLITS,
        crack=_pre_crack(precrack),
        parameters={
            "model": "plane_strain",
            "young": YOUNG,
            "poisson": POISSON,
            "eps": eps,
            "maxh": 0.1,
        },
        quick={"times": TIMES[::4], "tol_rel": 0.3},
    )


scene = make_scene()
