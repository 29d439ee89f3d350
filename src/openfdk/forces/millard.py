"""Millard et al. (2013) equilibrium muscle (OpenSim's ``Millard2012EquilibriumMuscle``) as
an openfdk strength model (docs/muscles.md, "Millard muscle").

The curves are OpenSim's (:mod:`.millard_curves`): active force–length f_L(l̃),
force–velocity f_V(ṽ), passive fibre force–length f_PE(l̃) and tendon force–length
f_T(l_T/Lt0), as the muscle adjusts them (``Millard2012EquilibriumMuscle::
extendFinalizeFromProperties``):

* *damped model* (``fiber_damping`` ≥ 0.001) or a rigid tendon (``ignore_tendon_compliance``):
  f_L's ``minimum_value`` becomes 0 and f_V's slopes at ±V_max become 0;
* *classic Hill model* (compliant tendon, no damping): f_L's ``minimum_value`` is raised to
  0.1 and f_V's slopes at ±V_max to at least half the slopes near ±V_max.

Pennation: constant thickness h = Lf0 sin α0 (``MuscleFixedWidthPennationModel``), sin α =
h/l_f, capped at ``maximum_pennation_angle`` (default acos 0.1); the fibre never gets shorter
than l_min = max(``min_norm_active_fiber_length``·Lf0, h/sin α_max) (OpenSim's clamp).

Inverse-dynamics rule (openfdk's, as for :class:`~.hill.Hill3ElementMuscle`): the tendon
force T(a) solves the fibre–tendon equilibrium

    F0 f_T((l_MT − x)/Lt0) = F0 (a f_L(l̃) f_V(ṽ) + f_PE(l̃)) cos α,   x = l_f cos α,

for a = 0 (T0) and a = 1 (T1), with the rigid-tendon velocity split ṽ = v_MT cos α/(V_max Lf0);
f_P = T0 and s = T1 − T0. With ``ignore_tendon_compliance`` the tendon stays at Lt0
(x = l_MT − Lt0, no equilibrium). ``fiber_damping`` selects OpenSim's damped or classic
curves (above); the damping force F0 β ṽ itself is not part of openfdk's strengths (it is
zero at zero fibre speed, so static and isometric states are unaffected; OpenSim's static
optimisation ignores it too). ``minimum_activation`` is read but does not enter the rule
(openfdk's passive state is a = 0; docs/muscles.md).

OpenSim's static optimisation (``recruitment: {static_optimization: opensim}``) uses
``calcInextensibleTendonActiveFiberForce`` instead: :func:`opensim_so_strength` below.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from .bracketed_newton import bracketed_newton_step
from .millard_curves import (CURVE_WIDTH, ActiveForceLengthCurve, CurveError, FiberForceLengthCurve,
                             ForceVelocityCurve, TendonForceLengthCurve, curve_value)

__all__ = ["MillardMuscle", "MIN_NONZERO_DAMPING", "millard_states", "millard_so_strengths"]

#: OpenSim's MIN_NONZERO_DAMPING_COEFFICIENT: below it the muscle is the undamped (classic) model
MIN_NONZERO_DAMPING = 0.001
_EPS = float(np.finfo(float).eps)
_SIGNIFICANT = _EPS ** 0.875  # SimTK::SignificantReal ≈ 1.8e-14

# row layout (the curves' layout is millard_curves.CURVE_WIDTH, SEGMENT_WIDTH = 21)
_F0, _LF0, _LT0, _H, _VMAX, _LMIN, _XMIN, _PEN_LMIN, _PEN_XMIN, _MAXPEN, _ALPHA0, _RIGID, _EISO, _ACCEL = range(1, 15)
_FAL = 16
_FV = _FAL + CURVE_WIDTH
_FPE = _FV + CURVE_WIDTH
_FSE = _FPE + CURVE_WIDTH
N_ROW = _FSE + CURVE_WIDTH

STATUS_OK, STATUS_SLACK, STATUS_COLLAPSED = 0, 1, 2


def _check(who, name, value, ok, expected):
    if not (isinstance(value, (int, float)) and math.isfinite(float(value)) and ok(float(value))):
        from .hill import MuscleParameterError
        raise MuscleParameterError(f"{who}: {name} must be finite and {expected}, got {value!r}")


@dataclass(frozen=True)
class MillardMuscle:
    """Millard 2012 equilibrium muscle (module docstring; defaults are OpenSim's).

    max_isometric_force : F0, N (> 0). optimal_fibre_length : Lf0, m. tendon_slack_length :
    Lt0, m. pennation_angle_at_optimal : α0, rad, in [0, π/2). max_contraction_velocity :
    V_max, Lf0/s (default 10). maximum_pennation_angle : rad, default acos(0.1).
    fiber_damping : β, default 0.1 (selects the damped model's curves, module docstring).
    ignore_tendon_compliance : rigid tendon. minimum_activation : OpenSim's activation floor
    (default 0.01, recorded; not used by the inverse-dynamics rule).
    active_force_length, force_velocity, fibre_force_length, tendon_force_length : the
    curves (:mod:`.millard_curves`) as the file gives them. curve_rule : "equilibrium"
    (Millard2012EquilibriumMuscle's adjustment of f_L and f_V, module docstring) or
    "as_given" (Millard2012AccelerationMuscle: the curves exactly as given). name : for
    messages.
    """

    max_isometric_force: float
    optimal_fibre_length: float
    tendon_slack_length: float
    pennation_angle_at_optimal: float = 0.0
    max_contraction_velocity: float = 10.0
    maximum_pennation_angle: float = math.acos(0.1)
    fiber_damping: float = 0.1
    ignore_tendon_compliance: bool = False
    minimum_activation: float = 0.01
    active_force_length: ActiveForceLengthCurve = field(default_factory=ActiveForceLengthCurve)
    force_velocity: ForceVelocityCurve = field(default_factory=ForceVelocityCurve)
    fibre_force_length: FiberForceLengthCurve = field(default_factory=FiberForceLengthCurve)
    tendon_force_length: TendonForceLengthCurve = field(default_factory=TendonForceLengthCurve)
    curve_rule: str = "equilibrium"
    name: str = ""

    def __post_init__(self):
        from .hill import MIN_LENGTH_M, MuscleParameterError
        who = f"MillardMuscle '{self.name}'" if self.name else "MillardMuscle"
        _check(who, "max_isometric_force", self.max_isometric_force, lambda v: v > 0, "> 0 N")
        for n in ("optimal_fibre_length", "tendon_slack_length"):
            _check(who, n, getattr(self, n), lambda v: v >= MIN_LENGTH_M, f">= {MIN_LENGTH_M:g} m")
        _check(who, "pennation_angle_at_optimal", self.pennation_angle_at_optimal,
               lambda v: 0 <= v <= math.pi / 2 - _SIGNIFICANT, "in [0, π/2) rad")
        _check(who, "maximum_pennation_angle", self.maximum_pennation_angle,
               lambda v: 0 <= v <= math.pi / 2, "in [0, π/2] rad")
        _check(who, "max_contraction_velocity", self.max_contraction_velocity, lambda v: v > 0, "> 0 Lf0/s")
        _check(who, "fiber_damping", self.fiber_damping, lambda v: v >= 0, ">= 0")
        _check(who, "minimum_activation", self.minimum_activation, lambda v: 0 <= v < 1, "in [0, 1)")
        if self.curve_rule not in ("equilibrium", "as_given"):
            raise MuscleParameterError(f"{who}: curve_rule must be 'equilibrium' or 'as_given', got "
                                       f"{self.curve_rule!r}")
        try:
            self._row()
        except CurveError as exc:
            raise MuscleParameterError(f"{who}: {exc}") from None

    @property
    def damped(self):
        """OpenSim's damped model (fiber_damping ≥ 0.001)."""
        return self.fiber_damping >= MIN_NONZERO_DAMPING

    def curves_in_use(self):
        """(f_L, f_V, f_PE, f_T) curves as the muscle adjusts them (module docstring)."""
        fal, fv = self.active_force_length, self.force_velocity
        if self.curve_rule == "as_given":  # Millard2012AccelerationMuscle
            return fal, fv, self.fibre_force_length, self.tendon_force_length
        kc, knc = fv.concentric_slope_at_vmax, fv.concentric_slope_near_vmax
        ke, kne = fv.eccentric_slope_at_vmax, fv.eccentric_slope_near_vmax
        if not self.ignore_tendon_compliance and not self.damped:  # classic Hill model
            fal = replace(fal, minimum_value=max(fal.minimum_value, 0.1))
            kc, ke = max(kc, 0.5 * knc), max(ke, 0.5 * kne)
        else:  # damped model or rigid tendon
            fal = replace(fal, minimum_value=min(fal.minimum_value, 0.0))
            kc, ke = min(kc, 0.0), min(ke, 0.0)
        fv = replace(fv, concentric_slope_at_vmax=kc, eccentric_slope_at_vmax=ke)
        return fal, fv, self.fibre_force_length, self.tendon_force_length

    def _row(self):
        lf0 = self.optimal_fibre_length
        alpha0 = self.pennation_angle_at_optimal
        h = lf0 * math.sin(alpha0) if alpha0 > _EPS else 0.0
        maxpen = self.maximum_pennation_angle
        pen_lmin = h / math.sin(maxpen) if maxpen > _SIGNIFICANT else 0.01 * lf0
        fal, fv, fpe, fse = self.curves_in_use()
        lmin = max(_SIGNIFICANT, fal.min_norm_active_fiber_length * lf0, pen_lmin)
        who = f"'{self.name}'" if self.name else "MillardMuscle"
        row = np.zeros(N_ROW)
        row[0] = 2.0
        row[_F0], row[_LF0], row[_LT0], row[_H] = self.max_isometric_force, lf0, self.tendon_slack_length, h
        row[_VMAX] = self.max_contraction_velocity * lf0
        row[_LMIN], row[_XMIN] = lmin, math.sqrt(max(lmin * lmin - h * h, 0.0))
        row[_PEN_LMIN], row[_PEN_XMIN] = pen_lmin, pen_lmin * math.cos(maxpen)
        row[_MAXPEN], row[_ALPHA0] = maxpen, alpha0
        row[_RIGID] = 1.0 if self.ignore_tendon_compliance else 0.0
        row[_EISO] = fse.strain_at_one_norm_force
        row[_ACCEL] = 1.0 if self.curve_rule == "as_given" else 0.0
        row[_FAL:_FV] = fal.table(f"{who} ActiveForceLengthCurve")
        row[_FV:_FPE] = fv.table(f"{who} ForceVelocityCurve")
        row[_FPE:_FSE] = fpe.table(f"{who} FiberForceLengthCurve")
        row[_FSE:] = fse.table(f"{who} TendonForceLengthCurve")
        return row

    def evaluate(self, l_MT, v_MT):
        """``(s, f_P)`` for states of this muscle; l_MT (n,) m, v_MT (n,) m/s -> (n,) N, (n,) N."""
        from .hill import _evaluate_single
        return _evaluate_single(self, l_MT, v_MT)

    def evaluate_states(self, l_MT, v_MT):
        """Full :class:`~.hill.MuscleStates` for n states of this muscle."""
        from .hill import _single_states
        return _single_states(self, l_MT, v_MT)


# ------------------------------------------------------------------------- kernels
@njit(cache=True)
def _pennation(l_f, p):
    """OpenSim's MuscleFixedWidthPennationModel::calcPennationAngle(l_f)."""
    if p[_ALPHA0] <= 2.220446049250313e-16:
        return 0.0
    if l_f > p[_PEN_LMIN]:
        s = p[_H] / l_f
        if s < math.sin(p[_MAXPEN]):
            return math.asin(s)
    return p[_MAXPEN]


@njit(cache=True)
def _so_strength(p, l_mt, v_mt):
    """OpenSim's calcInextensibleTendonActiveFiberForce(s, 1) (see opensim_so_strength)."""
    lf0, h = p[_LF0], p[_H]
    x = l_mt - p[_LT0]
    lce = math.sqrt(h * h + x * x) if x >= p[_PEN_XMIN] else p[_PEN_LMIN]
    dlce = v_mt * math.cos(_pennation(lce, p))
    if p[_ACCEL] != 0.0:  # Millard2012AccelerationMuscle: zero only below the pennation model's minimum
        if lce <= p[_PEN_LMIN]:
            return 0.0
        fal = curve_value(p, np.int64(_FAL), lce / lf0)[0]
        fv = curve_value(p, np.int64(_FV), dlce / p[_VMAX])[0]
        return p[_F0] * fal * fv * math.cos(_pennation(lce, p))
    if lce <= p[_LMIN]:
        return 0.0
    fal = curve_value(p, np.int64(_FAL), lce / lf0)[0]
    fv = curve_value(p, np.int64(_FV), dlce / p[_VMAX])[0]
    # OpenSim 4.x evaluates this pennation angle at the *normalised* fibre length
    # (calcActiveFiberForceAlongTendon: calcPennationAngle(lceN)); reproduced as is
    return p[_F0] * fal * fv * math.cos(_pennation(lce / lf0, p))


@njit(cache=True)
def millard_so_strengths(params, slot, l_mt, v_mt, out):
    """out[i] = F_opt of state i for slot[i] ≥ 0 (row of params); others untouched."""
    for i in range(l_mt.shape[0]):
        if slot[i] >= 0:
            out[i] = _so_strength(params[slot[i]], l_mt[i], v_mt[i])


@njit(cache=True)
def _fibre_force(x, a, v_mt, p):
    """Fibre force along the tendon at along-tendon fibre length x ≥ x_min:
    F0 (a f_L f_V + f_PE) cos α, its x-derivative and its v_MT-derivative."""
    f0, lf0, h, vmax = p[_F0], p[_LF0], p[_H], p[_VMAX]
    l_f = math.sqrt(x * x + h * h)
    cos_a = x / l_f
    dcos_dx = h * h / (l_f * l_f * l_f)
    l_norm = l_f / lf0
    dl_dx = cos_a / lf0
    g, dg = curve_value(p, np.int64(_FPE), l_norm)
    dg *= dl_dx
    dv = 0.0
    if a > 0.0:
        fl, dfl = curve_value(p, np.int64(_FAL), l_norm)
        fv, dfv = curve_value(p, np.int64(_FV), v_mt * cos_a / vmax)
        g += a * fl * fv
        dg += a * (dfl * dl_dx * fv + fl * dfv * v_mt * dcos_dx / vmax)
        dv = f0 * a * fl * dfv * cos_a * cos_a / vmax
    return f0 * g * cos_a, f0 * (dg * cos_a + g * dcos_dx), dv


@njit(cache=True)
def _residual(x, a, l_mt, v_mt, p):
    """R = T − F_fibre·cos α at x; (R, ∂R/∂x, k_T, ∂R/∂v, T)."""
    f0, lt0 = p[_F0], p[_LT0]
    ft, dft = curve_value(p, np.int64(_FSE), (l_mt - x) / lt0)
    k_t = f0 * dft / lt0
    fm, dfm, dv = _fibre_force(x, a, v_mt, p)
    return f0 * ft - fm, -k_t - dfm, k_t, -dv, f0 * ft


@njit(cache=True)
def _solve(a, lo, hi, x, l_mt, v_mt, p):
    """Root of R on [lo, hi] (R(lo) > 0 ≥ R(hi)) by safeguarded Newton."""
    x = min(max(x, lo), hi)
    tol = 1e-12 * p[_F0]
    for _ in range(200):
        r, dr, _k, _dv, _t = _residual(x, a, l_mt, v_mt, p)
        if abs(r) <= tol:
            break
        x, lo, hi, done = bracketed_newton_step(x, r, dr, lo, hi)
        if done:
            break
    return x


@njit(cache=True)
def millard_states(params, slot, l_mt, v_mt, out):
    """Fill out[:, i] = (s, f_P, ds/dl, ds/dv, df_P/dl, l_f1, l_f0, T1, status) for the states
    with slot[i] ≥ 0 (row of params), as :func:`openfdk.forces.hill._evaluate_kernel`."""
    for i in range(l_mt.shape[0]):
        if slot[i] < 0:
            continue
        p = params[slot[i]]
        for j in range(9):
            out[j, i] = 0.0
        h, lt0, x_lo = p[_H], p[_LT0], p[_XMIN]
        if p[_RIGID] != 0.0:  # rigid tendon: the fibre takes l_MT − Lt0, clamped
            x = l_mt[i] - lt0
            lce = math.sqrt(h * h + x * x) if x >= p[_PEN_XMIN] else p[_PEN_LMIN]
            clamped = lce <= p[_LMIN]
            if clamped:
                lce = p[_LMIN]
            cos_a = math.cos(_pennation(lce, p))
            xa = lce * cos_a
            t0, d0, _ = _fibre_force(xa, 0.0, v_mt[i], p)
            t1, d1, dv1 = _fibre_force(xa, 1.0, v_mt[i], p)
            if clamped or x < p[_PEN_XMIN]:
                d0 = d1 = 0.0
            out[0, i] = max(t1 - t0, 0.0)
            if t1 > t0:
                out[2, i], out[3, i] = d1 - d0, dv1
            out[1, i], out[4, i] = t0, d0
            out[5, i] = out[6, i] = lce
            out[7, i] = t1
            continue
        x_hi = l_mt[i] - lt0
        if x_hi <= x_lo:  # shorter than tendon + shortest fibre: slack
            out[5, i] = out[6, i] = p[_LMIN]
            out[8, i] = STATUS_SLACK
            continue
        # passive state (a = 0); f_PE = 0 below 1 + strain_at_zero_force
        l_zero = p[_FPE + 1] * p[_LF0]
        x_opt = max(math.sqrt(max(l_zero * l_zero - h * h, 0.0)), x_lo)
        t0, dt0 = 0.0, 0.0
        x0 = x_hi
        if x_hi > x_opt:
            x0 = _solve(0.0, x_opt, x_hi, x_hi, l_mt[i], 0.0, p)
            _r, dr, k_t, _dv, t0 = _residual(x0, 0.0, l_mt[i], 0.0, p)
            dt0 = k_t * (1.0 + k_t / dr) if dr != 0.0 else 0.0
        out[1, i], out[4, i] = t0, dt0
        out[6, i] = math.sqrt(x0 * x0 + h * h)
        # maximal state (a = 1) in [x_lo, x0]
        r_lo, _dx, k_lo, _dv, t_lo = _residual(x_lo, 1.0, l_mt[i], v_mt[i], p)
        if r_lo <= 0.0:  # OpenSim: fibre at its lower bound
            x1, t1, dt1, dv1 = x_lo, t_lo, k_lo, 0.0
            out[8, i] = STATUS_COLLAPSED
        else:
            x1 = _solve(1.0, x_lo, x0, x_hi - lt0 * p[_EISO], l_mt[i], v_mt[i], p)
            _r, dr, k_t, dr_dv, t1 = _residual(x1, 1.0, l_mt[i], v_mt[i], p)
            dt1, dv1 = 0.0, 0.0
            if dr != 0.0:
                dt1 = k_t * (1.0 + k_t / dr)
                dv1 = k_t * dr_dv / dr
        if t1 > t0:
            out[0, i] = t1 - t0
            out[2, i] = dt1 - dt0
            out[3, i] = dv1
        out[5, i] = math.sqrt(x1 * x1 + h * h)
        out[7, i] = t1


def opensim_so_strength(muscle, l_mt, v_mt):
    """F_opt (N) of a :class:`MillardMuscle` as OpenSim's StaticOptimization computes it
    (``Millard2012EquilibriumMuscle::calcInextensibleTendonActiveFiberForce`` at a = 1):
    rigid tendon at Lt0, fibre length √(h² + (l_MT − Lt0)²) (OpenSim's minimum below the
    shortest pennated length), v_f = v_MT cos α, zero force at or below l_min, and

        F_opt = F0 f_L(l̃) f_V(ṽ) cos α(l̃),

    the last pennation angle evaluated, as OpenSim 4.x does, at the normalised length l̃
    (so that for h > 0 cos α(l̃) = √(1 − (h/l̃)²) with h in metres); no passive or damping
    force. l_mt, v_mt : arrays (n,) m, m/s."""
    l_mt = np.atleast_1d(np.asarray(l_mt, float))
    v_mt = np.broadcast_to(np.asarray(v_mt, float), l_mt.shape)
    out = np.zeros(l_mt.shape[0])
    millard_so_strengths(muscle._row()[None, :], np.zeros(l_mt.shape[0], np.int64),
                         np.ascontiguousarray(l_mt), np.ascontiguousarray(v_mt), out)
    return out
