"""Zero-lag low-pass filtering of a measured external load (``external_loads`` entries
with ``cutoff_hz``), and the test that says a load's samples are unfiltered noise.

Why. openfdk low-pass filters the markers (6 Hz by default) and the force plates of a
C3D file at the same cut-off: inverse dynamics with kinematics and forces filtered
differently has artefacts (Kristianslund, Krosshaug & van den Bogert, J Biomech 45 (2012)
666–671). OpenSim's ExternalLoads data are applied as given, and a ground reaction
written at the plate's analog rate may be raw: DM's overground ``*_grf.sto`` files of the
Knee Grand Challenge are 1200 Hz samples whose second differences are larger than their
first (white noise dominates from sample to sample), with a centre of pressure that
jitters by about a millimetre. Applied at 120 Hz frames, that noise moved the knee's FDK
equilibrium from frame to frame (docs/tutorial-knee-gait.md, "Filtered ground reactions").

What. ``cutoff_hz`` > 0 filters the load's samples with the order-2 zero-lag Butterworth
of the markers and force plates (:mod:`openfdk.io.butterworth`), after resampling them
onto a uniform grid at their median spacing when their times are not uniform (linear
interpolation, before the low-pass):

* a load whose force and point are both given in the ground (a ground reaction) is
  filtered as a wrench: the force F and its moment about the ground origin
  M_O = p × F + T are linear in the plate's channels, so they are what is filtered, as
  a C3D plate's F and M are (a centre of pressure, a ratio, is not). Only its loaded
  runs (|F| ≥ ``threshold_n``, 20 N as for plates) are filtered, each on its own (a
  filter across the foot's landing would load the foot before it touches the plate: on
  DM og1 it pulled the swinging foot down by 12 N); runs too short for the filter's
  padding, and the samples between runs, are left as given. On a run the point is the
  centre of pressure: where the line of action of the filtered wrench meets the plate's
  plane, whose normal is the ground axis nearest the run's mean force and which passes
  through the median height of the run's measured points; the torque is the rest of the
  moment, T = M_O − p × F (the free moment). F and M_O, which are all a body feels of the
  load, are the filtered ones exactly, whatever the point.
* any other load (force or point given in the body, or no point) has each of its
  force, point and torque components filtered over the whole record.

:func:`noise_ratio` is the test for raw samples: the RMS of a load's second differences
over the RMS of its first differences, from sample to sample over its loaded samples.
For a signal with content well below the sampling rate it is about 2π f / rate (≪ 1);
for white noise it is √3 ≈ 1.7. DM's overground plates: 1.0–1.5; its filtered treadmill
files: 0.03.
"""

from __future__ import annotations

import numpy as np

from ..io.butterworth import butter_lowpass_sos, filtfilt_padlen, sosfiltfilt
from ..io.markers import UNIFORM_SPACING_TOLERANCE, visible_segments

#: the order of the Butterworth low-pass (as the markers' and the force plates')
FILTER_ORDER = 2
#: N: a sample of a ground reaction is loaded when |F| reaches this (the plates' default)
THRESHOLD_N = 20.0
#: :func:`noise_ratio` above this: the samples are called unfiltered
NOISY_RATIO = 0.5


def uniform_samples(times, columns):
    """(times_u (m,) s, columns_u (m, k)): the samples ``columns`` (n, k) at ``times``
    (n,) s, increasing, as they are when their spacing is uniform (within the markers'
    ``UNIFORM_SPACING_TOLERANCE``, 0.1 %), else linearly interpolated onto the uniform grid from the
    first time at the median spacing (the last time included when it falls on it)."""
    times = np.asarray(times, dtype=float)
    columns = np.asarray(columns, dtype=float)
    dt = np.diff(times)
    h = float(np.median(dt))
    if np.all(np.abs(dt - h) <= UNIFORM_SPACING_TOLERANCE * h):
        return times, columns
    n = int(np.floor((times[-1] - times[0]) / h * (1 + 1e-12))) + 1
    t_u = times[0] + h * np.arange(n)
    return t_u, np.column_stack([np.interp(t_u, times, c) for c in columns.T])


def _cop(F, M, P_measured):
    """(p (n, 3) m, T (n, 3) N m) of the wrench F (n, 3) N, M (n, 3) N m about the
    ground origin on one loaded run: p where the line of action meets the plate's plane
    (normal the ground axis nearest the run's mean force, through the median height of
    the measured points P_measured (n, 3) m), T = M − p × F. Samples whose force has
    (almost) no component along the normal keep their measured point."""
    axis = int(np.argmax(np.abs(F.mean(axis=0))))
    e1, e2 = (axis + 1) % 3, (axis + 2) % 3  # (n, e1, e2) is a right-handed cyclic order
    h = float(np.median(P_measured[:, axis]))
    Fn = F[:, axis]
    ok = np.abs(Fn) > 0.5 * THRESHOLD_N
    p = P_measured.copy()
    # (p × F) along e1 and e2 equals M there (no moment about the plane's axes):
    #   p_e2 F_n − h F_e2 = M_e1,  h F_e1 − p_e1 F_n = M_e2
    p[ok, axis] = h
    p[ok, e2] = (M[ok, e1] + h * F[ok, e2]) / Fn[ok]
    p[ok, e1] = (h * F[ok, e1] - M[ok, e2]) / Fn[ok]
    return p, M - np.cross(p, F)


def filter_load(times, F, P, T, world_point, cutoff_hz, threshold_n=THRESHOLD_N):
    """The samples of one load low-pass filtered at ``cutoff_hz`` (module docstring).

    times (n,) s; F (n, 3) N; P (n, 3) m or None (the frame's origin); T (n, 3) N m or
    None (0); world_point: force and point both in the ground (a ground reaction).
    Returns (times (m,) s, F, P, T) with P and T (m, 3) arrays (P None stays None).
    Raises ValueError when the cut-off is not below half the sampling rate, or when the
    filtered samples are not finite (values so large that the wrench overflows)."""
    n = len(times)
    P0 = np.zeros((n, 3)) if P is None else np.asarray(P, dtype=float)
    T0 = np.zeros((n, 3)) if T is None else np.asarray(T, dtype=float)
    t, X = uniform_samples(times, np.column_stack((F, P0, T0)))
    F, P0, T0 = X[:, 0:3], X[:, 3:6], X[:, 6:9]
    rate = 1.0 / float(t[1] - t[0])
    if not 0.0 < cutoff_hz < rate / 2:
        raise ValueError(f"cutoff_hz = {cutoff_hz:g} Hz must be below half the samples' rate ({rate:g} Hz)")
    sos = butter_lowpass_sos(FILTER_ORDER, cutoff_hz, rate)
    shortest = filtfilt_padlen(sos) + 1
    if not world_point:
        out = X.copy()
        if len(t) >= shortest:
            out = _finite(sosfiltfilt(sos, X), X)
        return t, out[:, 0:3], None if P is None else out[:, 3:6], out[:, 6:9]
    with np.errstate(over="ignore", invalid="ignore"):
        M = np.cross(P0, F) + T0
    F_f, P_f, T_f = F.copy(), P0.copy(), T0.copy()
    for a, b in visible_segments(np.linalg.norm(F, axis=1) >= threshold_n):
        if b - a < shortest:
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            W = sosfiltfilt(sos, np.column_stack((F[a:b], M[a:b])))
            F_f[a:b] = W[:, 0:3]
            P_f[a:b], T_f[a:b] = _cop(W[:, 0:3], W[:, 3:6], P0[a:b])
    _finite(np.column_stack((F_f, P_f, T_f)), X)
    return t, F_f, P_f, T_f


def _finite(filtered, samples):
    """``filtered`` if all of it is finite, else ValueError naming the largest sample."""
    if not np.all(np.isfinite(filtered)):
        raise ValueError(f"the filtered samples are not finite (the largest sample, "
                         f"{float(np.max(np.abs(samples))):.3g}, overflows the filter)")
    return filtered


def noise_ratio(F, threshold_n=THRESHOLD_N):
    """RMS of the second differences of the force samples F (n, 3) N over the RMS of
    their first differences, over the samples with |F| ≥ ``threshold_n`` and both
    neighbours loaded (module docstring); 0 when fewer than 3 such samples move."""
    F = np.asarray(F, dtype=float)
    loaded = np.linalg.norm(F, axis=1) >= threshold_n
    inner = loaded[1:-1] & loaded[:-2] & loaded[2:]
    if inner.sum() < 3:
        return 0.0
    d1 = (F[2:] - F[1:-1])[inner]
    d2 = (F[2:] - 2 * F[1:-1] + F[:-2])[inner]
    r1 = float(np.sqrt(np.mean(d1 * d1)))
    return float(np.sqrt(np.mean(d2 * d2))) / r1 if r1 > 0 else 0.0


__all__ = ["filter_load", "noise_ratio", "uniform_samples", "THRESHOLD_N", "NOISY_RATIO"]
