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


@pytest.mark.parametrize("case, f0, f, f_linear, f_model, expected", [
    # a large step where the contacts bent the model and g predicted f: it pays
    ("g right", [150.0, 0.0], [0.3, 0.0], [10.3, 0.0], [0.4, 0.0], True),
    # the same step, g no better than the linear model: it sleeps
    ("g wrong", [150.0, 0.0], [14.0, 0.0], [0.0, 0.0], [-3.0, 0.0], False),
    # near the root both miss by J's error (0.4 % of |f0|): no measure
    ("near root", [0.3, 0.0], [0.001, 0.0], [0.0, 0.0], [0.0005, 0.0], None),
    # a large miss the contacts had no part in (g = the linear model): no measure
    ("no signal", [150.0, 0.0], [14.0, 0.0], [0.0, 0.0], [0.0, 1.0], None),
    # below GAIN_FLOOR tolerances: no measure
    ("floor", [1e-3, 0.0], [5e-5, 0.0], [0.0, 0.0], [5e-5, 0.0], None),
])
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


def test_the_thresholds_of_the_cases_above():
    """The cases above sit on the side of each threshold they are meant to (so that the
    test fails if a threshold moves past them rather than passing by accident)."""
    assert 10.0 > max(GAIN_FLOOR * TOL, GAIN_RELATIVE * 150.0) and 9.9 > GAIN_SIGNAL * 10.0  # "g right"
    assert 14.0 > max(GAIN_FLOOR * TOL, GAIN_RELATIVE * 150.0) and 3.0 > GAIN_SIGNAL * 14.0  # "g wrong"
    # g's miss 0.1 of 10 pays from the prior, 17 of 14 (capped at 1) does not
    assert (1 - GAIN_WEIGHT) * GAIN_PRIOR + GAIN_WEIGHT * 0.01 < GAIN_LIMIT < (1 - GAIN_WEIGHT) * GAIN_PRIOR + GAIN_WEIGHT
    assert 0.001 < GAIN_RELATIVE * 0.3  # "near root"
    assert 1.0 < GAIN_SIGNAL * 14.0  # "no signal"
    assert 5e-5 < GAIN_FLOOR * TOL  # "floor"


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
