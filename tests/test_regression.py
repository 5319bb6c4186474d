"""End-to-end regression: the quick two-slits run against stored values.

Stored from ``ngat run two-slits --quick`` (commit of the adaptivity issue). Energies are
deterministic up to round-off on a fixed mesh sequence; the tolerances (0.1 % in energy, 5 % in
elements) allow a different BLAS but catch a change of the model, the estimators or the marking.
"""

import numpy as np
import pytest

STORED = {
    # t: (bulk, surface, total, elements)
    0.5: (0.7067190169183803, 0.005363996245071561, 0.7120830131634519, 2007),
    1.0: (2.6748129915818915, 0.09598745078753881, 2.7708004423694303, 6439),
    1.3: (4.145692858784631, 0.4059870173485212, 4.551679876133153, 12563),
}
FRACTURE_TIME = 1.45
FINAL_ELEMENTS = 31653


@pytest.mark.parametrize("t", sorted(STORED))
def test_energies_and_elements_match_stored_values(quick_run, t):
    result, _, _ = quick_run
    record = next(r for r in result.records if np.isclose(r["t"], t))
    bulk, surface, total, elements = STORED[t]
    np.testing.assert_allclose(
        [record["bulk"], record["surface"], record["total"]], [bulk, surface, total], rtol=1e-3
    )
    assert abs(record["elements"] - elements) <= 0.05 * elements


def test_fracture_time_and_final_mesh(quick_run):
    result, _, _ = quick_run
    assert result.summary["fracture_time"] == pytest.approx(FRACTURE_TIME)
    assert abs(result.records[-1]["elements"] - FINAL_ELEMENTS) <= 0.05 * FINAL_ELEMENTS
