"""Determinate kinematic analysis (paper Eqs. 1–3).

Positions: Newton–Raphson on Φ(q, t) = 0 with the update applied on the manifold;
velocities: Φ_q̂ v = ν (Eq. 2); accelerations: Φ_q̂ v̇ = γ (Eq. 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.framedata import FrameData  # noqa: F401  (re-exported for callers building stage data)
from ..trial.status import FrameReport, Reason
from .frame_kernels import MEASURE_ERROR, OK, SINGULAR, determinate_rates, newton_positions, rates_from_jacobian
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


def _kernel_args(system, state):
    """The compiled program and the state arrays, in the kernels' argument order."""
    return system.program.program + (system.program.n_node_rows,)


def solve_positions(system: ConstraintSystem, state, t, alpha=None, tol=1e-10, max_iter=50, data=None):
    """Newton–Raphson on Φ(q, t) = 0 starting from ``state`` (modified in place).

    tol : max |Φ| (SI) and max |Δq̂| for convergence. Returns FrameSolve. The iterations
    run in one kernel (:func:`.frame_kernels.newton_positions`); data : FrameData whose
    position stage (Φ, Φ_q̂, ν at the solved pose) is filled on convergence.
    """
    if system.n_rows != system.n_coords:  # the kernels solve square systems (no bounds checks in them)
        Phi_q = system.evaluate(state, t, alpha, order=1)[1]
        return FrameSolve(False, 0, float("nan"), f"{system.n_rows} constraint rows for {system.n_coords} coordinates: "
                          + diagnose_singular(system, Phi_q), Reason.SINGULAR)
    f, df, _ = system.targets(t, alpha)
    A, Phi = np.empty((system.n_rows, system.n_coords)), np.empty(system.n_rows)
    status, it, res, e_node, e_kind = newton_positions(
        *_kernel_args(system, state), state.p_WB, state.quat_WB, state.R_WB, state.w_BB, state.v_WB,
        state.column, state.moving, f, system.angle_rows, tol, max_iter, A, Phi, system.block_args)
    if status == OK:
        if data is not None:  # the position stage, from the kernel's check at the solved pose
            data.t, data.alpha = t, alpha
            data.Phi, data.Phi_q, data.nu = Phi, A, df.copy()  # Eq. 2: ν = −Φ_t = ḟ
        return FrameSolve(True, int(it), float(res))
    if status == MEASURE_ERROR:
        system.program.raise_error(e_node, e_kind, state)
    if status == SINGULAR:
        Phi_q = system.evaluate(state, t, alpha, order=1)[1]
        return FrameSolve(False, int(it), float(res), diagnose_singular(system, Phi_q), Reason.SINGULAR)
    Phi = system.evaluate(state, t, alpha, order=0)[0]
    msg = f"Newton–Raphson did not converge in {max_iter} iterations (max |Φ| = {res:.3g})"
    worst = system.row_names[int(np.argmax(np.abs(Phi)))]
    return FrameSolve(False, max_iter, float(res), msg + f"; largest violation in row {worst!r}",
                      Reason.ITERATION_LIMIT)


def solve_velocities_accelerations(system: ConstraintSystem, state, t, alpha=None, data=None):
    """Eqs. 2–3: set state velocities; returns (v (n,), v̇ (n,)) [m/s, rad/s, m/s², rad/s²]
    (also stored in ``data``, a FrameData, when given, with γ (m,)). With a position
    stage in ``data`` (data.Phi_q), Φ_q̂ is not evaluated again
    (:func:`.frame_kernels.rates_from_jacobian`).

    Raises ``np.linalg.LinAlgError`` if Φ_q̂ is singular or not square."""
    if system.n_rows != system.n_coords:  # the kernels solve square systems (no bounds checks in them)
        raise np.linalg.LinAlgError(f"{system.n_rows} constraint rows for {system.n_coords} coordinates")
    _, df, ddf = system.targets(t, alpha)
    n = system.n_coords
    v, vdot = np.empty(n), np.empty(n)
    if data is not None and data.Phi_q is not None:
        gamma = np.empty(system.n_rows)
        status, e_node, e_kind = rates_from_jacobian(
            *_kernel_args(system, state), state.p_WB, state.R_WB, state.w_BB, state.v_WB, state.column,
            state.moving, data.Phi_q, df, ddf, v, vdot, gamma, system.block_args)
        data.gamma = gamma
    else:
        status, e_node, e_kind = determinate_rates(
            *_kernel_args(system, state), state.p_WB, state.R_WB, state.w_BB, state.v_WB, state.column,
            state.moving, df, ddf, v, vdot, system.block_args)
    if status == MEASURE_ERROR:
        system.program.raise_error(e_node, e_kind, state)
    if status == SINGULAR:
        raise np.linalg.LinAlgError("Singular matrix")
    if data is not None:
        data.v, data.vdot = v, vdot
    return v, vdot
