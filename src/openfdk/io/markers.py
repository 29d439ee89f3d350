"""Measured marker trajectories that can be evaluated at any time t.

Over-determinate kinematics needs the measured marker positions, and the residual's
time derivatives, at t and t ± Δt (docs/design.md §1, paper Eqs. 7–10), so the samples are
low-pass filtered and interpolated (docs/design.md §1: "zero-lag Butterworth low-pass +
spline").

Per marker, per contiguous run of visible samples (a *segment*):

1. Filter: zero-lag filtering (:func:`openfdk.io.butterworth.sosfiltfilt`, what
   ``scipy.signal.sosfiltfilt`` computes) with an order-``order`` Butterworth low-pass
   designed at ``cutoff_hz``.  Running it forward and backward cancels the phase (zero
   lag) and squares the magnitude, so the effective order is 2·``order`` and the gain is

       |H(f)|² = 1 / (1 + (tan(π f / f_s) / tan(π f_c / f_s))^(2·order))

   (digital Butterworth by the bilinear transform).  No cutoff correction is applied:
   ``cutoff_hz`` is the design cutoff of each pass, where the zero-lag gain is ½
   (−6 dB); the −3 dB point of the zero-lag filter is lower, ≈ 0.80·f_c for order 2.
   Padding: scipy's default odd extension of 3·(2·n_sections + 1) samples (9 for
   order 2).  A segment that is not longer than the padding is interpolated *unfiltered*:
   a shorter pad makes the result an artefact of the padding (measured: a 4-sample
   segment of a 1.3 Hz, 50 mm motion moved by 5 mm).  Even on long segments the odd
   extension keeps the end value and slope but not the curvature, so the first and last
   ≈ f_s/(2 f_c) samples of every segment carry an end transient (≈ 1 mm for that
   motion at 6 Hz, vs 0.08 mm of attenuation in the middle).
2. Interpolate: a C² cubic spline through the (filtered) samples with not-a-knot ends
   (:mod:`openfdk.numerics.cubic_spline`, the spline ``scipy.interpolate.CubicSpline`` computes,
   without its ≈ 0.2 s of imports), so position, velocity and acceleration are
   continuous inside a segment.

A marker is *visible* at t iff t lies in [first sample time, last sample time] of one of
its segments (within 10⁻⁶ of a sample interval, so times computed as k/rate never fall
off a segment end by round-off).  A segment of a single sample is treated as not visible
— no velocity can be estimated from it.  Nothing is extrapolated across a gap: inside a
gap and outside the trial the marker is not visible and its values are NaN.

Evaluation is vectorised over markers: the spline coefficients of every marker on every
sample interval are stored in one array ``(n_frames − 1, 4, n_markers, 3)`` (NaN where the
interval is not inside a segment); the interval is found by bisection and position,
velocity and acceleration come from one product [p; ṗ; p̈] = T(τ)·c.  Memory: 96 bytes per
marker per frame (24 markers × 60 000 frames ≈ 140 MB).
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence

import numpy as np

from openfdk.numerics.cubic_spline import not_a_knot_coefficients
from openfdk.io.butterworth import butter_lowpass_sos, filtfilt_padlen, sosfiltfilt
from openfdk.io.c3d import MarkerTrial

__all__ = ["MarkerTrajectories", "visible_segments"]


def visible_segments(visible: np.ndarray) -> list[tuple[int, int]]:
    """Contiguous runs of True in ``visible (n_frames,) bool`` as ``[(start, stop), …]``
    with ``stop`` exclusive."""
    padded = np.concatenate(([False], np.asarray(visible, dtype=bool), [False]))
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


#: largest relative deviation of a sample interval from 1/rate that filtering accepts:
#: files write times rounded (a 120 Hz TRC with 6 decimals: 6e-5), and a Butterworth
#: filter designed for the nominal rate is then off by as little
UNIFORM_SPACING_TOLERANCE = 1e-3


class MarkerTrajectories:
    """Filtered, interpolated marker positions of a trial, evaluable at any time.

    Args:
        trial: the measured samples (``positions (n_frames, n_markers, 3) m``, NaN where
            missing), e.g. from :func:`openfdk.io.c3d.read_c3d`.
        cutoff_hz: Butterworth design cutoff, Hz (default 6 Hz); ``None`` disables
            filtering (the spline then interpolates the raw samples).  Must be below the
            Nyquist frequency rate/2.
        order: Butterworth order of each pass (the zero-lag filter has order 2·order).

    Attributes:
        labels: marker names, in column order.
        time: ``(n_frames,) s`` sample times; ``t_start``, ``t_end`` its ends.
        filtered_positions: ``(n_frames, n_markers, 3) m`` the filtered samples the
            splines pass through (NaN where not visible).
        min_filtered_samples: shortest segment that is filtered (None without filter).
    """

    def __init__(self, trial: MarkerTrial, cutoff_hz: float | None = 6.0, order: int = 2):
        if trial.n_frames < 2:
            raise ValueError(f"{trial.source}: needs at least 2 frames to interpolate "
                             f"markers, has {trial.n_frames}")
        if int(order) != order or order < 1:
            raise ValueError(f"filter order must be a positive integer, got {order}")
        nyquist_hz = 0.5 * trial.rate
        if cutoff_hz is not None and not (np.isfinite(cutoff_hz) and 0 < cutoff_hz < nyquist_hz):
            raise ValueError(
                f"cutoff_hz = {cutoff_hz} Hz must be positive and below the Nyquist "
                f"frequency {nyquist_hz:g} Hz of {trial.source} (sampled at "
                f"{trial.rate:g} Hz)")
        self.trial = trial
        self.cutoff_hz = None if cutoff_hz is None else float(cutoff_hz)
        self.order = int(order)
        time = trial.time
        if np.any(np.diff(time) <= 0):
            raise ValueError(f"{trial.source}: sample times must increase strictly")
        jitter = np.max(np.abs(np.diff(time) * trial.rate - 1.0))
        if cutoff_hz is not None and jitter > UNIFORM_SPACING_TOLERANCE:
            raise ValueError(f"{trial.source}: filtering needs samples spaced uniformly at "
                             f"1/rate = {1.0 / trial.rate:g} s (spacing differs by up to {100 * jitter:.3g} % "
                             f"of it; allowed {100 * UNIFORM_SPACING_TOLERANCE:g} %)")

        sos = None if cutoff_hz is None else butter_lowpass_sos(self.order, self.cutoff_hz, trial.rate)
        # more samples than the odd-extension padding; shorter segments stay unfiltered
        self.min_filtered_samples = None if sos is None else 1 + filtfilt_padlen(sos)

        n_frames, n_markers = trial.n_frames, trial.n_markers
        # coef[k, i, m, :] = c_i of marker m on [t_k, t_k+1]: p = Σ c_i (t − t_k)^i
        coef = np.full((n_frames - 1, 4, n_markers, 3), np.nan)
        filtered = np.full((n_frames, n_markers, 3), np.nan)
        segments: list[list[tuple[int, int]]] = []
        for m in range(n_markers):
            p_m = trial.positions[:, m, :]
            runs = [(a, b) for a, b in visible_segments(np.all(np.isfinite(p_m), axis=1))
                    if b - a >= 2]                          # single samples: not visible
            segments.append(runs)
            for a, b in runs:
                x = p_m[a:b]
                if sos is not None and b - a >= self.min_filtered_samples:
                    x = sosfiltfilt(sos, x)
                coef[a:b - 1, :, m] = not_a_knot_coefficients(time[a:b], x)   # (pieces, 4, 3)
                filtered[a:b, m] = x
        self._coef = coef
        self._valid = np.isfinite(coef[:, 0, :, 0])        # (n_frames − 1, n_markers)
        self._all_valid = self._valid.all(axis=1)          # (n_frames − 1,)
        self._segments = segments
        self._time = time
        self._time_list = time.tolist()
        self._tol = 1e-6 * float(np.min(np.diff(time)))
        self._t_low = float(time[0]) - self._tol
        self._t_high = float(time[-1]) + self._tol
        self._marker_index = np.arange(n_markers)
        filtered.setflags(write=False)
        self.filtered_positions = filtered

    # ------------------------------------------------------------------ description
    @property
    def labels(self) -> tuple[str, ...]:
        return self.trial.labels

    @property
    def n_markers(self) -> int:
        return self.trial.n_markers

    @property
    def time(self) -> np.ndarray:
        """``(n_frames,) s`` sample times."""
        return self._time

    @property
    def t_start(self) -> float:
        return float(self._time[0])

    @property
    def t_end(self) -> float:
        return float(self._time[-1])

    @property
    def rate(self) -> float:
        return self.trial.rate

    @property
    def source(self) -> str:
        return self.trial.source

    def visible_intervals(self, label: str) -> list[tuple[float, float]]:
        """``[(t_first, t_last), …] s``: the time intervals where marker ``label`` is
        visible."""
        m = self.trial.index(label)
        return [(float(self._time[a]), float(self._time[b - 1])) for a, b in self._segments[m]]

    def select(self, labels: Sequence[str]) -> MarkerTrajectories:
        """The same trajectories for ``labels`` only, in that order (e.g. the model's
        marker order); :class:`~openfdk.io.c3d.MissingMarkerError` names any missing."""
        return MarkerTrajectories(self.trial.select(labels), self.cutoff_hz, self.order)

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration and visibility of every marker at time t.

        Args:
            t: time, s (scalar).
        Returns:
            p_WM ``(n_markers, 3) m``, v_WM ``(n_markers, 3) m/s``,
            a_WM ``(n_markers, 3) m/s²`` (NaN rows where not visible) and
            visible ``(n_markers,) bool``.
        """
        t = float(t)
        n = self.n_markers
        if not (self._t_low <= t <= self._t_high):          # outside the trial (or NaN)
            nan = np.full((n, 3), np.nan)
            return nan, nan.copy(), nan.copy(), np.zeros(n, dtype=bool)
        time, tol = self._time_list, self._tol
        n_intervals = len(time) - 1
        # interval k with t_k ≤ t < t_k+1, clipped to the trial
        k = min(max(bisect.bisect_right(time, t) - 1, 0), n_intervals - 1)
        tau = t - time[k]
        if self._all_valid[k] and tau == 0.0:
            # at a sample (the usual analysis times): p = c0, ṗ = c1, p̈ = 2 c2 exactly
            c = self._coef[k].reshape(4, n, 3)
            return c[0].copy(), c[1].copy(), 2.0 * c[2], np.ones(n, dtype=bool)
        if self._all_valid[k]:
            # [p; ṗ; p̈] = T(τ) c with T = [[1, τ, τ², τ³], [0, 1, 2τ, 3τ²], [0, 0, 2, 6τ]]
            T = np.array([[1.0, tau, tau * tau, tau * tau * tau],
                          [0.0, 1.0, 2.0 * tau, 3.0 * tau * tau],
                          [0.0, 0.0, 2.0, 6.0 * tau]])
            pva = (T @ self._coef[k].reshape(4, 3 * n)).reshape(3, n, 3)
            visible = np.ones(n, dtype=bool)
        else:
            # at a segment's first or last sample t may sit (within tol) in the
            # neighbouring interval: evaluate that segment's end piece there
            interval = np.full(n, k)
            visible = self._valid[k].copy()
            if tau <= tol and k > 0:
                use = ~visible & self._valid[k - 1]
                interval[use] = k - 1
                visible |= use
            if tau >= time[k + 1] - time[k] - tol and k + 1 < n_intervals:
                use = ~visible & self._valid[k + 1]
                interval[use] = k + 1
                visible |= use
            tau_m = t - self._time[interval]                # (n_markers,)
            T = np.zeros((n, 3, 4))
            T[:, 0, 0] = T[:, 1, 1] = 1.0
            T[:, 0, 1] = tau_m
            T[:, 0, 2] = tau_m * tau_m
            T[:, 0, 3] = tau_m ** 3
            T[:, 1, 2] = 2.0 * tau_m
            T[:, 1, 3] = 3.0 * tau_m * tau_m
            T[:, 2, 2] = 2.0
            T[:, 2, 3] = 6.0 * tau_m
            c = self._coef[interval, :, self._marker_index]  # (n_markers, 4, 3)
            pva = np.ascontiguousarray(np.transpose(T @ c, (1, 0, 2)))
        return pva[0], pva[1], pva[2], visible

    def positions(self, t: float) -> np.ndarray:
        """``(n_markers, 3) m`` marker positions at time t s (NaN where not visible)."""
        return self.evaluate(t)[0]

    def velocities(self, t: float) -> np.ndarray:
        """``(n_markers, 3) m/s`` marker velocities at time t s (NaN where not visible)."""
        return self.evaluate(t)[1]

    def accelerations(self, t: float) -> np.ndarray:
        """``(n_markers, 3) m/s²`` marker accelerations at time t s (NaN where not
        visible)."""
        return self.evaluate(t)[2]

    def visible(self, t: float) -> np.ndarray:
        """``(n_markers,) bool``: which markers are visible at time t s."""
        return self.evaluate(t)[3]
