"""Zero-lag Butterworth low-pass filter of sampled marker data (docs/design.md §1: "zero-lag
Butterworth low-pass + spline"), written for openfdk so that reading a trial does not
import ``scipy.signal`` (≈ 0.3 s of imports — scipy.stats comes with it — on every
``openfdk`` command and every study worker). It computes what
``scipy.signal.sosfiltfilt(scipy.signal.butter(order, f_c, fs=f_s, output="sos"), x,
axis=0)`` computes, to round-off (tests/test_butterworth.py compares the two).

Design (Oppenheim & Schafer, *Discrete-Time Signal Processing*, 3rd ed., §7.3):

* analog prototype poles  p_k = exp(iπ (2k + N + 1) / (2N)),  k = 0 … N−1 (left half plane);
* cutoff pre-warped so the digital filter has its half-power point at f_c:
  ω_a = 2 f_s tan(π f_c / f_s)  (rad/s);
* bilinear transform of s_k = ω_a p_k:  z_k = (2 f_s + s_k) / (2 f_s − s_k); the N zeros at
  s = ∞ map to z = −1;
* one second-order section (SOS) per conjugate pole pair, b = g·[1, 2, 1],
  a = [1, −2 Re z_k, |z_k|²], and for odd N one first-order section b = g·[1, 1, 0],
  a = [1, −z_r, 0], each with its gain g set for unit gain at DC (z = 1); sections ordered
  by pole radius, the pole pair nearest the unit circle last (as scipy's ``zpk2sos``).

The gain of one pass is |H(f)|² = 1 / (1 + (tan(π f / f_s) / tan(π f_c / f_s))^(2N)).

Zero-lag filtering (Gustafsson, "Determining the initial states in forward-backward
filtering", IEEE Trans. Signal Process. 44(4), 1996; the choices of scipy's
``sosfiltfilt``): the samples are extended at both ends by an odd reflection of ``padlen``
= 3·(2·n_sections + 1 − n_first_order) samples about the end values
(x_{−j} = 2 x_0 − x_j), filtered forward with every section's state at the steady state of
a constant input equal to the first sample, then backward starting in the steady state of
the forward output's last sample, and the padding removed. A section in direct form II
transposed, input v, output y:

    y = b0 v + z1,   z1 ← b1 v − a1 y + z2,   z2 ← b2 v − a2 y;

with unit DC gain its steady state for a constant input v₀ is
z1 = (b1 + b2 − a1 − a2) v₀, z2 = (b2 − a2) v₀.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["butter_lowpass_sos", "filtfilt_padlen", "sosfiltfilt"]


def butter_lowpass_sos(order: int, cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Second-order sections ``(n_sections, 6)`` [b0, b1, b2, 1, a1, a2] of the order-``order``
    digital Butterworth low-pass with cutoff ``cutoff_hz`` (Hz, 0 < f_c < rate_hz/2) for
    samples at ``rate_hz`` (Hz); n_sections = ⌈order/2⌉, each of unit gain at DC."""
    order = int(order)
    if order < 1:
        raise ValueError(f"filter order must be a positive integer, got {order}")
    if not 0.0 < cutoff_hz < 0.5 * rate_hz:
        raise ValueError(f"cutoff {cutoff_hz} Hz must lie in (0, {0.5 * rate_hz:g}) Hz for samples at {rate_hz:g} Hz")
    k = np.arange(order)
    p = np.exp(1j * np.pi * (2 * k + order + 1) / (2 * order))     # analog prototype poles
    s = 2.0 * rate_hz * np.tan(np.pi * cutoff_hz / rate_hz) * p    # pre-warped cutoff ω_a
    z = (2.0 * rate_hz + s) / (2.0 * rate_hz - s)                  # bilinear transform
    sections = []
    for zk in z[: order // 2]:                                      # one of each conjugate pair
        a1, a2 = -2.0 * zk.real, abs(zk) ** 2
        g = (1.0 + a1 + a2) / 4.0
        sections.append((abs(zk), [g, 2.0 * g, g, 1.0, a1, a2]))
    if order % 2:
        zr = z[order // 2].real                                     # the real pole
        g = (1.0 - zr) / 2.0
        sections.append((abs(zr), [g, g, 0.0, 1.0, -zr, 0.0]))
    sections.sort(key=lambda item: item[0])                         # nearest the unit circle last
    return np.array([row for _, row in sections], dtype=float)


def filtfilt_padlen(sos: np.ndarray) -> int:
    """Samples of odd extension at each end: 3·(2·n_sections + 1 − n_first_order)."""
    sos = np.asarray(sos)
    n_first_order = min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    return 3 * (2 * len(sos) + 1 - n_first_order)


def sosfiltfilt(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Zero-lag filtering of ``x (n,)`` or ``(n, m)`` along axis 0 by the cascade ``sos
    (n_sections, 6)`` of unit-DC-gain sections (module docstring). Needs n > padlen
    (:func:`filtfilt_padlen`). Returns a new array of x's shape (float64)."""
    x = np.asarray(x, dtype=float)
    sos = np.ascontiguousarray(sos, dtype=float)
    edge = filtfilt_padlen(sos)
    n = x.shape[0]
    if n <= edge:
        raise ValueError(f"zero-lag filtering needs more than {edge} samples, got {n}")
    x2 = x.reshape(n, -1)
    # odd extension about the end values: x_{−j} = 2 x_0 − x_j, x_{n−1+j} = 2 x_{n−1} − x_{n−1−j}
    ext = np.concatenate((2.0 * x2[:1] - x2[edge:0:-1], x2, 2.0 * x2[-1:] - x2[-2:-edge - 2:-1]))
    out = np.empty_like(ext)
    _forward_backward(sos, np.ascontiguousarray(ext), out)
    return out[edge:edge + n].reshape(x.shape)


@njit(cache=True)
def _forward_backward(sos, ext, out):
    """The cascade over ``ext (n, m)`` forward into ``out``, then backward over ``out`` in
    place, each pass started in the steady state of its first input sample."""
    n, m = ext.shape
    n_s = sos.shape[0]
    z = np.empty((n_s, 2))
    for j in range(m):
        for direction in range(2):
            first = 0 if direction == 0 else n - 1
            step = 1 if direction == 0 else -1
            v0 = ext[first, j] if direction == 0 else out[first, j]
            for s in range(n_s):
                z[s, 0] = (sos[s, 1] + sos[s, 2] - sos[s, 4] - sos[s, 5]) * v0
                z[s, 1] = (sos[s, 2] - sos[s, 5]) * v0
            i = first
            for _ in range(n):
                v = ext[i, j] if direction == 0 else out[i, j]
                for s in range(n_s):
                    y = sos[s, 0] * v + z[s, 0]
                    z[s, 0] = sos[s, 1] * v - sos[s, 4] * y + z[s, 1]
                    z[s, 1] = sos[s, 2] * v - sos[s, 5] * y
                    v = y
                out[i, j] = v
                i += step
