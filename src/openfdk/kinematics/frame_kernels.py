"""One frame's kinematic solves as numba kernels over a compiled constraint program.

Each kernel runs a whole per-frame algorithm — the Newton–Raphson of determinate
positions (Eq. 1), the velocity and acceleration solves (Eqs. 2–3), the Gauss–Newton
SQP of marker tracking (Eqs. 4–5) and its velocity/acceleration solves (Eqs. 8–10) —
with no Python per iteration: the constraint rows come from
:func:`openfdk.model.compiled.evaluate_into`, markers from
:func:`openfdk.model.kernels.marker_positions_jacobian`, updates from
:func:`openfdk.model.kernels.displace_poses`. The callers in
:mod:`.determinate` and :mod:`.tracking` keep the Python-level contract (FrameSolve,
messages); a kernel returns a status code and leaves the state where the Python loop
would have left it, so that messages are built in Python from the same pose.

``prog`` below is the tuple ``CompiledMeasures.program + (n_node_rows,)``; ``f, df, ddf``
(m,) the rows' targets (Φ = m − f); ``angle`` (m,) bool rows compared modulo 2π;
``form`` the tuple (rows, cols, starts, ptr, earlier) of Φ_q̂'s block lower-triangular
form (:class:`~.block_triangular.BlockForm`, ``ConstraintSystem.block_args``): the
determinate solves factorise Φ_q̂ block by block (:func:`~.block_triangular.block_lu`).

(numba caches these kernels with the code of :func:`~openfdk.model.compiled.evaluate_into`
inlined: edit this file whenever that one changes — last: the program's column blocks,
linear chains folded,
rotation angles without allocation.)
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model.compiled import evaluate_into
from ..model.kernels import displace_poses, marker_positions_jacobian, set_velocities
from .block_triangular import block_lu, block_solve, lu_factor, lu_solve
from .envelope_lu import factor_permuted, solve_permuted
from .kkt import kkt_assemble, kkt_chord_step, kkt_step

OK, SINGULAR, NOT_CONVERGED, MEASURE_ERROR = 0, 1, 2, 3
#: the tracking's steps after the first reuse its factorized KKT matrix (chord steps) while
#: each is at most this fraction of the one before; else the next step factorizes anew
CHORD_CONTRACTION = 0.25
#: a chord step ends the solve when it is below this fraction of tol_step (what a linear
#: rate leaves behind it must be as far below the tolerance as Newton's square is)
CHORD_TOLERANCE = 1e-3


@njit(cache=True)
def _residual(val, f, angle, Phi):
    """Φ = m − f with angle rows wrapped into [−π, π) (Eq. 1); returns max |Φ|."""
    res = 0.0
    for r in range(val.shape[0]):
        x = val[r] - f[r]
        if angle[r]:
            x = (x + np.pi) % (2.0 * np.pi) - np.pi
        Phi[r] = x
        res = max(res, abs(x))
    return res


@njit(cache=True)
def newton_positions(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows, n_node_rows,
                     p_WB, quat_WB, R_WB, w_BB, v_WB, column, moving, f, angle, tol, max_iter, A_out, Phi_out, form):
    """Newton–Raphson on Φ(q, t) = 0 (Eq. 1), updates on the manifold, state in place.

    The convergence check evaluates the rows at order 1 at the solved pose: on OK,
    A_out (m, n) holds Φ_q̂ and Phi_out (m,) Φ there (the position stage, evaluated once).

    Converged when max |Δq̂| < tol and then max |Φ| < max(10 tol, 1e-9) (the rules of
    :func:`openfdk.kinematics.determinate.solve_positions`). Returns (status, iterations,
    max |Φ|, failing node, error code); on SINGULAR the state is at the pose whose Φ_q̂
    is singular, on NOT_CONVERGED at the last pose."""
    m = out_rows.shape[0]
    n = 6 * moving.shape[0]
    val = np.empty(m)
    A = np.empty((m, n))
    bias = np.empty(m)
    Phi = np.empty(m)
    piv = np.empty(n, np.int64)
    LU = np.empty((n, n))
    rhs = np.empty(n)
    dq = np.empty(n)
    rows, cols, starts, ptr, earlier = form
    res = 0.0
    for it in range(1, max_iter + 1):
        e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                       n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(1), val, A, bias)
        if e_node >= 0:
            return MEASURE_ERROR, it, np.inf, e_node, e_kind
        res = _residual(val, f, angle, Phi)
        if not block_lu(A, rows, cols, starts, LU, piv):
            return SINGULAR, it, res, -1, 0
        for r in range(n):
            rhs[r] = -Phi[r]
        block_solve(LU, piv, rows, cols, starts, ptr, earlier, rhs, dq)
        displace_poses(p_WB, quat_WB, R_WB, moving, column, dq)
        step = 0.0
        for r in range(n):
            step = max(step, abs(dq[r]))
        if step < tol:
            e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                           n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(1), val, A_out,
                                           bias)
            if e_node >= 0:
                return MEASURE_ERROR, it, np.inf, e_node, e_kind
            res = _residual(val, f, angle, Phi_out) if m > 0 else 0.0
            if res < max(tol * 10.0, 1e-9):
                return OK, it, res, -1, 0
    e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                   n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(0), val, A, bias)
    if e_node >= 0:
        return MEASURE_ERROR, max_iter, np.inf, e_node, e_kind
    res = _residual(val, f, angle, Phi)
    return NOT_CONVERGED, max_iter, res, -1, 0


@njit(cache=True)
def determinate_rates(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows, n_node_rows,
                      p_WB, R_WB, w_BB, v_WB, column, moving, df, ddf, v, vdot, form):
    """Φ_q̂ v = ν = ḟ (Eq. 2), sets the state's velocities, then Φ_q̂ v̇ = γ = f̈ − b
    (Eq. 3), one LU factorisation for both; Φ_q̂ evaluated here (callers without a
    position stage). v, vdot (n,) outputs. Returns (status, failing node, error code)."""
    m = out_rows.shape[0]
    n = 6 * moving.shape[0]
    val = np.empty(m)
    A = np.empty((m, n))
    bias = np.empty(m)
    e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                   n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(1), val, A, bias)
    if e_node >= 0:
        return MEASURE_ERROR, e_node, e_kind
    return rates_from_jacobian(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows, n_node_rows,
                               p_WB, R_WB, w_BB, v_WB, column, moving, A, df, ddf, v, vdot, np.empty(m), form)


@njit(cache=True)
def rates_from_jacobian(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows, n_node_rows,
                        p_WB, R_WB, w_BB, v_WB, column, moving, A, df, ddf, v, vdot, gamma, form):
    """Eqs. 2–3 with the position stage's Φ_q̂ = A (m, n) (not evaluated again): one LU
    factorisation of A, Φ_q̂ v = ḟ, the state's velocities set, one order-2 evaluation
    of the rows for b (it needs v), γ = f̈ − b (m,) output, Φ_q̂ v̇ = γ. v, vdot (n,)
    outputs. Returns (status, failing node, error code)."""
    m = out_rows.shape[0]
    n = 6 * moving.shape[0]
    val = np.empty(m)
    A2 = np.empty((m, n))
    bias = np.empty(m)
    piv = np.empty(n, np.int64)
    LU = np.empty((n, n))
    rows, cols, starts, ptr, earlier = form
    if not block_lu(A, rows, cols, starts, LU, piv):
        return SINGULAR, -1, 0
    block_solve(LU, piv, rows, cols, starts, ptr, earlier, df, v)
    set_velocities(v, column, moving, v_WB, w_BB)
    e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                   n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(2), val, A2, bias)
    if e_node >= 0:
        return MEASURE_ERROR, e_node, e_kind
    for r in range(m):
        gamma[r] = ddf[r] - bias[r]
    block_solve(LU, piv, rows, cols, starts, ptr, earlier, gamma, vdot)
    return OK, -1, 0


@njit(cache=True)
def _soft_rows(p_WB, R_WB, w_BB, v_WB, column, marker_body, p_BM, n, order,
               top, tnode_row, tnode_size, ti_start, tiparams, tf_start, tfparams, tout_rows, tn_node_rows):
    """The soft rows Ψ of Eq. 4 at the pose: the markers' 3 nm positions, then the nt
    task measures (coordinate tasks) of the task program ``t*``. Returns (p (3 nm + nt,),
    J (3 nm + nt, n), b (3 nm + nt,) (order 2), failing task node or −1, error code)."""
    pm, Jm, bm = marker_positions_jacobian(p_WB, R_WB, w_BB, column, marker_body, p_BM, n, order)
    nt = tout_rows.shape[0]
    if nt == 0:
        return pm, Jm, bm, -1, 0
    rows = pm.shape[0]
    p = np.empty(rows + nt)
    J = np.empty((rows + nt, n))
    b = np.zeros(rows + nt)
    p[:rows] = pm
    J[:rows] = Jm
    b[:rows] = bm
    tv = np.empty(nt)
    tJ = np.empty((nt, n))
    tb = np.empty(nt)
    e_node, e_kind = evaluate_into(top, tnode_row, tnode_size, ti_start, tiparams, tf_start, tfparams, tout_rows,
                                   tn_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, order, tv, tJ, tb)
    p[rows:] = tv
    J[rows:] = tJ
    if order >= 2:
        b[rows:] = tb
    return p, J, b, e_node, e_kind


@njit(cache=True)
def tracking_positions(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows, n_node_rows,
                       p_WB, quat_WB, R_WB, w_BB, v_WB, column, moving, f, angle,
                       marker_body, p_BM, w, x, tol_step, tol_constraint, max_iter, K, lam, S, use_S, perm,
                       LU, piv, first, last, held,
                       top, tnode_row, tnode_size, ti_start, tiparams, tf_start, tfparams, tout_rows, tn_node_rows):
    """Gauss–Newton SQP of marker tracking (Eqs. 4–5) from the state (in place).

    marker_body (nm,), p_BM (nm, 3) m; w (3 nm + nt,) row weights; x (3 nm + nt,) m
    measured positions, then the nt task targets (rad, m) (0 where w = 0); the task
    program ``t*`` (coordinate tasks, empty without); K (n + m, n + m) output, the last
    KKT matrix (reused by Eqs. 8–10); lam (m,) output multipliers; S (n, n), use_S: the
    Hessian's second-order terms added for the steps (:func:`~openfdk.kinematics.kkt.kkt_step`;
    Newton's steps instead of Gauss–Newton's, K as without); perm (n + m,) int: the order
    the steps' matrices are factorized in (:mod:`.envelope_lu`). The first step's matrix is
    factorized; the next steps are chord steps with it on the full stationarity residual
    (:func:`~openfdk.kinematics.kkt.kkt_chord_step`: the same optimum) while each
    contracts CHORD_CONTRACTION-fold, else the next step factorizes again. The
    factorization was the tracking's cost (DM knee: 255 × 255 KKT, 3 steps per pose).
    A chord step needs only the residual, so K is assembled only where the solve returns
    after one, at that step's pose, as a factorized step assembles it (DM knee: 4.6
    steps per pose, K's assembly 56 µs of each).
    LU (n + m, n + m), piv, first, last (n + m,) int: the factors of the step matrix,
    read and written; held (1,) bool: they hold an earlier solve's factors (read: the
    first step is then a chord step with them, as if this solve had factorized them;
    written: whether they hold factors on return). A solve of a pose near the one they
    were factorized at (FDK's evaluations of one frame, :class:`~.tracking.KKTFactors`)
    then factorizes only if a chord step stops contracting.
    Converged when max |Δq̂| < tol_step and max |Φ| ≤ tol_constraint at the start of that
    step. Returns (status, iterations, max |Φ|, last step, failing node, error code); a
    failing task node is reported as −2 − node."""
    m = out_rows.shape[0]
    n = 6 * moving.shape[0]
    val = np.empty(m)
    A = np.empty((m, n))
    bias = np.empty(m)
    Phi = np.empty(m)
    factored = held[0]  # LU holds an earlier step's matrix: chord steps (kkt_chord_step)
    stale = False  # the last step was a chord step: K is not assembled at its pose
    step = np.inf
    res = np.inf
    scratch = np.empty(n + m)
    p = np.empty(0)
    J = np.empty((0, n))
    for it in range(1, max_iter + 1):
        p, J, _, t_node, t_kind = _soft_rows(p_WB, R_WB, w_BB, v_WB, column, marker_body, p_BM, n, np.int64(1), top,
                                             tnode_row, tnode_size, ti_start, tiparams, tf_start, tfparams, tout_rows,
                                             tn_node_rows)
        if t_node >= 0:
            return MEASURE_ERROR, it, np.inf, step, -2 - t_node, t_kind
        e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                       n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(1), val, A, bias)
        if e_node >= 0:
            return MEASURE_ERROR, it, np.inf, step, e_node, e_kind
        _residual(val, f, angle, Phi)
        chord = factored
        if factored:
            sol, chord_step, res = kkt_chord_step(J, w, p, x, A, Phi, lam, LU, piv, perm, first, last)
            if not chord_step <= CHORD_CONTRACTION * step:
                # not contracting (the pose is far from the factorized one): the step is not
                # taken, a factorized step from this pose is (far from the optimum a poor
                # step could lead to another local optimum of the fit)
                factored = False
                chord = False
            else:
                step = chord_step
                for r in range(m):
                    lam[r] += sol[n + r]
        if not chord:
            held[0] = False  # (until the factorization below has succeeded)
            sol, step, res = kkt_step(J, w, p, x, A, Phi, K, S, use_S, LU, piv, perm, first, last)
            factored = True
            held[0] = True
            for r in range(m):
                lam[r] = sol[n + r]
        stale = chord
        for r in range(n):
            if not np.isfinite(sol[r]):
                return SINGULAR, it, np.nan, step, -1, 0
        displace_poses(p_WB, quat_WB, R_WB, moving, column, sol[:n].copy())
        # a chord step converges linearly: what is left after it is up to a third of it,
        # where Newton leaves its square (CHORD_TOLERANCE)
        if step < (CHORD_TOLERANCE * tol_step if chord else tol_step) and res <= tol_constraint:
            if stale:  # K at this step's pose, as kkt_step leaves it (handed to Eqs. 8–10)
                kkt_assemble(J, w, p, x, A, Phi, K, scratch)
            return OK, it, res, step, -1, 0
    if stale:
        kkt_assemble(J, w, p, x, A, Phi, K, scratch)
    return NOT_CONVERGED, max_iter, res, step, -1, 0


@njit(cache=True)
def tracking_rates(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows, n_node_rows,
                   p_WB, R_WB, w_BB, v_WB, column, moving, df, ddf, marker_body, p_BM, w,
                   target_v, target_a, K, perm, J, f, angle, v, vdot, A, Phi,
                   top, tnode_row, tnode_size, ti_start, tiparams, tf_start, tfparams, tout_rows, tn_node_rows):
    """Velocities (Eqs. 8–9) and accelerations (Eq. 10) with the KKT matrix K (n + m,
    n + m) of the position solve: K [v; ·] = [Ψ_q̂ᵀ W (ẋ + δ̇); ν], sets the state's
    velocities, then K [v̇; ·] = [Ψ_q̂ᵀ W (ẍ + δ̈ − b_Ψ); γ]. target_v, target_a (3 nm,)
    (0 where occluded), then the nt task rows' ḟ and f̈. J (3 nm, n): the marker Jacobian
    Ψ_q̂ at this pose (the position stage's); the task rows (program ``t*``) are evaluated
    here with their bias. The rows are evaluated once here, at order 2 (b needs v):
    outputs A (m, n) Φ_q̂ and Phi (m,) Φ = m − f (angle rows wrapped) at the pose, for the
    later stages. perm (n + m,) int: the order K is factorized in (:mod:`.envelope_lu`).
    Returns (status, failing node, error code)."""
    m = out_rows.shape[0]
    n = 6 * moving.shape[0]
    nt = tout_rows.shape[0]
    rows = marker_body.shape[0] * 3
    tv = np.empty(nt)
    tJ = np.empty((nt, n))
    tb = np.empty(nt)
    if nt > 0:
        e_node, e_kind = evaluate_into(top, tnode_row, tnode_size, ti_start, tiparams, tf_start, tfparams, tout_rows,
                                       tn_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(1), tv, tJ, tb)
        if e_node >= 0:
            return MEASURE_ERROR, -2 - e_node, e_kind
    val = np.empty(m)
    bias = np.empty(m)
    piv = np.empty(n + m, np.int64)
    first = np.empty(n + m, np.int64)
    last = np.empty(n + m, np.int64)
    LU = np.empty((n + m, n + m))
    if not factor_permuted(K, perm, LU, piv, first, last):
        return SINGULAR, -1, 0
    rhs = np.zeros(n + m)
    for c in range(n):
        s = 0.0
        for k in range(rows):
            s += J[k, c] * w[k] * target_v[k]
        for k in range(nt):
            s += tJ[k, c] * w[rows + k] * target_v[rows + k]
        rhs[c] = s
    for r in range(m):
        rhs[n + r] = df[r]
    sol = solve_permuted(LU, piv, first, last, perm, rhs)
    for c in range(n):
        v[c] = sol[c]
    set_velocities(v, column, moving, v_WB, w_BB)
    _, _, b_m = marker_positions_jacobian(p_WB, R_WB, w_BB, column, marker_body, p_BM, n, np.int64(2))
    e_node, e_kind = evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                                   n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(2), val, A, bias)
    if e_node >= 0:
        return MEASURE_ERROR, e_node, e_kind
    _residual(val, f, angle, Phi)
    if nt > 0:  # the task rows' bias, now that v is known
        e_node, e_kind = evaluate_into(top, tnode_row, tnode_size, ti_start, tiparams, tf_start, tfparams, tout_rows,
                                       tn_node_rows, p_WB, R_WB, w_BB, v_WB, column, n, np.int64(2), tv, tJ, tb)
        if e_node >= 0:
            return MEASURE_ERROR, -2 - e_node, e_kind
    for c in range(n):
        s = 0.0
        for k in range(rows):
            if w[k] != 0.0:
                s += J[k, c] * w[k] * (target_a[k] - b_m[k])
        for k in range(nt):
            s += tJ[k, c] * w[rows + k] * (target_a[rows + k] - tb[k])
        rhs[c] = s
    for r in range(m):
        rhs[n + r] = ddf[r] - bias[r]
    sol = solve_permuted(LU, piv, first, last, perm, rhs)
    for c in range(n):
        vdot[c] = sol[c]
    return OK, -1, 0


def small_solve(A, B):
    """X = A⁻¹ B for a small square A (n, n) and B (n,) or (n, k), by the compiled LU above
    (no BLAS call: at this size its thread start-up costs more than the solve). Raises
    numpy.linalg.LinAlgError if a pivot is exactly zero, as numpy.linalg.solve does."""
    LU = np.array(A, dtype=float, order="C")
    if LU.ndim != 2 or LU.shape[0] != LU.shape[1]:
        raise np.linalg.LinAlgError("small_solve: A must be square")
    piv = np.empty(LU.shape[0], np.int64)
    if not lu_factor(LU, piv):
        raise np.linalg.LinAlgError("singular matrix")
    B = np.asarray(B, dtype=float)
    if B.ndim == 1:
        return lu_solve(LU, piv, B.copy())
    X = np.empty(B.shape)
    for j in range(B.shape[1]):
        X[:, j] = lu_solve(LU, piv, np.array(B[:, j]))
    return X
