"""One step of the safeguarded Newton iteration shared by the muscle equilibrium solves
(:mod:`.hill`, :mod:`.millard`, :mod:`.curve_muscle`): a root of a residual R that is
positive at the bracket's low end and ≤ 0 at its high end, kept bracketed."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def bracketed_newton_step(x, r, dr, lo, hi):
    """(x_new, lo, hi, done) after the residual r = R(x) with slope dr = R′(x) at x.

    The bracket [lo, hi] shrinks to the side of x where the root lies (R(lo) > 0 ≥ R(hi));
    x_new is the Newton step when R falls (dr < 0) and it stays inside the bracket, else
    the bracket's midpoint; done when the bracket is narrower than 1e-15 of hi."""
    if r > 0.0:
        lo = x
    else:
        hi = x
    if hi - lo <= 1e-15 * hi:
        return x, lo, hi, True
    x_new = x - r / dr if dr < 0.0 else -1.0
    if not (lo < x_new < hi):
        x_new = 0.5 * (lo + hi)
    return x_new, lo, hi, False
