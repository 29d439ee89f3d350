"""Hard constraints, drivers and FDK DOF declarations (paper Eq. 1).

Every row is ``Φ(q, t) = m(q) − f(t) = 0`` for a measure m and a target f: a constant
for joints and generic constraints, a time function for drivers, and the input α for an
FDK DOF (``Φ^FDK(q) − α = 0`` with α̇ = α̈ = 0). With the paper's conventions
``Φ_q̂ v = −Φ_t = ḟ`` (Eq. 2) and ``Φ_q̂ v̇ = γ = f̈ − b`` (Eq. 3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .kernels import marker_positions_jacobian
from .measures import Measure
from .timefunctions import TimeFunction

JOINT = "joint"
DRIVER = "driver"


@dataclass(frozen=True, eq=False)
class Constraint:
    """A block of constraint rows ``measure(q) − target(t) = 0``.

    name : str; measure : Measure; kind : "joint" or "driver";
    function : TimeFunction giving the target (SI units of the measure) or None for
        ``target`` (size,) constant;
    reaction : whether its rows carry reaction forces in inverse dynamics (joints: yes;
        drivers: only if declared, e.g. a motor);
    row_names : one label per row, used in messages and outputs.
    """

    name: str
    measure: Measure
    kind: str = JOINT
    target: np.ndarray = field(default_factory=lambda: np.zeros(0))
    function: TimeFunction | None = None
    reaction: bool = True
    row_names: tuple = ()
    joint_type: str = "generic"

    @property
    def size(self):
        return self.measure.size

    def target_derivatives(self, t):
        """(f, ḟ, f̈) each (size,) in SI units at time t (s)."""
        if self.function is None:
            z = np.zeros(self.size)
            return self.target, z, z
        return self.function.derivatives(t)


@dataclass(frozen=True, eq=False)
class FDKDof:
    """A force-dependent kinematics DOF: a scalar measure whose value α is an input.

    name : str; measure : Measure of size 1; initial : α at the reference (SI unit of
    the measure, m or rad); settings : dict of FDK solver settings for this DOF
    (used by the FDK solver, e.g. ``max_step``).
    """

    name: str
    measure: Measure
    initial: float = 0.0
    settings: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class MarkerSet:
    """All markers of a model, packed for vectorised evaluation.

    body : (n,) int body index; p_BM : (n, 3) m; weight : (n,); names, labels : tuples.
    """

    names: tuple
    labels: tuple
    body: np.ndarray
    p_BM: np.ndarray
    weight: np.ndarray

    @property
    def size(self):
        return len(self.names)

    def positions(self, state):
        """Model marker positions p_WM (n, 3) m."""
        value, _, _ = marker_positions_jacobian(
            state.p_WB, state.R_WB, state.w_BB, state.column, self.body, self.p_BM, state.n_coords, 0)
        return value.reshape(-1, 3)

    def evaluate(self, state, order=1):
        """(p_WM (3n,) m, M (3n, 6 n_moving), b (3n,)) for all markers, stacked by marker.

        ∂p/∂δr = I, ∂p/∂δπ' = −R_WB p̃_BM, b = R_WB ω̃' ω̃' p_BM (docs/design.md §1); numba
        kernel :func:`openfdk.model.kernels.marker_positions_jacobian`.
        """
        value, M, b = marker_positions_jacobian(
            state.p_WB, state.R_WB, state.w_BB, state.column, self.body, self.p_BM, state.n_coords, order
        )
        return value, (M if order >= 1 else None), (b if order >= 2 else None)
