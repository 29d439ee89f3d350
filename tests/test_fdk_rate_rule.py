"""The rate rule of the FDK Newton iteration (openfdk.fdk.newton, BROYDEN_RATE): near the
root a Broyden-updated Jacobian divides max |f^FDK| by at most BROYDEN_RATE per step,
because f^FDK has kinks there (a muscle entering the recruitment's active set, the
contact patch's edge), so a fresh J is taken when that bound says the next step would not
reach the tolerance.

The frame below is one DOF with a kink at κ, the root r just beyond it:
    f(α) = k₂ (α − r)                     for α ≥ κ,
    f(α) = k₂ (κ − r) + k₁ (α − κ)        for α < κ  (continuous at κ).
From α₀ on the stiff side with the carried J = k₁ (the previous frame's), Newton's first
step lands at α₁ = κ + (k₂/k₁)(r − κ), between the kink and the root, where
f₁ = −k₂ (r − κ)(1 − k₂/k₁) exactly. With |f₁|² / |f₀| below the tolerance the quadratic
estimate says one more step with the updated J converges; but Broyden's update is the
secant through α₀ and α₁, mostly k₁'s side, and its step leaves f₂ = f₁ (1 − k₂/J₁),
about half of f₁. A fresh J at α₁ is k₂ itself, and its step lands on r.
"""

import numpy as np
import pytest

import openfdk.fdk.newton as newton
from openfdk.fdk.newton import BROYDEN_RATE, solve_frame
from openfdk.fdk.settings import FDKSettings

from fdk_stand_ins import ClosedFormResidual, Workspace

K1, K2 = 2e5, 1e5  # N/m, the slopes before and after the kink
KINK = 0.0  # m
ROOT = KINK + 4e-6  # m
ALPHA0 = KINK - 5e-4  # m
TOLERANCE = 1e-3  # N


def _kinked(alpha):
    a = alpha[0]
    return np.array([K2 * (a - ROOT) if a >= KINK else K2 * (KINK - ROOT) + K1 * (a - KINK)])


SETTINGS = FDKSettings(tolerance=TOLERANCE, jacobian="central", reuse_jacobian=True, max_step=(1e-3,),
                       perturbation=(1e-9,), restart=False)


def _solve():
    ctx = ClosedFormResidual(_kinked, ("normal",))
    return solve_frame(ctx, 0, np.array([ALPHA0]), Workspace(), SETTINGS, jacobian=np.array([[K1]])), ctx


def test_the_frame_is_where_the_bound_decides():
    f0 = abs(_kinked([ALPHA0])[0])
    alpha1 = KINK + K2 / K1 * (ROOT - KINK)
    f1 = abs(_kinked([alpha1])[0])
    assert f1 == pytest.approx(K2 * (ROOT - KINK) * (1 - K2 / K1))
    assert f1 * f1 / f0 < TOLERANCE <= f1 / BROYDEN_RATE  # the quadratic estimate says done; the bound does not


def test_a_fresh_jacobian_after_the_first_step_lands_on_the_root(monkeypatch):
    bounded, ctx = _solve()
    assert bounded.converged
    assert bounded.best.alpha[0] == pytest.approx(ROOT, abs=TOLERANCE / K2)
    # Newton's step with the carried J, then one with a fresh J (k₂): two steps
    assert bounded.iterations == 2 and bounded.jacobians == 1
    assert ctx.alphas[1][0] == pytest.approx(KINK + K2 / K1 * (ROOT - KINK), rel=1e-9)
    # without the bound the secant step leaves about half of f₁ and a third step is needed
    monkeypatch.setattr(newton, "BROYDEN_RATE", np.inf)
    unbounded, ctx = _solve()
    assert unbounded.converged and unbounded.iterations == 3
    alpha1, alpha2 = ctx.alphas[1][0], ctx.alphas[2][0]
    J1 = (_kinked([alpha1])[0] - _kinked([ALPHA0])[0]) / (alpha1 - ALPHA0)  # Broyden's secant
    f1 = _kinked([alpha1])[0]
    assert _kinked([alpha2])[0] == pytest.approx(f1 * (1 - K2 / J1), rel=1e-6)
    assert abs(_kinked([alpha2])[0]) > 0.4 * abs(f1)
    assert unbounded.evaluations > bounded.evaluations
