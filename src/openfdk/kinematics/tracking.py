"""Over-determinate kinematics: marker tracking under hard constraints (paper Eqs. 4–10).

Positions (Eqs. 4–5): min_q ½ Ψᵀ W Ψ  s.t. Φ(q, t) = 0, Φ^FDK(q) = α, with
Ψ = p_WM(q) − x_M(t) the marker residuals, solved by Gauss–Newton SQP on the KKT system

    [ Ψ_q̂ᵀ W Ψ_q̂   Φ_q̂ᵀ ] [ Δq̂ ]   [ −Ψ_q̂ᵀ W Ψ ]
    [ Φ_q̂           0    ] [ λ  ] = [ −Φ        ]

with Δq̂ applied on the manifold. Velocities (Eqs. 6–9) and accelerations (Eq. 10):
the same KKT matrix with right-hand sides Ψ_q̂ᵀ W (ẋ + δ̇), ν and
Ψ_q̂ᵀ W (ẍ + δ̈ − b_Ψ), γ, where δ = Ψ(q(t), t) is the residual history.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..numerics.spatial import quat_from_matrix
from ..trial.status import Reason
from .assembly import assemble
from .determinate import FrameSolve
from .envelope_lu import envelope_order
from .frame_kernels import MEASURE_ERROR, OK, SINGULAR, tracking_positions, tracking_rates
from .kkt import kkt_pattern
from .system import ConstraintSystem, undetermined_coordinates


#: a body's own rigid marker fit is used for the first pose only below this RMS residual
#: (m): markers placed wrongly in a model (the knee Grand Challenge's left foot: 0.43 m)
#: would turn the body half round and Gauss–Newton would not come back
INITIAL_FIT_RMS_M = 0.02


def _kabsch(P, X):
    """The rotation R (3, 3) and translation p (3,) with X ≈ R P + p in least squares
    (Kabsch), for points P, X (k, 3) m; None when P spans less than a plane."""
    Pc, Xc = P - P.mean(0), X - X.mean(0)
    H = Pc.T @ Xc
    if np.linalg.matrix_rank(H, tol=1e-12 * max(1.0, np.abs(H).max())) < 2:
        return None
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, X.mean(0) - R @ P.mean(0)


#: the kernel's S argument when there are no second-order terms (unused)
_NO_S = np.zeros((1, 1))


class KKTFactors:
    """The factors of a position solve's last factorized step matrix (K, or K with the
    curvature S; :func:`~.kkt.kkt_step`) and its multipliers λ, carried to the next
    solve of a nearby pose: that solve starts with chord steps on them
    (:func:`~.frame_kernels.tracking_positions`), which converge to the same optimum, and
    factorizes only where they stop contracting.

    FDK solves the poses of a frame and its neighbours at every evaluation, each a few
    µm from the last (:mod:`openfdk.fdk.residual`); a factorization is most of such a
    solve (DM knee, 255 × 255: 0.24 ms, a chord step 0.06 ms). size : n + m."""

    def __init__(self, size):
        self.LU = np.empty((size, size))  # (read only once held)
        self.piv = np.zeros(size, np.int64)
        self.first = np.zeros(size, np.int64)
        self.last = np.zeros(size, np.int64)
        self.lam = None  # (m,) the last solve's multipliers
        self.held = np.zeros(1, dtype=np.bool_)  # LU holds factors

    def copy(self):
        return KKTFactors.from_saved((self.LU, self.piv, self.first, self.last, self.held[0], self.lam))  # (copies)

    def saved(self):
        """(LU, piv, first, last, held: bool, λ or None), copies: plain data (a checkpoint's)."""
        return (self.LU.copy(), self.piv.copy(), self.first.copy(), self.last.copy(), bool(self.held[0]),
                None if self.lam is None else self.lam.copy())

    @staticmethod
    def from_saved(saved, size=None, m=None):
        """The KKTFactors of :meth:`saved`'s data. With ``size`` (n + m) and ``m`` (a
        checkpoint's, untrusted): ValueError unless LU is (size, size), the index arrays
        (size,) with every entry in [0, size) (the compiled solves do not check bounds)
        and λ (m,) or None."""
        LU, piv, first, last, held, lam = saved
        if size is not None:
            arrays = (np.asarray(piv), np.asarray(first), np.asarray(last))
            if np.shape(LU) != (size, size) or any(a.shape != (size,) for a in arrays):
                raise ValueError(f"KKT factors of another size than {size}")
            if any(not np.issubdtype(a.dtype, np.integer) or a.min(initial=0) < 0 or a.max(initial=0) >= size
                   for a in arrays):
                raise ValueError(f"KKT factors' pivots or envelope outside 0 … {size - 1}")
            if lam is not None and np.shape(lam) != (m,):
                raise ValueError(f"KKT multipliers of another size than {m}")
        out = KKTFactors(np.shape(LU)[0])
        out.LU[:], out.piv[:], out.first[:], out.last[:], out.held[0] = LU, piv, first, last, bool(held)
        out.lam = None if lam is None else np.array(lam, dtype=float)
        return out


@dataclass(frozen=True)
class TrackingSettings:
    """tol_step : max |Δq̂| (m, rad) to stop; tol_constraint : max |Φ| (m, rad);
    max_iter : Gauss–Newton iterations per frame; max_rms_residual : m, the RMS marker
    residual above which a solved frame fails (the markers do not fit the model)."""

    tol_step: float = 1e-9
    tol_constraint: float = 1e-9
    max_iter: int = 30
    #: a frame whose least-squares fit leaves an RMS marker residual above this (m) fails:
    #: the markers do not fit the model (wrong units, a mislabelled or misplaced marker)
    max_rms_residual: float = 0.1


class MarkerTracker:
    """Per-frame marker-tracking solver for a model's markers (in model order).

    system : ConstraintSystem (with FDK rows if α is to be imposed).
    """

    def __init__(self, system: ConstraintSystem, settings: TrackingSettings | None = None):
        from ..model.compiled import CompiledMeasures

        self.system = system
        self.markers = system.model.markers
        self.settings = settings or TrackingSettings()
        self._observable_cache = {}
        self._weight_cache = {}
        self.coord_names = system.model.coordinate_names()
        # coordinate tasks: soft rows of Eq. 4 beside the markers (model.tasks)
        self.tasks = tuple(system.model.tasks)
        self.task_program = CompiledMeasures([tk.measure for tk in self.tasks])
        self.task_weights = np.array([tk.weight for tk in self.tasks], dtype=float)
        self._task_args = self.task_program.program + (self.task_program.n_node_rows,)
        self.kkt_order = self._kkt_order(system.model.initial_state())  # (n + m,) int: read by the FDK Jacobian too

    def task_targets(self, t):
        """(f, ḟ, f̈) each (nt,) of the coordinate tasks at time t (s), rad or m."""
        nt = len(self.tasks)
        f, df, ddf = np.zeros(nt), np.zeros(nt), np.zeros(nt)
        for k, tk in enumerate(self.tasks):
            a, b, c = tk.function.derivatives(t)
            f[k], df[k], ddf[k] = a[0], b[0], c[0]
        return f, df, ddf

    def _task_jacobian(self, state):
        """J of the task rows (nt, n) at the pose."""
        if not self.tasks:
            return np.zeros((0, self.system.n_coords))
        return self.task_program.evaluate(state, 1)[1]

    def _kkt_order(self, state):
        """perm (n + m,) int: the order the KKT matrix is factorized in (reverse
        Cuthill–McKee, :mod:`.envelope_lu`), from its structure (:func:`.kkt.kkt_pattern`)
        at ``state``; the tracker keeps the one of the model's initial pose (``kkt_order``).
        Any order gives the same solution; this one makes the factorization cheaper (DM
        knee: 0.40 → 0.11 ms)."""
        on_body = np.zeros((len(self.markers.body), state.n_coords))  # a marker moves with its body's 6
        for i, b in enumerate(self.markers.body):
            if state.column[b] >= 0:
                on_body[i, state.column[b]:state.column[b] + 6] = 1.0
        J = np.vstack([on_body, self._task_jacobian(state)])
        return envelope_order(kkt_pattern(J, self.system.jacobian(state)))

    def _raise_task_error(self, e_node, e_kind, state):
        self.task_program.raise_error(-2 - e_node, e_kind, state)

    # -- helpers ------------------------------------------------------------------
    def _weights(self, visible):
        """Per-row weights (3 n_markers + n_tasks,) from marker weights and visibility,
        then the coordinate tasks' weights (cached per visibility pattern; read-only)."""
        return self._pattern(visible)[0]

    def _pattern(self, visible):
        """(per-row weights (3 n_markers,), per-row visibility (3 n_markers,) bool) of a
        visibility pattern (n_markers,) bool, built once per pattern; read-only."""
        key = visible.tobytes()
        out = self._weight_cache.get(key)
        if out is None:
            w = np.concatenate([np.repeat(np.where(visible, self.markers.weight, 0.0), 3), self.task_weights])
            vis3 = np.concatenate([np.repeat(visible, 3), np.ones(len(self.tasks), bool)])
            w.setflags(write=False)
            vis3.setflags(write=False)
            out = self._weight_cache[key] = (w, vis3)
        return out

    def observability_message(self, state, t, visible, alpha=None):
        """'' if the visible markers plus constraints fix the pose, else a message
        naming the bodies whose coordinates are undetermined. Cached per visibility
        pattern (the rank depends on the pattern, not on the pose, away from
        degenerate poses)."""
        key = visible.tobytes()
        if key not in self._observable_cache:
            _, J, _ = self.markers.evaluate(state, 1)
            J = np.vstack([J, self._task_jacobian(state)])
            _, A, _, _ = self.system.evaluate(state, t, alpha, order=1)
            self._observability(J, A, visible)
        return self._observable_cache[key]

    def _observability(self, J, A, visible):
        """The observability message from the marker Jacobian J (3 n_markers, n) and
        Φ_q̂ A (m, n) at some pose (cached per visibility pattern)."""
        key = visible.tobytes()
        if key in self._observable_cache:
            return self._observable_cache[key]
        sw = np.sqrt(self._weights(visible))
        stacked = np.vstack([sw[:, None] * J, A])
        free = undetermined_coordinates(stacked, self.coord_names, tol=1e-8)
        msg = ""
        if free:
            msg = f"the pose cannot be determined: {self._free_description(free, visible)}"
        self._observable_cache[key] = msg
        return msg

    #: bodies named one by one in an unobservable frame's message; the rest are counted
    MESSAGE_BODIES = 4

    def _free_description(self, free, visible):
        """What an unobservable frame's message says of its free coordinates ``free``
        (names 'body.dof'): their count, then per body (at most :data:`MESSAGE_BODIES`)
        its free DOFs and the markers tracked there (visible, weight > 0), so that a
        message stays one readable line on a 23-body model."""
        m = self.markers
        tracked = np.asarray(visible, bool) & (m.weight > 0)
        by_body = {}
        for c in free:
            body, dof = c.rsplit(".", 1)
            by_body.setdefault(body, []).append(dof)
        parts = []
        for body, dofs in list(by_body.items())[:self.MESSAGE_BODIES]:
            names = [n for n, bi, v in zip(m.names, m.body, tracked) if v and self.system.model.bodies[bi].name == body]
            parts.append(f"{body} ({', '.join(dofs)}; tracked markers: {', '.join(names) if names else 'none'})")
        if len(by_body) > self.MESSAGE_BODIES:
            parts.append(f"and {len(by_body) - self.MESSAGE_BODIES} more bodies")
        text = (f"the tracked markers and the constraints leave {len(free)} coordinate(s) of {len(by_body)} "
                f"body(ies) free: {'; '.join(parts)}")
        if not np.any(m.weight > 0):
            text += " (no marker is tracked: every marker's weight is 0)"
        return text

    def initial_guess(self, state, x_WM, visible):
        """Set the pose from rigid least-squares fits (Kabsch) of the visible markers:
        first the whole model as one rigid body (every visible marker at its position in
        the current pose), so that a body with too few markers of its own moves with the
        rest instead of staying where the reference pose put it (a knee's patella metres
        from its femur in a lab-frame trial); then each moving body with ≥ 3
        non-collinear markers by its own, when they fit it rigidly (RMS below
        :data:`INITIAL_FIT_RMS_M`). Markers of weight 0 (not tracked) are left out."""
        m = self.markers
        visible = visible & (m.weight > 0)  # untracked markers (weight 0) may be anywhere
        sel = np.flatnonzero(visible & (state.column[m.body] >= 0))
        if len(sel) >= 3:
            P = np.einsum("kij,kj->ki", state.R_WB[m.body[sel]], m.p_BM[sel]) + state.p_WB[m.body[sel]]
            fit = _kabsch(P, x_WM[sel])
            if fit is not None:
                R, p = fit  # x ≈ R P + p for the whole model
                for i in state.moving:
                    state.R_WB[i] = R @ state.R_WB[i]
                    state.quat_WB[i] = quat_from_matrix(state.R_WB[i])
                    state.p_WB[i] = R @ state.p_WB[i] + p
        for i in state.moving:
            sel = np.flatnonzero((m.body == i) & visible)
            if len(sel) < 3:
                continue
            fit = _kabsch(m.p_BM[sel], x_WM[sel])
            if fit is None:
                continue
            R, p = fit
            residual = x_WM[sel] - (m.p_BM[sel] @ R.T + p)
            if np.sqrt(np.mean(np.sum(residual * residual, axis=1))) > INITIAL_FIT_RMS_M:
                continue  # the body's markers do not fit it rigidly: keep the whole model's pose
            state.quat_WB[i] = quat_from_matrix(R)
            state.R_WB[i] = R
            state.p_WB[i] = p

    # -- Eqs. 4-5 -----------------------------------------------------------------
    def solve_positions(self, state, t, x_WM, visible, alpha=None, second_order=None, tol_step=None, factors=None):
        """Gauss–Newton SQP from ``state`` (modified in place).

        x_WM : (n_markers, 3) m measured positions (NaN where not visible);
        visible : (n_markers,) bool. Returns (FrameSolve, K, λ) where K is the KKT matrix
        (n + m, n + m) of the last iteration, reused by the velocity and acceleration
        solves (Eqs. 8–10), and λ (m,) the constraint multipliers of the last step. Converged when max |Δq̂| < tol_step and max |Φ| <
        tol_constraint at the start of that step (Φ only shrinks after it).

        second_order : (n, n) or None, the Lagrangian Hessian's second-order terms
        Σ w r ∇²p + Σ λ ∇²Φ at a nearby pose (the FDK Jacobian's, :mod:`openfdk.fdk.jacobian`),
        added to Ψ_q̂ᵀ W Ψ_q̂ for the steps: Newton's steps with a Hessian from nearby
        instead of Gauss–Newton's. The solution and K are those of the same stationarity
        conditions; only the path to them changes. Gauss–Newton converges linearly where
        the fit leaves residuals (on the DM knee about 0.2 per iteration: 6–8 iterations
        per pose to 1e-9); with these terms from the last Jacobian it takes 3–4. If that
        solve fails, plain Gauss–Newton is tried from the same start.

        tol_step : m, rad, the Gauss–Newton kernel's step tolerance instead of
        ``settings.tol_step`` (a pose that enters only through differences, FDK's
        neighbouring frames of Eq. 7, need not be known to the last digits).

        factors : a :class:`KKTFactors` of a solve at a nearby pose, read and updated (the
        kernel's first steps are chord steps with them), or None (a factorized first step).

        When the Gauss–Newton kernel fails from the warm start, the damped feasible-path
        solve of :mod:`openfdk.kinematics.assembly` takes over from the same pose (K then
        carries its final damping); the frame fails only when that fails too.
        """
        s = self.settings
        msg = self.observability_message(state, t, visible, alpha)
        if msg:
            return FrameSolve(False, 0, np.nan, msg, Reason.UNOBSERVABLE), None, None
        start = state.copy()
        out = self._gauss_newton(state, t, x_WM, visible, alpha, second_order, tol_step, factors)
        if out[0].converged:
            return out  # (the fit is checked where δ is formed: TrackingStep, FDK's residual)
        if factors is not None:
            factors.held[0] = False  # (whatever failed, the next solve factorizes)
        if second_order is not None:  # the nearby pose's curvature did not serve here
            _restore(start, state)
            out = self._gauss_newton(state, t, x_WM, visible, alpha, tol_step=tol_step)
            if out[0].converged:
                return out
        # far from the optimum, or a coordinate the markers barely see: the damped,
        # feasible-path solve from the same warm start (kinematics/assembly.py)
        _restore(start, state)
        try:
            ok, it, _, res, mu = assemble(self, state, t, x_WM, visible, alpha, tol_step=s.tol_step,
                                          tol_constraint=s.tol_constraint)
        except FloatingPointError:  # undefined on its path too: Gauss–Newton's failure says where
            ok = False
        if not ok:
            _restore(start, state)
            return out
        K = self.kkt_matrix(state, t, visible, alpha, damping=mu)
        # λ of the stationarity Ψ_q̂ᵀ W Ψ + Φ_q̂ᵀ λ = 0 at the solved pose
        p, J, _ = self.markers.evaluate(state, 1)
        x = np.where(visible[:, None], x_WM, 0.0).ravel()
        if self.tasks:
            tv, tJ, _ = self.task_program.evaluate(state, 1)
            p, J, x = np.concatenate([p, tv]), np.vstack([J, tJ]), np.concatenate([x, self.task_targets(t)[0]])
        n = self.system.n_coords
        Phi = self.system.evaluate(state, t, alpha, order=0)[0]
        sol = np.linalg.solve(K, np.concatenate([-J.T @ (self._weights(visible) * (p - x)), -Phi]))
        return self._check_fit((FrameSolve(True, out[0].iterations + it, res), K, sol[n:]), state, x_WM, visible)

    def _check_fit(self, out, state, x_WM, visible):
        """``out`` (FrameSolve, K, λ) of a converged solve, or a failed one when the
        markers do not fit (:meth:`fit_message`)."""
        msg = self.fit_message(self.markers.positions(state) - x_WM, visible)
        return out if not msg else (FrameSolve(False, out[0].iterations, out[0].residual, msg, Reason.FAILED),
                                    None, None)

    def fit_message(self, delta, visible):
        """'' or why a solved pose is refused: the RMS of the visible tracked markers'
        residuals δ (n_markers, 3) m exceeds ``settings.max_rms_residual`` (the worst one
        named). Markers of weight 0 are not tracked and may be anywhere."""
        visible = visible & (self.markers.weight > 0)
        d2 = np.sum(delta[visible] ** 2, axis=1)
        rms = float(np.sqrt(np.mean(d2))) if d2.size else 0.0
        if rms <= self.settings.max_rms_residual:
            return ""
        worst = int(np.argmax(d2))
        name = [n for n, v in zip(self.markers.names, visible) if v][worst]
        return (f"the markers do not fit the model: RMS residual {1e3 * rms:.0f} mm > "
                f"{1e3 * self.settings.max_rms_residual:.0f} mm (largest: {name!r}, {1e3 * np.sqrt(d2[worst]):.0f} mm); "
                "check the marker units and placement")

    def _gauss_newton(self, state, t, x_WM, visible, alpha, second_order=None, tol_step=None, factors=None):
        """The Gauss–Newton kernel's solve (see :meth:`solve_positions`)."""
        s = self.settings
        tol_step = s.tol_step if tol_step is None else tol_step
        w = self._weights(visible)
        x = np.where(visible[:, None], x_WM, 0.0).ravel()
        if self.tasks:
            x = np.concatenate([x, self.task_targets(t)[0]])
        n, m = self.system.n_coords, self.system.n_rows
        K = np.zeros((n + m, n + m))
        if factors is None:
            factors = KKTFactors(n + m)
        lam = factors.lam.copy() if factors.held[0] and factors.lam is not None else np.zeros(m)
        f, _, _ = self.system.targets(t, alpha)
        prog = self.system.program
        try:
            # Gauss–Newton iterations in one kernel (Eqs. 4–5)
            status, it, res, step, e_node, e_kind = tracking_positions(
                *prog.program, prog.n_node_rows, state.p_WB, state.quat_WB, state.R_WB, state.w_BB, state.v_WB,
                state.column, state.moving, f, self.system.angle_rows, self.markers.body, self.markers.p_BM,
                w, x, tol_step, s.tol_constraint, s.max_iter, K, lam,
                _NO_S if second_order is None else np.ascontiguousarray(second_order, dtype=float),
                second_order is not None, self.kkt_order, factors.LU, factors.piv, factors.first, factors.last,
                factors.held, *self._task_args)
            factors.lam = lam.copy()
        except np.linalg.LinAlgError as exc:
            return FrameSolve(False, 0, np.nan, f"KKT system singular: {exc}", Reason.SINGULAR), None, None
        if status == MEASURE_ERROR:
            # a measure undefined on the way (a rotation-angle measure at gimbal lock: DM's
            # patella, xyz at −90°, from an FDK trial step): a failed solve naming it, from
            # which solve_positions tries the damped solve; never an exception out of a run
            try:
                if e_node <= -2:
                    self._raise_task_error(e_node, e_kind, state)
                prog.raise_error(e_node, e_kind, state)  # (both raise, with the measure's message)
            except FloatingPointError as exc:
                return FrameSolve(False, int(it), np.nan, str(exc), Reason.FAILED), None, None
        if status == SINGULAR:
            return FrameSolve(False, int(it), np.nan, "KKT system singular (non-finite step)", Reason.SINGULAR), None, None
        if status == OK:
            return FrameSolve(True, int(it), float(res)), K, lam
        return (
            FrameSolve(False, s.max_iter, float(res), f"Gauss–Newton did not converge in {s.max_iter} iterations "
                       f"(last step {step:.3g}, max |Φ| = {res:.3g})", Reason.ITERATION_LIMIT),
            K, lam,
        )

    def kkt_matrix(self, state, t, visible, alpha=None, damping=None):
        """The KKT matrix (n + m, n + m) at the current pose (for Eqs. 8–10); with
        ``damping`` μ, the Hessian block is Ψ_q̂ᵀ W Ψ_q̂ + μ I (kinematics/assembly.py)."""
        n, m = self.system.n_coords, self.system.n_rows
        _, J, _ = self.markers.evaluate(state, 1)
        J = np.vstack([J, self._task_jacobian(state)])
        _, A, _, _ = self.system.evaluate(state, t, alpha, order=1)
        w = self._weights(visible)
        K = np.zeros((n + m, n + m))
        K[:n, :n] = J.T @ (J * w[:, None])
        if damping:
            K[:n, :n] += damping * np.eye(n)
        K[:n, n:] = A.T
        K[n:, :n] = A
        return K

    def residuals(self, state, x_WM):
        """δ = Ψ = p_WM(q) − x_M (n_markers, 3) m (NaN where x is NaN)."""
        return self.markers.positions(state) - x_WM

    # -- Eqs. 6-10 ----------------------------------------------------------------
    def solve_velocities_accelerations(self, state, t, K, visible, xdot, xddot, d_delta, dd_delta, alpha=None,
                                       J=None, rows=False):
        """Velocities (Eqs. 8–9) and accelerations (Eq. 10); sets state velocities.

        K : KKT matrix from :meth:`solve_positions` or :meth:`kkt_matrix`;
        xdot, xddot : (n_markers, 3) measured marker velocity (m/s) and acceleration (m/s²);
        d_delta, dd_delta : (n_markers, 3) residual rates δ̇ (m/s) and δ̈ (m/s²) (Eq. 7);
        J : (3 n_markers, n) the marker Jacobian at this pose if already evaluated (the
        marker stage), else evaluated here. The compiled kernel
        (:func:`.frame_kernels.tracking_rates`) evaluates the rows once, at order 2.
        Returns v, v̇ (6 n_moving,) each; with ``rows`` also Φ (m,), Φ_q̂ (m, n) and
        ν = ḟ (m,) at the pose, from that evaluation.
        """
        n = self.system.n_coords
        w, vis3 = self._pattern(visible)
        f, df, ddf = self.system.targets(t, alpha)
        if J is None:
            J = self.markers.evaluate(state, 1)[1]
        m = self.system.n_rows
        A, Phi = np.empty((m, n)), np.empty(m)
        target_v = (xdot + d_delta).ravel()
        target_a = (xddot + dd_delta).ravel()
        if self.tasks:
            _, tdf, tddf = self.task_targets(t)
            target_v, target_a = np.concatenate([target_v, tdf]), np.concatenate([target_a, tddf])
        target_v = np.where(vis3, target_v, 0.0)
        target_a = np.where(vis3, target_a, 0.0)
        v, vdot = np.empty(n), np.empty(n)
        prog = self.system.program
        status, e_node, e_kind = tracking_rates(
            *prog.program, prog.n_node_rows, state.p_WB, state.R_WB, state.w_BB, state.v_WB, state.column,
            state.moving, df, ddf, self.markers.body, self.markers.p_BM, w, target_v, target_a,
            np.ascontiguousarray(K), self.kkt_order, np.ascontiguousarray(J), f,
            self.system.angle_rows, v, vdot, A, Phi,
            *self._task_args)
        if status == MEASURE_ERROR:
            if e_node <= -2:
                self._raise_task_error(e_node, e_kind, state)
            prog.raise_error(e_node, e_kind, state)
        if status == SINGULAR:
            raise np.linalg.LinAlgError("Singular matrix")
        if rows:
            return v, vdot, Phi, A, df.copy()  # Eq. 2: ν = −Φ_t = ḟ
        return v, vdot


def _restore(src, dst):
    """Copy the poses of ``src`` into ``dst`` in place (same model)."""
    dst.p_WB[...] = src.p_WB
    dst.quat_WB[...] = src.quat_WB
    dst.R_WB[...] = src.R_WB


def window_spacing(times, trajectories=None):
    """The frame spacing (s) of a window ``times`` (nf,) s: its own, or for a one-frame
    window (``--start`` = ``--end``) the trial's median sample interval
    (``trajectories.time``), so that its residual rates (Eq. 7) are central differences
    over the trial's neighbouring samples as at every other frame; None when neither
    exists."""
    times = np.asarray(times, dtype=float)
    if len(times) > 1:
        return float(times[1] - times[0])
    t = getattr(trajectories, "time", None)
    if t is None or len(t) < 2:
        return None
    return float(np.median(np.diff(np.asarray(t, dtype=float))))


def residual_rates(prev, cur, nxt, dt):
    """δ̇ and δ̈ (nm, 3) of one frame from the residuals δ (nm, 3) m of the frame and its
    neighbours (Eq. 7 and its second-order analogue): central where all three are known,
    one-sided where a neighbour is missing (None: outside the trial) or NaN (failed
    frame, occluded marker), 0 otherwise. A neighbour whose set of visible markers differs
    from this frame's counts as missing for every marker: its pose solves another
    least-squares problem, so the residuals step between the two frames and a difference
    across that step is ±step/Δt² of spurious acceleration (tests/test_tracking_gap.py).
    dt : frame spacing, s. One compiled loop (:func:`_residual_rates`)."""
    cur = np.ascontiguousarray(cur, dtype=float)
    d1, d2 = np.empty_like(cur), np.empty_like(cur)
    _residual_rates(cur if prev is None else np.ascontiguousarray(prev, dtype=float), prev is not None,
                    cur, cur if nxt is None else np.ascontiguousarray(nxt, dtype=float), nxt is not None,
                    float(dt), d1.reshape(-1), d2.reshape(-1))
    return d1, d2


@njit(cache=True)
def _residual_rates(prev, has_prev, cur, nxt, has_next, dt, d1, d2):
    """d1, d2 (3 nm,) ← δ̇, δ̈ of :func:`residual_rates` (prev, cur, nxt (nm, 3) m; a
    neighbour counts as missing everywhere when ``has_*`` is False or when its finite
    entries are not this frame's)."""
    p, c, x = prev.reshape(-1), cur.reshape(-1), nxt.reshape(-1)
    for i in range(c.shape[0]):  # another visible set: the neighbour is missing everywhere
        if has_prev and np.isfinite(p[i]) != np.isfinite(c[i]):
            has_prev = False
        if has_next and np.isfinite(x[i]) != np.isfinite(c[i]):
            has_next = False
    for i in range(c.shape[0]):
        d1[i] = 0.0
        d2[i] = 0.0
        if not np.isfinite(c[i]):
            continue
        good_p = has_prev and np.isfinite(p[i])
        good_n = has_next and np.isfinite(x[i])
        if good_p and good_n:
            d1[i] = (x[i] - p[i]) / (2 * dt)
            d2[i] = (x[i] - 2 * c[i] + p[i]) / dt**2
        elif good_n:
            d1[i] = (x[i] - c[i]) / dt
        elif good_p:
            d1[i] = (c[i] - p[i]) / dt
