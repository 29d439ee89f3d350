"""The trust region of the FDK Newton iteration (fdk/newton.py): Powell's dogleg step
within a box of |Δα_i| ≤ r · max_step_i, and the rule that adapts the radius r ∈ (0, 1]
from how well the linear model f + J Δα predicted the step (Nocedal & Wright,
"Numerical Optimization", 2nd ed., §4.1, Algorithm 4.1, and §11.2; MINPACK's ``hybrj``,
Moré et al. 1980, is the same idea for nonlinear equations).

Why (measured on the DM knee in gait, docs/fdk.md "Trust region"): at heel strike the
patella and the tibial insert come into contact over a few vertices while the
quadriceps switch on, and f^FDK(α) stiffens steeply along the step. A full-box step then
overshoots (‖f‖ 186 → 422 N), and a golden-section search along it costs eight
evaluations per iteration while the next iteration's step overshoots again. With the
radius remembered, the steps stay where the model holds: og9's first heel strike took
147 evaluations per frame instead of 920, og4's first frames converged on 9 of 9 frames
instead of 7.

The merit is the residual's work, ‖W f‖₂ with W = diag(max_step) (:func:`work`), not
‖f‖₂. f^FDK is a generalised force, in N along a translation DOF and in N m along a
rotation, and pairs with Δα as work; the box already measures Δα in max_steps (1 mm,
0.05 rad by default), so the dual measure of f is f_i · max_step_i. ‖f‖₂ adds newtons to
newton-metres: a DOF's weight then depends on the unit of its coordinate, and the
rotations' moments (the DM knee's rotations and the patella's tilt and spin, its soft
modes) count 50 times less than with the work. With the work the iteration is the same
in any units (tests/test_fdk_trust_region.py), and on DM's six overground trials it
took 11 371 residual evaluations and 4 883 Jacobians instead of 13 958 and 6 357, every
frame converged either way (docs/fdk.md, "The merit: the residuals' work"). On a model
whose DOFs share one max_step (the mandible's) W is uniform and nothing changes.

Near the root a refused step is noise, not curvature: f^FDK is known only to a few mN
where a strong muscle sits at its recruitment threshold (the polynomial criterion's
activity grows as the square root of its multiplier there). Within :data:`NEAR_ROOT`
tolerances of the root, and after :data:`MAX_SHRINK` refusals, newton.py searches
along the step instead (golden section), as the paper does.
"""

from __future__ import annotations

import numpy as np

#: a refused step shrinks the radius to this fraction of its length
SHRINK = 0.25
#: refusals with one fresh J before the golden-section search along the step
MAX_SHRINK = 4
#: below this many tolerances of max |f^FDK| a refused step goes to the golden section
NEAR_ROOT = 10.0
#: the radius an accepted step with a poor prediction shrinks to, at least (× max_step)
RADIUS_MIN = 1e-4


def work(f, weights):
    """f (n,) N or N m weighted by ``weights`` (n,) SI (the DOFs' max_step, m or rad):
    each residual's work over one max_step of its DOF, J. The merit of the trust region is
    ‖work(f, max_step)‖₂ (module docstring); ``weights`` None: f itself."""
    return f if weights is None else f * weights


def reduction_ratio(J, f, step, f_trial, f_model=None, weights=None):
    """ρ = actual / predicted decrease of the merit ‖W f‖₂² for the step (n,) SI, W =
    diag(weights) (:func:`work`): (‖W f‖² − ‖W f_trial‖²) / (‖W f‖² − ‖W f_model‖²),
    f_model the model's f after the step (default the linear model's f + J step; the step
    with the contacts exact gives its own, :mod:`.contact_step`); J (n, n), f, f_trial and
    f_model (n,) N or N m; weights (n,) m or rad, or None (W = I). 0 when the model
    predicts no decrease."""
    f_model = f + J @ step if f_model is None else f_model
    f, f_trial, f_model = work(f, weights), work(f_trial, weights), work(f_model, weights)
    f2 = float(f @ f)
    predicted = f2 - float(f_model @ f_model)
    if not predicted > 0.0:
        return 0.0
    return (f2 - float(f_trial @ f_trial)) / predicted


def trust_radius(radius, reach, rho):
    """The radius (× max_step, ≤ 1) after an accepted step of length ``reach`` (its largest
    |Δα_i| / max_step_i) with reduction ratio ``rho``: doubled when the model predicted
    well (ρ > 3/4) and the step reached the boundary, shrunk to :data:`SHRINK` · reach
    when it predicted poorly (ρ < 1/4), else kept."""
    if rho > 0.75 and reach >= 0.99 * radius:
        return min(2.0 * radius, 1.0)
    if rho < 0.25:
        return max(SHRINK * reach, RADIUS_MIN)
    return radius


def dogleg_step(J, f, step_N, max_step, weights=None):
    """Powell's dogleg step within the box |Δα_i| ≤ max_step_i (Nocedal & Wright,
    "Numerical Optimization", 2nd ed., §4.1 and §11.2).

    J (n, n), f (n,) N or N m: the linear model f + J Δα; step_N (n,): the Newton step
    −J⁻¹ f; max_step (n,) SI: the box (the trust radius times the DOFs' max_step);
    weights (n,) m or rad: the merit's W (:func:`work`), or None. In the variables scaled
    by the box (it becomes the unit cube), with J_s = W J diag(max_step): the Newton step
    when it lies in the box; else the Cauchy point p_C = −(‖g‖² / ‖J_s g‖²) g,
    g = J_sᵀ W f the gradient of ½‖W (f + J Δα)‖² at 0, cut at the box when it leaves
    it; else the point where the segment from p_C to the Newton step leaves the box. Where J is nearly singular along a DOF the Newton step is long and
    points where the model is least trusted; the Cauchy point still decreases the model,
    so the step turns towards steepest descent instead of being scaled down whole.
    Returns Δα (n,)."""
    p_N = step_N / max_step
    ratio = np.max(np.abs(p_N))
    if ratio <= 1.0:
        return step_N
    w = np.ones(len(f)) if weights is None else np.asarray(weights, dtype=float)
    J_s = w[:, None] * J * max_step[None, :]
    g = J_s.T @ (w * f)
    Jg = J_s @ g
    gg, JgJg = float(g @ g), float(Jg @ Jg)
    if gg == 0.0 or JgJg == 0.0 or not np.isfinite(JgJg):
        return step_N / ratio
    p_C = -(gg / JgJg) * g
    reach = np.max(np.abs(p_C))
    if reach >= 1.0:
        return p_C / reach * max_step
    d = p_N - p_C
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(d != 0.0, (np.sign(d) - p_C) / d, np.inf)
    tau = float(min(1.0, np.min(tau)))
    return (p_C + tau * d) * max_step


__all__ = ["dogleg_step", "reduction_ratio", "trust_radius", "work", "SHRINK", "MAX_SHRINK", "NEAR_ROOT", "RADIUS_MIN"]
