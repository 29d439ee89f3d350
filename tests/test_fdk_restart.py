"""FDK restarts (fdk/newton.py, solve_frame_from): a Newton solve globalised by a line
search on ‖f^FDK‖₂ stalls at a kink of a piecewise-smooth f^FDK(α) that is a local
minimiser of ‖f‖ but not a root (the recruitment's active-set switch of the wide
realistic chewing, docs/fdk.md "Restarts"); a restart from the DOFs' initial α finds the
root.

The closed-form residual below has the same structure in one DOF: continuous, piecewise
linear, slopes +1 / −1 on either side of a kink at α = 0 where f = 0.5 N (the switch),
and a third piece of slope 2 for α < −1 m whose root is α* = −1.75 m exactly.
"""


import numpy as np
import pytest

from openfdk.fdk.newton import solve_frame, solve_frame_from
from openfdk.fdk.settings import FDKSettings

from fdk_stand_ins import ClosedFormResidual, Workspace

ROOT = -1.75  # 1.5 + 2 (α + 1) = 0


def _f(alpha):
    """f(α) N: 0.5 + |α| for α ≥ −1, 1.5 + 2 (α + 1) below (continuous at −1)."""
    a = alpha[0]
    return np.array([0.5 + abs(a) if a >= -1.0 else 1.5 + 2.0 * (a + 1.0)])


def _KinkedResidual():
    """The stand-in context of the closed-form f."""
    return ClosedFormResidual(_f)


SETTINGS = FDKSettings(tolerance=1e-9, jacobian="central", reuse_jacobian=False, max_step=(10.0,),
                       perturbation=(1e-6,))


def test_newton_with_line_search_stalls_at_the_kink_which_is_not_a_root():
    ctx = _KinkedResidual()
    sol = solve_frame(ctx, 0, np.array([0.3]), Workspace(), SETTINGS)
    assert not sol.converged and sol.reason in ("line_search", "singular")
    # the stall is at the kink, |f| = 0.5 N at α = 0 (to the golden section's resolution),
    # 1.75 m from the root
    assert sol.best.norm == pytest.approx(0.5, abs=1e-2)
    assert abs(sol.best.alpha[0]) < 1e-2


def test_restart_from_the_initial_alpha_finds_the_closed_form_root():
    ctx = _KinkedResidual()
    starts = [np.array([0.3]), np.array([0.2]), np.array([-1.5])]  # warm, previous, initial
    sol = solve_frame_from(ctx, 0, starts, Workspace(), SETTINGS)
    assert sol.converged and sol.reason == "converged" and sol.message == ""
    assert sol.best.alpha[0] == pytest.approx(ROOT, abs=1e-9)
    assert sol.restarts == 2  # the previous frame's α lies in the kink's basin too
    assert sol.evaluations == ctx.calls  # totals over all starts


def test_restart_setting_off_and_a_frame_that_converges_keep_the_single_solve():
    ctx = _KinkedResidual()
    off = FDKSettings(**{**SETTINGS.__dict__, "restart": False})
    sol = solve_frame_from(ctx, 0, [np.array([0.3]), np.array([-1.5])], Workspace(), off)
    assert not sol.converged and sol.restarts == 0
    ctx = _KinkedResidual()
    sol = solve_frame_from(ctx, 0, [np.array([-1.2]), np.array([0.3])], Workspace(), SETTINGS)
    assert sol.converged and sol.restarts == 0 and sol.best.alpha[0] == pytest.approx(ROOT, abs=1e-9)


def test_no_start_converges_reports_the_best_iterate_with_the_first_reason():
    ctx = _KinkedResidual()
    sol = solve_frame_from(ctx, 0, [np.array([0.3]), np.array([0.3]), np.array([0.1])], Workspace(), SETTINGS)
    assert not sol.converged and sol.restarts == 1  # the repeated start is skipped
    assert "1 restart(s) from other starting α did not converge either" in sol.message
    assert sol.best.norm == pytest.approx(0.5, abs=1e-2)


def test_restart_setting_is_read_from_the_model_file(tmp_path):
    from openfdk.fdk.settings import fdk_settings
    from openfdk.io.modelfile import load_model_and_settings

    text = "openfdk: 1\nbodies: {arm: {mass: 1, inertia: [1, 1, 1]}}\n"
    (tmp_path / "on.yaml").write_text(text)
    (tmp_path / "off.yaml").write_text(text + "fdk: {restart: false}\n")
    assert fdk_settings(*load_model_and_settings(tmp_path / "on.yaml")).restart is True
    assert fdk_settings(*load_model_and_settings(tmp_path / "off.yaml")).restart is False


def test_scan_starts_reach_a_root_beyond_the_previous_alphas_basin():
    """A fold: the branch the previous frames followed ends, the root left is far away
    (α* = −1.75 m). From the previous α (0.3 m) and the initial α (0.2 m) Newton stalls
    at the kink (0.5 N); the scan starts α_prev ± 2 max_step, ± 4 max_step (max_step
    0.5 m: −0.7, 1.3, −1.7, 2.3, nearest first) reach it from −1.7 m, the first start
    in the slope-2 piece, at the fourth restart (0.2, −0.7, 1.3, −1.7)."""
    from openfdk.fdk.analysis import scan_starts

    starts = scan_starts(np.array([0.3]), (0.5,))
    np.testing.assert_allclose(np.ravel(starts), [-0.7, 1.3, -1.7, 2.3])
    settings = FDKSettings(tolerance=1e-9, jacobian="central", reuse_jacobian=False, max_step=(0.5,),
                           perturbation=(1e-6,))
    ctx = _KinkedResidual()
    without = solve_frame_from(ctx, 0, [np.array([0.3]), np.array([0.2])], Workspace(), settings)
    assert not without.converged
    sol = solve_frame_from(ctx, 0, [np.array([0.3]), np.array([0.2])] + starts, Workspace(), settings)
    assert sol.converged and sol.best.alpha[0] == pytest.approx(ROOT, abs=1e-9)
    assert sol.restarts == 4


def test_scan_starts_move_one_dof_at_a_time():
    """Three DOFs with max_steps 0.5, 0.5, 1 mm: 12 starts, each differing from the
    previous α in one DOF by ±2 or ±4 max_steps, the ±2 ones first."""
    from openfdk.fdk.analysis import scan_starts

    prev, step = np.array([1e-3, -2e-3, 0.0]), np.array([0.5e-3, 0.5e-3, 1e-3])
    starts = np.array(scan_starts(prev, step))
    assert starts.shape == (12, 3)
    d = starts - prev
    assert np.all(np.count_nonzero(d, axis=1) == 1)
    multiples = np.abs(d).sum(axis=1) / step[np.argmax(np.abs(d), axis=1)]
    np.testing.assert_allclose(multiples, [2] * 6 + [4] * 6)


# A residual of two DOFs with no root and a kink, as at DM's stalls (a muscle at its
# recruitment threshold): f(x, y) = (0.5 + |x| + 0.2 y, 2 y − |x|) N. f₂ = 0 needs
# y = |x|/2, and then f₁ = 0.5 + 1.1 |x| > 0; no α has max |f| below 0.5/1.1 N (at x = 0,
# 0.5 + 0.2 y = −2 y). From (2, 2) the iteration creeps along the kink x = 0, each
# accepted step lowering ‖f‖ by a sliver.
def _kink_without_root(alpha):
    x, y = alpha
    return np.array([0.5 + abs(x) + 0.2 * y, 2.0 * y - abs(x)])


NO_ROOT_BOUND = 0.5 / 1.1  # N, the least max |f| over all α


def test_a_stalled_start_stops_as_no_progress_long_before_the_iteration_limit(monkeypatch):
    """MINPACK's progress tests (newton.SLOW_JACOBIANS, SLOW_STEPS): the start stops with
    reason ``no_progress`` after far fewer than its 200 iterations. With the tests off it
    creeps for all 200 and ends within 1e-3 N of where the tests stopped it."""
    from openfdk.fdk import newton

    settings = FDKSettings(tolerance=1e-9, max_iterations=200, jacobian="central", reuse_jacobian=False,
                           max_step=(1.0, 1.0), perturbation=(1e-6, 1e-6))
    sol = solve_frame(ClosedFormResidual(_kink_without_root, ("x", "y")), 0, np.array([2.0, 2.0]), Workspace(),
                      settings)
    assert not sol.converged and sol.reason == "no_progress"
    assert sol.message.startswith("no progress at iteration")
    assert sol.iterations < 40
    assert sol.best.norm >= NO_ROOT_BOUND
    monkeypatch.setattr(newton, "SLOW_JACOBIANS", 10 ** 9)
    monkeypatch.setattr(newton, "SLOW_STEPS", 10 ** 9)
    off = solve_frame(ClosedFormResidual(_kink_without_root, ("x", "y")), 0, np.array([2.0, 2.0]), Workspace(),
                      settings)
    assert not off.converged and off.reason == "iteration_limit" and off.iterations == 200
    assert off.evaluations > 5 * sol.evaluations
    assert off.best.norm >= NO_ROOT_BOUND
    assert sol.best.norm - off.best.norm < 1e-3  # the 180 more iterations gained nothing


def test_a_walk_of_full_boxes_towards_a_far_root_is_progress():
    """A linear spring whose root is 60 max_steps away: each step crosses the whole box and
    lowers ‖f‖² by only 2/60 or so, less than PROGRESS_JACOBIAN, yet the walk converges to
    the closed-form root α* = F/k; it is not stopped as a stall."""
    from openfdk.fdk.newton import PROGRESS_JACOBIAN, SLOW_JACOBIANS

    k, F = 1e4, 600.0  # N/m, N: the root 60 mm away, max_step 1 mm

    settings = FDKSettings(tolerance=1e-6, max_iterations=100, jacobian="central", reuse_jacobian=False,
                           max_step=(1e-3,), perturbation=(1e-9,), restart=False)
    ctx = ClosedFormResidual(lambda a: np.array([k * a[0] - F]))
    sol = solve_frame(ctx, 0, np.array([0.0]), Workspace(), settings)
    assert sol.converged
    assert sol.best.alpha[0] == pytest.approx(F / k, abs=1e-9)
    assert sol.iterations >= 60  # one box per step
    # the iterates (not the central differences' ±1e-9 m points): each step of the walk
    # lowered ‖f‖² by less than PROGRESS_JACOBIAN, for more than SLOW_JACOBIANS steps
    iterates = np.unique(np.round([a[0] for a in ctx.alphas], 7))  # 0, 1, 2 … mm
    f = np.abs(k * np.array(iterates) - F)
    reductions = 1 - (f[1:] / f[:-1]) ** 2
    assert np.sum(reductions[:SLOW_JACOBIANS + 1] < PROGRESS_JACOBIAN) == SLOW_JACOBIANS + 1
