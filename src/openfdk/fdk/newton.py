"""Newton–Raphson on f^FDK(α) = 0 for one frame (paper Fig. 1).

Each iteration: Jacobian J = ∂f^FDK/∂α (analytic or central differences), Newton step
Δα = −J⁻¹ f, scaled down uniformly so that no |Δα_i| exceeds its ``max_step``, then a
step length β: the full step is taken when it reduces ‖f^FDK‖₂; otherwise a golden-section
search on β ∈ (0, 1) (the paper's line search) picks the β with the smallest ‖f^FDK‖₂.
Converged when max |f^FDK| < tolerance. A frame that does not converge keeps its best
iterate and says why: line search failed, iteration limit, recruitment infeasible,
kinematics failed, or a singular Jacobian (no restoring force along a DOF).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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


def _norm2(ev):
    return float(np.linalg.norm(ev.f_fdk)) if ev.ok else np.inf


def solve_frame(ctx, k, alpha0, ws, settings, warm=None) -> FrameSolution:
    """Find α with f^FDK(α) = 0 at frame k, starting from alpha0 (n_fdk,) and the
    warm-start poses ``ws`` (FrameWorkspace, updated)."""
    names = [d.name for d in ctx.model.fdk_dofs]
    max_step = np.asarray(settings.max_step, dtype=float)
    ev = ctx.evaluate(k, alpha0, ws, warm)
    evaluations = 1
    if not ev.ok:
        return FrameSolution(ev, False, 0, evaluations, ev.message, ev.stage or "failed", ws)
    best, best_ws = ev, ws.copy()
    for it in range(1, settings.max_iterations + 1):
        if ev.norm < settings.tolerance:
            return FrameSolution(ev, True, it - 1, evaluations, "", "converged", ws)
        if settings.jacobian == "analytic":
            J, n_ev, msg = analytic_jacobian(ctx, k, ev)
        else:
            J, n_ev, msg = central_jacobian(ctx, k, ev, ws, settings.perturbation)
        evaluations += n_ev
        if J is None:
            return FrameSolution(best, False, it, evaluations, msg, "jacobian", best_ws)
        try:
            step = np.linalg.solve(J, -ev.f_fdk)
            if not np.all(np.isfinite(step)):
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:
            weak = [names[i] for i in np.flatnonzero(np.max(np.abs(J), axis=0) < 1e-9 * max(1.0, np.abs(J).max()))]
            return FrameSolution(best, False, it, evaluations,
                                 f"singular FDK Jacobian: no restoring force along {weak or names}", "singular", best_ws)
        ratio = np.max(np.abs(step) / max_step)
        if ratio > 1.0:
            step = step / ratio
        trial_ws = ws.copy()
        trial = ctx.evaluate(k, ev.alpha + step, trial_ws, ev.frame.recruitment)
        evaluations += 1
        if _norm2(trial) < _norm2(ev):
            ev, ws = trial, trial_ws
        elif settings.line_search:
            trial, trial_ws, n_ev = _golden_section(ctx, k, ev, ws, step, settings.golden_section_evaluations)
            evaluations += n_ev
            if trial is None:
                return FrameSolution(best, False, it, evaluations,
                                     f"line search failed: no step length along the Newton direction reduced "
                                     f"max |f^FDK| = {best.norm:.4g} (iteration {it})", "line_search", best_ws)
            ev, ws = trial, trial_ws
        else:
            return FrameSolution(best, False, it, evaluations,
                                 f"the Newton step did not reduce max |f^FDK| = {best.norm:.4g} (no line search)",
                                 "line_search", best_ws)
        if ev.norm < best.norm:
            best, best_ws = ev, ws.copy()
    if best.norm < settings.tolerance:
        return FrameSolution(best, True, settings.max_iterations, evaluations, "", "converged", best_ws)
    return FrameSolution(best, False, settings.max_iterations, evaluations,
                         f"iteration limit ({settings.max_iterations}) reached, max |f^FDK| = {best.norm:.4g}",
                         "iteration_limit", best_ws)


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
