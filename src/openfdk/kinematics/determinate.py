"""Determinate kinematic analysis (paper Eqs. 1–3).

Positions: Newton–Raphson on Φ(q, t) = 0 with the update applied on the manifold;
velocities: Φ_q̂ v = ν (Eq. 2); accelerations: Φ_q̂ v̇ = γ (Eq. 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.framedata import FrameData
from ..trial.status import FrameReport, Reason
from .stages import position_stage, velocity_stage_determinate
from .system import ConstraintSystem, KinematicsError, dependent_rows, undetermined_coordinates


@dataclass(frozen=True)
class FrameSolve:
    """Outcome of one frame's position (and velocity/acceleration) solve.

    converged : bool; iterations : int; residual : max |Φ| (m or rad) at the end;
    message : str ('' when converged); reason : Reason (why it failed).
    """

    converged: bool
    iterations: int
    residual: float
    message: str = ""
    reason: Reason = Reason.CONVERGED

    def report(self) -> FrameReport:
        """The frame's structured status."""
        if self.converged:
            return FrameReport.ok(self.iterations, self.residual)
        return FrameReport.failed(self.reason, self.message, self.iterations, self.residual)


def check_square(system: ConstraintSystem):
    """Raise KinematicsError unless the constraints number 6 n_moving rows."""
    m, n = system.n_rows, system.n_coords
    if m != n:
        model = system.model
        kind = "too few" if m < n else "too many"
        raise KinematicsError(
            f"determinate kinematics of model {model.name!r} needs {n} constraint rows "
            f"(6 per moving body), the model has {m} ({kind}); add drivers/joints or use "
            f"marker tracking. Rows: {system.row_names}"
        )


def diagnose_singular(system: ConstraintSystem, Phi_q):
    """A message naming redundant rows and undetermined coordinates of Φ_q̂."""
    rank, rows = dependent_rows(Phi_q, system.row_names)
    coords = undetermined_coordinates(Phi_q, system.model.coordinate_names())
    return (
        f"constraint Jacobian is singular (rank {rank} of {Phi_q.shape[0]} rows): "
        f"redundant or inconsistent rows {rows}; coordinates not determined {coords}"
    )


def solve_positions(system: ConstraintSystem, state, t, alpha=None, tol=1e-10, max_iter=50, data=None):
    """Newton–Raphson on Φ(q, t) = 0 starting from ``state`` (modified in place).

    tol : max |Φ| (SI) and max |Δq̂| for convergence: after a step smaller than tol,
    max |Φ| at the new pose below max(10 tol, 1e-9). Each pose is evaluated once (Φ,
    Φ_q̂, ν); the last one, the solved pose, is the position stage kept in ``data``
    (FrameData, optional). Returns FrameSolve (iterations = Newton steps).
    """
    data = FrameData() if data is None else data
    small_step = False
    for it in range(0, max_iter + 1):
        Phi = position_stage(system, data, state, t, alpha).Phi
        if small_step:
            res = float(np.max(np.abs(Phi))) if Phi.size else 0.0
            if res < max(tol * 10, 1e-9):
                return FrameSolve(True, it, res)
        if it == max_iter:
            break
        try:
            dq = np.linalg.solve(data.Phi_q, -Phi)
        except np.linalg.LinAlgError:
            return FrameSolve(False, it + 1, float(np.max(np.abs(Phi))), diagnose_singular(system, data.Phi_q),
                              Reason.SINGULAR)
        if not np.any(dq) and Phi.size:
            # an exactly zero step leaves the pose as it is: no second evaluation there
            res = float(np.max(np.abs(Phi)))
            if res < max(tol * 10, 1e-9):
                return FrameSolve(True, it + 1, res)
        state.displace(dq)
        small_step = bool(np.max(np.abs(dq)) < tol)
    res = float(np.max(np.abs(Phi)))
    msg = f"Newton–Raphson did not converge in {max_iter} iterations (max |Φ| = {res:.3g})"
    worst = system.row_names[int(np.argmax(np.abs(Phi)))]
    return FrameSolve(False, max_iter, res, msg + f"; largest violation in row {worst!r}", Reason.ITERATION_LIMIT)


def solve_velocities_accelerations(system: ConstraintSystem, state, t, alpha=None, data=None):
    """Eqs. 2–3: set state velocities; returns (v (n,), v̇ (n,)) [m/s, rad/s, m/s², rad/s²].
    ``data``: a FrameData whose position stage ran at this pose (else it runs here)."""
    if data is None or data.Phi_q is None:
        data = position_stage(system, FrameData(), state, t, alpha)
    velocity_stage_determinate(system, data, state)
    return data.v, data.vdot
