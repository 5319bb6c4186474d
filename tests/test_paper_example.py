"""The full paper example (slow: about two minutes; ``pytest -m slow``).

Checks of issue 4: fracture time in [1.38, 1.50], both cracks grow from the slit tips towards the
centre and join, final elements in [3e4, 2.5e5], smallest diameter in [5e−4, 2e−3], largest ≥ 0.2.
"""

import numpy as np
import pytest

from ngat.driver import run
from ngat.scene import load_scene


@pytest.mark.slow
def test_full_paper_example(tmp_path):
    scene = load_scene("two-slits")
    parameters, times = scene.configure()
    result = run(scene, parameters, times, tmp_path / "two-slits")
    records, summary = result.records, result.summary
    assert 1.38 <= summary["fracture_time"] <= 1.50
    last = records[-1]
    assert 3e4 <= last["elements"] <= 2.5e5
    assert 5e-4 <= min(r["h_min"] for r in records) <= 2e-3
    assert last["h_max"] >= 0.2
    # Both cracks leave their slit tips towards the centre (3, 3) before the body breaks.
    before = [r for r in records if r["t"] < summary["fracture_time"]][-1]
    centre = np.array([3.0, 3.0])
    for i, tip in ((1, (2.0, 2.0)), (2, (4.0, 4.0))):
        grown = np.array([before[f"tip{i}_x"], before[f"tip{i}_y"]])
        assert np.linalg.norm(grown - centre) < np.linalg.norm(np.array(tip) - centre)
    # After the break the cracked set joins the two slits through the centre.
    state = result.state
    cracked = state.arrays.coords[state.v_values < 0.1]
    assert np.min(np.linalg.norm(cracked - centre, axis=1)) < 0.3
