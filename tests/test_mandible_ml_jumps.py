"""Frame-to-frame jumps of the FDK medio-lateral DOF (openfdk.mandible.ml_jumps) on
series whose jumps are known by construction."""

import numpy as np

from openfdk.mandible.ml_jumps import ml_jumps


def test_jumps_of_a_known_series():
    """A ramp of 0.1 mm per frame with a 3 mm drop after frame 20 and a 0.8 mm rise
    after frame 40 (one NaN frame, unsolved, between 60 and 62): the largest jump is
    3 mm − 0.1 mm = 2.9 mm into frame 21, two jumps exceed 0.5 mm (largest first), and
    the NaN neighbours count as no jump."""
    time = np.arange(80) * 0.01
    alpha = 1e-4 * np.arange(80)
    alpha[21:] -= 3e-3
    alpha[41:] += 0.8e-3
    alpha[61] = np.nan
    out = ml_jumps(time, alpha)
    assert out["max_mm"] == 2.9 and out["at_s"] == 0.21
    assert out["count"] == 2 and out["frames"] == [21, 41]
    assert np.isclose(out["threshold_mm"], 0.5)


def test_no_solved_frames():
    out = ml_jumps(np.arange(3) * 0.01, np.full(3, np.nan))
    assert out["max_mm"] is None and out["count"] == 0 and out["frames"] == []
