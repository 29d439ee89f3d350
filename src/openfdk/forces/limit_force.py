"""A coordinate's limit force (OpenSim's CoordinateLimitForce): zero inside
[lower, upper], rising beyond each limit with a stiffness that fades in over a
transition width, with a damper faded in the same way.

For a coordinate q (rad or m) and its rate q̇:

    K_up(q)  = K_u · s((q − q_u) / Δ)              s the quintic step 10u³ − 15u⁴ + 6u⁵
    K_low(q) = K_l · (1 − s((q − q_l + Δ) / Δ))    (clamped to [0, 1]: Simbody's Step)
    f = −K_up (q − q_u) + K_low (q_l − q) − c (K_up/K_u + K_low/K_l) q̇

with limits q_u, q_l, stiffnesses K_u, K_l (N m/rad or N/m), transition width Δ and
damping c (N m s/rad or N s/m), all SI. OpenSim gives a rotational coordinate's limits
and transition in degrees and its stiffnesses and damping per degree; the import
converts (:mod:`openfdk.io.opensim.passive_forces`).
"""

from __future__ import annotations

import numpy as np

from .force_laws import ForceLawError

__all__ = ["CoordinateLimitLaw"]


def _step(u):
    """Simbody's stepUp on u clamped to [0, 1]: (value, derivative)."""
    if u <= 0.0:
        return 0.0, 0.0
    if u >= 1.0:
        return 1.0, 0.0
    return u * u * u * (10.0 + u * (6.0 * u - 15.0)), 30.0 * u * u * (1.0 - u) * (1.0 - u)


class CoordinateLimitLaw:
    """The law of the module docstring (SI). ``force(q)`` the elastic part,
    ``dforce_dmeasure(q)`` its slope, ``damping_force(q, q̇)`` the damper."""

    def __init__(self, upper_limit, upper_stiffness, lower_limit, lower_stiffness, transition, damping=0.0,
                 unit="rad", name=""):
        values = dict(upper_limit=upper_limit, upper_stiffness=upper_stiffness, lower_limit=lower_limit,
                      lower_stiffness=lower_stiffness, transition=transition, damping=damping)
        for key, value in values.items():
            if not np.isfinite(value):
                raise ForceLawError(f"spring {name!r}: {key} must be finite, got {value!r}")
        if upper_stiffness <= 0 or lower_stiffness <= 0 or transition <= 0 or damping < 0:
            raise ForceLawError(f"spring {name!r}: stiffnesses and transition must be > 0 and damping >= 0")
        if lower_limit > upper_limit:
            raise ForceLawError(f"spring {name!r}: lower_limit {lower_limit:g} is above upper_limit {upper_limit:g}")
        self.upper_limit, self.upper_stiffness = float(upper_limit), float(upper_stiffness)
        self.lower_limit, self.lower_stiffness = float(lower_limit), float(lower_stiffness)
        self.transition, self.damping, self.unit, self.name = float(transition), float(damping), unit, name

    def _factors(self, q):
        """(s_up, ds_up/dq, s_low, ds_low/dq): the fade-in factors K/K_max and slopes."""
        s_up, d_up = _step((q - self.upper_limit) / self.transition)
        s_lo, d_lo = _step((q - self.lower_limit + self.transition) / self.transition)
        return s_up, d_up / self.transition, 1.0 - s_lo, -d_lo / self.transition

    def _scalar(self, q):
        s_up, d_up, s_lo, d_lo = self._factors(q)
        K_u, K_l = self.upper_stiffness, self.lower_stiffness
        f = -K_u * s_up * (q - self.upper_limit) + K_l * s_lo * (self.lower_limit - q)
        df = -K_u * (d_up * (q - self.upper_limit) + s_up) + K_l * (d_lo * (self.lower_limit - q) - s_lo)
        return f, df

    def force(self, measure):
        """Elastic generalised force (N m or N), same shape as ``measure``."""
        m = np.asarray(measure, float)
        out = np.array([self._scalar(float(q))[0] for q in m.ravel()]).reshape(m.shape)
        return out if out.ndim else float(out)

    def dforce_dmeasure(self, measure):
        """Its slope df/dq (N m/rad or N/m), same shape as ``measure``."""
        m = np.asarray(measure, float)
        out = np.array([self._scalar(float(q))[1] for q in m.ravel()]).reshape(m.shape)
        return out if out.ndim else float(out)

    def damping_force(self, q, qdot):
        """−c (K_up/K_u + K_low/K_l) q̇ (N m or N) at one coordinate value and rate."""
        s_up, _, s_lo, _ = self._factors(float(q))
        return -self.damping * (s_up + s_lo) * float(qdot)
