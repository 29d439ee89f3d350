"""Determinate kinematics and inverse dynamics of a whole trial in compiled calls, for a
tree of OpenSim-style joints driven by its coordinates (``openfdk run model.osim
--motion ik.mot [--external-loads grf.xml]``: OpenSim's inverse dynamics).

:func:`openfdk.analysis.run.run_trial` takes this path whenever it covers the run
(:func:`tree_trial`), and the trial driver's frame-by-frame one otherwise. Covered:

* determinate kinematics (no marker trial), no FDK DOF;
* every moving body the child of one joint of type ``custom`` and every coordinate set
  by a driver or a lock of its own (:func:`openfdk.kinematics.tree_kinematics.tree_plan`:
  no coupler, no other joint or constraint);
* a statically determinate equilibrium (no muscle, actuator or one-sided reaction,
  polynomial criterion: :func:`openfdk.dynamics.determinate_reactions.reactions_form`)
  whose only applied loads are measured ones (``external_loads``, known at every frame).

Per frame, in one kernel over a chunk of frames (:func:`_frames`):

1. the coordinates' targets f, ḟ, f̈ (sampled for all frames at once beforehand,
   :meth:`~openfdk.kinematics.system.ConstraintSystem.targets_over`) give the bodies'
   poses, velocities and accelerations by forward kinematics
   (:func:`~openfdk.kinematics.tree_kinematics.tree_forward`), where Newton's method,
   Eq. 2 and Eq. 3 give the same (to round-off);
2. the constraint program at that pose (order 1: Φ and Φ_q̂, one evaluation); the
   frame is accepted only if max |Φ| ≤ 1e-10 (Newton's tolerance);
3. d = [m (r̈ − g); J ω̇' + ω̃' J ω'] − Q^applied and C = the reaction rows of Φ_q̂ᵀ
   (Eqs. 12–13, :mod:`openfdk.dynamics.equilibrium`), solved by 6×6 blocks
   (:func:`_reactions`: the factors of
   :func:`~openfdk.dynamics.determinate_reactions.block_reactions`, read from Φ_q̂'s
   pattern only).

The recorded values are those of the frame-by-frame run (kinematics.csv, forces.csv,
generalized_forces.csv), except the Newton iterations, 0 here. A frame where a step
fails (Φ not ≈ 0, a measure undefined, a singular or inaccurate solve) sends the whole
run to the frame-by-frame path, which names the frame and its reason.

No frame depends on another (no warm start), so checkpoints are not needed: a resumed
run computes every frame again, with the same result. Ctrl-C stops between chunks of
:data:`CHUNK` frames with the finished frames (as the trial driver does).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kinematics.block_triangular import block_solve, lu_factor_range
from ..dynamics.equilibrium import _body_arrays, _inertial_minus_gravity, _reaction_rows
from ..dynamics.results import COLUMN, EXTERNAL_LOAD_KEYS, forces_fields, forces_result
from ..forces.data_loads import apply_data_loads
from ..kinematics.analysis import kinematics_fields, kinematics_result
from ..kinematics.tree_kinematics import tree_forward, tree_plan
from ..model.compiled import evaluate_program
from ..model.kernels import get_poses, get_velocities
from ..numerics.spatial import rotation_matrix
from ..recruitment.result import STATUS_OPTIMAL
from ..trial.driver import Recording, TrialInterrupted, _progress, _StopOnSigint
from ..trial.status import FrameReport

#: frames per compiled call (progress and Ctrl-C between calls)
CHUNK = 1000
#: max |Φ| (m or rad) of an accepted forward-kinematics pose (Newton's tolerance)
TOLERANCE = 1e-10
OK, NOT_CLOSED, MEASURE_FAILED, SOLVE_FAILED = 0, 1, 2, 3


class TreeTrial:
    """The compiled run of one trial (module docstring). Build it with :func:`tree_trial`."""

    def __init__(self, model, system, solver, plan, times, alpha):
        self.model, self.system, self.solver, self.plan = model, system, solver, plan
        self.times, self.alpha = times, alpha
        self.targets = system.targets_over(times, alpha)
        nl = len(model.external_loads)
        loads = solver.forces.by_kind.get("external_loads")
        self.loads = (np.zeros(0, np.int64), np.zeros((0, 2), bool), np.zeros((0, 3)), np.zeros((0, 3, 3))) \
            if loads is None else loads.kernel_args
        self.samples = np.zeros((len(times), 0, 9)) if loads is None else loads.table(times)
        self.n_loads = nl
        # [(k, name)]: the loads applied (their bodies move); forces.csv records each as applied
        self.applied = [(k, load.name) for k, load in enumerate(model.external_loads)
                        if model.bodies[load.body].column >= 0]

    def _kernel_args(self, state):
        lay, prog, form = self.solver.layout, self.system.program, self.solver._determinate
        sel, sign = _reaction_rows(lay)
        F, dF, ddF = self.targets
        return (self.plan.args, prog.program, prog.n_node_rows, self.system.angle_rows, F, dF, ddF,
                _body_arrays(self.model), np.asarray(self.model.gravity_W, float), self.loads, self.samples,
                np.asarray(lay.eq_coords, np.int64), sel, sign, (form.rows, form.cols, form.starts, form.ptr,
                                                                  form.earlier),
                state.p_WB, state.quat_WB, state.R_WB, state.w_BB, state.v_WB, state.column, state.moving)

    def run(self, build, progress=False):
        """``build(recording)`` of the trial, or None when a frame failed (module
        docstring: the caller then runs the frame-by-frame path)."""
        model, nf = self.model, len(self.times)
        n, nm = model.n_coords, len(model.moving_bodies)
        out_q, out_v, out_vdot = np.empty((nf, 7 * nm)), np.empty((nf, n)), np.empty((nf, n))
        out_phi, out_f, out_res = np.empty(nf), np.empty((nf, self.solver.layout.n_columns)), np.empty(nf)
        status = np.zeros(nf, np.int64)
        args = self._kernel_args(model.initial_state())
        rec = Recording(nf, {**kinematics_fields(model, 0), **forces_fields(self.solver), **self._load_fields()})
        bar = _progress(nf, progress, "kinematics + inverse dynamics")
        stop = _StopOnSigint()
        done = 0
        try:
            with stop:
                while done < nf:
                    hi = min(done + CHUNK, nf)
                    _frames(done, hi, *args, out_q, out_v, out_vdot, out_phi, out_f, out_res, status)
                    if np.any(status[done:hi] != OK):
                        return None
                    self._record(rec, done, hi, out_q, out_v, out_vdot, out_phi, out_f, out_res)
                    if self.n_loads:
                        rec.record_block(done, self._load_columns(done, hi, out_q))
                    if bar is not None:
                        bar.update(hi - done)
                    done = hi
                    if stop.requested and done < nf:
                        raise KeyboardInterrupt
        except KeyboardInterrupt:
            rec.interrupted = True
            raise TrialInterrupted(build(rec.truncated(rec.frames_done)), nf) from None
        finally:
            if bar is not None:
                bar.close()
        return build(rec)

    def _load_fields(self):
        """The Recording's fields of the measured loads' columns (``dyn.col.<load>.<key>``)."""
        return {f"dyn.{COLUMN}{name}.{key}": ((), float, np.nan)
                for _, name in self.applied for key in EXTERNAL_LOAD_KEYS}

    def _load_columns(self, lo, hi, q):
        """{field: (hi − lo,)}: each applied load's force and point in the world (N, m) at
        frames lo … hi − 1 from their poses ``q`` (nf, 7 n_moving), as the frame-by-frame
        path records them (:func:`apply_data_loads`: x_W = R_WB R_BF x_F for components
        given in the body, p_W = r_WB + R_WB p_BF + R_WB R_BF p_F), for all frames at once."""
        _, in_body, p_BF, R_BF = self.loads
        moving = self.model.moving_bodies
        out = {}
        for k, name in self.applied:
            S = self.samples[lo:hi, k]
            F, P = S[:, 0:3], S[:, 3:6]
            if in_body[k].any():
                body = self.model.bodies[self.model.external_loads[k].body]
                j = next(m for m, b in enumerate(moving) if b is body)
                pose = q[lo:hi, 7 * j : 7 * j + 7]
                R_WB = np.moveaxis(rotation_matrix(pose[:, 3:].T), -1, 0)  # (frames, 3, 3)
                R_WF = R_WB @ R_BF[k]
                if in_body[k, 0]:
                    F = np.einsum("fab,fb->fa", R_WF, F)
                if in_body[k, 1]:
                    P = pose[:, :3] + R_WB @ p_BF[k] + np.einsum("fab,fb->fa", R_WF, P)
            for key, values in zip(EXTERNAL_LOAD_KEYS, (*F.T, *P.T)):
                out[f"dyn.{COLUMN}{name}.{key}"] = values
        return out

    @staticmethod
    def _record(rec, lo, hi, q, v, vdot, phi, f, res):
        k = hi - lo
        rec.record_block(lo, {
            "kin.q": q[lo:hi], "kin.v": v[lo:hi], "kin.vdot": vdot[lo:hi], "kin.constraint_violation": phi[lo:hi],
            "kin.iterations": np.zeros(k, int), "kin.report": FrameReport.ok_many(phi[lo:hi]),
            "dyn.f": f[lo:hi], "dyn.status": [STATUS_OPTIMAL] * k, "dyn.iterations": np.zeros(k, int),
            "dyn.report": FrameReport.ok_many(res[lo:hi])})


def tree_trial(model, system, solver, times, alpha):
    """(TreeTrial, "") when the compiled path covers the run (module docstring), else
    (None, the reason). system : the model's ConstraintSystem; solver : its
    InverseDynamics; times (nf,) s; alpha (0,)."""
    plan, why = tree_plan(model, system)
    if plan is None:
        return None, why
    if solver._determinate is None:
        return None, "the equilibrium is not statically determinate (muscles, actuators or one-sided reactions)"
    kinds = {fs.kind for fs in solver.forces.sets} - {"external_loads"}
    if kinds:
        return None, f"applied loads other than measured ones ({', '.join(sorted(kinds))})"
    if any(load.invalid for load in model.external_loads):
        return None, "a measured load is unknown at some frames"
    loads = solver.forces.by_kind.get("external_loads")
    if loads is not None and loads.table(np.asarray(times, float)[:1]) is None:
        return None, "a measured load has no data at the first frame"
    try:
        trial = TreeTrial(model, system, solver, plan, np.asarray(times, float), alpha)
    except ValueError as exc:  # a driver's spline outside its data: the frame-by-frame path names the frame
        return None, str(exc)
    if loads is not None and trial.samples is None:
        return None, "a measured load has no data at some frames"
    return trial, ""


@njit(cache=True)
def _frames(lo, hi, plan, program, n_node_rows, angle_rows, F, dF, ddF, bodies, g, loads, samples, eq_coords,
            sel, sign, form, p_WB, quat_WB, R_WB, w_BB, v_WB, column, moving,
            out_q, out_v, out_vdot, out_phi, out_f, out_res, status):
    """Frames lo … hi − 1 (module docstring, steps 1–3). Poses carry over from frame to
    frame (the quaternions' hemisphere). Outputs per frame k: out_q (nf, 7 n_moving),
    out_v, out_vdot (nf, n), out_phi (nf,) max |Φ|, out_f (nf, n_columns) N or N m,
    out_res (nf,) max |C f − d|, status (nf,) OK or the step that failed."""
    parent, child, R_aF, p_aF, R_bM, p_bM, axis, row, value, fstart, fparams = plan
    op, node_row, node_size, i_start, iparams, f_start, fp, out_rows = program
    b_col, mass, inertia, index = bodies
    l_body, in_body, l_p_BF, l_R_BF = loads
    rows, cols, starts, ptr, earlier = form
    n = out_v.shape[1]
    n_eq, n_react = eq_coords.shape[0], sel.shape[0]
    val, M, b = np.empty(n_node_rows), np.empty((n_node_rows, n)), np.empty(n_node_rows)
    vdot, d_full, Q = np.empty(n), np.empty(n), np.empty(n)
    W = np.empty((l_body.shape[0], 9))
    d, f = np.empty(n_eq), np.empty(n_react)
    # C in block form, entry (i, j) = C[rows[i], cols[j]] = ±Φ_q̂[sel[cols[j]], eq[rows[i]]]: where to read it in M
    src_row, src_sign, src_col = np.empty(n_react, np.int64), np.empty(n_react), np.empty(n_eq, np.int64)
    for j in range(n_react):
        src_row[j] = out_rows[sel[cols[j]]]
        src_sign[j] = sign[cols[j]]
    for i in range(n_eq):
        src_col[i] = eq_coords[rows[i]]
    LU, piv = np.zeros((n_eq, n_react)), np.empty(n_eq, np.int64)  # zero outside the blocks' pattern, for good
    for k in range(lo, hi):
        # 1. forward kinematics: poses, velocities, accelerations (Eqs. 1-3 in closed form)
        tree_forward(parent, child, R_aF, p_aF, R_bM, p_bM, axis, row, value, fstart, fparams, column,
                     F[k], dF[k], ddF[k], p_WB, quat_WB, R_WB, w_BB, v_WB, vdot)
        # 2. Φ, Φ_q̂ at the pose; accepted when max |Φ| <= TOLERANCE (angle rows modulo 2π)
        err, _ = evaluate_program(op, node_row, node_size, i_start, iparams, f_start, fp,
                                  p_WB, R_WB, w_BB, v_WB, column, n, np.int64(1), val, M, b)
        if err >= 0:
            status[k] = MEASURE_FAILED
            continue
        worst = 0.0
        for r in range(out_rows.shape[0]):
            phi = val[out_rows[r]] - F[k, r]
            if angle_rows[r]:
                phi = (phi + np.pi) % (2.0 * np.pi) - np.pi
            worst = max(worst, abs(phi))
        out_phi[k] = worst
        if not worst <= TOLERANCE:
            status[k] = NOT_CLOSED
            continue
        get_poses(p_WB, quat_WB, moving, out_q[k])
        get_velocities(v_WB, w_BB, column, moving, out_v[k])
        out_vdot[k, :] = vdot
        # 3. C f = d (Eqs. 12-13): d = inertial − gravity − Q_applied, C = ±Φ_q̂ᵀ of the reaction rows
        _inertial_minus_gravity(b_col, mass, inertia, index, w_BB, vdot, g, d_full)
        Q[:] = 0.0
        apply_data_loads(l_body, column, in_body, l_p_BF, l_R_BF, p_WB, R_WB, samples[k], Q, W)
        for r in range(n_eq):
            c = eq_coords[r]
            d[r] = d_full[c] - Q[c]
        worst = _reactions(M, src_row, src_sign, src_col, rows, cols, starts, ptr, earlier, d, LU, piv, f)
        if not worst >= 0.0:
            status[k] = SOLVE_FAILED
            continue
        out_res[k] = worst
        out_f[k, :] = f
        status[k] = OK


@njit(cache=True)
def _reactions(M, src_row, src_sign, src_col, rows, cols, starts, ptr, earlier, d, LU, piv, f):
    """f ← C⁻¹ d by blocks, C read from the node Jacobians M where its block form has
    entries (each diagonal block and the earlier columns its rows touch; LU (n, n) is
    zero elsewhere and stays so: pivoting swaps rows of one block, whose entries right
    of the block are all zero). The factors and f are those of
    :func:`openfdk.dynamics.determinate_reactions.block_reactions` (the same entries,
    pivots and order), without its two dense passes over C. Returns max |C f − d|, or
    −1 when C is singular, f not finite or the residual above 1e-8 max(|d|, 1)."""
    for b in range(starts.shape[0] - 1):
        s, e = starts[b], starts[b + 1]
        for i in range(s, e):
            c = src_col[i]
            for q in range(ptr[b], ptr[b + 1]):
                j = earlier[q]
                LU[i, j] = M[src_row[j], c] * src_sign[j]
            for j in range(s, e):
                LU[i, j] = M[src_row[j], c] * src_sign[j]
        if not lu_factor_range(LU, piv, s, e):
            return -1.0
    block_solve(LU, piv, rows, cols, starts, ptr, earlier, d, f)
    scale, worst = 1.0, 0.0
    for r in range(d.shape[0]):
        scale = max(scale, abs(d[r]))
    for b in range(starts.shape[0] - 1):
        s, e = starts[b], starts[b + 1]
        for i in range(s, e):
            c = src_col[i]
            acc = -d[rows[i]]
            for q in range(ptr[b], ptr[b + 1]):
                j = earlier[q]
                acc += M[src_row[j], c] * src_sign[j] * f[cols[j]]
            for j in range(s, e):
                if not np.isfinite(f[cols[j]]):
                    return -1.0
                acc += M[src_row[j], c] * src_sign[j] * f[cols[j]]
            worst = max(worst, abs(acc))
    return worst if worst <= 1e-8 * scale else -1.0
