"""ngat: adaptive finite elements for Ambrosio–Tortorelli brittle fracture on NGSolve.

The package follows the paper in ``shared/paper/adaptive-at-fracture.md``: P1 elements with mass
lumping, alternating minimisation, the CRTOL crack set and residual estimators driving refinement.
"""

__version__ = "0.1.0"
