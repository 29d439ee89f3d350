"""Pseudo-transient continuation for a frame far from its root: the window's first frame,
and a frame whose warm start failed after a converged frame (fdk/approach.py).

f^FDK(α) (paper Fig. 1, Eq. 14's residual-force columns) is the force an actuator along
each FDK DOF would need to hold the joint at α. Without that actuator the joint moves
against it: where the joint is stable, J = ∂f^FDK/∂α is a stiffness whose eigenvalues
have positive real parts, and the relaxation

    dz/dτ = −f̃(z),   z = α / max_step,   f̃ = f^FDK · max_step (the residuals' work,
                                             :func:`~.trust_region.work`)

ends at the frame's root. Pseudo-transient continuation (Kelley & Keyes, "Convergence
analysis of pseudo-transient continuation", SIAM J. Numer. Anal. 35 (1998) 508–523)
follows it with linearised implicit Euler steps of a growing pseudo-time step δ,

    (I / δ + J̃) Δz = −f̃,   J̃ = diag(max_step) J diag(max_step),

which are short steps along −f̃ while δ is small (the stiff directions damped, the soft
ones moving at their own pace) and Newton's steps once δ is large. δ grows as the merit
‖f̃‖₂ falls (switched evolution relaxation: δ ← δ ‖f̃_old‖ / ‖f̃_new‖), at least
:data:`MIN_GROWTH` times after a step that lowered it.

Why: Newton's method globalised by a merit (fdk/newton.py) stops where the merit is
stationary but f^FDK is not zero. From the DOFs' initial values the DM knee in gait has
such points: the patella's tilt and medio-lateral translation are nearly free, and a
constant force along a flat valley keeps ‖f‖ from falling until the valley's wall
(og9 4.558 s: 15.9 N, singular values down to 0.002). The relaxation moves on along the
force. Started directly at the window's first frame (fdk/approach.py) it replaced the
lead-in at every DM cold start measured: on DM's 15 cold starts (og1, og3, og4, og5 and
og9 at three times each), each drawn twice, the first frames took 750 evaluations
(median 20) instead of 5 098 (median 92), the first three frames 1 371 instead of 5 589,
every frame converged (docs/fdk.md, "The first frame: pseudo-transient continuation").
As the first restart after a failed warm start it took DM's six overground stances from
9 463 evaluations to 8 048.

Every step is accepted whose pose can be evaluated (the method's theory has no line
search); a step where it cannot is retried with δ divided by four. So is a step that
does not go against f̃ (f̃ · Δz ≥ 0): along a mode of negative stiffness (J̃'s
eigenvalue λ < 0: the merit's stationary point is such a mode's crest) the linearised
implicit Euler step reverses once 1/δ < −λ, and climbs back to the crest; with δ below
that it runs down the other side, as the relaxation does (tests/test_fdk_transient.py: a
cubic residual whose |f| has a local minimum between the start and the root).

The Jacobian of a step: a fresh analytic one at the first step, at least every
:data:`FRESH_EVERY`-th step after it, and after a step that did not lower the merit.
Between them, where the model has implant contacts (fdk/contact_step.py), the last fresh
J's part without the contacts J_s is kept, and U = dq̂/dα, R and the contacts' stiffness
along U are taken again at the step's pose (``refreshed_split``, as a warm frame's first
step takes them): J = J_s − R K_c U. The contacts are what bends f^FDK from step to
step; J_s changes less. On DM such a J costs 4 ms against 17 ms for a fresh one. Over
DM's 15 cold starts drawn twice (stop 59, three frames each): 1 406 evaluations and 567
Jacobians against 1 340 and 1 204 with a fresh J at every step, 15 % less CPU time; the
first frames 790 evaluations against 744. With Broyden's update of the whole J between
fresh ones instead (stop 58) the first frames took 962 evaluations against 750.
"""

from __future__ import annotations

import numpy as np

from .jacobian import refreshed_split
from .newton import FrameSolution, _jacobian, _merit
from .trust_region import work

#: the first step's reach along −f̃, in max_steps (δ₀ = FIRST_REACH / max |f̃|)
FIRST_REACH = 0.5
#: no step reaches further than this many max_steps (a longer one is scaled down)
MAX_REACH = 1.0
#: δ grows at least this many times after a step that lowered the merit ‖f̃‖₂ (SER alone:
#: 26 evaluations for DM's bench window's first frame, with 2: 18; with 3 the transient
#: start failed at 4 of the 30 cold starts' draws, 1 924 first-frame evaluations against
#: 750)
MIN_GROWTH = 2.0
#: ... and at most this many times per step
MAX_GROWTH = 10.0
#: δ shrinks at most to this fraction per step where the merit rose
MIN_RATIO = 0.1
#: δ's division after a step whose pose could not be evaluated
FAILED_SHRINK = 4.0
#: a fresh Jacobian at least every this many steps, the contacts' part taken again at
#: the steps between (module docstring). Over DM's 30 cold-start draws (90 frames), with
#: a fresh J also wherever the merit did not fall: every 3rd step 1 436 evaluations and
#: 678 fresh Jacobians, every 4th 1 406 and 567, every 5th 1 460 and 546, every 8th 1 773
#: and 602, never otherwise 2 470 and 671 (a fresh one at every step: 1 340 and 1 204)
FRESH_EVERY = 4


def pseudo_time_step(delta, merit, merit_new):
    """δ after an accepted step that took the merit ‖f̃‖₂ (J) from ``merit`` to
    ``merit_new``: switched evolution relaxation δ · merit / merit_new, at least
    :data:`MIN_GROWTH` times δ where the merit fell, within [MIN_RATIO, MAX_GROWTH] × δ."""
    ratio = merit / merit_new if merit_new > 0.0 else MAX_GROWTH
    floor = MIN_GROWTH if merit_new < merit else MIN_RATIO
    return delta * min(max(ratio, floor), MAX_GROWTH)


def transient_step(J, f, delta, max_step):
    """The linearised implicit Euler step Δα (n,) SI of dz/dτ = −f̃ (module docstring):
    (I / δ + J̃) Δz = −f̃ in the variables scaled by ``max_step`` (n,) m or rad, scaled
    down to :data:`MAX_REACH` max_steps. J (n, n), f (n,) N or N m, δ > 0 in 1/J (z is
    in max_steps, f̃ in J; ``inf``: Newton's step). Raises numpy.linalg.LinAlgError when
    singular."""
    J_s = max_step[:, None] * J * max_step[None, :]
    A = J_s + (0.0 if np.isinf(delta) else 1.0 / delta) * np.eye(len(f))
    dz = np.linalg.solve(A, -work(f, max_step))
    if not np.all(np.isfinite(dz)):
        raise np.linalg.LinAlgError("non-finite pseudo-transient step")
    reach = float(np.max(np.abs(dz)))
    if reach > MAX_REACH:
        dz *= MAX_REACH / reach
    return dz * max_step


def solve_transient(ctx, k, alpha0, ws, settings, warm=None) -> FrameSolution:
    """Frame k's root by pseudo-transient continuation from alpha0 (n_fdk,) SI, the poses
    from ``ws`` (FrameWorkspace, updated), the recruitment warm-started from ``warm``.
    Converged when max |f^FDK| < settings.tolerance (N or N m), else the best iterate
    after settings.max_iterations steps. The returned FrameSolution carries no Jacobian:
    the next frame takes a fresh one, split into the contacts' part and the rest
    (fdk/contact_step.py). (With this one carried on, Broyden-updated past the last step,
    the split came later: DM's bench window took 5–6 evaluations in its frames 2–7
    instead of 3–4.)"""
    max_step = np.asarray(settings.max_step, dtype=float)
    ev = ctx.evaluate(k, alpha0, ws, warm)
    evaluations, n_jac, J = 1, 0, None

    def done(sol_ev, converged, it, message, reason, workspace):
        return FrameSolution(sol_ev, converged, it, evaluations, message, reason, workspace, None, n_jac)

    if not ev.ok:
        return done(ev, False, 0, ev.message, ev.stage or "failed", ws)
    best, best_ws = ev, ws.copy()
    merit = _merit(ev, max_step)
    delta = FIRST_REACH / max(float(np.max(np.abs(work(ev.f_fdk, max_step)))), np.finfo(float).tiny)
    fresh = False
    contacts = ctx.solver.forces.by_kind.get("contacts") if settings.contact_step else None
    split, lagged = None, 0  # the last fresh J's contact split, and the steps taken since it
    for it in range(1, settings.max_iterations + 1):
        if ev.norm < settings.tolerance:
            return done(ev, True, it - 1, "", "converged", ws)
        if not fresh:
            refreshed = refreshed_split(ctx, ev, split) if split is not None and lagged < FRESH_EVERY - 1 else None
            if refreshed is not None:
                split, lagged = refreshed, lagged + 1
                J = split.jacobian_at(split.terms(contacts, ev.state)[1])  # J_s − R K_c U here
            else:
                J, n_ev, msg = _jacobian(ctx, k, ev, ws, settings)
                evaluations += n_ev
                n_jac += 1
                if J is None:
                    return done(best, False, it, msg, "jacobian", best_ws)
                split, lagged = (ev.contact_split if contacts is not None else None), 0
                if split is not None:
                    split.split(J, split.terms(contacts, ev.state)[1])
            if ev.dq_dalpha is not None and ctx.tracker is not None:
                ws.alpha, ws.dq_dalpha = ev.alpha.copy(), ev.dq_dalpha  # poses predicted from here on
            fresh = True
        try:
            step = transient_step(J, ev.f_fdk, delta, max_step)
        except np.linalg.LinAlgError:
            step = None
        if step is None or float(work(ev.f_fdk, max_step) @ (step / max_step)) >= 0.0:
            # (I/δ + J̃) singular or not positive along the step: δ beyond the stability of
            # a mode whose stiffness is negative (module docstring), whose step then turns
            # against the flow; a smaller δ, the same J
            delta /= FAILED_SHRINK
            continue
        trial_ws = ws.copy()
        trial = ctx.evaluate(k, ev.alpha + step, trial_ws, ev.frame.recruitment)
        evaluations += 1
        if not trial.ok:
            delta /= FAILED_SHRINK  # the same J, a shorter step
            continue
        merit_new = _merit(trial, max_step)
        if merit_new >= merit:
            lagged = FRESH_EVERY  # a fresh J at the next step
        delta = pseudo_time_step(delta, merit, merit_new)
        ev, ws, merit, fresh = trial, trial_ws, merit_new, False
        if ev.norm < best.norm:
            best, best_ws = ev, ws.copy()
    if best.norm < settings.tolerance:
        return done(best, True, settings.max_iterations, "", "converged", best_ws)
    return done(best, False, settings.max_iterations,
                f"pseudo-transient continuation: iteration limit ({settings.max_iterations}) reached, "
                f"max |f^FDK| = {best.norm:.4g}", "iteration_limit", best_ws)


__all__ = ["solve_transient", "transient_step", "pseudo_time_step", "FIRST_REACH", "MAX_REACH", "MIN_GROWTH",
           "MAX_GROWTH", "MIN_RATIO", "FAILED_SHRINK", "FRESH_EVERY"]
