"""Linear spring on a scalar kinematic measure (e.g. the weak springs on FDK DOFs).

    f = −k·(m − m_rest),   df/dm = −k

``f`` is the generalized force conjugate to the measure ``m`` (N for a length measure,
N·m for an angle measure): it pushes the measure back to its rest value. The FDK paper
(Andersen et al. 2017, J Biomech Eng 139:091001) puts a weak spring (≈ 0.1 N/m) on each
FDK DOF so the equilibrium problem stays regular when the joint is out of contact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SpringParameterError", "LinearSpring"]


class SpringParameterError(ValueError):
    """A spring parameter is invalid; the message names the spring."""


@dataclass(frozen=True)
class LinearSpring:
    """Linear spring ``f = −k (m − m_rest)`` on a scalar measure value ``m``.

    stiffness : float, ≥ 0, N/<unit> (N/m for a length, N·m/rad for an angle).
    rest_value : float, <unit> (m or rad): the measure value at which ``f = 0``.
    unit : str, the unit of the measure, e.g. ``"m"`` or ``"rad"`` (documentation and
        error messages; the arithmetic is unit-agnostic).
    name : str, used in error messages.
    """

    stiffness: float
    rest_value: float
    unit: str = "m"
    name: str = ""

    def __post_init__(self):
        label = f"spring '{self.name}'" if self.name else "spring"
        k = float(self.stiffness)
        if not (np.isfinite(k) and k >= 0.0):
            raise SpringParameterError(
                f"{label}: stiffness must be finite and >= 0 N/{self.unit}, got {self.stiffness!r}"
            )
        if not np.isfinite(float(self.rest_value)):
            raise SpringParameterError(
                f"{label}: rest_value must be finite ({self.unit}), got {self.rest_value!r}"
            )
        if not isinstance(self.unit, str) or not self.unit:
            raise SpringParameterError(
                f"{label}: unit must be a non-empty string, got {self.unit!r}")

    def force(self, measure):
        """Generalized force ``f = −k (m − m_rest)``; ``measure`` any shape, <unit>.

        Returns the same shape, N (length measure) or N·m (angle measure).
        """
        f = -self.stiffness * (np.asarray(measure, dtype=float) - self.rest_value)
        return f if f.ndim else float(f)

    def dforce_dmeasure(self, measure):
        """``df/dm = −k`` for every entry of ``measure`` (same shape), N/<unit>."""
        df = np.full(np.shape(measure), -float(self.stiffness))
        return df if df.ndim else float(df)
