"""The warm start of a frame's FDK DOFs α from the converged frames before it: the
predictor of the continuation along a trial.

Linear extrapolation α_k ≈ 2 α_{k−1} − α_{k−2} errs by about α̈ Δt²; quadratic
α_k ≈ 3 α_{k−1} − 3 α_{k−2} + α_{k−3} by about α⃛ Δt³. Where α(t) is smooth that is far
less. At a kink it is far more: a muscle entering or leaving the recruitment's active set
(paper Eq. 11), contact spreading at heel strike. There the third difference is large.
With four converged predecessors the order is chosen by how each extrapolation would
have predicted the last of them, α_{k−1} from α_{k−2}, α_{k−3}, α_{k−4}. The quadratic
is used if its miss was at most half the linear one's (max norm, each DOF in units of
its max_step): it is then trusted while it keeps predicting clearly better, and dropped
at the first frame after a kink. "Clearly": while α(t) settles after a cold frame (the
DM knee's lead-in, :mod:`.approach`) both miss by similar amounts, and there the
parabola chosen on any advantage overshot: 5 of the 12 lead-in frames failed instead of
2, 593 evaluations instead of 353. With the factor ½ the lead-in is the line's.

Measured on the bench's knee in gait (`openfdk bench --only tka_knee_gait`, 50 frames of
stance, α in max_step units): the sum of the warm starts' errors is 7.66 with linear
extrapolation throughout, 9.53 with quadratic throughout (mid-stance errors 5–10×
smaller, heel strike and push-off errors up to 3× larger) and 7.58 with the choice.
Newton then needs 3.80 residual evaluations per frame instead of 4.06.
"""

from __future__ import annotations

import numpy as np

#: converged frames kept for the warm start (the choice of order needs four)
HISTORY = 4
#: the parabola is used when its miss of α_{k−1} was at most this fraction of the line's
CLEARLY_BETTER = 0.5


def _linear(a1, a2):
    """α_k from α_{k−1}, α_{k−2} (each (n,))."""
    return 2.0 * a1 - a2


def _quadratic(a1, a2, a3):
    """α_k from α_{k−1}, α_{k−2}, α_{k−3} (each (n,)): the parabola through them."""
    return 3.0 * a1 - 3.0 * a2 + a3


def extrapolated(history, k, scale):
    """The warm start α (n,) of frame k, SI units, or None without two converged frames
    just before it.

    history : [(frame, α (n,))], the most recent converged frames in order (at most
    HISTORY are used); scale : (n,) the DOFs' max_step (m or rad), the units of the
    comparison that picks the order (module docstring)."""
    run = []  # α_{k−1}, α_{k−2}, ... while the frames are consecutive
    for frame, alpha in reversed(history[-HISTORY:]):
        if frame != k - 1 - len(run):
            break
        run.append(np.asarray(alpha, dtype=float))
    if len(run) < 2:
        return None
    if len(run) == HISTORY:
        s = np.asarray(scale, dtype=float)
        linear_miss = np.max(np.abs(_linear(run[1], run[2]) - run[0]) / s)
        quadratic_miss = np.max(np.abs(_quadratic(run[1], run[2], run[3]) - run[0]) / s)
        if quadratic_miss <= CLEARLY_BETTER * linear_miss:
            return _quadratic(run[0], run[1], run[2])
    return _linear(run[0], run[1])


__all__ = ["extrapolated", "HISTORY", "CLEARLY_BETTER"]
