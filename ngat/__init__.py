"""ngat: adaptive finite elements for Ambrosio–Tortorelli brittle fracture on NGSolve.

The package follows *Adaptive finite element approximation of the Francfort–Marigo model of
brittle fracture* (Burke, Ortner, Süli): P1 elements with mass lumping, alternating minimisation,
the CRTOL crack set and residual estimators driving refinement; ``docs/design.md`` holds the
design notes the code relies on.

In Python, ``result = ngat.run("two-slits", out="results/x", eps=0.025)`` runs a scene as
``ngat run`` does and returns its :class:`RunResult`; ``ngat.load_results(folder)`` reads a
results folder back into one. (``ngat.run`` is :func:`ngat.experiment.run`; the load-history
loop it calls is :func:`ngat.driver.run`.)
"""

__version__ = "0.1.0"

from ngat.experiment import run
from ngat.results import RunResult, load_results

__all__ = ["run", "load_results", "RunResult", "__version__"]
