"""Pseudo-transient continuation for a frame far from its root (openfdk.fdk.transient).

The frame below is one DOF whose residual is the cubic
    f(α) = F (u³ − 3u + 3),   u = α / L,
with one real root u* (Cardano) where f' > 0 (a stable equilibrium), and a local
minimum of |f| at u = 1 (f' = 0, f = F ≠ 0): a stationary point of the merit that is not
a root, between the start u = 2 and the root. Newton's method globalised by the merit
(openfdk.fdk.newton) stops there; the relaxation du/dτ = −f passes it (f keeps its sign
from u = 1 down to u*) and reaches the root.
"""

import numpy as np
import pytest

from openfdk.fdk import transient
from openfdk.fdk.newton import solve_frame
from openfdk.fdk.settings import FDKSettings
from openfdk.fdk.transient import pseudo_time_step, solve_transient, transient_step

from fdk_stand_ins import ClosedFormResidual, Workspace

F = 10.0  # N
L = 1e-3  # m, also the DOF's max_step
TOLERANCE = 1e-3  # N


def _cubic(alpha):
    u = alpha[0] / L
    return np.array([F * (u ** 3 - 3.0 * u + 3.0)])


def _root():
    """u* of u³ − 3u + 3 = 0 by Cardano's formula (one real root: the discriminant
    (q/2)² + (p/3)³ = 9/4 − 1 > 0)."""
    s = np.sqrt(9.0 / 4.0 - 1.0)
    return float(np.cbrt(-1.5 + s) + np.cbrt(-1.5 - s))


SETTINGS = FDKSettings(tolerance=TOLERANCE, jacobian="central", reuse_jacobian=True, max_step=(L,),
                       perturbation=(1e-9,), restart=False, max_iterations=100)


def test_the_cubic_has_a_stationary_merit_between_start_and_root():
    u_star = _root()
    assert u_star ** 3 - 3 * u_star + 3 == pytest.approx(0.0, abs=1e-12)
    assert 3 * u_star ** 2 - 3 > 0  # stable: J > 0 at the root
    assert _cubic([L])[0] == pytest.approx(F)  # f(u = 1) = F, f'(1) = 0: |f| has a local minimum
    u = np.linspace(u_star + 1e-6, 2.0, 2001)
    assert np.all(u ** 3 - 3 * u + 3 > 0)  # f keeps its sign from the root to the start


def test_newton_with_the_merit_stops_at_the_stationary_point():
    ctx = ClosedFormResidual(_cubic)
    sol = solve_frame(ctx, 0, np.array([2.0 * L]), Workspace(), SETTINGS, cold=True)
    assert not sol.converged
    assert sol.best.alpha[0] / L == pytest.approx(1.0, abs=0.05)
    assert sol.best.norm == pytest.approx(F, rel=0.01)


def test_the_transient_start_passes_it_and_reaches_the_root():
    ctx = ClosedFormResidual(_cubic)
    sol = solve_transient(ctx, 0, np.array([2.0 * L]), Workspace(), SETTINGS)
    assert sol.converged and sol.reason == "converged"
    stiffness = F * (3 * _root() ** 2 - 3) / L  # f'(α*), N/m
    assert sol.best.alpha[0] == pytest.approx(_root() * L, abs=TOLERANCE / stiffness)
    assert sol.best.norm < TOLERANCE
    assert sol.jacobian is None  # the next frame takes a fresh J (its contacts' split)
    assert sol.evaluations == ctx.calls


def test_the_first_step_goes_first_reach_max_steps_along_minus_f():
    ctx = ClosedFormResidual(_cubic)
    solve_transient(ctx, 0, np.array([2.0 * L]), Workspace(), SETTINGS)
    # central differences: the evaluations after the start are J's two, then the step's
    u0, u1 = ctx.alphas[0][0] / L, ctx.alphas[3][0] / L
    f_s, J_s = 5.0 * F * L, 9.0 * F * L  # f̃ = f · max_step, J̃ = f' · max_step² at u = 2 (J, scaled)
    delta = transient.FIRST_REACH / f_s
    assert u1 - u0 == pytest.approx(-f_s / (1.0 / delta + J_s), rel=1e-5)


def test_transient_step_closed_forms():
    max_step = np.array([1e-3, 0.05])
    J = np.diag([4e5, 20.0])  # N/m, N m/rad
    f = np.array([30.0, -0.5])
    J_s, f_s = np.diag(J) * max_step ** 2, f * max_step  # 0.4 and 0.05 J; 0.03 and -0.025 J
    for delta in (0.1, 2.0):
        dz = -f_s / (1.0 / delta + J_s)
        expected = dz * min(1.0, transient.MAX_REACH / np.max(np.abs(dz))) * max_step
        assert transient_step(J, f, delta, max_step) == pytest.approx(expected, rel=1e-12)
    # δ → ∞: Newton's step −J⁻¹ f, here within the box
    assert transient_step(J, f, np.inf, max_step) == pytest.approx(-f / np.diag(J), rel=1e-12)
    # a step beyond MAX_REACH max_steps is scaled down to it, its direction kept
    long = transient_step(J, np.array([3e3, 0.0]), np.inf, max_step)
    assert np.max(np.abs(long / max_step)) == pytest.approx(transient.MAX_REACH)
    assert long[1] == 0.0 and long[0] < 0.0


def test_pseudo_time_step_switched_evolution_relaxation():
    # SER: δ · merit / merit_new, at least MIN_GROWTH × where the merit fell
    assert pseudo_time_step(1.0, 10.0, 2.0) == pytest.approx(5.0)
    assert pseudo_time_step(1.0, 10.0, 9.0) == pytest.approx(transient.MIN_GROWTH)
    assert pseudo_time_step(1.0, 10.0, 1e-3) == pytest.approx(transient.MAX_GROWTH)
    assert pseudo_time_step(1.0, 10.0, 20.0) == pytest.approx(0.5)  # a rise shrinks δ
    assert pseudo_time_step(1.0, 10.0, 1e4) == pytest.approx(transient.MIN_RATIO)


def test_a_pose_that_cannot_be_evaluated_shortens_the_step_and_never_raises():
    """f = F (u − 3) with no pose for 1.2 < u < 2.5, a gap wider than MAX_REACH max_steps:
    no step from u ≤ 1.2 can jump it, so each step into it divides δ by FAILED_SHRINK
    and the iteration limit ends the solve with its best iterate and the reason."""

    def gapped(alpha):
        u = alpha[0] / L
        return None if 1.2 < u < 2.5 else np.array([F * (u - 3.0)])

    ctx = ClosedFormResidual(gapped)
    settings = FDKSettings(tolerance=TOLERANCE, jacobian="central", max_step=(L,), perturbation=(1e-9,),
                           restart=False, max_iterations=30)
    sol = solve_transient(ctx, 0, np.array([0.0]), Workspace(), settings)
    assert not sol.converged and sol.reason == "iteration_limit" and "max |f^FDK|" in sol.message
    assert sol.best.ok and sol.best.alpha[0] > 0.0  # it moved towards the root, up to the gap
    assert sol.best.alpha[0] / L <= 1.2
    assert sol.best.norm == pytest.approx(F * (3.0 - sol.best.alpha[0] / L))
    assert any(1.2 < a[0] / L < 2.5 for a in ctx.alphas)  # the gap was met
    assert sol.evaluations == ctx.calls
