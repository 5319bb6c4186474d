"""ngat: adaptive finite elements for Ambrosio–Tortorelli brittle fracture on NGSolve.

The package follows *Adaptive finite element approximation of the Francfort–Marigo model of
brittle fracture* (Burke, Ortner, Süli): P1 elements with mass lumping, alternating minimisation,
the CRTOL crack set and residual estimators driving refinement; ``docs/design.md`` holds the
design notes the code relies on.
"""

__version__ = "0.1.0"
