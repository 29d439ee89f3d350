"""Frame-to-frame jumps of the FDK model's medio-lateral DOF, and whether a second root
was passed over (issue 28).

The medio-lateral FDK DOF is weakly held when the condyles float lightly in their
fossae (≈ 0.5 N/mm against ≈ 60 N/mm along the condyle normals in the wide chewing),
and its root can move by millimetres from one frame to the next. The FDK solver
already continues from the previous frames (warm start extrapolated from the two
previous α, then restarts from the previous α; docs/fdk.md). A jump is then either

* **genuine**: the branch the previous frames followed ends (a fold of f^FDK(α) = 0) and
  the only root left is millimetres away; or
* **a passed-over root**: a root near the previous frame's α still exists, and the warm
  start went past it to another one.

:func:`ml_jumps` reports the jumps of a run; :func:`continuation_check` tells the two
cases apart at the largest ones: frame k is solved again from the previous frame's α
alone (pure continuation, no extrapolation, no restart) with Newton steps limited to
``CHECK_STEP_M`` (0.1 mm), which follows the local basin. If that converges to a root
more than ``SAME_ROOT_M`` from the reported one, a second root exists and is reported
(never silently swapped); if it converges to the reported root or does not converge
(it walks toward the reported root and the branch is gone), the jump is genuine.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["CHECK_STEP_M", "JUMP_M", "SAME_ROOT_M", "continuation_check", "ml_jumps"]

#: a frame-to-frame change of the ML DOF above this is a jump, m
JUMP_M = 0.5e-3
#: Newton step limit of the continuation check, m (all DOFs are lengths here)
CHECK_STEP_M = 0.1e-3
#: two roots closer than this are the same root, m
SAME_ROOT_M = 0.3e-3
#: history (s) solved before a checked frame to rebuild the solver's warm start
CHECK_HISTORY_S = 0.1


def ml_jumps(time, alpha_ml, threshold=JUMP_M) -> dict:
    """Frame-to-frame jumps of the ML DOF.

    Args: time (n,) s; alpha_ml (n,) m, the ML DOF's α per frame (NaN where not solved).
    Returns {"max_mm", "at_s" (time of the frame after the largest jump), "count" (jumps
    above ``threshold``), "threshold_mm", "frames" (indices k of the frames after each
    jump, largest first)}."""
    a = np.asarray(alpha_ml, dtype=float)
    d = np.abs(np.diff(a))
    finite = np.isfinite(d)
    if not finite.any():
        return {"max_mm": None, "at_s": None, "count": 0, "threshold_mm": 1e3 * threshold, "frames": []}
    d = np.where(finite, d, -1.0)
    k = int(np.argmax(d))
    big = np.flatnonzero(d > threshold)
    big = big[np.argsort(-d[big])]
    return {"max_mm": round(1e3 * float(d[k]), 4), "at_s": round(float(time[k + 1]), 4), "count": int(big.size),
            "threshold_mm": 1e3 * threshold, "frames": [int(j + 1) for j in big]}


def continuation_check(model_path, trial, times, frames, limit=3) -> list:
    """Solve the ``limit`` first of ``frames`` (indices into ``times``, the run's frame
    times, s) again by pure continuation from the previous frame (module docstring).

    Each check re-runs the FDK solver over ``CHECK_HISTORY_S`` before the frame (to
    rebuild the previous frame's α and poses as the run had them), then solves the
    frame from that α with steps ≤ ``CHECK_STEP_M``. Returns one dict per frame:
    ``t_s``, ``previous_mm``, ``reported_mm`` (the run's ML α at the frame, as
    re-solved), ``continued_mm``, ``continued_converged``, ``residual_N``,
    ``second_root`` (True: the continuation converged to a root more than
    ``SAME_ROOT_M`` from the reported one)."""
    from ..fdk.analysis import FDKStep, fdk_context
    from ..fdk.newton import solve_frame
    from ..fdk.residual import FrameWorkspace
    from ..fdk.settings import fdk_settings
    from ..io.modelfile import load_model_and_settings
    from ..analysis.jobs import analysis_inputs

    model, file_settings = load_model_and_settings(model_path)
    names = [d.name for d in model.fdk_dofs]
    ml = names.index("tmj_ml")
    out = []
    for i in list(frames)[:limit]:
        t = float(times[i])
        traj, local, _ = analysis_inputs(model, trial, None, t - CHECK_HISTORY_S, t + 1e-6, file_settings)
        ctx = fdk_context(model, traj, local, settings=file_settings)
        settings = fdk_settings(model, file_settings)
        step = FDKStep(model, ctx, settings)
        k = int(np.argmin(np.abs(local - t)))
        for j in range(k):
            step.step(j)
        if not step.history or step.history[-1][0] != k - 1:
            continue                                       # the previous frame did not converge here
        previous = step.history[-1][1].copy()
        ws = FrameWorkspace({j: step.last_state for j in ctx.frames_needed(k)})
        step.step(k)                                       # the frame as the run solved it
        reported = step.history[-1][1] if step.history[-1][0] == k else np.full_like(previous, np.nan)
        # the frame once more, from the previous α only, with short steps
        small = dataclasses.replace(settings, max_step=tuple(CHECK_STEP_M for _ in settings.max_step))
        sol = solve_frame(ctx, k, previous.copy(), ws, small, step.warm, None)
        continued = sol.best.alpha
        second = bool(sol.converged and abs(continued[ml] - reported[ml]) > SAME_ROOT_M)
        out.append({"t_s": round(t, 4), "previous_mm": round(1e3 * float(previous[ml]), 3),
                    "reported_mm": round(1e3 * float(reported[ml]), 3),
                    "continued_mm": round(1e3 * float(continued[ml]), 3), "continued_converged": bool(sol.converged),
                    "residual_N": float(sol.best.norm), "second_root": second})
    return out
