"""Muscle strengths as OpenSim's static optimisation computes them (``recruitment:
{static_optimization: opensim}``, docs/recruitment.md).

OpenSim's StaticOptimization with ``use_muscle_physiology`` overrides each muscle's
force with a · F_opt, where F_opt is its active fibre force along the tendon at full
activation with an inextensible tendon (``Muscle::calcInextensibleTendonActiveFiberForce``):

    F_opt = F0 · f_L(l̃) · f_V(ṽ) · cos α,

with the fibre length from the path and the tendon slack length (rigid tendon,
constant-thickness pennation: x = l_MT − Lt0 along the tendon, l_f = √(x² + h²),
cos α = x/l_f, h = Lf0 sin α0), the fibre velocity v_f = v_MT cos α, and Thelen's
(2003, Eqs. 6–7) force–velocity curve at a = 1 (OpenSim's ``Thelen2003Muscle``):

    concentric  (−1 < ṽ ≤ 0):   f_V = (1 + ṽ)/(1 − ṽ/A_f)
    eccentric   (ṽ > 0):        f_V = (1 + k F_len)/(1 + k),   k = ṽ (2 + 2/A_f)/(F_len − 1)
                                (twice openfdk's eccentric slope at ṽ = 0), continued
                                linearly (the same slope) beyond f_V = 0.95 F_len, OpenSim's
                                ``fv_linear_extrap_threshold``;
    ṽ ≤ −1:                     f_V = 0 (OpenSim extrapolates to a negative force).

The passive fibre force is not applied: an overridden muscle delivers exactly a · F_opt.
Millard muscles (:class:`~.millard.MillardMuscle`) use OpenSim's rule for that muscle,
:func:`.millard.opensim_so_strength` (the same F_opt with Millard's curves); OpenSim's
curve muscles (:class:`~.curve_muscle.CurveMuscle`) theirs, :func:`.curve_muscle.curve_so_strengths`.
Compared with openfdk's own rule (:mod:`.hill`: compliant tendon in equilibrium, the
passive force an applied load, a C¹ eccentric branch) this is what a user needs to
reproduce OpenSim's numbers. Verified against OpenSim 4.6's StaticOptimization
(tests/test_actuators.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: OpenSim's Thelen2003Muscle ``fv_linear_extrap_threshold`` default
LINEAR_EXTRAPOLATION_THRESHOLD = 0.95


@njit(cache=True)
def _thelen_force_velocity(v, a_f, f_len, threshold):
    """Thelen's force–velocity multiplier at full activation (module docstring)."""
    if v <= -1.0:
        return 0.0
    if v <= 0.0:
        return (1.0 + v) / (1.0 - v / a_f)
    c = (2.0 + 2.0 / a_f) / (f_len - 1.0)
    k = c * v
    fv = (1.0 + k * f_len) / (1.0 + k)
    if fv < threshold * f_len:
        return fv
    k_star = (threshold * f_len - 1.0) / (f_len * (1.0 - threshold))
    slope = c * (f_len - 1.0) / ((1.0 + k_star) * (1.0 + k_star))
    return threshold * f_len + slope * (v - k_star / c)


@njit(cache=True)
def rigid_tendon_strengths(params, l_mt, v_mt, threshold, out):
    """F_opt (n,) N of the muscles (rows of :class:`~.hill.MuscleSet`'s parameter table)
    at path lengths l_mt (n,) m and lengthening speeds v_mt (n,) m/s into ``out``; a
    constant-strength muscle keeps its strength."""
    for i in range(params.shape[0]):
        p = params[i]
        if p[0] != 1.0:  # constant strength (kind 0)
            out[i] = p[1]
            continue
        f0, lf0, lt0, h, v_max, width, a_f, f_len = p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8]
        x = l_mt[i] - lt0
        if x <= 0.0:
            out[i] = 0.0
            continue
        l_f = math.sqrt(x * x + h * h)
        cos_a = x / l_f
        f_l = math.exp(-((l_f / lf0 - 1.0) ** 2) / width)
        f_v = _thelen_force_velocity(v_mt[i] * cos_a / v_max, a_f, f_len, threshold)
        out[i] = f0 * f_l * f_v * cos_a


def opensim_strengths(muscle_set, l_mt, v_mt):
    """F_opt (n_muscles,) N of a :class:`~.hill.MuscleSet` (module docstring)."""
    out = np.empty(muscle_set.n_muscles)
    l_mt, v_mt = np.ascontiguousarray(l_mt, float), np.ascontiguousarray(v_mt, float)
    rigid_tendon_strengths(muscle_set._params, l_mt, v_mt, LINEAR_EXTRAPOLATION_THRESHOLD, out)
    if muscle_set._millard_params.size:  # Millard muscles: their own rule (.millard)
        from .millard import millard_so_strengths

        millard_so_strengths(muscle_set._millard_params, muscle_set._millard_slot, l_mt, v_mt, out)
    if muscle_set._curve_rows.size:  # OpenSim's curve muscles: their own rule (.curve_muscle)
        from .curve_muscle import curve_so_strengths

        curve_so_strengths(muscle_set._curve_rows, muscle_set._curve_functions, muscle_set._curve_slot, l_mt,
                           v_mt, out)
    return out
