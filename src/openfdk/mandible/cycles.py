"""Splitting a repeated jaw movement into cycles and normalising each to 0–100 %.

The paper evaluates five cycles of each task (Andersen et al. 2017, "Motion capture
data", Tables 1–2, Figs. 5–7). :func:`split_cycles` finds them in one scalar signal that
is smallest with the mouth closed (incisal opening, condyle AP displacement; negate a
signal that is largest when closed), :func:`normalize_cycles` resamples any per-frame
series on those cycles.

Cycle rule (docs/mandible-study-outputs.md, "Cycles"):

1. The signal is low-pass filtered (zero-lag 2nd-order Butterworth, cut-off
   ``harmonics`` / T with T the dominant period from the autocorrelation, bounded by
   ``min_period``/``max_period``). NaN gaps are bridged linearly before filtering.
2. Opening peaks are the maxima of the smoothed signal that are at least 0.6 T apart
   (or ``min_period``) and rise by at least 30 % of its 2–98 % range.
3. A cycle starts at the closed-mouth minimum before each peak: the LAST sample of the
   trough (between the previous peak, or the record start, and this peak) whose smoothed
   value is within a closed-mouth band of the trough's minimum: ``flat_tolerance`` ×
   (peak − minimum) plus 4 σ_s, σ_s the noise left after smoothing (estimated from the
   filter residual). For a flat closed-mouth rest this is the onset of the opening, so
   rest before the movement is not part of the first cycle; for a sharp minimum it is
   just after the minimum (noise-free sinusoid, default 1 %: 0.032 T late).
4. A cycle stops where the next one starts. After the last peak the signal must come
   back to the closed level (a trough that is not the record's last samples); the last
   cycle then stops at the next opening onset, or — when the mouth stays closed to the
   record end — one median cycle duration after its start (at most the last sample).
5. A trough is only a valid start if it is a real minimum: not at the record's first
   samples unless a closed rest (≥ 5 % of T) precedes the opening. A record that starts
   mid-opening therefore skips the partial cycle.
6. Cycles shorter than ``min_period`` or longer than ``max_period`` are discarded; the
   first ``n_cycles`` remaining cycles are returned.

Indices are inclusive at both ends: cycle k covers ``time[start_k] … time[stop_k]`` and
``stop_k == start_{k+1}`` for successive cycles (0 % of one is 100 % of the previous).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, filtfilt, find_peaks

__all__ = ["CycleError", "normalize_cycles", "split_cycles"]

_PEAK_SPACING = 0.6         # minimum peak distance, fraction of the period estimate
_PEAK_RISE = 0.30           # minimum peak prominence, fraction of the 2–98 % range
_EDGE = 0.05                # closed rest needed at a record edge, fraction of the period


class CycleError(ValueError):
    """The signal does not contain the requested cycles, or the inputs are malformed."""


# --------------------------------------------------------------------------------------
# Signal preparation
# --------------------------------------------------------------------------------------

def _check_time_signal(time, signal) -> tuple[np.ndarray, np.ndarray, float]:
    """Validated (time (n,) s, gap-filled signal (n,), sampling interval s)."""
    t = np.asarray(time, dtype=float)
    x = np.asarray(signal, dtype=float)
    if t.ndim != 1 or x.shape != t.shape:
        raise CycleError(f"time and signal must be 1-D of equal length; got shapes {t.shape} "
                         f"and {x.shape}")
    if t.size < 16:
        raise CycleError(f"signal has {t.size} samples; at least 16 are needed to find cycles")
    dt = np.diff(t)
    if not np.all(np.isfinite(t)) or np.any(dt <= 0):
        raise CycleError("time must be finite and strictly increasing")
    h = float(np.median(dt))
    if np.max(np.abs(dt - h)) > 0.01 * h:
        raise CycleError(f"time must be uniformly sampled (median step {h:g} s, steps range "
                         f"{dt.min():g}–{dt.max():g} s); resample it first")
    finite = np.isfinite(x)
    if finite.sum() < 16:
        raise CycleError(f"signal has {finite.sum()} finite samples; at least 16 are needed")
    if not finite.all():                       # bridge gaps linearly (ends held constant)
        x = np.interp(t, t[finite], x[finite])
    return t, x, h


def _dominant_period(x, h, min_period, max_period) -> float:
    """Dominant period (s) of x (n,) sampled every h s: the first major maximum of the
    autocorrelation after its first zero crossing, searched in [min_period, max_period]."""
    n = x.size
    z = x - x.mean()
    spectrum = np.fft.rfft(z, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    if acf[0] <= 0.0:
        raise CycleError("signal is constant; no movement cycles to find")
    acf = acf / acf[0]
    lo = 1 if min_period is None else max(1, int(np.floor(min_period / h)))
    if min_period is None:                     # skip the central lobe
        negative = np.flatnonzero(acf < 0.0)
        lo = int(negative[0]) if negative.size else n
    hi = n // 2 if max_period is None else min(n - 1, int(np.ceil(max_period / h)))
    lags, _ = find_peaks(acf[: hi + 1])
    lags = lags[lags >= lo]
    if lags.size == 0:
        raise CycleError("no periodic movement found in the signal (its autocorrelation has "
                         "no maximum in the allowed period range)")
    best = acf[lags].max()
    return float(lags[np.argmax(acf[lags] >= 0.7 * best)] * h)


def _smooth(x, h, period, harmonics) -> tuple[np.ndarray, float]:
    """Zero-lag Butterworth low-pass (order 2, cut-off harmonics/period) of x (n,), and
    the standard deviation of the white noise left in it (unit of x)."""
    wn = 2.0 * h * harmonics / period          # cut-off / Nyquist frequency
    if wn >= 0.99:
        return x.copy(), 0.0
    b, a = butter(2, wn)
    s = filtfilt(b, a, x)
    # filtfilt of order 2: |H|⁴ = 1/(1 + (ω/ω_c)⁸) passes a fraction
    # ∫|H|⁴dω/π ≈ wn·(π/8)/sin(π/8) = 1.026 wn of white-noise variance; the residual x − s
    # holds the rest, (1 − 1.026 wn) σ² → σ from its median absolute deviation.
    kept = min(1.026 * wn, 0.9)
    r = x - s
    sigma = 1.4826 * float(np.median(np.abs(r - np.median(r)))) / np.sqrt(1.0 - kept)
    return s, sigma * np.sqrt(kept)


# --------------------------------------------------------------------------------------
# Cycle detection
# --------------------------------------------------------------------------------------

def _closed_end(s, lo, hi, level, tolerance):
    """Last index in [lo, hi] with s ≤ level + tolerance (the opening onset) and the
    length of the closed run ending there."""
    window = s[lo : hi + 1]
    closed = np.flatnonzero(window <= level + tolerance)
    end = lo + int(closed[-1])
    run_start = end
    while run_start > lo and s[run_start - 1] <= level + tolerance:
        run_start -= 1
    return end, end - run_start


def split_cycles(time, signal, n_cycles: int = 5, min_period: float | None = None,
                 max_period: float | None = None, *, harmonics: float = 6.0,
                 flat_tolerance: float = 0.01) -> list[tuple[int, int]]:
    """The first ``n_cycles`` complete cycles of a quasi-periodic jaw movement.

    Cycles start at successive closed-mouth minima of the low-pass-filtered signal (the
    rule is in the module docstring); robust to measurement noise, to a period that
    varies from cycle to cycle, to rest before/after the movement and to partial cycles
    at the record's ends.

    Args:
        time : (n,) s, uniformly sampled, strictly increasing.
        signal : (n,) any unit, smallest with the mouth closed (e.g. incisal opening,
            condyle AP displacement in m); NaN gaps are bridged linearly.
        n_cycles : number of cycles wanted.
        min_period, max_period : s, optional bounds on a cycle's duration (they also bound
            the period search and the peak spacing).
        harmonics : low-pass cut-off as a multiple of the dominant frequency.
        flat_tolerance : closed-mouth band above a trough's minimum, as a fraction of the
            following rise.
    Returns: list of ``n_cycles`` (start_index, stop_index), both inclusive, in time order.
    Raises: CycleError (a ValueError) naming the cycles found when fewer than
        ``n_cycles`` complete cycles exist, or when the inputs are malformed.
    """
    if n_cycles < 1:
        raise CycleError(f"n_cycles must be ≥ 1; got {n_cycles}")
    if min_period is not None and max_period is not None and not 0 < min_period < max_period:
        raise CycleError(f"need 0 < min_period < max_period; got {min_period}, {max_period}")
    t, x, h = _check_time_signal(time, signal)
    period = _dominant_period(x, h, min_period, max_period)
    s, noise = _smooth(x, h, period, harmonics)
    n = s.size
    edge = max(2, int(round(_EDGE * period / h)))

    # opening peaks: far enough apart and rising enough
    spacing = (min_period if min_period is not None else _PEAK_SPACING * period) / h
    lo_pct, hi_pct = np.percentile(s, [2.0, 98.0])
    peaks, _ = find_peaks(s, distance=max(1, int(spacing)),
                          prominence=_PEAK_RISE * (hi_pct - lo_pct))
    if peaks.size == 0:
        raise CycleError(f"found no opening peak in the signal (period estimate {period:.3g} s)")

    # one candidate start per peak: the end of the closed trough before it (None if partial)
    starts: list[int | None] = []
    for j, peak in enumerate(peaks):
        lo = 0 if j == 0 else int(peaks[j - 1])
        level = float(s[lo : peak + 1].min())
        band = flat_tolerance * (s[peak] - level) + 4.0 * noise
        start, run = _closed_end(s, lo, int(peak), level, band)
        real_minimum = int(np.argmin(s[lo : peak + 1])) + lo > lo + edge or run >= edge
        starts.append(start if (j > 0 or real_minimum) else None)

    # each peak's cycle stops where the next one starts; the last needs a closed return
    stops: list[int | None] = [starts[j + 1] for j in range(len(peaks) - 1)]
    last = int(peaks[-1])
    tail = s[last:]
    level = float(tail.min())
    rise = float(s[last] - (s[starts[-1]] if starts[-1] is not None else level))
    returned = rise > 0.0 and level <= s[last] - 0.9 * rise       # back to ≤ 10 % of the rise
    stop_last: int | None = None
    if returned and last < n - 1:
        end, run = _closed_end(s, last, n - 1, level, flat_tolerance * rise + 4.0 * noise)
        if end < n - 1 - edge:
            stop_last = end                                  # the next opening begins
        elif int(np.argmin(tail)) + last < n - 1 - edge or run >= edge:
            stop_last = -1                                   # closed to the record end
    stops.append(stop_last)

    durations = [b - a for a, b in zip(starts, stops) if a is not None and b is not None and b > 0]
    typical = int(round(np.median(durations))) if durations else int(round(period / h))
    cycles, skipped = [], []
    for a, b in zip(starts, stops):
        if a is None or b is None:
            skipped.append("partial")
            continue
        if b == -1:
            b = min(a + typical, n - 1)
        duration = t[b] - t[a]
        if (min_period is not None and duration < min_period) or (
                max_period is not None and duration > max_period):
            skipped.append(f"{duration:.3g} s long at t = {t[a]:.3g} s")
            continue
        cycles.append((int(a), int(b)))
    if len(cycles) < n_cycles:
        found = ", ".join(f"{t[a]:.3g}–{t[b]:.3g} s" for a, b in cycles) or "none"
        raise CycleError(
            f"found {len(cycles)} complete cycle(s) ({found}) but n_cycles={n_cycles} were "
            f"requested; {len(peaks)} opening peak(s) at t = "
            f"{', '.join(f'{t[p]:.3g}' for p in peaks)} s, period estimate {period:.3g} s"
            + (f"; skipped: {'; '.join(skipped)}" if skipped else ""))
    return cycles[:n_cycles]


# --------------------------------------------------------------------------------------
# Normalisation
# --------------------------------------------------------------------------------------

def normalize_cycles(time, values, cycles, n_points: int = 101) -> np.ndarray:
    """Resample each cycle to ``n_points`` equally spaced instants, 0 % … 100 %.

    Linear interpolation in time between the two samples that bracket each instant.
    NaN-aware: an instant whose bracketing samples include a NaN is NaN (a gap stays a
    gap; nothing is extrapolated), while an instant that falls exactly on a finite
    sample takes its value.

    Args:
        time : (n_frames,) s, increasing.
        values : (n_frames, ...) any unit, e.g. (n_frames, 3) m.
        cycles : sequence of (start_index, stop_index), inclusive (from :func:`split_cycles`).
        n_points : samples per normalised cycle (101 → every 1 %).
    Returns: (n_cycles, n_points, ...) in the unit of ``values``.
    """
    t = np.asarray(time, dtype=float)
    v = np.asarray(values, dtype=float)
    if t.ndim != 1 or v.ndim < 1 or v.shape[0] != t.size:
        raise CycleError(f"values must have shape (n_frames, ...) with n_frames = len(time) = "
                         f"{t.size}; got {v.shape}")
    if n_points < 2:
        raise CycleError(f"n_points must be ≥ 2; got {n_points}")
    flat = v.reshape(t.size, -1)
    out = np.empty((len(cycles), n_points, flat.shape[1]))
    u = np.linspace(0.0, 1.0, n_points)
    for k, cycle in enumerate(cycles):
        a, b = (int(i) for i in cycle)
        if not 0 <= a < b < t.size:
            raise CycleError(f"cycle {k} = ({a}, {b}) is not a valid index range in "
                             f"0…{t.size - 1}")
        t_c = t[a : b + 1]
        t_u = t_c[0] + u * (t_c[-1] - t_c[0])
        # bracket: t_c[j] ≤ t_u < t_c[j+1]; weight w of the right sample
        j = np.clip(np.searchsorted(t_c, t_u, side="right") - 1, 0, t_c.size - 2)
        w = (t_u - t_c[j]) / (t_c[j + 1] - t_c[j])
        left, right = flat[a + j], flat[a + j + 1]
        w = w[:, None]
        result = (1.0 - w) * left + w * right                  # NaN if either side is NaN
        on_left, on_right = w[:, 0] == 0.0, w[:, 0] == 1.0
        result[on_left] = left[on_left]
        result[on_right] = right[on_right]
        out[k] = result
    return out.reshape((len(cycles), n_points) + v.shape[1:])
