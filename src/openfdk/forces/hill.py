"""Muscle strength models for inverse dynamics: constant strength and a Hill 3-element model.

In the recruitment (docs/design.md §1, paper Eq. 11) each muscle contributes an unknown active
force ``0 ≤ f^M ≤ s`` and a known passive force ``f_P`` (an applied load, tension
positive). A model maps the muscle–tendon length ``l_MT`` (m) and lengthening speed
``v_MT`` (m/s, positive when lengthening) to ``(s, f_P)``. The full derivation, every
parameter and its source are in docs/muscles.md; the equations in brief:

Normalised variables: ``l̃ = l_f/Lf0``, ``ṽ = v_f/(V_max·Lf0)``, ``ε_T = (l_T − Lt0)/Lt0``.

* Active force–length, Gaussian (Thelen 2003 Eq. 2): ``f_L = exp(−(l̃ − 1)²/γ)``,
  γ = 0.45.
* Force–velocity, Hill hyperbola (Hill 1938; Thelen 2003 Eqs. 6–7 at a = 1) with the
  curvature ``A = 0.1 + 0.4·ff`` from the fast-fibre fraction (Umberger et al. 2003)::

      f_V = 0                            ṽ ≤ −1
      f_V = (1 + ṽ)/(1 − ṽ/A)            −1 < ṽ ≤ 0   (concentric)
      f_V = (1 + c·F_len·ṽ)/(1 + c·ṽ)    ṽ > 0        (eccentric)
      c = (1 + 1/A)/(F_len − 1)

  ``c`` makes f_V C¹ at ṽ = 0 (Thelen uses twice this slope, a kink; see docs).
* Parallel elastic (Thelen 2003 Eq. 3), shape factor ``k_PE`` and strain ``ε0_M`` at F0::

      f_PE = (exp(k_PE (l̃ − 1)/ε0_M) − 1)/(exp(k_PE) − 1)  for l̃ > 1, else 0

* Tendon (Thelen 2003 Eq. 5, exponential toe + linear), strain ``ε0_T`` at F0::

      f_T = F_toe (exp(k_toe ε_T/ε_toe) − 1)/(exp(k_toe) − 1)   0 < ε_T ≤ ε_toe
      f_T = F_toe + k_lin (ε_T − ε_toe)                         ε_T > ε_toe, else 0

  F_toe = 0.33, k_toe = 3; ``ε_toe`` and ``k_lin`` are solved so that f_T is C¹ at
  ε_toe and f_T(ε0_T) = 1 exactly (Thelen rounds them to 0.609 ε0_T and 1.712/ε0_T).
* Constant-thickness pennation (Zajac 1989): ``l_f sin α = Lf0 sin α0 = h``, and
  ``l_MT = l_T + l_f cos α``.

Inverse-dynamics rule (the state is resolved without knowing the activation ``a``):
the fibre length is the root of the tendon–fibre equilibrium
``F0 f_T(ε_T) = F0 (a f_L f_V + f_PE) cos α`` for ``a = 0`` (passive state, tendon force
``T0``) and ``a = 1`` (maximal state, ``T1``), with the rigid-tendon velocity split
``v_f = v_MT cos α``. Then ``f_P = T0`` and ``s = T1 − T0``: at ``f^M = s`` the unit
delivers exactly its maximal tendon force. Both roots come from a bracketed, safeguarded
Newton iteration; the bracket of the maximal state ends at the passive root, so T1 ≥ T0.

References: Hill AV (1938) Proc R Soc B 126:136–195. Zajac FE (1989) Crit Rev Biomed Eng
17:359–411. Thelen DG (2003) J Biomech Eng 125:70–77. Umberger BR, Gerritsen KGM,
Martin PE (2003) Comput Methods Biomech Biomed Engin 6:99–111.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit

from .bracketed_newton import bracketed_newton_step

__all__ = [
    "MuscleParameterError",
    "ConstantStrengthMuscle",
    "Hill3ElementMuscle",
    "MuscleSet",
    "MuscleStates",
    "hill_curvature",
    "tendon_toe_constants",
    "active_force_length",
    "force_velocity",
    "passive_force_length",
    "tendon_force_strain",
]

TENDON_TOE_FORCE = 0.33  # F_toe, normalised tendon force at the end of the toe (Thelen 2003)
TENDON_TOE_SHAPE = 3.0  # k_toe, exponential shape of the toe (Thelen 2003)

STATUS_OK = 0  # both equilibria solved
STATUS_SLACK = 1  # l_MT ≤ Lt0: the unit cannot be taut; s = f_P = 0
STATUS_COLLAPSED = 2  # no maximal-state root: tendon cannot balance the fibre at any length

_KIND_CONSTANT, _KIND_HILL = 0.0, 1.0
# parameter row: kind, F0|strength, Lf0, Lt0, h, V_max (m/s), γ, A, F_len, c, k_PE, ε0_M,
# ε_toe, k_lin
_N_PARAMS = 14
# output row: s, f_P, ds/dl, ds/dv, df_P/dl, l_f(a=1), l_f(a=0), T1, status
_N_OUT = 9


class MuscleParameterError(ValueError):
    """A muscle parameter or input is invalid; the message names the muscle."""


# ----------------------------------------------------------------------------- curves
@njit(cache=True)
def _active_force_length(l_norm, width):
    # f_L = exp(−(l̃ − 1)²/γ) (Thelen 2003 Eq. 2) and df_L/dl̃
    f = math.exp(-((l_norm - 1.0) ** 2) / width)
    return f, -2.0 * (l_norm - 1.0) / width * f


@njit(cache=True)
def _force_velocity(v_norm, curvature, f_len, c_ecc):
    if v_norm <= -1.0:  # faster than V_max: no active force
        return 0.0, 0.0
    if v_norm <= 0.0:  # concentric Hill hyperbola (1 + ṽ)/(1 − ṽ/A)
        den = 1.0 - v_norm / curvature
        return (1.0 + v_norm) / den, (1.0 + 1.0 / curvature) / (den * den)
    den = 1.0 + c_ecc * v_norm  # eccentric (1 + c F_len ṽ)/(1 + c ṽ)
    return (1.0 + c_ecc * f_len * v_norm) / den, c_ecc * (f_len - 1.0) / (den * den)


@njit(cache=True)
def _passive_force_length(l_norm, shape, strain_at_f0):
    if l_norm <= 1.0:
        return 0.0, 0.0
    # f_PE = (exp(k_PE (l̃ − 1)/ε0_M) − 1)/(exp(k_PE) − 1) (Thelen 2003 Eq. 3)
    scale = 1.0 / math.expm1(shape)
    e = math.exp(shape * (l_norm - 1.0) / strain_at_f0)
    return (e - 1.0) * scale, shape / strain_at_f0 * e * scale


@njit(cache=True)
def _tendon_force_strain(strain, strain_toe, k_lin):
    if strain <= 0.0:
        return 0.0, 0.0
    if strain <= strain_toe:
        # toe: F_toe (exp(k_toe ε/ε_toe) − 1)/(exp(k_toe) − 1) (Thelen 2003 Eq. 5)
        scale = TENDON_TOE_FORCE / math.expm1(TENDON_TOE_SHAPE)
        e = math.exp(TENDON_TOE_SHAPE * strain / strain_toe)
        return (e - 1.0) * scale, TENDON_TOE_SHAPE / strain_toe * e * scale
    return TENDON_TOE_FORCE + k_lin * (strain - strain_toe), k_lin


def hill_curvature(fast_fibre_fraction):
    """Hill curvature ``A = a/F0 = 0.1 + 0.4·ff`` (Umberger et al. 2003); ff in [0, 1]."""
    return 0.1 + 0.4 * np.asarray(fast_fibre_fraction, dtype=float)


def tendon_toe_constants(strain_at_max_force):
    """``(ε_toe, k_lin)`` that make the tendon curve C¹ with ``f_T(ε0_T) = 1``.

    With ``S = F_toe k_toe e^k_toe/(e^k_toe − 1)`` (the toe slope at ε_toe times ε_toe):
    ``ε_toe = r ε0_T`` with ``r = S/(S + 1 − F_toe)``, and
    ``k_lin = (1 − F_toe)/(ε0_T − ε_toe)``.
    strain_at_max_force : ε0_T, dimensionless. Returns (ε_toe, k_lin), dimensionless.
    """
    s_toe = TENDON_TOE_FORCE * TENDON_TOE_SHAPE / -math.expm1(-TENDON_TOE_SHAPE)
    ratio = s_toe / (s_toe + 1.0 - TENDON_TOE_FORCE)
    strain_toe = ratio * float(strain_at_max_force)
    return strain_toe, (1.0 - TENDON_TOE_FORCE) / (float(strain_at_max_force) - strain_toe)


def _vectorised(curve, x, *args):
    value, slope = np.vectorize(lambda xi: curve(float(xi), *args), otypes=[float, float])(x)
    return (value, slope) if np.ndim(value) else (float(value), float(slope))


def active_force_length(l_norm, width=0.45):
    """Active force–length ``f_L(l̃)`` and ``df_L/dl̃``; ``l_norm`` any shape (l_f/Lf0)."""
    return _vectorised(_active_force_length, l_norm, float(width))


def force_velocity(v_norm, curvature=0.26, max_eccentric_force=1.4):
    """Force–velocity ``f_V(ṽ)`` and ``df_V/dṽ``; ``v_norm`` any shape (v_f/(V_max Lf0))."""
    c_ecc = (1.0 + 1.0 / curvature) / (max_eccentric_force - 1.0)
    return _vectorised(_force_velocity, v_norm, float(curvature), float(max_eccentric_force), c_ecc)


def passive_force_length(l_norm, shape_factor=3.0, strain_at_max_force=0.6):
    """Parallel-elastic ``f_PE(l̃)`` and ``df_PE/dl̃``; ``l_norm`` any shape (l_f/Lf0)."""
    return _vectorised(_passive_force_length, l_norm, float(shape_factor),
                       float(strain_at_max_force))


def tendon_force_strain(strain, strain_at_max_force=0.053):
    """Tendon ``f_T(ε_T)`` and ``df_T/dε_T``; ``strain`` any shape ((l_T − Lt0)/Lt0)."""
    strain_toe, k_lin = tendon_toe_constants(strain_at_max_force)
    return _vectorised(_tendon_force_strain, strain, strain_toe, k_lin)


# ------------------------------------------------------------------- equilibrium kernel
@njit(cache=True)
def _equilibrium_residual(x, activation, l_mt, v_mt, p):
    """R(x) = F0 f_T − F0 (a f_L f_V + f_PE) cos α at along-tendon fibre length x (m).

    Returns R (N), ∂R/∂x, ∂R/∂l_MT (N/m), ∂R/∂v_MT (N·s/m), tendon force (N).
    """
    f0, lf0, lt0, h, v_max = p[1], p[2], p[3], p[4], p[5]
    l_f = math.sqrt(x * x + h * h)  # constant thickness: l_f sin α = h
    cos_a = x / l_f
    dcos_dx = h * h / (l_f * l_f * l_f)  # d(x/l_f)/dx = sin²α/l_f
    l_norm = l_f / lf0
    dlnorm_dx = cos_a / lf0  # dl_f/dx = cos α
    f_t, df_t = _tendon_force_strain((l_mt - x - lt0) / lt0, p[12], p[13])
    tendon_stiffness = f0 * df_t / lt0  # dT/dl_T, N/m
    g, dg_dx = _passive_force_length(l_norm, p[10], p[11])
    dg_dx *= dlnorm_dx
    dr_dv = 0.0
    if activation > 0.0:
        f_l, df_l = _active_force_length(l_norm, p[6])
        v_norm = v_mt * cos_a / v_max  # rigid-tendon split: v_f = v_MT cos α
        f_v, df_v = _force_velocity(v_norm, p[7], p[8], p[9])
        g += activation * f_l * f_v
        dg_dx += activation * (df_l * dlnorm_dx * f_v + f_l * df_v * v_mt * dcos_dx / v_max)
        dr_dv = -f0 * activation * f_l * df_v * cos_a * cos_a / v_max
    r = f0 * f_t - f0 * g * cos_a
    dr_dx = -tendon_stiffness - f0 * (dg_dx * cos_a + g * dcos_dx)
    return r, dr_dx, tendon_stiffness, dr_dv, f0 * f_t


@njit(cache=True)
def _solve_equilibrium(activation, x_lo, x_hi, x_start, l_mt, v_mt, p):
    """Root of R on [x_lo, x_hi] (R(x_lo) > 0 ≥ R(x_hi)) by safeguarded Newton.

    Newton steps that leave the current bracket, or meet ∂R/∂x ≥ 0, are replaced by
    bisection, so the iteration always converges to a root inside the bracket.
    """
    lo, hi = x_lo, x_hi
    x = min(max(x_start, lo), hi)
    tolerance = 1e-12 * p[1]
    for _ in range(200):
        r, dr_dx, _k, _dv, _t = _equilibrium_residual(x, activation, l_mt, v_mt, p)
        if abs(r) <= tolerance:
            break
        x, lo, hi, done = bracketed_newton_step(x, r, dr_dx, lo, hi)
        if done:
            break
    return x


@njit(cache=True)
def _evaluate_kernel(params, index, l_mt, v_mt, out):
    """Fill out[:, i] = (s, f_P, ds/dl, ds/dv, df_P/dl, l_f1, l_f0, T1, status) per state i."""
    for i in range(l_mt.shape[0]):
        p = params[index[i]]
        for j in range(_N_OUT):
            out[j, i] = 0.0
        if p[0] == _KIND_CONSTANT:
            out[0, i] = p[1]
            out[5, i] = np.nan
            out[6, i] = np.nan
            continue
        lf0, lt0, h = p[2], p[3], p[4]
        x_lo = 1e-6 * lf0  # shortest along-tendon fibre length considered
        x_hi = l_mt[i] - lt0  # tendon exactly at slack length
        if x_hi <= x_lo:  # the unit is shorter than its tendon: slack, no force
            out[5, i] = out[6, i] = math.sqrt(x_lo * x_lo + h * h)
            out[8, i] = STATUS_SLACK
            continue
        # passive state (a = 0): F0 f_T = F0 f_PE cos α; zero force while l_f ≤ Lf0
        x_opt = math.sqrt(max(lf0 * lf0 - h * h, 0.0))
        t0, dt0_dl = 0.0, 0.0
        x0 = x_hi
        if x_hi > x_opt:
            x0 = _solve_equilibrium(0.0, x_opt, x_hi, x_hi - lt0 * p[12], l_mt[i], 0.0, p)
            _r, dr_dx, k_t, _dv, t0 = _equilibrium_residual(x0, 0.0, l_mt[i], 0.0, p)
            # implicit function: dx/dl = −R_l/R_x, dT/dl = k_T (1 − dx/dl)
            dt0_dl = k_t * (1.0 + k_t / dr_dx) if dr_dx != 0.0 else 0.0
        out[1, i] = t0
        out[4, i] = dt0_dl
        out[6, i] = math.sqrt(x0 * x0 + h * h)
        # maximal state (a = 1), bracketed by [x_lo, passive root] so that T1 ≥ T0
        r_lo, _dx, k_lo, _dv, t_lo = _equilibrium_residual(x_lo, 1.0, l_mt[i], v_mt[i], p)
        if r_lo <= 0.0:  # the fibre out-pulls the tendon at every length: collapsed
            x1, t1, dt1_dl, dt1_dv = x_lo, t_lo, k_lo, 0.0
            out[8, i] = STATUS_COLLAPSED
        else:
            x_start = x_hi - lt0 * (p[12] + (1.0 - TENDON_TOE_FORCE) / p[13])  # ε_T = ε0_T
            x1 = _solve_equilibrium(1.0, x_lo, x0, x_start, l_mt[i], v_mt[i], p)
            _r, dr_dx, k_t, dr_dv, t1 = _equilibrium_residual(x1, 1.0, l_mt[i], v_mt[i], p)
            dt1_dl, dt1_dv = 0.0, 0.0  # R_x = 0 only with a slack tendon and no fibre force
            if dr_dx != 0.0:
                dt1_dl = k_t * (1.0 + k_t / dr_dx)  # dT/dl = k_T (1 − dx/dl)
                dt1_dv = k_t * dr_dv / dr_dx  # dT/dv = −k_T dx/dv, dx/dv = −R_v/R_x
        # s = T1 − T0 (never negative)
        if t1 > t0:
            out[0, i] = t1 - t0
            out[2, i] = dt1_dl - dt0_dl
            out[3, i] = dt1_dv
        out[5, i] = math.sqrt(x1 * x1 + h * h)
        out[7, i] = t1


# ------------------------------------------------------------------------- models
def _label(kind, name):
    return f"{kind} '{name}'" if name else kind


def _check(label, field, value, unit, ok, expected):
    value_f = float(value)
    if not (math.isfinite(value_f) and ok(value_f)):
        raise MuscleParameterError(
            f"{label}: {field} must be finite and {expected} {unit}, got {value!r}")


@dataclass(frozen=True)
class ConstantStrengthMuscle:
    """Constant strength: ``s = strength`` (N, > 0), ``f_P = 0``, for any state.

    Also models the unilateral "muscles" of the POP TMJ (20 kN push-only reactions).
    """

    strength: float
    name: str = ""

    def __post_init__(self):
        _check(_label("ConstantStrengthMuscle", self.name), "strength", self.strength, "N",
               lambda x: x > 0.0, "> 0")

    def _row(self):
        row = np.zeros(_N_PARAMS)
        row[0], row[1] = _KIND_CONSTANT, self.strength
        return row

    def evaluate(self, l_MT, v_MT):
        """``(s, f_P)`` for states of this muscle; l_MT (n,) m, v_MT (n,) m/s -> (n,) N, (n,) N."""
        return _evaluate_single(self, l_MT, v_MT)


#: the shortest optimal fibre and tendon slack length, m (found by the fuzz suite: 1e-303 m
#: made the fibre equilibrium divide by zero)
MIN_LENGTH_M = 1e-9


@dataclass(frozen=True)
class Hill3ElementMuscle:
    """Hill-type 3-element muscle (contractile, parallel elastic, serial elastic tendon).

    Parameters (defaults and sources in docs/muscles.md):

    max_isometric_force : F0, N (> 0).
    optimal_fibre_length : Lf0, m (>= MIN_LENGTH_M, 1e-9).
    tendon_slack_length : Lt0, m (>= MIN_LENGTH_M, 1e-9).
    tendon_strain_at_max_force : ε0_T, default 0.053 (tendon strain at F0).
    pennation_angle_at_optimal : α0, rad, default 0 (in [0, π/2)).
    fast_fibre_fraction : ff, default 0.4 (in [0, 1]); Hill curvature A = 0.1 + 0.4 ff.
    passive_shape_factor : k_PE, default 3 (exponential shape of the parallel element).
    passive_strain_at_max_force : ε0_M, default 0.6 (fibre strain at which f_PE = F0).
    max_contraction_velocity : V_max, Lf0/s, default 10 (Zajac 1989; Thelen 2003).
    force_length_width : γ, default 0.45 (Gaussian force–length, Thelen 2003).
    max_eccentric_force : F_len, ×F0, default 1.4 (asymptote of the eccentric branch, > 1).
    name : str, used in error messages.
    """

    max_isometric_force: float
    optimal_fibre_length: float
    tendon_slack_length: float
    tendon_strain_at_max_force: float = 0.053
    pennation_angle_at_optimal: float = 0.0
    fast_fibre_fraction: float = 0.4
    passive_shape_factor: float = 3.0
    passive_strain_at_max_force: float = 0.6
    max_contraction_velocity: float = 10.0
    force_length_width: float = 0.45
    max_eccentric_force: float = 1.4
    name: str = ""

    def __post_init__(self):
        label = _label("Hill3ElementMuscle", self.name)
        positive = (lambda x: x > 0.0, "> 0")
        # a shorter length overflows the normalised lengths (l / Lf0) of any real path
        length = (lambda x: x >= MIN_LENGTH_M, f">= {MIN_LENGTH_M:g}")
        for field, unit, (ok, expected) in (
            ("max_isometric_force", "N", positive),
            ("optimal_fibre_length", "m", length),
            ("tendon_slack_length", "m", length),
            ("tendon_strain_at_max_force", "", positive),
            ("pennation_angle_at_optimal", "rad",
             (lambda x: 0.0 <= x < 0.5 * math.pi, "in [0, π/2)")),
            ("fast_fibre_fraction", "", (lambda x: 0.0 <= x <= 1.0, "in [0, 1]")),
            ("passive_shape_factor", "", positive),
            ("passive_strain_at_max_force", "", positive),
            ("max_contraction_velocity", "Lf0/s", positive),
            ("force_length_width", "", positive),
            ("max_eccentric_force", "×F0", (lambda x: x > 1.0, "> 1")),
        ):
            _check(label, field, getattr(self, field), unit, ok, expected)

    def _row(self):
        curvature = float(hill_curvature(self.fast_fibre_fraction))
        strain_toe, k_lin = tendon_toe_constants(self.tendon_strain_at_max_force)
        lf0 = self.optimal_fibre_length
        return np.array([
            _KIND_HILL, self.max_isometric_force, lf0, self.tendon_slack_length,
            lf0 * math.sin(self.pennation_angle_at_optimal),  # h, constant thickness
            self.max_contraction_velocity * lf0,  # V_max in m/s
            self.force_length_width, curvature, self.max_eccentric_force,
            (1.0 + 1.0 / curvature) / (self.max_eccentric_force - 1.0),  # c, C¹ at ṽ = 0
            self.passive_shape_factor, self.passive_strain_at_max_force, strain_toe, k_lin,
        ])

    def evaluate(self, l_MT, v_MT):
        """``(s, f_P)`` for states of this muscle; l_MT (n,) m, v_MT (n,) m/s -> (n,) N, (n,) N."""
        return _evaluate_single(self, l_MT, v_MT)

    def evaluate_states(self, l_MT, v_MT):
        """Full :class:`MuscleStates` for n states of this muscle (l_MT (n,) m, v_MT (n,) m/s)."""
        return _single_states(self, l_MT, v_MT)


def _single_states(muscle, l_MT, v_MT):
    l_MT, v_MT = np.broadcast_arrays(np.atleast_1d(l_MT), np.atleast_1d(v_MT))
    return MuscleSet([muscle])._states(l_MT, v_MT, True)


def _evaluate_single(muscle, l_MT, v_MT):
    states = _single_states(muscle, l_MT, v_MT)
    if np.ndim(l_MT) == 0 and np.ndim(v_MT) == 0:
        return float(states.strength[0]), float(states.passive_force[0])
    return states.strength, states.passive_force


@dataclass(frozen=True)
class MuscleStates:
    """Per-muscle results of :meth:`MuscleSet.evaluate_states`; every field is (n,).

    strength s (N); passive_force f_P (N); dstrength_dlength ds/dl_MT (N/m);
    dstrength_dspeed ds/dv_MT (N·s/m); dpassive_dlength df_P/dl_MT (N/m; f_P does not
    depend on v_MT); fibre_length_active / fibre_length_passive: l_f at the a = 1 / a = 0
    equilibria (m, NaN for constant-strength muscles); tendon_force_active T1 (N);
    status (int): 0 ok, 1 slack (l_MT ≤ Lt0), 2 collapsed (no a = 1 equilibrium).
    Derivatives are one-sided at the kinks listed in docs/muscles.md.
    """

    strength: np.ndarray
    passive_force: np.ndarray
    dstrength_dlength: np.ndarray
    dstrength_dspeed: np.ndarray
    dpassive_dlength: np.ndarray
    fibre_length_active: np.ndarray
    fibre_length_passive: np.ndarray
    tendon_force_active: np.ndarray
    status: np.ndarray


class MuscleSet:
    """Many muscles of mixed kinds evaluated at once (one compiled loop, no Python per muscle).

    muscles : sequence of :class:`ConstantStrengthMuscle` / :class:`Hill3ElementMuscle` /
    :class:`~.millard.MillardMuscle` / :class:`~.curve_muscle.CurveMuscle`, in the order of the recruitment's muscle columns. Non-empty names must be unique.
    """

    def __init__(self, muscles: Sequence):
        from .curve_muscle import CurveMuscle, curve_tables
        from .millard import MillardMuscle

        muscles = tuple(muscles)
        seen = set()
        for i, muscle in enumerate(muscles):
            if not isinstance(muscle, (ConstantStrengthMuscle, Hill3ElementMuscle, MillardMuscle, CurveMuscle)):
                raise MuscleParameterError(
                    f"muscle {i} is a {type(muscle).__name__}; expected ConstantStrengthMuscle, "
                    "Hill3ElementMuscle, MillardMuscle or CurveMuscle")
            if muscle.name and muscle.name in seen:
                raise MuscleParameterError(f"muscle name '{muscle.name}' appears twice in the set")
            seen.add(muscle.name)
        self.muscles = muscles
        self.names = tuple(m.name for m in muscles)
        self.n_muscles = len(muscles)
        # Millard muscles (wide rows, :mod:`.millard`) sit in the Hill table as placeholder
        # constant rows and are evaluated by their own kernel; _millard_slot maps a muscle
        # to its row of _millard_params (−1: not a Millard muscle)
        is_millard = [isinstance(m, MillardMuscle) for m in muscles]
        is_curve = [isinstance(m, CurveMuscle) for m in muscles]  # the same for :mod:`.curve_muscle`
        placeholder = ConstantStrengthMuscle(1.0)._row()
        self._params = np.array([placeholder if mm or mc else m._row()
                                 for m, mm, mc in zip(muscles, is_millard, is_curve)]).reshape(-1, _N_PARAMS)
        self._curve_slot = np.cumsum(is_curve, dtype=np.int64) - 1
        self._curve_slot[~np.array(is_curve, dtype=bool)] = -1
        self._curve_rows, self._curve_functions = curve_tables([m for m, mc in zip(muscles, is_curve) if mc])
        self._millard_slot = np.cumsum(is_millard, dtype=np.int64) - 1
        self._millard_slot[~np.array(is_millard, dtype=bool)] = -1
        self._millard_params = np.array([m._row() for m, mm in zip(muscles, is_millard) if mm])
        self._index = np.arange(self.n_muscles, dtype=np.int64)
        # the last whole-set states (l_MT, v_MT, out): Millard rows whose l_MT and v_MT are
        # the same bit for bit are copied instead of solved again (a Jacobian's differences
        # and Newton's iterates move only the muscles that cross the moved joints)
        self._last = None

    def _run(self, l_MT, v_MT, single):
        l_MT = np.ascontiguousarray(l_MT, dtype=float)
        v_MT = np.ascontiguousarray(v_MT, dtype=float)
        if single:
            if l_MT.ndim != 1 or v_MT.shape != l_MT.shape:
                raise MuscleParameterError(
                    f"{self._who(0)}: l_MT and v_MT must be scalars or equal-length (n,) arrays, "
                    f"got shapes {l_MT.shape} and {v_MT.shape}")
            index = np.zeros(l_MT.shape[0], dtype=np.int64)
        else:
            if l_MT.shape != (self.n_muscles,) or v_MT.shape != (self.n_muscles,):
                raise MuscleParameterError(
                    f"MuscleSet: l_MT and v_MT must have shape ({self.n_muscles},), "
                    f"got {l_MT.shape} and {v_MT.shape}")
            index = self._index
        bad = ~(np.isfinite(l_MT) & np.isfinite(v_MT))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise MuscleParameterError(
                f"{self._who(index[k])}: non-finite muscle-tendon state l_MT={l_MT[k]!r} m, "
                f"v_MT={v_MT[k]!r} m/s")
        out = np.empty((_N_OUT, l_MT.shape[0]))  # rows are contiguous (n,) results
        _evaluate_kernel(self._params, index, l_MT, v_MT, out)
        if self._millard_params.size:
            from .millard import millard_states

            slot = self._millard_slot[index]
            last = None if single else self._last
            if last is not None:
                same = (l_MT == last[0]) & (v_MT == last[1]) & (slot >= 0)
                out[:, same] = last[2][:, same]
                slot = np.where(same, -1, slot)
            millard_states(self._millard_params, slot, l_MT, v_MT, out)
            if not single:
                self._last = (l_MT.copy(), v_MT.copy(), out.copy())
        if self._curve_rows.size:
            from .curve_muscle import curve_states

            curve_states(self._curve_rows, self._curve_functions, self._curve_slot[index], l_MT, v_MT, out)
        return out

    def _who(self, i):
        name = self.names[i]
        return f"muscle {i}" + (f" '{name}'" if name else "")

    def evaluate(self, l_MT, v_MT):
        """Strengths and passive forces of all muscles.

        l_MT : (n_muscles,) m, muscle–tendon lengths. v_MT : (n_muscles,) m/s, lengthening
        speeds. Returns (strength (n_muscles,) N, passive_force (n_muscles,) N).
        """
        out = self._run(l_MT, v_MT, False)
        return out[0], out[1]

    def evaluate_with_passive_slope(self, l_MT, v_MT):
        """(strength (n_muscles,) N, passive force f_P (n_muscles,) N, df_P/dl_MT
        (n_muscles,) N/m) of all muscles; l_MT (n_muscles,) m, v_MT (n_muscles,) m/s."""
        out = self._run(l_MT, v_MT, False)
        return out[0], out[1], out[4]

    def evaluate_states(self, l_MT, v_MT):
        """Like :meth:`evaluate` but returns the full :class:`MuscleStates` (derivatives,
        fibre lengths, status); l_MT (n_muscles,) m, v_MT (n_muscles,) m/s."""
        return self._states(l_MT, v_MT, False)

    def _states(self, l_MT, v_MT, single):
        out = self._run(l_MT, v_MT, single)
        return MuscleStates(
            strength=out[0], passive_force=out[1], dstrength_dlength=out[2],
            dstrength_dspeed=out[3], dpassive_dlength=out[4],
            fibre_length_active=out[5], fibre_length_passive=out[6],
            tendon_force_active=out[7], status=out[8].astype(np.int64))
