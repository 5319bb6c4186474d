"""SENS with the side edges held in y and Miehe's spectral split: the published peak force.

The plate, notch, material, shear load and length scale of ``sens`` (Miehe, Hofacker,
Welschinger, CMAME 199 (2010)), with u_y = 0 on the left and right edges (u_x free there), as
several reproductions of the benchmark hold them, and ``split=spectral``, the split of that
paper. Measured (docs/plane-elasticity.md): the force reaches 0.50 kN at ℓ = 0.0075 mm before
the crack starts, the published peak, against 0.38 kN for ``sens`` (free sides,
volumetric–deviatoric split).
"""

from __future__ import annotations

import dataclasses

from netgen.occ import X

from ngat.geometries import sens, sent


def geometry():
    """Return ``sent``'s notched square with its ``left`` and ``right`` edges named as well."""
    square = sent.geometry()
    square.edges.Max(X).name = "right"
    for edge in square.edges:
        if abs(edge.center.x) < 1e-12:  # both parts of the left edge, above and below the notch
            edge.name = "left"
    return square


scene = dataclasses.replace(
    sens.scene,
    name="sens-held",
    description="single-edge notched shear, sides held in y, spectral split (Miehe 2010)",
    geometry=geometry,
    loads={**sens.scene.loads, "left": lambda t: {"y": 0.0}, "right": lambda t: {"y": 0.0}},
    parameters={**sens.scene.parameters, "split": "spectral"},
)
