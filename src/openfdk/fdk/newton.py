"""Newton–Raphson on f^FDK(α) = 0 for one frame (paper Fig. 1).

Each iteration: Jacobian J = ∂f^FDK/∂α (analytic or central differences), Newton step
Δα = −J⁻¹ f, replaced by Powell's dogleg step within the trust region |Δα_i| ≤ r max_step_i
(:mod:`.trust_region`; r starts each frame at 1 and adapts to how well the linear model
predicted the last step). A step that does not reduce the merit ‖W f^FDK‖₂ (W =
diag(max_step): the residuals' work over one max_step, :func:`~.trust_region.work`) is
refused: the region shrinks and the same J gives a shorter step; within NEAR_ROOT
tolerances of the root, or after MAX_SHRINK refusals, a golden-section search on the step
length β ∈ (0, 1) (the paper's line search) picks the β with the smallest merit instead.
Converged when max |f^FDK| < tolerance.

Jacobian reuse (setting ``reuse_jacobian``, default on): instead of a fresh J at every
iteration, the J of the previous iteration — or of the previous frame, since the
configuration changes little in 10 ms — is kept and corrected after every accepted step
by Broyden's rank-one update J ← J + (Δf − J Δα) Δαᵀ / (Δαᵀ Δα) (a quasi-Newton method;
the converged α satisfies the same max |f^FDK| < tolerance). A fresh J is computed when
there is none, when a step with the carried J did not reduce the merit at least
:data:`CARRIED_J_REDUCTION` times (a Newton step with an accurate J reduces it far more
near the root; a carried J that does less converges only linearly), and when an accepted
step's own rate, carried on, would not reach the tolerance in one more step
(max |f₁| · max(max |f₁| / max |f₀|, 1 / BROYDEN_RATE) ≥ tolerance): Broyden's updates
then converge linearly, a fresh J quadratically. On the synthetic knee in gait this last
rule takes 4.48 → 4.06 residual evaluations and 1.04 → 1.34 Jacobians per frame (before
the bound :data:`BROYDEN_RATE`; full Newton, ``reuse_jacobian: false``:
3.62 and 2.62, at 70 % of the speed). A cold frame (``cold``: no converged frame just
before it, so it starts far from its root) applies the rate rule only within
:data:`~.trust_region.NEAR_ROOT` tolerances of the root: farther out, where the trust
region rather than J limits the steps, a fresh J serves a second, Broyden-updated step
while the steps keep reducing the merit tenfold. Measured on 15 cold starts of the DM
knee in gait (5 trials × 3 times, each the window's first frame with its lead-in and
the two frames after it): 8 910 → 5 607 residual evaluations, 315 → 190 s, failed
frames 2 → 0; the warm frames after them are unchanged. Only a fresh J's step goes on to the line
search. With ``reuse_jacobian: false`` every iteration
computes J, as in the paper.

The step with the contacts exact (setting ``contact_step``, default on;
:mod:`.contact_step`): with the analytic Jacobian and grid-mode contacts, J is split into
the contacts' part −R K_c U and the rest J_s, and the step solves g(Δα) = f + J_s Δα −
R [Q_c(q̂ ⊕ U Δα) − Q_c(q̂)] = 0 by Newton's method on the contacts alone where that
step lies within the trust region (else the linear model's dogleg step). Broyden's update
then corrects J_s by what g missed. Between frames J_s is carried, U and R are taken
again at the warm start, unless the step they give leaves the max_step box: then the
whole J carried on as without the split. DM bench window past its lead-in: 4.47 → 3.53
residual evaluations and 1.80 → 0.67 Jacobians per frame, 71 → 56 ms.

A frame that does not converge keeps its best iterate and says why: line search failed,
iteration limit, recruitment failed (infeasible, or not converged although a feasible
force set exists), kinematics failed, or a singular Jacobian (no restoring force along a
DOF).

Restarts (setting ``restart``, default on; :func:`solve_frame_from`). A Newton method
globalised by a line search on a merit ‖W f^FDK‖₂ converges to a stationary point of the
merit, J(α)ᵀ W² f(α) = 0 (or a kink of f where no direction descends), which is a root only
when J is regular there (Nocedal & Wright, "Numerical Optimization", 2nd ed., §11.2,
Theorem 11.6 and the discussion after it; the usual remedy for a stall at a non-root
minimiser of the merit is to start again from another point). f^FDK(α) is continuous but only
piecewise smooth: its slope jumps where a muscle enters or leaves the recruitment's
active set (paper Eq. 11, bounds 0 ≤ f^M ≤ s). Measured on the wide realistic chewing
(docs/fdk.md, "Restarts"): the equilibrium moves up to 4 mm along the soft medio-lateral
DOF (stiffness ≈ 0.5 N/mm against ≈ 60 N/mm along the normals) from one 10 ms frame to
the next, and the extrapolated warm start then lies in the basin of such a non-root
minimiser (‖f‖ ≈ 0.5 N at a muscle's active-set kink) that remains of the branch the
previous frames followed. When the solve from the warm start fails, the frame is solved
again from the previous frame's α and then from the DOFs' declared initial values (the
model's neutral α), each with a fresh Jacobian; the first start that converges gives the
frame's α, otherwise the best iterate of all starts is reported with the warm start's
reason. A restart never changes a frame that converges from its warm start.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..kinematics.frame_kernels import small_solve
from .contact_step import INNER_REACH, INNER_RELATIVE, INNER_SOLVED, ContactSplit
from .jacobian import analytic_jacobian, central_jacobian, refreshed_split
from .trust_region import MAX_SHRINK, NEAR_ROOT, SHRINK, dogleg_step, reduction_ratio, trust_radius, work

GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0
#: a start stops as stalled (reason ``no_progress``) after this many consecutive Newton
#: steps from a fresh J that each lowered the merit's square by less than
#: PROGRESS_JACOBIAN, or after SLOW_STEPS consecutive steps that each lowered it by less
#: than PROGRESS_STEP: MINPACK's ``hybrj`` tests of "not making good progress" (its
#: ``info`` 4 and 5; Moré, Garbow & Hillstrom, "User Guide for MINPACK-1", Argonne
#: ANL-80-74, 1980), with its values. Such a start sits at a kink of f^FDK that is not a
#: root (a muscle at its recruitment threshold, a contact's edge; "Restarts" in the
#: module docstring), where the iteration keeps max |f^FDK| to three digits for the rest
#: of its iterations (DM og7 1.692 s: 0.059 N for 80 evaluations and 30 Jacobians), and
#: the next start is what helps. Measured on DM's six overground trials: 9 985 residual
#: evaluations and 4 021 Jacobians instead of 11 371 and 4 883, every frame converged
#: (docs/fdk.md, "Stalled starts")
SLOW_JACOBIANS = 5
PROGRESS_JACOBIAN = 0.1
SLOW_STEPS = 10
PROGRESS_STEP = 1e-3
#: an accepted step this long (in max_steps) is never slow: MINPACK's trust region grows
#: without bound, this one stops at the max_step box, and a root N boxes away is reached
#: by steps that each lower the merit's square by only about 2/N
WALK_REACH = 0.99
#: a step with a carried (Broyden-updated) J must divide the merit ‖W f^FDK‖₂ by this, else the next
#: iteration computes a fresh J. Measured on the DM knee's bench window (31 frames,
#: `dm_pt.yaml`): 2 → 7 evaluations per frame (median), 1.4 Jacobians; 10 → 5 and 2.2
#: Jacobians, the same wall time; 50 → 5 and 2.8
CARRIED_J_REDUCTION = 10.0
#: the rate rule (module docstring) carries a step's own rate on, but a Broyden-updated J
#: divides max |f^FDK| by at most this per step near the root: the kinks of f^FDK (the
#: recruitment's active set, the contact patch's edge) bound it. Measured on the DM
#: bench window's warm frames: 26–160 times (median about 50) with the carried J, 250–2 500
#: with a fresh one. Without the bound, a warm frame at 0.2 N after its first step went on
#: with the carried J to 6 mN and needed a fourth evaluation; with it, the 30 later
#: frames took 3.33 evaluations and 0.80 Jacobians instead of 3.53 and 0.67, in the same
#: CPU time (41.9 ms per frame both, alternated three times each)
BROYDEN_RATE = 100.0


@dataclass
class FrameSolution:
    """Result of one frame: best evaluation, converged, iterations (Newton),
    evaluations (residual evaluations = recruitment solves), message, reason code."""

    best: object
    converged: bool
    iterations: int
    evaluations: int
    message: str
    reason: str
    workspace: object = None
    # the last J (n_fdk, n_fdk), or the ContactSplit carrying J_s (fdk/contact_step.py), for
    # reuse in the next frame
    jacobian: object = None
    jacobians: int = 0  # Jacobians computed in this frame
    restarts: int = 0  # further starts solved after the warm start failed (solve_frame_from)


def _merit(ev, max_step):
    """The trust region's and the line search's merit at ``ev``: ‖W f^FDK‖₂, W =
    diag(max_step) (n_fdk,) m or rad (:func:`~.trust_region.work`, J); inf where the pose
    could not be evaluated."""
    return float(np.linalg.norm(work(ev.f_fdk, max_step))) if ev.ok else np.inf


def solve_frame(ctx, k, alpha0, ws, settings, warm=None, jacobian=None, cold=False) -> FrameSolution:
    """Find α with f^FDK(α) = 0 at frame k, starting from alpha0 (n_fdk,) and the
    warm-start poses ``ws`` (FrameWorkspace, updated). ``jacobian`` (n_fdk, n_fdk), or a
    ContactSplit: the previous frame's J to start from, used only with
    ``settings.reuse_jacobian``;
    ``cold``: no converged frame just before this one (the rate rule of the module
    docstring only near the root)."""
    names = [d.name for d in ctx.model.fdk_dofs]
    max_step = np.asarray(settings.max_step, dtype=float)
    reuse = settings.reuse_jacobian
    # the model of the step: linear in J, or with the contacts exact (split, fdk/contact_step.py);
    # a split that did not pay sleeps (``asleep``: carried with the whole J, not used)
    J, split, asleep = None, None, None
    gain = float("nan")  # the split's running gain (ContactSplit.pays), kept across new splits
    if reuse and isinstance(jacobian, ContactSplit):
        carried = jacobian.copy()
        gain = carried.gain
        if carried.sleep > 0:
            carried.sleep -= 1
            J, asleep = carried.J_whole, carried
        elif carried.J_s is None:
            J = carried.J_whole  # awake again: split at the next fresh J
        else:
            J, split = carried.J_s, carried
    elif reuse and jacobian is not None:
        J = np.array(jacobian, dtype=float)
    contacts = ctx.solver.forces.by_kind.get("contacts") if settings.contact_step else None
    base = None  # (evaluation, split, the contacts' Q_c and K_c U there)
    fresh, n_jac = False, 0
    ev = ctx.evaluate(k, alpha0, ws, warm)
    evaluations = 1

    def done(sol_ev, converged, it, message, reason, workspace):
        carried = J
        if split is not None and J is not None:
            carried = split
        elif asleep is not None and J is not None:
            carried, asleep.J_whole = asleep, J
        return FrameSolution(sol_ev, converged, it, evaluations, message, reason, workspace,
                             carried if reuse else None, n_jac)

    if not ev.ok:
        return done(ev, False, 0, ev.message, ev.stage or "failed", ws)
    if split is not None and ev.norm >= settings.tolerance:
        # a carried split: its J_s still serves, its U and R are taken again here
        # (fdk/contact_step.py), where the Newton step they give stays within the trust
        # region; else (a contact the carried J_s was split at has come apart or closed)
        # the whole J carried on from the last frame, as without the split
        J, (split, base) = split.J_whole, _refreshed(ctx, ev, split, contacts, max_step)
        if split is not None:
            J = split.J_s
            if ctx.tracker is not None:
                ws.alpha, ws.dq_dalpha = ev.alpha.copy(), ev.dq_dalpha  # poses predicted from here on
    best, best_ws = ev, ws.copy()
    radius, rejected = 1.0, 0  # the trust region (multiples of max_step) and the steps it refused
    linear_only = False  # this iterate refused the contacts-exact step: the linear model's
    slow_jacobians = slow_steps = 0  # the stall tests (SLOW_JACOBIANS, SLOW_STEPS)
    for it in range(1, settings.max_iterations + 1):
        if ev.norm < settings.tolerance:
            return done(ev, True, it - 1, "", "converged", ws)
        new_J = J is None or (not reuse and not fresh)  # (a refused step keeps its fresh J)
        if new_J:
            J, n_ev, msg = _jacobian(ctx, k, ev, ws, settings)
            evaluations += n_ev
            if ev.dq_dalpha is not None and ctx.tracker is not None:
                ws.alpha, ws.dq_dalpha = ev.alpha.copy(), ev.dq_dalpha  # poses predicted from here on
            n_jac += 1
            fresh = True
            if J is None:
                return done(best, False, it, msg, "jacobian", best_ws)
            new = ev.contact_split if contacts is not None else None
            if new is not None:
                new.gain = gain  # the gain measured so far goes on
            if new is not None and asleep is not None:
                split, asleep = None, replace(new, sleep=asleep.sleep)  # it sleeps on
            else:
                split = new
                if split is not None:
                    split.J_s = None  # split at this pose below
        if split is not None:
            # the contacts at this pose: J = J_s − R K_c U (fdk/contact_step.py)
            if base is None or base[0] is not ev or base[1] is not split:
                base = (ev, split, *split.terms(contacts, ev.state))
            _, _, Q_c, KU = base
            if split.J_s is None:
                split.split(J, KU)
            J = split.jacobian_at(KU)
        try:
            step_N = small_solve(J, -ev.f_fdk)  # the Newton step
            if not np.all(np.isfinite(step_N)):
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:
            if not fresh:  # a carried J went singular: compute one here
                J = split = None
                continue
            weak = [names[i] for i in np.flatnonzero(np.max(np.abs(J), axis=0) < 1e-9 * max(1.0, np.abs(J).max()))]
            return done(best, False, it, f"singular FDK Jacobian: no restoring force along {weak or names}",
                        "singular", best_ws)
        inner = None
        if split is not None and not linear_only and np.max(np.abs(step_N / max_step)) <= INNER_REACH * radius:
            # the step with the contacts exact (fdk/contact_step.py), where it lies within
            # the trust region and g was solved; else the dogleg on the linear model (not
            # tried where the linear model's step is far outside the region)
            d, g = split.solve(contacts, ev.f_fdk, ev.state, Q_c, step_N,
                               max(0.1 * settings.tolerance, INNER_RELATIVE * ev.norm))
            if np.max(np.abs(g)) < INNER_SOLVED * ev.norm and np.max(np.abs(d / max_step)) <= radius:
                inner = (d, g)
        step = inner[0] if inner is not None else dogleg_step(J, ev.f_fdk, step_N, radius * max_step, max_step)

        def predicted(step):
            """The model's f^FDK after ``step``: g (contacts exact) or f + J Δα."""
            if split is None:
                return ev.f_fdk + J @ step
            if inner is not None and step is inner[0]:
                return inner[1]
            return split.model(contacts, ev.f_fdk, ev.state, Q_c, step)[0]

        trial_ws = ws.copy()
        trial = ctx.evaluate(k, ev.alpha + step, trial_ws, ev.frame.recruitment)
        evaluations += 1
        reach = float(np.max(np.abs(step / max_step)))  # the step's length in max_steps
        # the step's actual reduction of the merit's square (negative: refused); an
        # accepted step across the whole max_step box walks towards a far root at the
        # box's pace, which is progress however small its share of the merit
        merit, merit_trial = _merit(ev, max_step), _merit(trial, max_step)
        reduction = 1.0 - (merit_trial / merit) ** 2 if trial.ok else -np.inf
        walking = reduction > 0.0 and reach >= WALK_REACH
        slow_steps = 0 if reduction >= PROGRESS_STEP or walking else slow_steps + 1
        slow_jacobians = 0 if reduction >= PROGRESS_JACOBIAN or walking else slow_jacobians + int(new_J)
        if slow_jacobians >= SLOW_JACOBIANS or slow_steps >= SLOW_STEPS:
            if trial.ok and trial.norm < best.norm:
                best, best_ws = trial, trial_ws.copy()
            if best.norm < settings.tolerance:
                return done(best, True, it, "", "converged", best_ws)
            why = (f"the steps of the last {SLOW_JACOBIANS} Jacobians each lowered the residual's work by less "
                   f"than {PROGRESS_JACOBIAN:.0%}" if slow_jacobians >= SLOW_JACOBIANS else
                   f"the last {SLOW_STEPS} steps each lowered the residual's work by less than {PROGRESS_STEP:.1%}")
            return done(best, False, it, f"no progress at iteration {it} ({why}), max |f^FDK| = {best.norm:.4g}",
                        "no_progress", best_ws)
        if merit_trial < merit:
            f_model = predicted(step)
            radius, rejected = trust_radius(radius, reach, reduction_ratio(J, ev.f_fdk, step, trial.f_fdk,
                                                                           f_model, max_step)), 0
            reduced = merit_trial * CARRIED_J_REDUCTION <= merit
            if reuse:
                f_linear = ev.f_fdk + J @ step  # the linear model's f^FDK after the step
                if split is not None:
                    split.J_whole = _broyden(J, step, trial.f_fdk - ev.f_fdk)
                J = _corrected(J, split, step, trial.f_fdk - ev.f_fdk, trial.f_fdk - f_model)
                if inner is not None:
                    paid = split.pays(ev.f_fdk, trial.f_fdk, f_linear, f_model, settings.tolerance)
                    gain = split.gain
                    if paid is False:  # the linear model from here on
                        J, split, asleep = split.J_whole, None, replace(split, J_s=None)
                slow = trial.norm * max(trial.norm / ev.norm, 1.0 / BROYDEN_RATE) > settings.tolerance
                if (not fresh and not reduced) or (slow and (not cold or trial.norm < NEAR_ROOT * settings.tolerance)):
                    # the carried J is too far off, or this step's rate carried on would not
                    # reach the tolerance in one more step (a cold frame: near the root
                    # only): a fresh J next iteration
                    J = split = None
            ev, ws = trial, trial_ws
            fresh, linear_only = False, False
        elif not fresh:
            J = split = None  # retry this iterate with a fresh J
            continue
        elif inner is not None:
            linear_only = True  # the contacts-exact model failed here: the linear one's step
            continue
        elif settings.line_search and rejected < MAX_SHRINK and ev.norm > NEAR_ROOT * settings.tolerance:
            # the linear model is not trusted this far: a shorter dogleg step, the same J
            radius, rejected = SHRINK * reach, rejected + 1
            continue
        elif settings.line_search:
            # near the root (or the region shrunk MAX_SHRINK times): golden section along the step
            step = dogleg_step(J, ev.f_fdk, step_N, max_step, max_step)
            radius, rejected = 1.0, 0
            trial, trial_ws, n_ev = _golden_section(ctx, k, ev, ws, step, settings.golden_section_evaluations,
                                                    max_step)
            evaluations += n_ev
            if trial is None:
                return done(best, False, it, f"line search failed: no step length along the Newton direction "
                                             f"reduced max |f^FDK| = {best.norm:.4g} (iteration {it})",
                            "line_search", best_ws)
            if reuse:
                beta_step = trial.alpha - ev.alpha
                if split is not None:
                    split.J_whole = _broyden(J, beta_step, trial.f_fdk - ev.f_fdk)
                J = _corrected(J, split, beta_step, trial.f_fdk - ev.f_fdk, trial.f_fdk - predicted(beta_step))
            ev, ws = trial, trial_ws
            fresh, linear_only = False, False
        else:
            return done(best, False, it, f"the Newton step did not reduce max |f^FDK| = {best.norm:.4g} "
                                         f"(no line search)", "line_search", best_ws)
        if ev.norm < best.norm:
            best, best_ws = ev, ws.copy()
    if best.norm < settings.tolerance:
        return done(best, True, settings.max_iterations, "", "converged", best_ws)
    return done(best, False, settings.max_iterations,
                f"iteration limit ({settings.max_iterations}) reached, max |f^FDK| = {best.norm:.4g}",
                "iteration_limit", best_ws)


def solve_frame_from(ctx, k, starts, ws, settings, warm=None, jacobian=None, first_settings=None,
                     cold=False) -> FrameSolution:
    """:func:`solve_frame` from ``starts[0]`` (the warm start, with the carried
    ``jacobian``, and ``first_settings`` if given: a cold frame's larger iteration limit);
    if that fails and ``settings.restart``, from each further start (n_fdk,)
    in turn — fresh Jacobian, poses from a copy of ``ws`` as given — until one converges.

    starts : sequence of (n_fdk,) α in SI units; repeats of an earlier start are skipped
    (:func:`solve_restarts`, :func:`combined`).
    Returns the converged FrameSolution (``restarts`` = further starts solved), or the
    best iterate of all starts (smallest max |f^FDK|) with the first start's message and
    reason. ``iterations``, ``evaluations`` and ``jacobians`` are totals over all starts.
    """
    ws0 = ws.copy()
    first = solve_frame(ctx, k, starts[0], ws, first_settings or settings, warm, jacobian, cold)
    if first.converged or not settings.restart:
        return first
    return combined(first, solve_restarts(ctx, k, starts[1:], ws0, settings, warm, [starts[0]], cold))


def solve_restarts(ctx, k, starts, ws0, settings, warm=None, tried=None, cold=False):
    """Solutions (list of FrameSolution) of frame k from each start (n_fdk,) in turn —
    fresh Jacobian, poses from a copy of ``ws0`` — until one converges; starts equal to
    one in the list ``tried`` or an earlier one are skipped (each start solved is added
    to ``tried``); ``cold`` as for :func:`solve_frame`."""
    tried = [] if tried is None else tried
    tried[:] = [np.asarray(a, dtype=float) for a in tried]
    out = []
    for alpha0 in starts:
        alpha0 = np.asarray(alpha0, dtype=float)
        if any(np.array_equal(alpha0, a) for a in tried):
            continue
        tried.append(alpha0)
        out.append(solve_frame(ctx, k, alpha0, ws0.copy(), settings, warm, None, cold))
        if out[-1].converged:
            break
    return out


def combined(first, later) -> FrameSolution:
    """One FrameSolution of a frame solved from several starts: ``first`` (the warm
    start's, whose message and reason a failure reports) and ``later`` (the further
    solutions in order, each counting 1 + its own restarts). The converged one if any,
    else the best iterate of all (smallest max |f^FDK|); iterations, evaluations and
    Jacobians are totals."""
    best, restarts = first, first.restarts
    totals = np.array([first.iterations, first.evaluations, first.jacobians])
    for sol in later:
        restarts += 1 + sol.restarts
        totals += (sol.iterations, sol.evaluations, sol.jacobians)
        if sol.converged:
            best = sol
            break
        if not best.converged and sol.best.norm < best.best.norm:
            best = sol
    it, n_ev, n_jac = (int(x) for x in totals)
    if best.converged:
        return FrameSolution(best.best, True, it, n_ev, "", "converged", best.workspace, best.jacobian, n_jac,
                             restarts)
    message = first.message
    if restarts:
        message += f"; {restarts} restart(s) from other starting α did not converge either"
    return FrameSolution(best.best, False, it, n_ev, message, first.reason, best.workspace, None, n_jac, restarts)


def _jacobian(ctx, k, ev, ws, settings):
    """(J (n_fdk, n_fdk) or None, residual evaluations used, message)."""
    if settings.jacobian == "analytic":
        return analytic_jacobian(ctx, k, ev)
    return central_jacobian(ctx, k, ev, ws, settings.perturbation)


def _broyden(J, s, y):
    """Broyden's ("good") rank-one update of J (n, n) so that J s = y; s = Δα (n,),
    y = Δf^FDK (n,)."""
    ss = float(s @ s)
    if ss <= 0.0 or not np.all(np.isfinite(y)):
        return J
    return J + np.outer(y - J @ s, s) / ss


def _refreshed(ctx, ev, split, contacts, max_step):
    """(The carried ``split`` with U and R taken at ``ev`` (:func:`~.jacobian.refreshed_split`),
    (ev, split, Q_c, K_c U) there) when its Newton step −J⁻¹ f, J = J_s − R K_c U at ev's pose,
    lies within the max_step box, else (None, None)."""
    split = refreshed_split(ctx, ev, split)
    if split is None:
        return None, None
    base = (ev, split, *split.terms(contacts, ev.state))
    try:
        step = small_solve(split.jacobian_at(base[3]), -ev.f_fdk)
    except np.linalg.LinAlgError:
        return None, None
    return (split, base) if np.all(np.isfinite(step)) and np.max(np.abs(step / max_step)) <= 1.0 else (None, None)


def _corrected(J, split, s, y, miss):
    """Broyden's update after a step s (n,) that changed f^FDK by y (n,) and whose f^FDK
    the model missed by ``miss`` (n,): of J (the linear model, :func:`_broyden`) or, with a
    contact split, of its J_s (the contacts stay exact). Returns the J to carry: J, or the
    split's J_s."""
    if split is None:
        return _broyden(J, s, y)
    split.J_s = _broyden(split.J_s, s, miss + split.J_s @ s)
    return split.J_s


def _golden_section(ctx, k, ev, ws, step, max_evaluations, max_step):
    """Golden-section search of β ∈ (0, 1) minimising the merit ‖W f^FDK(α + β Δα)‖₂
    (:func:`_merit`, W = diag(max_step) (n_fdk,) m or rad); returns the best evaluation if
    it beats β = 0, else (None, None, n)."""
    a, b = 0.0, 1.0
    cache = {}

    def value(beta):
        if beta not in cache:
            w = ws.copy()
            cache[beta] = (ctx.evaluate(k, ev.alpha + beta * step, w, ev.frame.recruitment), w)
        return _merit(cache[beta][0], max_step)

    c = b - GOLDEN * (b - a)
    d = a + GOLDEN * (b - a)
    while len(cache) < max_evaluations:
        if value(c) < value(d):
            b, d = d, c
            c = b - GOLDEN * (b - a)
        else:
            a, c = c, d
            d = a + GOLDEN * (b - a)
    beta = min(cache, key=lambda x: _merit(cache[x][0], max_step))
    trial, w = cache[beta]
    if _merit(trial, max_step) < _merit(ev, max_step):
        return trial, w, len(cache)
    return None, None, len(cache)
