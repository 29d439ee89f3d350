"""What OpenSim's InverseDynamicsTool does to a coordinate file before it differentiates
it, so that ``--motion FILE --motion-cutoff HZ`` gives OpenSim's generalised forces
(OpenSim 4.6, ``InverseDynamicsTool::run``, ``Storage::pad``, ``Storage::lowpassIIR``,
``Signal::Pad``, ``Signal::LowpassIIR``; read to learn what they compute):

1. **Padding** (:func:`pad_odd`): n // 2 samples are added at each end, the samples
   reflected about the end sample in time and in value (y(t_0 − τ) = 2 y(t_0) − y(t_0 + τ)),
   which continues the value and the slope; the time column is padded the same way.
2. **Filter** (:func:`lowpass_iir3`): the third-order Butterworth low-pass filter by the
   bilinear transform with the cut-off prewarped, H(s) = 1/((s + 1)(s² + s + 1)) at
   s = (1 − z⁻¹)/(ω_a (1 + z⁻¹)), ω_a = tan(π f_c T), run forward and then backward over
   the padded samples. Each pass starts with its first three outputs equal to its inputs.
3. **Spline**: the natural quintic spline through the padded, filtered samples
   (``GCVSpline`` of degree 5, error variance 0: :mod:`openfdk.numerics.natural_spline`),
   whose derivatives are the velocities and accelerations.

Without a cut-off OpenSim neither pads nor filters, and splines the samples as given.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pad_odd", "iir3_coefficients", "lowpass_iir3"]


def pad_odd(times, values, pad: int):
    """(times (n + 2 pad,), values (n + 2 pad, k)): ``values (n, k)`` at ``times (n,)``
    with ``pad`` ≤ n − 1 samples added at each end by odd reflection about the end
    samples (module docstring, step 1). Units: those of the inputs."""
    times = np.asarray(times, dtype=float)
    values = np.asarray(values, dtype=float)
    if pad == 0:
        return times, values
    if not 0 < pad < len(times):
        raise ValueError(f"padding of {pad} samples needs more than {pad} samples, got {len(times)}")

    def reflect(a):
        head = 2.0 * a[0] - a[pad:0:-1]
        tail = 2.0 * a[-1] - a[-2:-2 - pad:-1]
        return np.concatenate([head, a, tail])

    return reflect(times), reflect(values)


def iir3_coefficients(cutoff_hz: float, dt: float):
    """(b (4,), a (4,)) of the filter of step 2 (module docstring): y_i = Σ_j b_j x_{i−j}
    − Σ_{j≥1} a_j y_{i−j}, a_0 = 1. ``cutoff_hz`` in Hz, below 1/(2 dt); ``dt`` in s."""
    wa = np.tan(np.pi * cutoff_hz * dt)
    # both sides multiplied by ω_a³ (1 + z⁻¹)³; polynomials in z⁻¹, lowest power first
    one_plus, one_minus = np.array([1.0, 1.0]), np.array([1.0, -1.0])
    first = one_minus + wa * one_plus                                # s + 1
    second = (np.convolve(one_minus, one_minus) + wa * np.convolve(one_minus, one_plus)
              + wa * wa * np.convolve(one_plus, one_plus))          # s² + s + 1
    a = np.convolve(first, second)
    b = wa ** 3 * np.array([1.0, 3.0, 3.0, 1.0])
    return b / a[0], a / a[0]


def lowpass_iir3(values, cutoff_hz: float, dt: float):
    """``values (n, k)`` sampled every ``dt`` s, filtered by step 2 of the module
    docstring (forward, then backward; the first three outputs of each pass equal to its
    inputs): ``(n, k)``, the units of ``values``. Needs n ≥ 4 and a cut-off below the
    Nyquist frequency."""
    from scipy.signal import lfilter, lfiltic

    x = np.array(values, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.shape[0] < 4:
        raise ValueError(f"the filter needs at least 4 samples, got {x.shape[0]}")
    if not 0.0 < cutoff_hz < 0.5 / dt:
        raise ValueError(f"cut-off {cutoff_hz:g} Hz must be positive and below the Nyquist frequency {0.5 / dt:g} Hz")
    b, a = iir3_coefficients(cutoff_hz, dt)

    def one_pass(s):
        out = s.copy()
        for c in range(s.shape[1]):
            zi = lfiltic(b, a, s[2::-1, c], s[2::-1, c])  # the past three outputs equal the inputs
            out[3:, c] = lfilter(b, a, s[3:, c], zi=zi)[0]
        return out

    return one_pass(one_pass(x)[::-1])[::-1]
