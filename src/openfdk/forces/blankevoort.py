"""Blankevoort (1991) ligament law: slack, quadratic toe region, linear region.

This is the ligament law of the FDK paper (Andersen et al. 2017, "Introduction to
Force-dependent Kinematics", J Biomech Eng 139:091001, TMJ ligaments) and of OpenSim's
``Blankevoort1991Ligament`` (see docs/design.md §1 "Ligaments" and docs/ligaments.md).

Governing equations (tension positive, ligaments only pull)::

    l0 = l_r / (1 + ε_r)                       slack length from a reference length/strain
    ε  = (l − l0) / l0                         strain
    f  = 0                                     ε < 0           (slack)
    f  = k·l0·ε² / (4 ε_l)                     0 ≤ ε ≤ 2 ε_l   (toe)
    f  = k·l0·(ε − ε_l)                        ε > 2 ε_l       (linear)
    f_total = max(0, f + c·l̇)  if ε > 0, else 0   (optional linear damping)

``f`` and its slope ``df/dl`` are continuous everywhere (C¹): at ε = 2ε_l both branches
give ``k·l0·ε_l`` and slope ``k``. The stiffness in the linear region is ``df/dl = k``
(N/m) and ``k·l0`` is the force per unit strain (N).

Relation to OpenSim's ``Blankevoort1991Ligament``: OpenSim's ``transition_strain`` is the
strain at which the toe region *ends*, i.e. ``2·ε_l`` here (default 0.06 in both), and
OpenSim's ``linear_stiffness`` (force per unit strain, N) is ``k·l0`` here.

References:
    Blankevoort L, Kuiper JH, Huiskes R, Grootenboer HJ (1991). Articular contact in a
    three-dimensional model of the knee. J Biomech 24(11):1019–1031; and Blankevoort L,
    Huiskes R (1991). Ligament-bone interaction in a three-dimensional model of the knee.
    J Biomech Eng 113(3):263–269.
    Andersen MS, de Zee M, Damsgaard M, Nolte D, Rasmussen J (2017). Introduction to
    force-dependent kinematics: theory and application to mandible modeling. J Biomech
    Eng 139(9):091001.
    OpenSim ``Blankevoort1991Ligament`` (Smith CR, OpenSim 4.1+), documented in its header.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LigamentParameterError", "Blankevoort1991Ligament", "damped_tension"]

#: the strain over which OpenSim fades a ligament's damping in (its SimTK::Function::Step(0, 1, 0, 0.01))
OPENSIM_DAMPING_STRAIN = 0.01


def damped_tension(f, strain, speed, damping, opensim):
    """Tension with damping (arrays, N): f elastic (N), strain ε, speed l̇ (m/s), damping
    c (N·s/m); opensim (bool or array): OpenSim's rule (only lengthening, faded in by the
    quintic step over 0 ≤ ε ≤ 0.01) instead of c·l̇ while taut. Clipped at 0; 0 when slack."""
    u = np.clip(strain / OPENSIM_DAMPING_STRAIN, 0.0, 1.0)
    step = u * u * u * (10.0 + u * (6.0 * u - 15.0))
    f_d = np.where(opensim, np.where(speed > 0.0, damping * speed * step, 0.0), damping * speed)
    return np.where(strain > 0.0, np.maximum(f + f_d, 0.0), 0.0)


class LigamentParameterError(ValueError):
    """A ligament parameter is out of its valid range; the message names the ligament."""


@dataclass(frozen=True)
class Blankevoort1991Ligament:
    """One Blankevoort (1991) ligament element (a line element between two points).

    Properties (all SI):

    stiffness : float, N/m
        ``k``: slope ``df/dl`` of the linear region; ``k·l0`` (N) is the force per unit
        strain. No default. (The FDK paper's TMJ study: 136.2, 272.4, 544.8 N/m for the
        whole ligament, split equally over its 3 elements.)
    slack_length : float, m
        ``l0``: the length at which the ligament becomes taut (ε = 0). No default; see
        :meth:`from_reference` for the reference-length/reference-strain form.
    transition_strain : float, dimensionless, default 0.03
        ``ε_l`` of Blankevoort (1991) and the FDK paper. The toe region ends at
        **2·ε_l** (= 0.06 by default). Note: OpenSim's property of the same name is the
        end of the toe region, so OpenSim ``transition_strain`` = 2 × this value.
    damping : float, N·s/m, default 0.0
        ``c``: linear damping ``c·l̇`` added while the ligament is taut (ε > 0); the total
        force is clipped at 0 (a ligament cannot push).
    damping_rule : "openfdk" (default: ``c·l̇`` while taut) or "opensim" (OpenSim's
        Blankevoort1991Ligament: only while taut *and lengthening*, faded in by
        Simbody's quintic step s(ε/0.01) = 10u³ − 15u⁴ + 6u⁵ over 0 ≤ ε ≤ 0.01).
    name : str, default ""
        Used in error messages.

    Methods are vectorised: ``l`` may be a scalar or an array of any shape (m).
    """

    stiffness: float
    slack_length: float
    transition_strain: float = 0.03
    damping: float = 0.0
    name: str = ""
    damping_rule: str = "openfdk"

    def __post_init__(self):
        if self.damping_rule not in ("openfdk", "opensim"):
            raise LigamentParameterError(f"ligament '{self.name}': damping_rule must be 'openfdk' or 'opensim', "
                                         f"got {self.damping_rule!r}")
        label = f"ligament '{self.name}'" if self.name else "ligament"
        checks = (
            ("stiffness", self.stiffness, "N/m", lambda x: x >= 0.0, ">= 0"),
            ("slack_length", self.slack_length, "m", lambda x: x > 0.0, "> 0"),
            ("transition_strain", self.transition_strain, "", lambda x: x > 0.0, "> 0"),
            ("damping", self.damping, "N·s/m", lambda x: x >= 0.0, ">= 0"),
        )
        for field, value, unit, ok, expected in checks:
            value_f = float(value)
            if not np.isfinite(value_f) or not ok(value_f):
                raise LigamentParameterError(
                    f"{label}: {field} must be finite and {expected} {unit}".rstrip()
                    + f", got {value!r}"
                )

    @classmethod
    def from_reference(
        cls,
        stiffness: float,
        reference_length: float,
        reference_strain: float,
        transition_strain: float = 0.03,
        damping: float = 0.0,
        name: str = "",
    ) -> "Blankevoort1991Ligament":
        """Build from a reference length ``l_r`` (m) and the strain ``ε_r`` at that length.

        ``l0 = l_r / (1 + ε_r)`` (FDK paper, parameter study): e.g. the element length in
        the CT (closed-mouth) pose with ``ε_r ∈ {−0.04, …, 0.04}``. A positive ``ε_r``
        means the ligament is already stretched at ``l_r``. Requires ``ε_r > −1``.
        """
        label = f"ligament '{name}'" if name else "ligament"
        if not float(reference_strain) > -1.0:
            raise LigamentParameterError(
                f"{label}: reference_strain must be > -1, got {reference_strain!r}"
            )
        if not (np.isfinite(float(reference_length)) and float(reference_length) > 0.0):
            raise LigamentParameterError(
                f"{label}: reference_length must be finite and > 0 m, got {reference_length!r}"
            )
        # l0 = l_r / (1 + ε_r)  (paper, reference-strain parametrisation)
        slack_length = float(reference_length) / (1.0 + float(reference_strain))
        return cls(stiffness, slack_length, transition_strain, damping, name)

    # ------------------------------------------------------------------ law
    def strain(self, length):
        """Strain ``ε = (l − l0)/l0``; ``length`` any shape, m -> same shape, dimensionless."""
        l = np.asarray(length, dtype=float)
        return (l - self.slack_length) / self.slack_length

    def elastic_force(self, length):
        """Elastic (undamped) tension ``f(l)``; ``length`` any shape, m -> same shape, N."""
        eps = self.strain(length)
        eps_l = self.transition_strain
        k_l0 = self.stiffness * self.slack_length  # force per unit strain, N
        toe = k_l0 * eps * eps / (4.0 * eps_l)  # k·l0·ε²/(4ε_l), 0 ≤ ε ≤ 2ε_l
        linear = k_l0 * (eps - eps_l)  # k·l0·(ε − ε_l), ε > 2ε_l
        f = np.where(eps > 2.0 * eps_l, linear, np.where(eps >= 0.0, toe, 0.0))
        return f if f.ndim else float(f)

    def force(self, length, lengthening_speed=None):
        """Ligament tension (N, ≥ 0).

        length : any shape, m.  lengthening_speed : same shape or None, m/s (``l̇``,
        positive when lengthening); damping acts only when taut and the total is
        clipped at 0. Returns the tension, same shape as ``length``, N.
        """
        f = np.asarray(self.elastic_force(length), dtype=float)
        if lengthening_speed is not None and self.damping > 0.0:
            f = np.asarray(damped_tension(f, self.strain(length), np.asarray(lengthening_speed, dtype=float),
                                          self.damping, self.damping_rule == "opensim"))
        return f if f.ndim else float(f)

    def dforce_dlength(self, length):
        """Elastic stiffness ``df/dl`` (N/m), the ligament term of the FDK Jacobian.

        ``df/dl = 0`` (ε < 0), ``k·ε/(2ε_l)`` (toe), ``k`` (linear). ``length`` any
        shape, m -> same shape, N/m. (Damping is not included.)
        """
        eps = self.strain(length)
        eps_l = self.transition_strain
        k = self.stiffness
        # d/dl [k·l0·ε²/(4ε_l)] = k·ε/(2ε_l);  d/dl [k·l0·(ε − ε_l)] = k
        toe = k * eps / (2.0 * eps_l)
        df = np.where(eps > 2.0 * eps_l, k, np.where(eps >= 0.0, toe, 0.0))
        return df if df.ndim else float(df)
