"""OpenSim's muscles whose curves are plain functions of the file: ``RigidTendonMuscle``
and ``Schutte1993Muscle_Deprecated``, as openfdk strength models (docs/muscles.md,
"OpenSim curve muscles").

Both read their curves as OpenSim Functions (SimmSpline, PiecewiseLinearFunction, …;
:mod:`openfdk.model.coordinate_functions`), of the normalised fibre length
l̃ = l_f/Lf0, the normalised fibre velocity ṽ and the tendon strain ε_T = l_T/Lt0 − 1.
Pennation keeps the fibre's thickness h = Lf0 sin α0: along the tendon the fibre spans
x = l_f cos α with l_f = √(x² + h²).

**RigidTendonMuscle** (``kind="rigid_tendon"``; OpenSim's ``RigidTendonMuscle``): the
tendon stays at Lt0, x = max(l_MT − Lt0, 0) (the fibre is l_f = x when h ≤ √ε, with
cos α = 1, as OpenSim), ṽ = v_MT/(V_max Lf0) — OpenSim takes the path's lengthening
speed as the fibre velocity, without cos α — and

    s   = F0 f_L(l̃) f_V(ṽ) cos α,      f_P = F0 clamp(f_PE(l̃), 0, 10) cos α.

This is also OpenSim's static-optimisation strength (``Muscle::
calcInextensibleTendonActiveFiberForce``), so both rules give it.

**Schutte1993Muscle_Deprecated** (``kind="schutte1993"``; Schutte 1992, Delp's SIMM
muscle): tendon f_T(ε_T) (0 for ε_T < 0), active f_L(l̃) (clamped at ≥ 0), passive
f_PE(l̃) — or, when the file gives no ``passive_force_length_curve``, OpenSim's
exponential exp(8(l̃ − 1))/e⁴ — and a force–velocity law that OpenSim writes as its
inverse (``calcFiberVelocity``). Solved for the force, with F_v the fibre's
velocity-dependent force, a·f_L = A, ṽ = v_f·time_scale/Lf0, damping d, and OpenSim's
constants k_v = 0.15, k_s = 0.13, F_max = 1.4, s = k_s k_v/(k_v + 1):

    ṽ ≤ −1:       F_v = d ṽ
    −1 < ṽ ≤ 0:   F_v = A (1 + ṽ)/(1 − ṽ/k_v) + d ṽ
    ṽ > 0:        F_v = A (s + F_max ṽ)/(s + ṽ) + d ṽ

and the tendon balances the fibre: F0 f_T = F0 (F_v + f_PE) cos α. openfdk's rule (as
for :mod:`.hill` and :mod:`.millard`) solves that balance at a = 0 (f_P = T0) and a = 1
(s = T1 − T0) with the rigid-tendon velocity split ṽ = v_MT cos α·time_scale/Lf0, and
leaves the damping force d ṽ out of the strengths (zero at zero fibre speed).
:meth:`CurveMuscle.fibre_force` gives the whole law, damping included.

OpenSim's static optimisation uses for a Schutte muscle
``ActivationFiberLengthMuscle_Deprecated::calcInextensibleTendonActiveFiberForce``: its
isometric force at a = 1 (compliant tendon, passive force included, iterated to 0.01 N)
times a generic f_V = 1.8 − 1.8/(1 + exp((0.04 − ṽ)/0.18)), ṽ = −cos α0 v_MT/(V_max Lf0)
with V_max = ``max_contraction_velocity``: :func:`curve_so_strengths` gives T1 at zero
speed times that f_V.

Source: OpenSim 4.6 ``RigidTendonMuscle.cpp``, ``Schutte1993Muscle_Deprecated.cpp``,
``ActivationFiberLengthMuscle_Deprecated.cpp`` (read, re-derived; checked against
OpenSim 4.6 in tests/test_opensim_curve_muscles.py). Schutte LM (1992) Using
musculoskeletal models to explore strategies for improving performance in electrical
stimulation-induced leg cycle ergometry. MS thesis, Stanford University.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..model.coordinate_functions import function_from_spec, pp_evaluate
from .bracketed_newton import bracketed_newton_step

__all__ = ["CurveMuscle", "curve_states", "curve_so_strengths", "DEFAULT_CURVES", "SCHUTTE_FV"]

#: OpenSim's default curves (x, y of SimmSplines), from RigidTendonMuscle and
#: Schutte1993Muscle_Deprecated::constructProperties (OpenSim 4.6)
DEFAULT_CURVES = {
    "active_force_length": (
        (-5.307692, -4.307692, -1.923077, -0.884615, -0.269231, 0.230769, 0.461538, 0.52725, 0.62875, 0.71875,
         0.86125, 1.045, 1.2175, 1.43875, 1.5, 1.615385, 2.0, 2.961538, 3.692308, 5.461538, 9.901902),
        (0.012188, 0.021899, 0.036466, 0.052493, 0.075312, 0.114158, 0.157859, 0.226667, 0.636667, 0.856667,
         0.95, 0.993333, 0.77, 0.246667, 0.193821, 0.133252, 0.072683, 0.044417, 0.036341, 0.021899, 0.007332)),
    "passive_force_length": (
        (-5.0, 0.998, 0.999, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.601, 1.602, 5.0),
        (0.0, 0.0, 0.0, 0.0, 0.035, 0.12, 0.26, 0.55, 1.17, 2.0, 2.0, 2.0, 2.0)),
    "force_velocity": (
        (-1.001, -1.0, -0.95, -0.9, -0.85, -0.8, -0.75, -0.7, -0.65, -0.6, -0.55, -0.5, -0.45, -0.4, -0.35, -0.3,
         -0.25, -0.2, -0.15, -0.1, -0.05, 0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6,
         0.65, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95, 1.0),
        (0.0, 0.0, 0.010417, 0.021739, 0.034091, 0.047619, 0.0625, 0.078947, 0.097222, 0.117647, 0.140625,
         0.166667, 0.196429, 0.230769, 0.270833, 0.318182, 0.375, 0.444444, 0.53125, 0.642857, 0.791667, 1.0,
         1.482014, 1.601571, 1.655791, 1.686739, 1.706751, 1.720753, 1.731099, 1.739055, 1.745365, 1.75049,
         1.754736, 1.758312, 1.761364, 1.763999, 1.766298, 1.768321, 1.770115, 1.771717, 1.773155, 1.774455)),
    "tendon_force_length": (
        (-10.0, -0.002, -0.001, 0.0, 0.00131, 0.00281, 0.00431, 0.00581, 0.00731, 0.00881, 0.0103, 0.0118, 0.0123,
         9.2, 9.201, 9.202, 20.0),
        (0.0, 0.0, 0.0, 0.0, 0.0108, 0.0257, 0.0435, 0.0652, 0.0915, 0.123, 0.161, 0.208, 0.227, 345.0, 345.0,
         345.0, 345.0)),
}
#: Schutte's force–velocity constants (OpenSim's calcFiberVelocity): k_v, k_s, F_max
SCHUTTE_FV = (0.15, 0.13, 1.4)
_SQRT_EPS = math.sqrt(np.finfo(float).eps)
_KIND = {"rigid_tendon": 0.0, "schutte1993": 1.0}
# row layout
_K, _F0, _LF0, _LT0, _H, _VNORM, _DAMP, _EXP, _FAL, _FPE, _FV, _FT, _SO_VMAX, _COS0 = range(14)
N_ROW = 14
STATUS_OK, STATUS_SLACK, STATUS_COLLAPSED = 0, 1, 2


def _spec(spec, key):
    return spec if spec is not None else {"type": "simm_spline", "x": list(DEFAULT_CURVES[key][0]),
                                          "y": list(DEFAULT_CURVES[key][1])}


@dataclass(frozen=True)
class CurveMuscle:
    """An OpenSim curve muscle (module docstring).

    kind : "rigid_tendon" (RigidTendonMuscle) or "schutte1993" (Schutte1993Muscle_Deprecated).
    max_isometric_force : F0, N (> 0). optimal_fibre_length : Lf0, m. tendon_slack_length :
    Lt0, m. pennation_angle_at_optimal : α0, rad in [0, π/2). max_contraction_velocity :
    V_max, Lf0/s (the rigid-tendon muscle's f_V; a Schutte muscle's static-optimisation
    f_V). time_scale : s (Schutte: ṽ = v_f·time_scale/Lf0), damping : d (Schutte).
    active_force_length, passive_force_length, force_velocity, tendon_force_length :
    function dicts (:func:`~openfdk.model.coordinate_functions.function_from_spec`) of
    the normalised variable, None for OpenSim's default (a Schutte muscle's absent
    passive curve is OpenSim's exponential). name : for messages.
    """

    kind: str
    max_isometric_force: float
    optimal_fibre_length: float
    tendon_slack_length: float
    pennation_angle_at_optimal: float = 0.0
    max_contraction_velocity: float = 10.0
    time_scale: float = 0.1
    damping: float = 0.1
    active_force_length: dict = None
    passive_force_length: dict = None
    force_velocity: dict = None
    tendon_force_length: dict = None
    name: str = ""

    def __post_init__(self):
        from .hill import MIN_LENGTH_M, MuscleParameterError
        from .millard import _check

        who = f"{self.kind} muscle '{self.name}'" if self.name else f"{self.kind} muscle"
        if self.kind not in _KIND:
            raise MuscleParameterError(f"{who}: kind must be one of {sorted(_KIND)}")
        _check(who, "max_isometric_force", self.max_isometric_force, lambda v: v > 0, "> 0 N")
        for n in ("optimal_fibre_length", "tendon_slack_length"):
            _check(who, n, getattr(self, n), lambda v: v >= MIN_LENGTH_M, f">= {MIN_LENGTH_M:g} m")
        _check(who, "pennation_angle_at_optimal", self.pennation_angle_at_optimal,
               lambda v: 0 <= v < math.pi / 2, "in [0, π/2) rad")
        _check(who, "max_contraction_velocity", self.max_contraction_velocity, lambda v: v > 0, "> 0 Lf0/s")
        _check(who, "time_scale", self.time_scale, lambda v: v > 0, "> 0 s")
        _check(who, "damping", self.damping, lambda v: v >= 0, ">= 0")
        try:
            self._functions()
        except (ValueError, TypeError) as exc:
            raise MuscleParameterError(f"{who}: {exc}") from None

    def _functions(self):
        """{key: PiecewisePolynomial or None} of the curves this kind uses."""
        def error(path, msg):
            return ValueError(f"{path}: {msg}")

        keys = ["active_force_length", "passive_force_length"]
        keys.append("force_velocity" if self.kind == "rigid_tendon" else "tendon_force_length")
        out = {}
        for key in keys:
            spec = getattr(self, key)
            if key == "passive_force_length" and spec is None and self.kind == "schutte1993":
                out[key] = None  # OpenSim's exponential
            else:
                out[key] = function_from_spec(_spec(spec, key), key, error)
        return out

    def tables(self):
        """(row (N_ROW,), functions (m,)): the parameter row with the curves' offsets
        into ``functions`` (the concatenated :meth:`PiecewisePolynomial.to_params`)."""
        funcs = self._functions()
        row = np.full(N_ROW, -1.0)
        lf0 = self.optimal_fibre_length
        row[_K], row[_F0], row[_LF0], row[_LT0] = _KIND[self.kind], self.max_isometric_force, lf0, \
            self.tendon_slack_length
        row[_H] = lf0 * math.sin(self.pennation_angle_at_optimal)
        row[_COS0] = math.cos(self.pennation_angle_at_optimal)
        vmax = self.max_contraction_velocity * lf0
        row[_VNORM] = vmax if self.kind == "rigid_tendon" else lf0 / self.time_scale
        row[_SO_VMAX] = vmax
        row[_DAMP] = self.damping if self.kind == "schutte1993" else 0.0
        row[_EXP] = 1.0 if funcs.get("passive_force_length", 0) is None else 0.0
        parts, at = [], 0
        for key, slot in (("active_force_length", _FAL), ("passive_force_length", _FPE),
                          ("force_velocity", _FV), ("tendon_force_length", _FT)):
            f = funcs.get(key)
            if f is not None:
                row[slot] = at
                p = f.to_params()
                parts.append(p)
                at += p.shape[0]
        return row, np.concatenate(parts)

    def fibre_force(self, activation, fibre_length, fibre_velocity):
        """The fibre force along the tendon (N) of OpenSim's law at ``activation``,
        ``fibre_length`` (m) and ``fibre_velocity`` (m/s), damping included (module
        docstring); scalars."""
        funcs = self._functions()
        lf0, h = self.optimal_fibre_length, self.optimal_fibre_length * math.sin(self.pennation_angle_at_optimal)
        l_n = fibre_length / lf0
        if self.kind == "rigid_tendon":
            cos_a = math.sqrt(max(fibre_length ** 2 - h * h, 0.0)) / fibre_length if h > _SQRT_EPS else 1.0
            v_n = fibre_velocity / (self.max_contraction_velocity * lf0)
            fpe = min(max(funcs["passive_force_length"].evaluate(l_n)[0], 0.0), 10.0)
            fal = funcs["active_force_length"].evaluate(l_n)[0]
            fv = funcs["force_velocity"].evaluate(v_n)[0]
            return self.max_isometric_force * (activation * fal * fv + fpe) * cos_a
        sin_a = h / fibre_length
        cos_a = 0.0 if sin_a >= 1.0 else math.sqrt(1.0 - sin_a * sin_a)
        v_n = fibre_velocity * self.time_scale / lf0
        fpe = math.exp(8.0 * (l_n - 1.0)) / math.exp(4.0) if funcs["passive_force_length"] is None \
            else funcs["passive_force_length"].evaluate(l_n)[0]
        fal = max(funcs["active_force_length"].evaluate(l_n)[0], 0.0)
        fv = _schutte_fv(v_n)[0]
        return self.max_isometric_force * (activation * fal * fv + fpe + self.damping * v_n) * cos_a

    def evaluate(self, l_MT, v_MT):
        """``(s, f_P)`` for states of this muscle; l_MT (n,) m, v_MT (n,) m/s -> (n,) N, (n,) N."""
        from .hill import _evaluate_single
        return _evaluate_single(self, l_MT, v_MT)

    def evaluate_states(self, l_MT, v_MT):
        """Full :class:`~.hill.MuscleStates` for n states of this muscle."""
        from .hill import _single_states
        return _single_states(self, l_MT, v_MT)


def curve_tables(muscles):
    """(rows (k, N_ROW), functions (m,)) of the CurveMuscles ``muscles``: each row's
    function offsets shifted into the shared array."""
    rows, funcs, at = [], [], 0
    for m in muscles:
        row, f = m.tables()
        for slot in (_FAL, _FPE, _FV, _FT):
            if row[slot] >= 0:
                row[slot] += at
        rows.append(row)
        funcs.append(f)
        at += f.shape[0]
    return np.array(rows).reshape(-1, N_ROW), (np.concatenate(funcs) if funcs else np.zeros(0))


# ------------------------------------------------------------------------- kernels
@njit(cache=True)
def _schutte_fv(v):
    """Schutte's force–velocity multiplier at a = 1 and its slope (module docstring)."""
    kv, ks, fmax = 0.15, 0.13, 1.4
    if v <= -1.0:
        return 0.0, 0.0
    if v <= 0.0:
        d = 1.0 - v / kv
        return (1.0 + v) / d, (1.0 + 1.0 / kv) / (d * d)
    s = ks * kv / (kv + 1.0)
    return (s + fmax * v) / (s + v), s * (fmax - 1.0) / ((s + v) * (s + v))


@njit(cache=True)
def _passive(p, funcs, l_n):
    """f_PE(l̃) and its slope: the file's curve or Schutte's exponential."""
    if p[_EXP] != 0.0:
        f = math.exp(8.0 * l_n - 12.0)
        return f, 8.0 * f
    f, df, _ = pp_evaluate(funcs, int(p[_FPE]), l_n)
    return f, df


@njit(cache=True)
def _schutte_fibre(x, a, v_mt, p, funcs):
    """Fibre force along the tendon F0 (a f_L⁺ f_V + f_PE) cos α at along-tendon length
    x > 0 (no damping), its x-derivative and its v_MT-derivative."""
    f0, lf0, h, vn = p[_F0], p[_LF0], p[_H], p[_VNORM]
    l_f = math.sqrt(x * x + h * h)
    cos_a = x / l_f
    dcos = h * h / (l_f * l_f * l_f)
    l_n = l_f / lf0
    dl = cos_a / lf0
    g, dg = _passive(p, funcs, l_n)
    dg *= dl
    dv = 0.0
    if a > 0.0:
        fl, dfl, _ = pp_evaluate(funcs, int(p[_FAL]), l_n)
        if fl < 0.0:
            fl, dfl = 0.0, 0.0
        fv, dfv = _schutte_fv(v_mt * cos_a / vn)
        g += a * fl * fv
        dg += a * (dfl * dl * fv + fl * dfv * v_mt * dcos / vn)
        dv = f0 * a * fl * dfv * cos_a * cos_a / vn
    return f0 * g * cos_a, f0 * (dg * cos_a + g * dcos), dv


@njit(cache=True)
def _residual(x, a, l_mt, v_mt, p, funcs):
    """R = T − F_fibre at x: (R, ∂R/∂x, k_T, ∂R/∂v, T)."""
    f0, lt0 = p[_F0], p[_LT0]
    eps = (l_mt - x) / lt0 - 1.0
    ft, dft = 0.0, 0.0
    if eps >= 0.0:
        ft, dft, _ = pp_evaluate(funcs, int(p[_FT]), eps)
    k_t = f0 * dft / lt0
    fm, dfm, dv = _schutte_fibre(x, a, v_mt, p, funcs)
    return f0 * ft - fm, -k_t - dfm, k_t, -dv, f0 * ft


@njit(cache=True)
def _solve(a, lo, hi, l_mt, v_mt, p, funcs):
    """Root of R on [lo, hi] (R(lo) > 0 ≥ R(hi)) by safeguarded Newton."""
    x = hi
    tol = 1e-12 * p[_F0]
    for _ in range(200):
        r, dr, _k, _dv, _t = _residual(x, a, l_mt, v_mt, p, funcs)
        if abs(r) <= tol:
            break
        x, lo, hi, done = bracketed_newton_step(x, r, dr, lo, hi)
        if done:
            break
    return x


@njit(cache=True)
def _state(a, x_lo, x_hi, l_mt, v_mt, p, funcs):
    """(x, T, dT/dl, dT/dv, status) of the balance at activation a on [x_lo, x_hi]."""
    r_lo, _d, k_lo, _v, t_lo = _residual(x_lo, a, l_mt, v_mt, p, funcs)
    if r_lo <= 0.0:  # the tendon cannot balance the fibre: fibre at its lower bound
        return x_lo, t_lo, k_lo, 0.0, STATUS_COLLAPSED
    r_hi, _d, _k, _v, t_hi = _residual(x_hi, a, l_mt, v_mt, p, funcs)
    if r_hi >= 0.0:  # slack tendon still pulling (a curve with f_T(0) > 0)
        return x_hi, t_hi, 0.0, 0.0, STATUS_OK
    x = _solve(a, x_lo, x_hi, l_mt, v_mt, p, funcs)
    _r, dr, k_t, dr_dv, t = _residual(x, a, l_mt, v_mt, p, funcs)
    dt, dtv = 0.0, 0.0
    if dr != 0.0:
        dt = k_t * (1.0 + k_t / dr)
        dtv = k_t * dr_dv / dr
    return x, t, dt, dtv, STATUS_OK


@njit(cache=True)
def _rigid(p, funcs, l_mt, v_mt, out, i):
    """RigidTendonMuscle: s, f_P and their slopes into out[:, i]."""
    f0, lf0, h = p[_F0], p[_LF0], p[_H]
    x = l_mt - p[_LT0]
    dx = 1.0
    if x < 0.0:
        x, dx = 0.0, 0.0
        out[8, i] = STATUS_SLACK
    if h > 1.4901161193847656e-08:
        l_f = math.sqrt(x * x + h * h)
        cos_a = x / l_f
        dl = cos_a / lf0 * dx
        dcos = h * h / (l_f * l_f * l_f) * dx
    else:
        l_f, cos_a, dl, dcos = x, 1.0, dx / lf0, 0.0
    l_n = l_f / lf0
    vn = v_mt / p[_VNORM]
    fl, dfl, _ = pp_evaluate(funcs, int(p[_FAL]), l_n)
    fv, dfv, _ = pp_evaluate(funcs, int(p[_FV]), vn)
    fp, dfp, _ = pp_evaluate(funcs, int(p[_FPE]), l_n)
    if fp < 0.0 or fp > 10.0:
        fp, dfp = min(max(fp, 0.0), 10.0), 0.0
    s = f0 * fl * fv * cos_a
    out[0, i] = s
    out[1, i] = f0 * fp * cos_a
    out[2, i] = f0 * fv * (dfl * dl * cos_a + fl * dcos)
    out[3, i] = f0 * fl * dfv * cos_a / p[_VNORM]
    out[4, i] = f0 * (dfp * dl * cos_a + fp * dcos)
    out[5, i] = out[6, i] = l_f
    out[7, i] = s + out[1, i]


@njit(cache=True)
def curve_states(rows, funcs, slot, l_mt, v_mt, out):
    """Fill out[:, i] = (s, f_P, ds/dl, ds/dv, df_P/dl, l_f1, l_f0, T1, status) for the
    states with slot[i] ≥ 0 (row of ``rows``), as :func:`openfdk.forces.hill._evaluate_kernel`."""
    for i in range(l_mt.shape[0]):
        if slot[i] < 0:
            continue
        p = rows[slot[i]]
        for j in range(9):
            out[j, i] = 0.0
        if p[_K] == 0.0:
            _rigid(p, funcs, l_mt[i], v_mt[i], out, i)
            continue
        h, lt0 = p[_H], p[_LT0]
        x_hi = l_mt[i] - lt0
        x_lo = 0.0 if h > 0.0 else 1e-9 * p[_LF0]
        if x_hi <= x_lo:  # the tendon is slack at any fibre length
            out[5, i] = out[6, i] = max(h, x_lo)
            out[8, i] = STATUS_SLACK
            continue
        x0, t0, dt0, _dv0, _st = _state(0.0, x_lo, x_hi, l_mt[i], 0.0, p, funcs)
        x1, t1, dt1, dv1, status = _state(1.0, x_lo, x0, l_mt[i], v_mt[i], p, funcs)
        out[1, i], out[4, i] = t0, dt0
        if t1 > t0:
            out[0, i], out[2, i], out[3, i] = t1 - t0, dt1 - dt0, dv1
        out[5, i] = math.sqrt(x1 * x1 + h * h)
        out[6, i] = math.sqrt(x0 * x0 + h * h)
        out[7, i] = t1
        out[8, i] = status


@njit(cache=True)
def curve_so_strengths(rows, funcs, slot, l_mt, v_mt, out):
    """out[i] = OpenSim's static-optimisation strength F_opt of state i for slot[i] ≥ 0
    (module docstring); others untouched."""
    tmp = np.zeros((9, 1))
    for i in range(l_mt.shape[0]):
        if slot[i] < 0:
            continue
        p = rows[slot[i]]
        one_l = np.array([l_mt[i]])
        if p[_K] == 0.0:
            _rigid(p, funcs, l_mt[i], v_mt[i], tmp, np.int64(0))
            out[i] = tmp[0, 0]
            continue
        curve_states(rows, funcs, np.array([slot[i]]), one_l, np.zeros(1), tmp)
        v_n = -p[_COS0] * v_mt[i] / p[_SO_VMAX]
        fv = 1.8 - 1.8 / (1.0 + math.exp((0.04 - v_n) / 0.18))
        out[i] = tmp[7, 0] * fv
