"""Newton–Raphson on f^FDK(α) = 0 for one frame (paper Fig. 1).

Each iteration: Jacobian J = ∂f^FDK/∂α (analytic or central differences), Newton step
Δα = −J⁻¹ f, scaled down uniformly so that no |Δα_i| exceeds its ``max_step``, then a
step length β: the full step is taken when it reduces ‖f^FDK‖₂; otherwise a golden-section
search on β ∈ (0, 1) (the paper's line search) picks the β with the smallest ‖f^FDK‖₂.
Converged when max |f^FDK| < tolerance.

Jacobian reuse (setting ``reuse_jacobian``, default on): instead of a fresh J at every
iteration, the J of the previous iteration — or of the previous frame, since the
configuration changes little in 10 ms — is kept and corrected after every accepted step
by Broyden's rank-one update J ← J + (Δf − J Δα) Δαᵀ / (Δαᵀ Δα) (a quasi-Newton method;
the converged α satisfies the same max |f^FDK| < tolerance). A fresh J is computed when
there is none, or when a step with the carried J did not at least halve ‖f^FDK‖₂; only a
fresh J's step goes on to the line search. With ``reuse_jacobian: false`` every iteration
computes J, as in the paper.

A frame that does not converge keeps its best iterate and says why: line search failed, iteration limit, recruitment infeasible,
kinematics failed, or a singular Jacobian (no restoring force along a DOF).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kinematics.frame_kernels import small_solve
from .jacobian import analytic_jacobian, central_jacobian

GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


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
    jacobian: object = None  # the last J (n_fdk, n_fdk), for reuse in the next frame
    jacobians: int = 0  # Jacobians computed in this frame


def _norm2(ev):
    return float(np.linalg.norm(ev.f_fdk)) if ev.ok else np.inf


def solve_frame(ctx, k, alpha0, ws, settings, warm=None, jacobian=None) -> FrameSolution:
    """Find α with f^FDK(α) = 0 at frame k, starting from alpha0 (n_fdk,) and the
    warm-start poses ``ws`` (FrameWorkspace, updated). ``jacobian`` (n_fdk, n_fdk): a J
    to start from (the previous frame's), used only with ``settings.reuse_jacobian``."""
    names = [d.name for d in ctx.model.fdk_dofs]
    max_step = np.asarray(settings.max_step, dtype=float)
    reuse = settings.reuse_jacobian
    J = np.array(jacobian, dtype=float) if (reuse and jacobian is not None) else None
    fresh, n_jac = False, 0
    ev = ctx.evaluate(k, alpha0, ws, warm)
    evaluations = 1

    def done(sol_ev, converged, it, message, reason, workspace):
        return FrameSolution(sol_ev, converged, it, evaluations, message, reason, workspace,
                             J if reuse else None, n_jac)

    if not ev.ok:
        return done(ev, False, 0, ev.message, ev.stage or "failed", ws)
    best, best_ws = ev, ws.copy()
    for it in range(1, settings.max_iterations + 1):
        if ev.norm < settings.tolerance:
            return done(ev, True, it - 1, "", "converged", ws)
        if J is None or not reuse:
            J, n_ev, msg = _jacobian(ctx, k, ev, ws, settings)
            evaluations += n_ev
            n_jac += 1
            fresh = True
            if J is None:
                return done(best, False, it, msg, "jacobian", best_ws)
        try:
            step = small_solve(J, -ev.f_fdk)
            if not np.all(np.isfinite(step)):
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:
            if not fresh:  # a carried J went singular: compute one here
                J = None
                continue
            weak = [names[i] for i in np.flatnonzero(np.max(np.abs(J), axis=0) < 1e-9 * max(1.0, np.abs(J).max()))]
            return done(best, False, it, f"singular FDK Jacobian: no restoring force along {weak or names}",
                        "singular", best_ws)
        ratio = np.max(np.abs(step) / max_step)
        if ratio > 1.0:
            step = step / ratio
        trial_ws = ws.copy()
        trial = ctx.evaluate(k, ev.alpha + step, trial_ws, ev.frame.recruitment)
        evaluations += 1
        if _norm2(trial) < _norm2(ev):
            halved = _norm2(trial) <= 0.5 * _norm2(ev)
            if reuse:
                J = _broyden(J, trial.alpha - ev.alpha, trial.f_fdk - ev.f_fdk)
                if not fresh and not halved:
                    J = None  # the carried J is too far off: a fresh one next iteration
            ev, ws = trial, trial_ws
            fresh = False
        elif not fresh:
            J = None  # retry this iterate with a fresh J
            continue
        elif settings.line_search:
            trial, trial_ws, n_ev = _golden_section(ctx, k, ev, ws, step, settings.golden_section_evaluations)
            evaluations += n_ev
            if trial is None:
                return done(best, False, it, f"line search failed: no step length along the Newton direction "
                                             f"reduced max |f^FDK| = {best.norm:.4g} (iteration {it})",
                            "line_search", best_ws)
            if reuse:
                J = _broyden(J, trial.alpha - ev.alpha, trial.f_fdk - ev.f_fdk)
            ev, ws = trial, trial_ws
            fresh = False
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


def _golden_section(ctx, k, ev, ws, step, max_evaluations):
    """Golden-section search of β ∈ (0, 1) minimising ‖f^FDK(α + β Δα)‖₂; returns the
    best evaluation if it beats β = 0, else (None, None, n)."""
    a, b = 0.0, 1.0
    cache = {}

    def value(beta):
        if beta not in cache:
            w = ws.copy()
            cache[beta] = (ctx.evaluate(k, ev.alpha + beta * step, w, ev.frame.recruitment), w)
        return _norm2(cache[beta][0])

    c = b - GOLDEN * (b - a)
    d = a + GOLDEN * (b - a)
    while len(cache) < max_evaluations:
        if value(c) < value(d):
            b, d = d, c
            c = b - GOLDEN * (b - a)
        else:
            a, c = c, d
            d = a + GOLDEN * (b - a)
    beta = min(cache, key=lambda x: _norm2(cache[x][0]))
    trial, w = cache[beta]
    if _norm2(trial) < _norm2(ev):
        return trial, w, len(cache)
    return None, None, len(cache)
