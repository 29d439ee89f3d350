"""Splitting a repeated jaw movement into cycles and normalising each to 0–100 %.

The paper evaluates five cycles of each task (Andersen et al. 2017, "Motion capture
data", Tables 1–2, Figs. 5–7). :func:`split_cycles` finds them in one scalar signal that
is smallest with the mouth closed (incisal opening, condyle AP displacement; negate a
signal that is largest when closed), :func:`normalize_cycles` resamples any per-frame
series on those cycles.

Cycle rule (docs/mandible-study-outputs.md, "Cycles"):

1. Smoothing: zero-lag 2nd-order Butterworth low-pass, cut-off ``harmonics`` / T, with
   T the dominant period (first major maximum of the autocorrelation, searched within
   ``min_period``…``max_period``; it must reach max(0.2, 5/√n), white noise stays
   below ≈ 3.5/√n). NaN gaps are bridged linearly first. σ_s, the white
   noise left after smoothing, is estimated from the filter residual.
2. Opening peaks: maxima of the smoothed signal s at least 0.6 T (or ``min_period``)
   apart whose prominence is ≥ 30 % of the 2–98 % range of s and ≥ 8 σ_s.
3. Closed-mouth band of the trough before each peak (between the previous peak, or the
   record start, and this peak): the band width is b = ``flat_tolerance`` × (peak −
   trough minimum) + 4 σ_s; the closed level L is the median of s over the trough's
   samples within b of its minimum (robust to noise wiggles in a long rest).
4. A cycle starts at the last trough sample with s ≤ L + b: the onset of the opening
   (the usual "baseline + k·SD" onset rule). For a flat closed rest this excludes the
   rest; for a sharp minimum it is just after the minimum (noise-free sinusoid, default
   1 %: ≈ 0.03 T late); with noise, the time the signal needs to rise 4 σ_s.
5. A cycle stops where the next one starts (both indices belong to it). After the last
   peak the mouth must close again; the last cycle then stops at the next opening onset
   if the signal rises again (by > 25 % of the cycle's rise), otherwise — closed to the
   record end — one median cycle duration after its start (at most the last sample).
6. Record edges: the trough before the first peak (or after the last) counts only if
   enough of its samples lie at the closed level of the interior troughs (median L + b):
   3 % of T, at most 0.05 s and at least 2 samples. A record that starts mid-opening or
   stops mid-closing therefore skips that partial cycle, while a slow task (T up to 5 s)
   whose record starts or stops after a short closed rest keeps its edge cycles.
7. Cycles shorter than ``min_period`` or longer than ``max_period`` are discarded; the
   first ``n_cycles`` remaining cycles (all of them for ``n_cycles=None``) are returned.

Split the **whole record** and then select cycles: a record cut to the first n cycles ±
a few samples has too little closed rest at its ends for rule 6. :func:`find_cycles`
returns every complete cycle with what was skipped; :func:`split_cycles` the first n.

Indices are inclusive at both ends: cycle k covers ``time[start_k] … time[stop_k]`` and
``stop_k == start_{k+1}`` for successive cycles (0 % of one is 100 % of the previous).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt, find_peaks

__all__ = ["CycleError", "CycleSplit", "find_cycles", "normalize_cycles", "split_cycles"]

_PEAK_SPACING = 0.6         # minimum peak distance, fraction of the period estimate
_PEAK_RISE = 0.30           # minimum peak prominence, fraction of the 2–98 % range …
_PEAK_NOISE = 8.0           # … and in units of the smoothed noise σ_s
_BAND_NOISE = 4.0           # closed-mouth band above the trough: 4 σ_s (+ flat_tolerance)
_EDGE = 0.03                # closed samples needed in an edge trough, fraction of T …
_EDGE_MAX_S = 0.05          # … but at most this long (s), so slow tasks keep edge cycles
_REOPEN = 0.25              # rise after the last closing that marks a new opening
_MIN_AUTOCORRELATION = 0.2  # weakest autocorrelation accepted as a periodic movement …
_NOISE_AUTOCORRELATION = 5.0  # … and ≥ 5/√n (white noise: max ≈ 3.5/√n)


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
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]      # biased estimator
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
    needed = max(_MIN_AUTOCORRELATION, _NOISE_AUTOCORRELATION / np.sqrt(n))
    if lags.size == 0 or acf[lags].max() < needed:
        best = f"{acf[lags].max():.2f}" if lags.size else "none"
        raise CycleError("no periodic movement found in the signal (largest autocorrelation "
                         f"maximum in the allowed period range: {best}; need ≥ {needed:.2f})")
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

def _trough(s, lo, hi, top, flat_tolerance, noise) -> tuple[float, float, int]:
    """Closed level L, band b and opening onset (last index with s ≤ L + b) of the
    trough s[lo … hi] below the peak value ``top`` (rules 3–4 of the module docstring)."""
    window = s[lo : hi + 1]
    minimum = float(window.min())
    band = flat_tolerance * (top - minimum) + _BAND_NOISE * noise
    level = float(np.median(window[window <= minimum + band]))
    onset = lo + int(np.flatnonzero(window <= level + band)[-1])
    return level, band, onset


@dataclass(frozen=True)
class CycleSplit:
    """Every complete cycle of a record (:func:`find_cycles`).

    ``cycles``: list of (start_index, stop_index), both inclusive, in time order;
    ``skipped``: what was left out and why (partial edge cycles, cycles outside the
    period bounds), one phrase each; ``period`` s, the dominant period; ``peaks``
    (n_peaks,) int, indices of the opening peaks; ``time`` (n,) s.
    """

    cycles: list
    skipped: list
    period: float
    peaks: np.ndarray
    time: np.ndarray

    def describe(self) -> str:
        """One line: the cycles found (s), the peaks and what was skipped."""
        t = self.time
        found = ", ".join(f"{t[a]:.3g}–{t[b]:.3g} s" for a, b in self.cycles) or "none"
        return (f"found {len(self.cycles)} complete cycle(s) ({found}); {len(self.peaks)} opening "
                f"peak(s) at t = {', '.join(f'{t[p]:.3g}' for p in self.peaks)} s, period estimate "
                f"{self.period:.3g} s" + (f"; skipped {', '.join(self.skipped)}" if self.skipped else ""))


def find_cycles(time, signal, min_period: float | None = None, max_period: float | None = None, *,
                harmonics: float = 6.0, flat_tolerance: float = 0.01) -> CycleSplit:
    """Every complete cycle of a quasi-periodic jaw movement over the whole record.

    Cycles start at successive closed-mouth minima (opening onsets) of the low-pass
    filtered signal; the rule is in the module docstring. Robust to measurement noise,
    to a period that varies from cycle to cycle (periods 0.3–5 s at 100 Hz), to rest
    before/after the movement and to partial cycles at the record's ends.

    Args:
        time : (n,) s, uniformly sampled, strictly increasing.
        signal : (n,) any unit, smallest with the mouth closed (e.g. incisal opening,
            condyle AP displacement in m); NaN gaps are bridged linearly.
        min_period, max_period : s, optional bounds on a cycle's duration (they also bound
            the period search and the peak spacing).
        harmonics : low-pass cut-off as a multiple of the dominant frequency.
        flat_tolerance : part of the closed-mouth band, as a fraction of the trough's rise.
    Returns: a :class:`CycleSplit` (possibly with no cycles).
    Raises: CycleError (a ValueError) when the inputs are malformed or the signal has no
        periodic movement.
    """
    if min_period is not None and max_period is not None and not 0 < min_period < max_period:
        raise CycleError(f"need 0 < min_period < max_period; got {min_period}, {max_period}")
    t, x, h = _check_time_signal(time, signal)
    period = _dominant_period(x, h, min_period, max_period)
    s, noise = _smooth(x, h, period, harmonics)
    n = s.size
    edge = max(2, round(min(_EDGE * period, _EDGE_MAX_S) / h))

    # rule 2: opening peaks
    spacing = (min_period if min_period is not None else _PEAK_SPACING * period) / h
    lo_pct, hi_pct = np.percentile(s, [2.0, 98.0])
    peaks, _ = find_peaks(s, distance=max(1, int(spacing)),
                          prominence=max(_PEAK_RISE * (hi_pct - lo_pct), _PEAK_NOISE * noise))
    if peaks.size == 0:
        raise CycleError(f"found no opening peak rising above the noise (period estimate "
                         f"{period:.3g} s, smoothed noise σ = {noise:.3g})")

    # rules 3–4: one trough (level, band, onset) before each peak, one after the last
    bounds = [0] + [int(p) for p in peaks]
    troughs = [_trough(s, bounds[j], int(p), s[p], flat_tolerance, noise)
               for j, p in enumerate(peaks)]
    last = int(peaks[-1])
    tail = _trough(s, last, n - 1, s[last], flat_tolerance, noise) if last < n - 1 else None
    interior = [level for level, _, _ in troughs[1:]]
    typical_level = float(np.median(interior)) if interior else troughs[0][0]

    # rule 6: edge troughs must reach the closed level of the interior troughs
    def closed_samples(lo, hi, band):
        return int(np.count_nonzero(s[lo : hi + 1] <= typical_level + band))

    starts: list[int | None] = [onset for _, _, onset in troughs]
    if closed_samples(0, starts[0], troughs[0][1]) < edge:
        starts[0] = None                                    # record starts mid-opening

    # rule 5: stops
    stops: list[int | None] = starts[1:]
    stop_last: int | None = None
    if tail is not None and closed_samples(last, n - 1, tail[1]) >= edge:
        level, _, onset = tail
        rise = s[last] - level
        if np.max(s[onset:]) - level > _REOPEN * rise:
            stop_last = onset                               # the next opening begins
        else:
            stop_last = -1                                  # closed to the record end
    stops.append(stop_last)

    durations = [b - a for a, b in zip(starts, stops) if a is not None and b is not None and b > 0]
    typical = int(np.rint(np.median(durations))) if durations else round(period / h)
    cycles, skipped = [], []
    for a, b in zip(starts, stops):
        if a is None or b is None:
            skipped.append("a partial cycle at the " + ("start" if a is None else "end"))
            continue
        if b == -1:
            b = min(a + typical, n - 1)
        duration = t[b] - t[a]
        if (min_period is not None and duration < min_period) or (
                max_period is not None and duration > max_period):
            skipped.append(f"a cycle {duration:.3g} s long at t = {t[a]:.3g} s")
            continue
        cycles.append((int(a), int(b)))
    return CycleSplit(cycles, skipped, period, peaks, t)


def split_cycles(time, signal, n_cycles: int | None = 5, min_period: float | None = None,
                 max_period: float | None = None, *, allow_fewer: bool = False,
                 harmonics: float = 6.0, flat_tolerance: float = 0.01) -> list[tuple[int, int]]:
    """The first ``n_cycles`` complete cycles of a quasi-periodic jaw movement.

    The cycles are found on the whole record by :func:`find_cycles` (same arguments),
    then the first ``n_cycles`` are taken (all of them for ``n_cycles=None``).

    Args:
        time, signal, min_period, max_period, harmonics, flat_tolerance: as in
            :func:`find_cycles`.
        n_cycles : number of cycles wanted (≥ 1), or None for every complete cycle.
        allow_fewer : when fewer than ``n_cycles`` exist, return those (at least one)
            instead of raising; the caller says so (the study warns and reports n).
    Returns: list of (start_index, stop_index), both inclusive, in time order.
    Raises: CycleError (a ValueError) naming the cycles found when there are fewer than
        ``n_cycles`` (or none at all), or when the inputs are malformed.
    """
    if n_cycles is not None and n_cycles < 1:
        raise CycleError(f"n_cycles must be ≥ 1 or None (all); got {n_cycles}")
    split = find_cycles(time, signal, min_period, max_period, harmonics=harmonics,
                        flat_tolerance=flat_tolerance)
    cycles = split.cycles
    if not cycles or (n_cycles is not None and len(cycles) < n_cycles and not allow_fewer):
        wanted = "at least one was" if n_cycles is None else f"n_cycles={n_cycles} were"
        raise CycleError(f"{split.describe().replace('; ', f' but {wanted} requested; ', 1)}")
    return cycles if n_cycles is None else cycles[:n_cycles]


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
