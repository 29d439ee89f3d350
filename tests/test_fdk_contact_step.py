"""The rule that puts the contacts-exact step to sleep where it does not pay
(openfdk.fdk.contact_step.ContactSplit.pays); the step itself is tested on the JAM knee
(tests/test_knee_jam_fdk.py) and the recruitment's sensitivity to d in test_recruitment."""

import numpy as np
import pytest

from openfdk.fdk.contact_step import (GAIN_FLOOR, GAIN_LIMIT, GAIN_PRIOR, GAIN_RELATIVE, GAIN_SIGNAL, GAIN_WEIGHT,
                                      SLEEP_FRAMES, ContactSplit)

TOL = 1e-3


def _split():
    return ContactSplit(np.zeros((6, 2)), np.zeros((2, 6)), np.arange(6), np.array([[0, -1]]))


CASES = [
    # a large step where the contacts bent the model and g predicted f: it pays
    ("g right", [150.0, 0.0], [0.3, 0.0], [10.3, 0.0], [0.4, 0.0], True),
    # the same step, g no better than the linear model: it sleeps
    ("g wrong", [150.0, 0.0], [14.0, 0.0], [0.0, 0.0], [-3.0, 0.0], False),
    # near the root both miss by J's error (0.4 % of |f0|): no measure
    ("near root", [0.3, 0.0], [0.001, 0.0], [0.0, 0.0], [0.0005, 0.0], None),
    # a large miss the contacts had no part in (g = the linear model): no measure
    ("no signal", [150.0, 0.0], [14.0, 0.0], [0.0, 0.0], [0.0, 0.5], None),
    # below GAIN_FLOOR tolerances: no measure
    ("floor", [1e-3, 0.0], [5e-5, 0.0], [0.0, 0.0], [5e-5, 0.0], None),
]


@pytest.mark.parametrize("case, f0, f, f_linear, f_model, expected", CASES)
def test_the_split_sleeps_where_g_misses_as_the_linear_model_does(case, f0, f, f_linear, f_model, expected):
    split = _split()
    assert split.pays(*(np.array(x) for x in (f0, f, f_linear, f_model)), TOL) is expected, case
    assert split.sleep == (SLEEP_FRAMES if expected is False else 0)
    if expected is None:
        assert np.isnan(split.gain)
    else:
        ratio = min(np.linalg.norm(np.subtract(f, f_model)) / np.linalg.norm(np.subtract(f, f_linear)), 1.0)
        assert split.gain == pytest.approx((1 - GAIN_WEIGHT) * GAIN_PRIOR + GAIN_WEIGHT * ratio, rel=1e-14)
        assert (split.gain <= GAIN_LIMIT) is expected


@pytest.mark.parametrize("case, f0, f, f_linear, f_model, expected", CASES)
def test_each_case_is_decided_by_its_own_threshold_with_a_margin(case, f0, f, f_linear, f_model, expected):
    """Each case above sits at least 1.5 times away from the threshold that decides it
    (computed from its numbers as ContactSplit.pays does), so that it tests that threshold
    and moving the threshold a little fails it rather than passing it by accident."""
    f0, f, f_linear, f_model = (np.array(x) for x in (f0, f, f_linear, f_model))
    miss = np.linalg.norm(f - f_linear)
    floor = max(GAIN_FLOOR * TOL, GAIN_RELATIVE * np.linalg.norm(f0))
    signal = np.linalg.norm(f_model - f_linear) / (GAIN_SIGNAL * miss)
    if case in ("near root", "floor"):
        assert floor > 1.5 * miss  # below the floor
        return
    assert miss > 1.5 * floor
    if case == "no signal":
        assert signal < 1 / 1.5
        return
    assert signal > 1.5
    gain = (1 - GAIN_WEIGHT) * GAIN_PRIOR + GAIN_WEIGHT * min(np.linalg.norm(f - f_model) / miss, 1.0)
    # the gain's distance from the limit, against the widest the newest ratio can move it
    assert abs(gain - GAIN_LIMIT) > 0.05 and bool(gain <= GAIN_LIMIT) is expected


def test_one_step_that_does_not_pay_among_many_that_do_does_not_put_it_to_sleep():
    """The gain is a running mean, each ratio capped at 1, from GAIN_PRIOR: DM's trials have
    single ratios of 0.5–5 among ratios of 0.01–0.3; the bench's own knee has ratios of
    0.6–1.2 throughout, and its first one puts the split to sleep."""
    f0, f_linear = np.array([150.0, 0.0]), np.zeros(2)
    split = _split()
    for ratio in (0.1, 0.05, 2.2, 0.1):  # g's miss over the linear model's miss of 10 N
        assert split.pays(f0, np.array([10.0, 0.0]), f_linear, np.array([10.0 - 10.0 * ratio, 0.0]), TOL) is True
    assert split.sleep == 0
    mean = GAIN_PRIOR
    for ratio in (0.1, 0.05, 1.0, 0.1):  # (2.2 capped at 1)
        mean = (1 - GAIN_WEIGHT) * mean + GAIN_WEIGHT * ratio
    assert split.gain == pytest.approx(mean, rel=1e-12)
    knee = _split()
    assert knee.pays(f0, np.array([10.0, 0.0]), f_linear, np.array([19.7, 0.0]), TOL) is False  # ratio 0.97
    assert knee.sleep == SLEEP_FRAMES
