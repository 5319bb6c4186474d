"""Single-edge notched shear (SENS) in plane strain with the volumetric–deviatoric split.

C. Miehe, M. Hofacker, F. Welschinger, *A phase field model for rate-independent crack
propagation: robust algorithmic implementation based on operator splits*, CMAME 199 (2010): the
plate, notch and material of ``sent`` (the unit square in mm, a notch from the middle of the
left edge to the centre; λ = 121.15 and μ = 80.77 kN/mm², G_c = 2.7e−3 kN/mm, ε = ℓ/2), sheared:
the bottom edge is held (u = 0) and the top edge moved sideways, u = (t, 0). The left and right
edges are free (some reproductions also hold u_y there).

Under shear half of the plate is compressed; without a split the compressed side would crack
as well. ``split=voldev`` (Amor et al. 2009, :mod:`ngat.elasticity`) degrades only the
deviatoric and the tensile volumetric energy, and the crack curves from the notch tip down
towards the lower right corner. ``--set split=spectral`` runs it with Miehe's own split of
the tensile principal strains, which keeps the energy of the compressive one: a higher peak and
a crack that grows stably. ``force_top_x`` (kN per mm of thickness) against t is the
benchmark's curve; the published peak is about 0.5 kN at ℓ = 0.0075 mm
(docs/plane-elasticity.md compares).
"""

from __future__ import annotations

import numpy as np
from ngsolve import CF

from ngat.geometries import sent
from ngat.scene import Scene

TIMES = np.round(np.concatenate([np.arange(0, 81, 10), np.arange(85, 201, 5)]) * 1e-4, 12)
"""Load times: 1e−3 mm steps to 0.008 mm, then 5e−4 mm steps to 0.02 mm (the crack grows
stably under shear, so the steps stay small past the peak)."""

scene = Scene(
    name="sens",
    description="single-edge notched shear, plane strain, volumetric-deviatoric split (Miehe 2010)",
    geometry=sent.geometry,
    loads={"bottom": lambda t: CF((0, 0)), "top": lambda t: CF((t, 0))},
    times=TIMES,
    slits=sent.SLITS,
    # Not the crack extension: SENS's crack curves, and straight jumps flatten its path.
    parameters={**sent.scene.parameters, "split": "voldev", "crack_extension": False},
    quick=sent.scene.quick,
)
