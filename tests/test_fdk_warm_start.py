"""The FDK warm start (openfdk.fdk.warm_start): the predictor's order, chosen by how
linear and quadratic extrapolation predicted the last converged frame."""

import numpy as np
import pytest

from openfdk.fdk.warm_start import CLEARLY_BETTER, HISTORY, extrapolated

SCALE = np.array([0.05, 0.001, 0.05])  # max_step: rad, m, rad


def _history(values, first=0):
    return [(first + j, np.asarray(v, dtype=float)) for j, v in enumerate(values)]


def test_a_parabola_is_continued_exactly_and_a_line_would_miss_it():
    a, b, c = np.array([0.1, 0.002, -0.3]), np.array([0.01, -1e-4, 0.02]), np.array([-0.004, 3e-5, 0.001])
    alpha = [a + b * j + c * j * j for j in range(10)]
    k = 8
    got = extrapolated(_history(alpha[k - HISTORY:k], k - HISTORY), k, SCALE)
    np.testing.assert_allclose(got, alpha[k], rtol=0, atol=1e-14)
    linear = 2 * alpha[k - 1] - alpha[k - 2]
    np.testing.assert_allclose(alpha[k] - linear, 2 * c, rtol=1e-9)  # the line's miss, 2c per frame², non-zero


def test_after_a_kink_the_line_is_kept():
    # flat up to frame 1, then rising: the line through frames 1, 2 misses frame 3 by 0.1,
    # the parabola through frames 0–2 by 0.9 (× 0.01 rad)
    values = np.array([[0.0], [0.0], [1.0], [2.1]]) * 0.01
    got = extrapolated(_history(values), 4, SCALE[:1])
    np.testing.assert_allclose(got, [0.032], rtol=0, atol=1e-15)  # the line through frames 2, 3
    parabola = 3 * values[3] - 3 * values[2] + values[1]
    assert abs(parabola[0] - 0.032) > 0.0009


def test_the_order_is_chosen_in_max_step_units():
    # DOF 0 (m, max_step 1 mm): a parabola, the line misses α_{k−1} by 2 mm = 2 max_steps;
    # DOF 1 (rad, max_step 0.05): a kink at frame 1, the parabola misses α_{k−1} by
    # 0.01 rad = 0.2 max_steps. In SI numbers the line's miss (0.002) is the smaller; in max_steps the
    # parabola's (0.2 < 2): the parabola is used.
    m = [0.001 * j * j for j in range(4)]
    rad = [0.01, 0.0, 0.0, 0.0]
    hist = _history(np.column_stack([m, rad]))
    lin_miss = np.abs(2 * hist[2][1] - hist[1][1] - hist[3][1])
    quad_miss = np.abs(3 * hist[2][1] - 3 * hist[1][1] + hist[0][1] - hist[3][1])
    assert lin_miss.max() < quad_miss.max()  # SI numbers would pick the line
    assert (lin_miss / SCALE[1::-1]).max() > (quad_miss / SCALE[1::-1]).max()
    got = extrapolated(hist, 4, SCALE[1::-1])
    expected = 3 * hist[3][1] - 3 * hist[2][1] + hist[1][1]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)
    assert not np.allclose(expected, 2 * hist[3][1] - hist[2][1])


@pytest.mark.parametrize("frames, expected", [
    ([5, 6], "linear"),            # two converged predecessors
    ([4, 5, 6], "linear"),         # three: no frame to judge the parabola by
    ([1, 2, 4, 5, 6], "linear"),   # frame 3 failed: the run before k is three long
    ([2, 3, 4, 5, 6], "choice"),   # four and more: the parabola here (a parabola's data)
    ([6], None),                   # one: no extrapolation (the caller starts from α_{k−1})
    ([3, 4, 5], None),             # frame 6 failed: none
])
def test_only_consecutive_frames_before_k_are_extrapolated(frames, expected):
    k = 7
    alpha = {j: np.array([0.001 * j * j]) for j in range(10)}
    got = extrapolated([(j, alpha[j]) for j in frames], k, SCALE[:1])
    if expected is None:
        assert got is None
    elif expected == "linear":
        np.testing.assert_allclose(got, 2 * alpha[6] - alpha[5], atol=1e-15)
        assert not np.allclose(got, alpha[k])
    else:
        np.testing.assert_allclose(got, alpha[k], atol=1e-15)


@pytest.mark.parametrize("alpha0, expected", [(0.3, 2.0), (0.6, 3.0)])
def test_the_parabola_must_be_clearly_better(alpha0, expected):
    # α1 = α2 = 0, α3 = 1: the line missed α3 by 1; the parabola through α0..α2 by
    # |α0 − 1|: 0.7 (not at most half: the line, 2 α3 − α2 = 2) or 0.4 (the parabola,
    # 3 α3 − 3 α2 + α1 = 3)
    got = extrapolated(_history([[alpha0], [0.0], [0.0], [1.0]]), 4, [1.0])
    assert CLEARLY_BETTER == 0.5
    np.testing.assert_allclose(got, [expected], rtol=0, atol=1e-15)
