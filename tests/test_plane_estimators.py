"""μ of plane elasticity on a mode-I slit: rates under uniform and μ-driven refinement.

The small variant of ``scripts/plane_estimator_rates.py``: Williams' mode-I field as Dirichlet
data, v ≡ 1. Uniform refinement converges at ndof^{−1/4} (the r^{1/2} singularity), Dörfler
marking on μ at ndof^{−1/2}; μ must follow the true energy-norm error (bounded effectivity).
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "plane_estimator_rates.py"


@pytest.fixture(scope="module")
def rates_script():
    spec = importlib.util.spec_from_file_location("plane_estimator_rates", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    "marking, expected, max_dofs", [("uniform", -0.25, 3e4), ("adaptive", -0.5, 2e4)]
)
def test_mu_converges_at_the_expected_rate(rates_script, marking, expected, max_dofs):
    rows = rates_script.sequence(marking, max_dofs)
    skip = len(rows) // 3
    assert rates_script.rate(rows, "mu", skip) == pytest.approx(expected, abs=0.1)
    assert rates_script.rate(rows, "error", skip) == pytest.approx(expected, abs=0.1)
    effectivity = np.array([r["effectivity"] for r in rows])
    assert effectivity.max() / effectivity.min() < 2.0
    assert 0.5 < effectivity.min()
