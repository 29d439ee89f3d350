"""The trust region of the FDK Newton iteration (openfdk.fdk.trust_region, used by
openfdk.fdk.newton.solve_frame), against closed forms.

The frame below is a contact in one DOF: a layer of thickness h on the non-linear
elastic-foundation law (Bei & Fregly 2004), P(α) = −P₀ ln(1 − α/h) for a depth α < h,
pressed by a load F. Its root is α* = h (1 − exp(−F/P₀)) exactly. Beyond the layer the
law is undefined and the evaluation fails, as a pose through an implant does. From the
undeformed α = 0 the Newton step is F h / P₀ = 3 h: the first trial (the max_step box,
h) goes through the layer and is refused, and the trust region must shrink to a step the
law describes.
"""


import numpy as np
import pytest

from openfdk.fdk.newton import solve_frame
from openfdk.fdk.settings import FDKSettings
from openfdk.fdk.trust_region import SHRINK, reduction_ratio, trust_radius

from fdk_stand_ins import ClosedFormResidual, Workspace

H = 1e-3  # m, layer thickness
P0 = 1e3  # N, the law's modulus times the contact area
F = 3e3  # N, load
ROOT = H * (1.0 - np.exp(-F / P0))  # m


def _layer(alpha):
    """f(α) N of the layer, None through it."""
    if alpha[0] >= H:
        return None
    return np.array([-P0 * np.log1p(-alpha[0] / H) - F])


def _LayerContact():
    return ClosedFormResidual(_layer, ("normal",))


SETTINGS = FDKSettings(tolerance=1e-6, jacobian="central", reuse_jacobian=False, max_step=(H,),
                       perturbation=(1e-9,), restart=False)


def test_a_step_through_the_layer_shrinks_the_region_and_the_solve_reaches_the_closed_form_root():
    ctx = _LayerContact()
    sol = solve_frame(ctx, 0, np.array([0.0]), Workspace(), SETTINGS)
    assert sol.converged
    assert sol.best.alpha[0] == pytest.approx(ROOT, abs=1e-12)
    # the trials (every evaluation but the start and the central differences ±1e-9 m)
    a = [float(x[0]) for x in ctx.alphas]
    trials = [a[i] for i in range(1, len(a)) if not any(abs(a[i] - b) == pytest.approx(1e-9, rel=1e-3)
                                                        for b in a[:i])]
    assert trials[0] == pytest.approx(H)  # the Newton step 3 h, cut at the box: through the layer
    assert trials[1] == pytest.approx(SHRINK * H)  # the same J, a quarter of that length


def test_the_same_frame_without_a_line_search_stops_at_the_refused_step():
    sol = solve_frame(_LayerContact(), 0, np.array([0.0]), Workspace(),
                      FDKSettings(**{**SETTINGS.__dict__, "line_search": False}))
    assert not sol.converged and sol.reason == "line_search"
    assert sol.best.alpha[0] == 0.0


def test_the_reduction_ratio_is_one_for_a_linear_f_and_the_closed_form_for_a_quadratic():
    J = np.array([[2.0, 1.0], [0.0, 3.0]])
    f = np.array([1.0, -2.0])
    step = np.array([0.1, 0.3])
    assert reduction_ratio(J, f, step, f + J @ step) == pytest.approx(1.0, rel=1e-14)
    # f(α) = f + J α + c α₀²: actual decrease over predicted, written out
    c = np.array([5.0, -1.0])
    f_trial = f + J @ step + c * step[0] ** 2
    predicted = f @ f - np.sum((f + J @ step) ** 2)
    assert reduction_ratio(J, f, step, f_trial) == pytest.approx((f @ f - f_trial @ f_trial) / predicted, rel=1e-14)
    assert reduction_ratio(J, f, np.zeros(2), f) == 0.0  # no predicted decrease


@pytest.mark.parametrize("radius, reach, rho, expected", [
    (0.5, 0.5, 0.9, 1.0),  # good prediction at the boundary: doubled
    (0.75, 0.75, 0.9, 1.0),  # ... but never beyond the max_step box
    (0.5, 0.2, 0.9, 0.5),  # good prediction inside the region: kept
    (1.0, 0.8, 0.5, 1.0),  # fair prediction: kept
    (1.0, 0.8, 0.1, SHRINK * 0.8),  # poor prediction: shrunk to a quarter of the step
])
def test_the_radius_rule(radius, reach, rho, expected):
    assert trust_radius(radius, reach, rho) == pytest.approx(expected)


def test_a_cold_frame_keeps_a_fresh_jacobian_for_a_second_step_far_from_the_root():
    """newton.solve_frame(cold=True): far from the root (beyond NEAR_ROOT tolerances) a
    fresh J serves a second, Broyden-updated step, where a warm frame computes one per
    step. The layer pressed by 8 P₀ with a box of h/40: the root α* = h (1 − e⁻⁸) is
    40 boxes away, so both walk there at the box, but the cold one computes J for about
    every other step; near the root both converge (the rate rule), to the closed form."""
    from openfdk.fdk.trust_region import NEAR_ROOT

    load = 8 * P0
    root = H * (1.0 - np.exp(-load / P0))

    def layer(alpha):
        return None if alpha[0] >= H else np.array([-P0 * np.log1p(-alpha[0] / H) - load])

    settings = FDKSettings(tolerance=1e-6, max_iterations=200, jacobian="central", reuse_jacobian=True,
                           max_step=(H / 40,), perturbation=(1e-10,), restart=False)
    warm = solve_frame(ClosedFormResidual(layer), 0, np.array([0.0]), Workspace(), settings)
    cold = solve_frame(ClosedFormResidual(layer), 0, np.array([0.0]), Workspace(), settings, cold=True)
    stiffness = P0 / (H - root)  # dP/dα at the root, N/m
    for sol in (warm, cold):
        assert sol.converged
        assert sol.best.alpha[0] == pytest.approx(root, abs=2 * settings.tolerance / stiffness)
    assert warm.iterations >= 40 and cold.iterations >= 40  # the box walk
    # a warm frame: a fresh J for each step until the last one (within NEAR_ROOT
    # tolerances its rate rule may keep J for the final step)
    # a warm frame: a fresh J for nearly every step (a refused step keeps its J, and a
    # step that reduced ‖f‖ tenfold near the root keeps the updated one); measured 49 for 53
    assert warm.jacobians >= 0.9 * warm.iterations
    # cold: about one J per two steps on the walk (measured 26 for 58), and fewer
    # evaluations in all (each central J costs two)
    assert cold.jacobians <= 0.6 * cold.iterations
    assert cold.evaluations < warm.evaluations
    assert NEAR_ROOT * settings.tolerance < load  # (the walk starts far from the root)


# A joint of two DOFs in different units: a rotation θ (rad, residual a moment in N m) and
# a translation x (m, residual a force in N), held by a stiffening contact at a lever arm
# r and a rotational spring, under a load F and a moment M. The contact's depth is
# d = x + r θ and its force P(d) = P₁ (exp(d/δ) − 1), so
#   f_θ = r P(d) + k θ − M,   f_x = P(d) − F,
# whose root is, in closed form, d* = δ ln(1 + F/P₁), θ* = (M − r F)/k, x* = d* − r θ*.
R_ARM, K_ROT, P1, DELTA = 0.03, 50.0, 100.0, 0.5e-3  # m, N m/rad, N, m
F_LOAD, M_LOAD = 2000.0, 62.0  # N, N m
THETA_ROOT = (M_LOAD - R_ARM * F_LOAD) / K_ROT
X_ROOT = DELTA * np.log1p(F_LOAD / P1) - R_ARM * THETA_ROOT


def _joint(x_unit):
    """f(α) of the joint with x measured in ``x_unit`` metres (1: m, 1e-3: mm): α = (θ,
    x / x_unit), and the generalised force along the second coordinate is f_x · x_unit
    (the work f_x dx is the same in either unit)."""
    def f(alpha):
        theta, x = alpha[0], alpha[1] * x_unit
        P = P1 * np.expm1((x + R_ARM * theta) / DELTA)
        return np.array([R_ARM * P + K_ROT * theta - M_LOAD, (P - F_LOAD) * x_unit])
    return ClosedFormResidual(f, ("theta", "x"))


def test_the_iteration_is_the_same_in_any_unit_of_a_dof():
    """The merit is the residuals' work ‖diag(max_step) f‖₂ (trust_region.work), so the
    iteration is invariant under a change of a DOF's unit: x in millimetres (its max_step,
    perturbation and generalised force rescaled with it) gives the same trial poses as x
    in metres, through a globalisation of refused and cut steps (the Newton step from
    rest is about 10 max_steps long through the exponential contact), and both reach the
    closed-form root. With ‖f‖₂ the force's weight would change a thousandfold with the
    unit and the two iterations would differ from the first refused step on."""
    runs = {}
    for unit in (1.0, 1e-3):
        settings = FDKSettings(tolerance=1e-9, max_iterations=60, jacobian="central", reuse_jacobian=False,
                               max_step=(0.05, 1e-3 / unit), perturbation=(1e-7, 1e-9 / unit), restart=False)
        ctx = _joint(unit)
        sol = solve_frame(ctx, 0, np.zeros(2), Workspace(), settings)
        assert sol.converged
        assert sol.best.alpha[0] == pytest.approx(THETA_ROOT, abs=1e-9)
        assert sol.best.alpha[1] * unit == pytest.approx(X_ROOT, abs=1e-12)
        runs[unit] = np.array([[a[0], a[1] * unit] for a in ctx.alphas])  # θ rad, x m
    metres, millimetres = runs[1.0], runs[1e-3]
    # the globalisation: from rest until max |f| is within 1 N of the root
    f_m = np.array([np.max(np.abs(_joint(1.0).f(a))) for a in metres])
    far = int(np.argmax(f_m < 1.0))
    assert far >= 12  # a long walk: the Newton step from rest is far out of the box
    x_steps = np.diff(metres[:far, 1])
    assert np.any(x_steps < 0)  # a trial refused or cut back on the way (not a plain march)
    np.testing.assert_allclose(millimetres[:far], metres[:far], rtol=1e-6, atol=1e-12)
