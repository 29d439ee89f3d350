"""Tests of openfdk.io.markers.MarkerTrajectories: interpolation accuracy against the
cubic-spline error bounds, the zero-lag Butterworth response against its closed form,
gap handling, and the model-order selection."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.io.c3d import MarkerTrial, MissingMarkerError, read_c3d, write_c3d
from openfdk.io.markers import MarkerTrajectories, visible_segments

# Analytic trajectory x = A sin(ωt + φ), y = A cos(ωt), z = B t³ − C t
A, OMEGA, PHASE = 0.05, 2 * np.pi * 1.3, 0.3


def analytic(t):
    """(p, v, a) of the analytic marker at times t: each (len(t), 3)."""
    s, c = np.sin(OMEGA * t + PHASE), np.cos(OMEGA * t)
    p = np.stack([A * s, A * c, 0.01 * t ** 3 - 0.02 * t], axis=-1)
    v = np.stack([A * OMEGA * np.cos(OMEGA * t + PHASE), -A * OMEGA * np.sin(OMEGA * t),
                  0.03 * t ** 2 - 0.02], axis=-1)
    a = np.stack([-A * OMEGA ** 2 * s, -A * OMEGA ** 2 * c, 0.06 * t], axis=-1)
    return p, v, a


def trial_from(t, p, labels=("M",), source="<test>"):
    """MarkerTrial from sample times t (n,) s and p (n, n_markers, 3) m."""
    rate = 1.0 / (t[1] - t[0])
    return MarkerTrial(labels=tuple(labels), rate=rate, time=t, positions=p, source=source)


def spline_errors(rate, duration=2.0):
    """Max |error| of p, v, a at off-sample times (τ = 0.37 h), interior and overall."""
    h = 1.0 / rate
    t = np.arange(round(duration * rate) + 1) * h
    p, _, _ = analytic(t)
    markers = MarkerTrajectories(trial_from(t, p[:, None, :]), cutoff_hz=None)
    t_query = t[:-1] + 0.37 * h
    errors = np.zeros((len(t_query), 3))
    for i, tq in enumerate(t_query):
        p_hat, v_hat, a_hat, visible = markers.evaluate(tq)
        assert visible[0]
        p_true, v_true, a_true = (x[0] for x in analytic(np.array([tq])))
        errors[i] = [np.abs(p_hat[0] - p_true).max(), np.abs(v_hat[0] - v_true).max(),
                     np.abs(a_hat[0] - a_true).max()]
    interior = errors[10:-10].max(axis=0)
    return interior, errors.max(axis=0)


def test_spline_reproduces_analytic_trajectory_within_error_bounds():
    """Hall & Meyer (1976) bounds for a cubic spline interpolant of f ∈ C⁴ with knot
    spacing h: |f − s| ≤ 5/384 h⁴ M₄, |f' − s'| ≤ 1/24 h³ M₄, |f'' − s''| ≤ 3/8 h² M₄,
    M₄ = max|f⁗| = A ω⁴ here (the cubic z axis has f⁗ = 0 and is reproduced exactly).
    They are proved for the complete (clamped) spline; away from the ends the
    not-a-knot spline's end effects have decayed (by ≈ 0.27 per knot), so the interior
    (10 samples in from each end) is held to them.  The not-a-knot end pieces have a
    larger error constant (≈ 2.2× here); they are held to the same orders of
    convergence, O(h⁴), O(h³), O(h²), by halving h, and to 4× the bounds."""
    rate = 100.0
    h = 1.0 / rate
    M4 = A * OMEGA ** 4
    bounds = np.array([5 / 384 * h ** 4 * M4, h ** 3 * M4 / 24, 3 / 8 * h ** 2 * M4])
    interior, overall = spline_errors(rate)
    assert np.all(interior <= bounds), (interior, bounds)
    assert np.all(overall <= 4 * bounds), (overall, bounds)
    assert overall[0] < 2e-6 * A                                # relative position error
    # convergence order: halving h divides the errors by ≈ 2⁴, 2³, 2²
    interior_fine, overall_fine = spline_errors(2 * rate)
    for coarse, fine in ((interior, interior_fine), (overall, overall_fine)):
        ratios = coarse / fine
        assert ratios[0] > 12 and ratios[1] > 6 and ratios[2] > 3, ratios


def test_velocity_and_acceleration_are_derivatives_of_position():
    """Central differences of the evaluated positions reproduce the evaluated velocity
    and acceleration.  Inside one cubic piece the central difference of p has error
    ε² p‴/6 (ε = 1e-6 → ≈ 1e-10 here) plus round-off ≈ 1e-16/ε; the second difference is
    exact for a cubic up to round-off ≈ 4e-16/ε² (ε = 1e-4 → 4e-8).  Query times are
    ≥ 1e-3 s from a knot."""
    rng = np.random.default_rng(11)
    t = np.arange(300) / 100.0
    p = rng.normal(scale=0.01, size=(300, 3, 3)).cumsum(axis=0)   # a rough random walk
    markers = MarkerTrajectories(trial_from(t, p, labels=("a", "b", "c")), cutoff_hz=8.0)
    for tq in (0.512, 1.237, 2.9871):
        _, v, a, _ = markers.evaluate(tq)
        eps = 1e-6
        v_fd = (markers.positions(tq + eps) - markers.positions(tq - eps)) / (2 * eps)
        eps = 1e-4
        a_fd = (markers.positions(tq + eps) - 2 * markers.positions(tq)
                + markers.positions(tq - eps)) / eps ** 2
        assert np.abs(v).max() > 1e-3 and np.abs(a).max() > 1e-2     # non-trivial
        np.testing.assert_allclose(v, v_fd, rtol=0, atol=1e-8)
        np.testing.assert_allclose(a, a_fd, rtol=0, atol=1e-6)


def fitted_gain_and_phase(frequency, rate=100.0, cutoff=6.0, order=2):
    """Zero-lag gain and phase of a unit sinusoid of ``frequency`` Hz, fitted by least
    squares on the middle half of a 20 s record (edge transients excluded)."""
    t = np.arange(2001) / rate
    p = np.zeros((len(t), 1, 3))
    p[:, 0, 0] = 0.01 * np.sin(2 * np.pi * frequency * t + 0.2)
    markers = MarkerTrajectories(trial_from(t, p), cutoff_hz=cutoff, order=order)
    middle = t[500:1500]
    y = np.array([markers.positions(tq)[0, 0] for tq in middle])
    basis = np.stack([np.sin(2 * np.pi * frequency * middle + 0.2),
                      np.cos(2 * np.pi * frequency * middle + 0.2)], axis=1)
    (in_phase, quadrature), *_ = np.linalg.lstsq(basis, y, rcond=None)
    return np.hypot(in_phase, quadrature) / 0.01, np.arctan2(quadrature, in_phase)


def butterworth_zero_lag_gain(frequency, rate, cutoff, order):
    """|H|² of a digital (bilinear) Butterworth low-pass run forward and backward:
    1 / (1 + (tan(π f/f_s) / tan(π f_c/f_s))^(2·order))."""
    ratio = np.tan(np.pi * frequency / rate) / np.tan(np.pi * cutoff / rate)
    return 1.0 / (1.0 + ratio ** (2 * order))


def test_filter_passes_slow_motion_without_lag():
    gain, phase = fitted_gain_and_phase(0.5)
    assert abs(gain - 1.0) < 0.01
    assert abs(phase) < 1e-6                                   # zero lag
    assert gain == pytest.approx(butterworth_zero_lag_gain(0.5, 100.0, 6.0, 2), rel=1e-6)


@pytest.mark.parametrize("frequency, order", [(20.0, 2), (12.0, 2), (20.0, 3), (6.0, 2)])
def test_filter_attenuates_per_butterworth_response(frequency, order):
    gain, phase = fitted_gain_and_phase(frequency, order=order)
    expected = butterworth_zero_lag_gain(frequency, 100.0, 6.0, order)
    assert gain == pytest.approx(expected, rel=1e-6)
    assert abs(phase) < 1e-6
    if frequency == 6.0:
        assert gain == pytest.approx(0.5, rel=1e-9)            # −6 dB at the cutoff
    else:
        assert gain < 0.06


def gapped_trial():
    """Three markers at 100 Hz over 2 s; marker 'B' is missing for samples 80–99 and
    has an isolated sample at 150 (neighbours 149 and 151 missing)."""
    t = np.arange(201) / 100.0
    p, _, _ = analytic(t)
    positions = np.stack([p, p + 0.1, p - 0.2], axis=1)
    positions[80:100, 1] = np.nan
    positions[149, 1] = positions[151, 1] = np.nan
    return trial_from(t, positions, labels=("A", "B", "C"), source="gaps.c3d")


@pytest.mark.parametrize("cutoff", [None, 6.0])
def test_gap_is_not_visible_and_does_not_bleed(cutoff):
    markers = MarkerTrajectories(gapped_trial(), cutoff_hz=cutoff)
    t = markers.time
    assert markers.visible_intervals("B") == [(t[0], t[79]), (t[100], t[148]), (t[152], t[200])]
    for tq in (t[79] + 1e-4, 0.85, t[99], t[100] - 1e-4, t[150]):
        p, v, a, visible = markers.evaluate(tq)
        assert visible.tolist() == [True, False, True]
        assert np.isnan(p[1]).all() and np.isnan(v[1]).all() and np.isnan(a[1]).all()
        assert np.isfinite(p[[0, 2]]).all() and np.isfinite(a[[0, 2]]).all()
    # the segment ends are visible and finite, at the sample and just inside
    for tq in (t[79], t[79] - 1e-4, t[100], t[100] + 1e-4, 100 * 0.01, t[200]):
        p, v, a, visible = markers.evaluate(tq)
        assert visible.all(), tq
        assert np.isfinite(p).all() and np.isfinite(v).all() and np.isfinite(a).all()
    if cutoff is None:
        # unfiltered, each segment is an interpolant of the analytic motion (+0.1 offset):
        # accurate up to its ends, so no NaN or gap artefact bleeds into it
        for tq in (t[79], t[79] - 0.0063, t[100], t[100] + 0.0063):
            p_true, v_true, _ = (x[0] for x in analytic(np.array([tq])))
            p, v, _, _ = markers.evaluate(tq)
            assert np.abs(p[1] - (p_true + 0.1)).max() < 1e-6
            assert np.abs(v[1] - v_true).max() < 1e-3
        np.testing.assert_allclose(markers.positions(t[79])[1], gapped_trial().positions[79, 1],
                                   atol=1e-15)


def test_gap_leaves_other_markers_unchanged():
    """Marker A's trajectory does not depend on B's gaps (markers are fitted separately)."""
    trial = gapped_trial()
    together = MarkerTrajectories(trial)
    alone = MarkerTrajectories(trial.select(["A"]))
    for tq in np.linspace(0.0, 2.0, 37):
        np.testing.assert_array_equal(together.positions(tq)[0], alone.positions(tq)[0])


def test_sample_times_computed_by_round_off_stay_visible():
    t0 = 0.1
    t = t0 + np.arange(101) * 0.01
    p, _, _ = analytic(t)
    trial = MarkerTrial(labels=("M",), rate=100.0, time=t, positions=p[:, None, :])
    markers = MarkerTrajectories(trial)
    assert markers.t_start == pytest.approx(0.1) and markers.t_end == pytest.approx(1.1)
    for tq in (0.1 + 100 * 0.01, sum([0.01] * 100) + 0.1, 1.1 * (1 + 1e-15), 0.1 * (1 - 1e-15)):
        assert markers.visible(tq)[0], tq
    for tq in (0.0999, 1.1001, float("nan")):
        assert not markers.visible(tq)[0]
        assert np.isnan(markers.positions(tq)).all()


def test_short_segments():
    """Segments not longer than the filter's padding (9 samples for order 2) are
    interpolated unfiltered, so they pass through their samples; a 10-sample segment is
    filtered (moved, but only by the end transient of a smooth motion, < 2 mm)."""
    t = np.arange(80) / 100.0
    p, _, _ = analytic(t)
    positions = np.repeat(p[:, None, :], 3, axis=1)
    for m, keep in enumerate((np.arange(20, 23), np.arange(30, 39), np.arange(50, 60))):
        positions[~np.isin(np.arange(80), keep), m] = np.nan
    markers = MarkerTrajectories(trial_from(t, positions, labels=("three", "nine", "ten")))
    assert markers.min_filtered_samples == 10
    for k in range(20, 23):
        np.testing.assert_allclose(markers.positions(t[k])[0], p[k], rtol=0, atol=1e-15)
    for k in range(30, 39):
        np.testing.assert_allclose(markers.positions(t[k])[1], p[k], rtol=0, atol=1e-15)
    moved = np.abs(markers.filtered_positions[50:60, 2] - p[50:60])
    assert 1e-5 < moved.max() < 2e-3
    assert markers.visible(t[21] + 0.003).tolist() == [True, False, False]
    assert markers.visible(t[32] + 0.004).tolist() == [False, True, False]
    assert markers.visible(t[59]).tolist() == [False, False, True]
    assert not markers.visible(t[23] + 0.001).any()


def test_evaluate_agrees_with_single_quantity_methods():
    markers = MarkerTrajectories(gapped_trial())
    for tq in (0.0, 0.4321, 1.0, 2.0):
        p, v, a, visible = markers.evaluate(tq)
        np.testing.assert_array_equal(markers.positions(tq), p)
        np.testing.assert_array_equal(markers.velocities(tq), v)
        np.testing.assert_array_equal(markers.accelerations(tq), a)
        np.testing.assert_array_equal(markers.visible(tq), visible)
        assert p.shape == v.shape == a.shape == (3, 3) and visible.shape == (3,)


def test_cutoff_must_be_below_nyquist():
    trial = gapped_trial()
    with pytest.raises(ValueError, match=r"Nyquist frequency 50 Hz of gaps.c3d"):
        MarkerTrajectories(trial, cutoff_hz=50.0)
    with pytest.raises(ValueError, match="cutoff_hz"):
        MarkerTrajectories(trial, cutoff_hz=-1.0)
    with pytest.raises(ValueError, match="order"):
        MarkerTrajectories(trial, order=0)
    MarkerTrajectories(trial, cutoff_hz=49.0)                  # just below: fine
    uneven = MarkerTrial(labels=("M",), rate=100.0, time=[0.0, 0.01, 0.03, 0.04],
                         positions=np.zeros((4, 1, 3)))
    with pytest.raises(ValueError, match="uniformly"):
        MarkerTrajectories(uneven)
    MarkerTrajectories(uneven, cutoff_hz=None)                 # interpolation alone: fine


def test_select_puts_markers_in_model_order():
    markers = MarkerTrajectories(gapped_trial())
    model_order = markers.select(["C", "A"])
    assert model_order.labels == ("C", "A")
    np.testing.assert_array_equal(model_order.positions(0.5), markers.positions(0.5)[[2, 0]])
    with pytest.raises(MissingMarkerError) as info:
        markers.select(["A", "Skull_1", "Skull_2"])
    assert info.value.missing == ("Skull_1", "Skull_2")
    assert "gaps.c3d" in str(info.value)


def test_from_c3d_file(tmp_path):
    """C3D → trial → trajectories: units and gaps carry through."""
    trial = gapped_trial()
    path = tmp_path / "gaps.c3d"
    write_c3d(path, trial.labels, trial.positions, trial.rate, units="mm")
    markers = MarkerTrajectories(read_c3d(path), cutoff_hz=None)
    assert markers.visible(0.85).tolist() == [True, False, True]
    p_true, _, _ = analytic(np.array([0.5]))
    np.testing.assert_allclose(markers.positions(0.5)[0], p_true[0], atol=2e-6)


def test_visible_segments():
    assert visible_segments(np.array([0, 1, 1, 0, 1, 0, 0, 1, 1, 1], dtype=bool)) == [
        (1, 3), (4, 5), (7, 10)]
    assert visible_segments(np.zeros(4, dtype=bool)) == []


def test_rounded_sample_times_are_uniform_enough_to_filter():
    """A 120 Hz trial whose times are written with 6 decimals (a real TRC: 0.758333,
    0.766667, …) is filtered: the spacing differs from 1/rate by 6e-5 of it, below the
    0.1 % tolerance; a 1 % jitter is refused naming the file and the size of it. The
    filtered signal of a constant marker stays constant (the filter is not disturbed)."""
    t = np.round(0.75 + np.arange(60) / 120.0, 6)
    p = np.tile([0.1, 0.2, 0.3], (60, 1))[:, None, :]
    trial = MarkerTrial(labels=("M",), rate=120.0, time=t, positions=p, source="trial.trc")
    markers = MarkerTrajectories(trial, cutoff_hz=6.0)
    np.testing.assert_allclose(markers.filtered_positions[:, 0, :], p[:, 0, :], atol=1e-12)
    jittered = t.copy()
    jittered[30:] += 0.02 / 120.0
    with pytest.raises(ValueError, match=r"trial\.trc: filtering needs samples spaced uniformly.*by up to 2 % of it"):
        MarkerTrajectories(MarkerTrial(labels=("M",), rate=120.0, time=jittered, positions=p, source="trial.trc"),
                           cutoff_hz=6.0)


def test_tracking_times_of_a_rounded_trial_are_its_uniform_grid():
    """The analysed times of a trial with rounded sample times are the uniform grid over
    the same span (where the marker splines are evaluated); a real gap is refused."""
    from types import SimpleNamespace

    from openfdk.kinematics.analysis import tracking_times

    t = np.round(0.75 + np.arange(40) / 120.0, 6)
    times = tracking_times(SimpleNamespace(time=t), None)
    np.testing.assert_allclose(times, 0.75 + np.arange(40) * (t[-1] - t[0]) / 39, rtol=0, atol=1e-15)
    assert np.ptp(np.diff(times)) < 1e-12 and np.max(np.abs(times - t)) < 1e-6
    gap = np.concatenate([t[:20], t[20:] + 0.5 / 120.0])
    with pytest.raises(ValueError, match="uniformly spaced"):
        tracking_times(SimpleNamespace(time=gap), None)
