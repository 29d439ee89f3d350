"""Nonlinear force laws on a scalar measure, and the 6-DOF linear bushing.

A law gives the generalized force ``f(m)`` conjugate to a scalar measure m (N for a
length, N m for an angle) and ``df/dm`` (the stiffness the analytic FDK Jacobian needs),
with the same interface as :class:`~openfdk.forces.spring.LinearSpring`, so a law is the
``law`` of a :class:`~openfdk.forces.elements.Spring` element: Q = Mᵀ f,
K = Mᵀ (df/dm) M + f ∂Mᵀ/∂q̂ (:mod:`openfdk.forces.spring_forces`).

Each law is written as a *resisting* force F(m) (positive when it pushes m back down,
like a spring's k (m − m_rest)) and acts as f = −F(m):

* :class:`PolynomialSpring`  F = Σ_{k≥0} c_k (m − m_rest)^k (Horner, numba);
* :class:`TabulatedSpring`   F through (m_i, F_i) by the monotone piecewise-cubic
  Hermite interpolant (Fritsch & Carlson 1980, scipy's PCHIP slopes; no overshoot, C¹),
  continued linearly with the end slopes outside the table;
* :class:`Blankevoort1991Spring` the piecewise quadratic–linear ligament law of
  Blankevoort et al. (1991) on a length measure (a ligament with a general measure).

:func:`add_bushing` adds a 6-DOF linear bushing between two frames: springs on the three
components of the child origin in the parent frame (N/m) and on the three x-y-z Cardan
angles of the child frame in the parent frame (N m/rad), like OpenSim's BushingForce;
its energy is ½ Σ k_i m_i², so Q = Σ M_iᵀ (−k_i m_i).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .blankevoort import Blankevoort1991Ligament

__all__ = ["PolynomialSpring", "TabulatedSpring", "Blankevoort1991Spring", "add_bushing", "add_nonlinear_spring"]


class ForceLawError(ValueError):
    """A force-law parameter is invalid; the message names the element."""


@njit(cache=True)
def polynomial_force(c, x):
    """F = Σ c_k x^k and dF/dx (Horner); c (n,) lowest order first."""
    F = 0.0
    dF = 0.0
    for k in range(c.shape[0] - 1, -1, -1):
        dF = dF * x + F
        F = F * x + c[k]
    return F, dF


@njit(cache=True)
def hermite_force(xs, Fs, ds, x):
    """Piecewise-cubic Hermite F(x) and dF/dx through (xs, Fs) with slopes ds (n,);
    linear with the end slopes outside [xs[0], xs[-1]]."""
    n = xs.shape[0]
    if x <= xs[0]:
        return Fs[0] + ds[0] * (x - xs[0]), ds[0]
    if x >= xs[n - 1]:
        return Fs[n - 1] + ds[n - 1] * (x - xs[n - 1]), ds[n - 1]
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    h = xs[hi] - xs[lo]
    t = (x - xs[lo]) / h
    h00 = 2 * t**3 - 3 * t**2 + 1
    h10 = t**3 - 2 * t**2 + t
    h01 = -2 * t**3 + 3 * t**2
    h11 = t**3 - t**2
    F = h00 * Fs[lo] + h10 * h * ds[lo] + h01 * Fs[hi] + h11 * h * ds[hi]
    dF = ((6 * t**2 - 6 * t) * Fs[lo] + (3 * t**2 - 4 * t + 1) * h * ds[lo]
          + (-6 * t**2 + 6 * t) * Fs[hi] + (3 * t**2 - 2 * t) * h * ds[hi]) / h
    return F, dF


class _ScalarLaw:
    """f = −F(m) and df/dm = −dF/dm for scalars or arrays (same shape)."""

    unit = "m"
    name = ""

    def _F(self, x):  # pragma: no cover - interface
        raise NotImplementedError

    def _apply(self, measure, which):
        m = np.asarray(measure, dtype=float)
        out = np.array([-self._F(float(x))[which] for x in m.ravel()]).reshape(m.shape)
        return out if out.ndim else float(out)

    def force(self, measure):
        """Generalized force f = −F(m) (N or N m), same shape as ``measure``."""
        return self._apply(measure, 0)

    def dforce_dmeasure(self, measure):
        """df/dm = −dF/dm (N/m or N m/rad), same shape as ``measure``."""
        return self._apply(measure, 1)


class PolynomialSpring(_ScalarLaw):
    """F = Σ_k c_k (m − m_rest)^k. coefficients (n,) lowest order first, c_k in
    N/unit^k (SI); rest_value in the measure's unit (m or rad)."""

    def __init__(self, coefficients, rest_value=0.0, unit="m", name=""):
        c = np.atleast_1d(np.asarray(coefficients, dtype=float))
        if c.ndim != 1 or c.size == 0 or not np.all(np.isfinite(c)):
            raise ForceLawError(f"spring {name!r}: polynomial coefficients must be finite numbers, got {coefficients!r}")
        if not np.isfinite(rest_value):
            raise ForceLawError(f"spring {name!r}: rest_value must be finite")
        self.coefficients, self.rest_value, self.unit, self.name = c, float(rest_value), unit, name

    def _F(self, x):
        return polynomial_force(self.coefficients, x - self.rest_value)


class TabulatedSpring(_ScalarLaw):
    """F through the points (values (n,) in the measure's unit, strictly increasing;
    forces (n,) N or N m), n ≥ 2: monotone cubic Hermite (PCHIP) inside, linear outside."""

    def __init__(self, values, forces, unit="m", name=""):
        from scipy.interpolate import PchipInterpolator

        x = np.asarray(values, dtype=float)
        F = np.asarray(forces, dtype=float)
        if x.ndim != 1 or F.shape != x.shape or x.size < 2:
            raise ForceLawError(f"spring {name!r}: the table needs matching lists of >= 2 values and forces")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(F))):
            raise ForceLawError(f"spring {name!r}: the table has non-finite entries")
        if np.any(np.diff(x) <= 0):
            raise ForceLawError(f"spring {name!r}: table values must be strictly increasing")
        self.values, self.forces, self.unit, self.name = x, F, unit, name
        self.slopes = PchipInterpolator(x, F).derivative()(x) if x.size > 2 else np.full(2, (F[1] - F[0]) / (x[1] - x[0]))

    def _F(self, x):
        return hermite_force(self.values, self.forces, self.slopes, x)


class Blankevoort1991Spring(_ScalarLaw):
    """The Blankevoort (1991) ligament law on a length measure (m): F = tension T(l) ≥ 0
    of :class:`~openfdk.forces.blankevoort.Blankevoort1991Ligament` (stiffness k N/m,
    slack length l0 m, transition strain ε_l)."""

    def __init__(self, stiffness, slack_length, transition_strain=0.03, name=""):
        self.law = Blankevoort1991Ligament(stiffness, slack_length, transition_strain, name=name)
        self.unit, self.name = "m", name

    def _F(self, x):
        return float(self.law.force(x)), float(self.law.dforce_dlength(x))


def add_nonlinear_spring(b, name, measure, law):
    """A spring element with any law of this module on a scalar measure (or its name)."""
    from ..model.model import ModelError
    from .elements import SPRINGS, Spring, _append

    if isinstance(measure, str):
        measure = b.measure(measure)
    if measure.size != 1:
        raise ModelError(f"spring {name!r}: the measure must be scalar")
    return _append(b, SPRINGS, Spring(name, measure, law))


def add_bushing(b, name, parent, child, translational_stiffness, rotational_stiffness,
                rest_position=(0.0, 0.0, 0.0), rest_angles=(0.0, 0.0, 0.0)):
    """A 6-DOF linear bushing between frames ``parent`` and ``child`` ("body.frame"):
    springs k_t (3,) N/m on the child origin's coordinates in the parent frame and
    k_r (3,) N m/rad on the x-y-z Cardan angles of the child in the parent frame. Adds
    the spring elements ``{name}.x``, ``.y``, ``.z``, ``.rx``, ``.ry``, ``.rz``."""
    from ..model.model import ModelError
    from .elements import add_spring

    k_t = np.asarray(translational_stiffness, dtype=float)
    k_r = np.asarray(rotational_stiffness, dtype=float)
    if k_t.shape != (3,) or k_r.shape != (3,) or np.any(~np.isfinite(np.r_[k_t, k_r])) or np.any(np.r_[k_t, k_r] < 0):
        raise ModelError(f"bushing {name!r}: stiffnesses must be 3 + 3 finite numbers >= 0")
    position = b.vector(parent, child, expressed_in=parent)
    angles = b.angles(parent, child)
    out = []
    for j, axis in enumerate("xyz"):
        out.append(add_spring(b, f"{name}.{axis}", b._select(position, [j]), k_t[j], rest_position[j], "m"))
    for j, axis in enumerate("xyz"):
        out.append(add_spring(b, f"{name}.r{axis}", b._select(angles, [j]), k_r[j], rest_angles[j], "rad"))
    return out
