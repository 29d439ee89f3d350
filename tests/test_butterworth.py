"""openfdk.io.butterworth: the zero-lag Butterworth low-pass of the marker pipeline,
against its closed-form gain, physical invariants (DC, zero phase) and scipy.signal (an
independent implementation of the same filter)."""

import numpy as np
import pytest
import scipy.signal as ss

from openfdk.io.butterworth import butter_lowpass_sos, filtfilt_padlen, sosfiltfilt


def _response(sos, f, rate):
    """H(e^{iω}) of the cascade at frequencies f (Hz), evaluated from the coefficients."""
    z1 = np.exp(-2j * np.pi * np.asarray(f) / rate)                  # z⁻¹
    h = np.ones_like(z1)
    for b0, b1, b2, a0, a1, a2 in sos:
        h *= (b0 + b1 * z1 + b2 * z1**2) / (a0 + a1 * z1 + a2 * z1**2)
    return h


@pytest.mark.parametrize("order", [1, 2, 3, 4, 7])
@pytest.mark.parametrize("cutoff, rate", [(6.0, 100.0), (15.0, 250.0), (40.0, 100.0)])
def test_gain_is_the_closed_form_butterworth_magnitude(order, cutoff, rate):
    sos = butter_lowpass_sos(order, cutoff, rate)
    assert sos.shape == (-(-order // 2), 6)
    f = np.linspace(0.0, 0.499 * rate, 200)
    gain2 = np.abs(_response(sos, f, rate)) ** 2
    closed = 1.0 / (1.0 + (np.tan(np.pi * f / rate) / np.tan(np.pi * cutoff / rate)) ** (2 * order))
    np.testing.assert_allclose(gain2, closed, rtol=1e-10, atol=1e-13)
    assert abs(_response(sos, [cutoff], rate)[0]) ** 2 == pytest.approx(0.5, rel=1e-12)   # half power at f_c
    poles = np.concatenate([np.roots(row[3:]) for row in sos])
    assert np.all(np.abs(poles) < 1.0)                                                 # stable


def test_constant_passes_exactly_and_a_sinusoid_keeps_its_phase():
    rate, cutoff = 100.0, 6.0
    sos = butter_lowpass_sos(2, cutoff, rate)
    const = np.full((50, 3), [0.1, -2.0, 3.5])
    np.testing.assert_allclose(sosfiltfilt(sos, const), const, rtol=0, atol=1e-14)
    t = np.arange(2000) / rate
    f = 4.0
    x = np.sin(2 * np.pi * f * t)
    y = sosfiltfilt(sos, x)
    gain2 = abs(_response(sos, [f], rate)[0]) ** 2                    # forward and backward pass
    assert 0.5 < gain2 < 0.9                                          # attenuated, not removed
    middle = slice(200, -200)                                         # past the end transients
    np.testing.assert_allclose(y[middle], gain2 * x[middle], atol=1e-9)  # same phase: no lag


@pytest.mark.parametrize("order", [1, 2, 3, 6])
def test_same_as_scipy_sosfiltfilt(order):
    rng = np.random.default_rng(order)
    rate, cutoff = 200.0, 12.0
    x = rng.normal(size=(300, 3)).cumsum(axis=0)
    ours = butter_lowpass_sos(order, cutoff, rate)
    theirs = ss.butter(order, cutoff, fs=rate, output="sos")
    y = sosfiltfilt(ours, x)
    np.testing.assert_allclose(y, ss.sosfiltfilt(theirs, x, axis=0), rtol=0, atol=1e-12 * np.abs(x).max())
    np.testing.assert_allclose(sosfiltfilt(ours, x[:, 1]), y[:, 1], rtol=0, atol=1e-15)   # 1-D input
    assert filtfilt_padlen(ours) == 3 * (2 * len(ours) + 1 - order % 2)                     # scipy's default
    assert np.abs(y - x).max() > 0.01                                                       # it filtered


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="order"):
        butter_lowpass_sos(0, 6.0, 100.0)
    with pytest.raises(ValueError, match="cutoff"):
        butter_lowpass_sos(2, 50.0, 100.0)
    sos = butter_lowpass_sos(2, 6.0, 100.0)
    with pytest.raises(ValueError, match="more than 9 samples"):
        sosfiltfilt(sos, np.zeros(9))
