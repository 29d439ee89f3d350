"""Powell's dogleg step in the max_step box (openfdk.fdk.trust_region.dogleg_step), against
its definition: the Newton step inside the box, the Cauchy point found by a brute-force
search along steepest descent, and the box boundary."""

import numpy as np

from openfdk.fdk.trust_region import dogleg_step

MAX_STEP = np.array([1e-3, 1e-3, 0.05])  # m, m, rad


def _model(J, f, p):
    return float(np.linalg.norm(f + J @ p))


def _cauchy_by_search(J, f):
    """The minimiser of ‖f + J p‖ along p = −t g, g = J_sᵀ f in the box-scaled variables
    (p = max_step ⊙ p_s), by a fine search on t."""
    J_s = J * MAX_STEP[None, :]
    g = J_s.T @ f
    ts = np.linspace(0, 4 * (g @ g) / np.sum((J_s @ g) ** 2), 400001)
    values = np.linalg.norm(f[None, :] - ts[:, None] * (J_s @ g)[None, :], axis=1)
    return -ts[int(np.argmin(values))] * g * MAX_STEP


def test_inside_the_box_the_newton_step_is_unchanged():
    J = np.diag([5e4, 6e4, 30.0]) + 1e3 * np.ones((3, 3))
    f = np.array([10.0, -20.0, 0.5])
    p_N = np.linalg.solve(J, -f)
    assert np.all(np.abs(p_N) <= MAX_STEP)
    np.testing.assert_array_equal(dogleg_step(J, f, p_N, MAX_STEP), p_N)


def test_a_long_newton_step_along_a_soft_dof_turns_towards_steepest_descent():
    """A nearly singular J (the third DOF almost free, as the DM patella's tilt): the Newton
    step is 40 max_steps long along it. The dogleg step lies on the segment from the
    Cauchy point (found by search, to 1e-5 relative) to the Newton step, on the box
    boundary, and lowers the linear model more than the Newton step scaled down whole."""
    J = np.array([[5e4, 1e3, 10.0], [1e3, 6e4, -5.0], [20.0, -8.0, 0.02]])
    f = np.array([30.0, -12.0, 0.07])
    p_N = np.linalg.solve(J, -f)
    ratio = np.max(np.abs(p_N) / MAX_STEP)
    assert ratio > 10
    step = dogleg_step(J, f, p_N, MAX_STEP)
    p_C = _cauchy_by_search(J, f)
    assert np.max(np.abs(p_C) / MAX_STEP) < 1  # the Cauchy point is inside the box
    np.testing.assert_allclose(np.max(np.abs(step) / MAX_STEP), 1.0, rtol=1e-12)
    # on the segment p_C + τ (p_N − p_C), 0 < τ < 1 (scaled variables)
    a, d = p_C / MAX_STEP, (p_N - p_C) / MAX_STEP
    tau = float(d @ (step / MAX_STEP - a) / (d @ d))
    assert 0 < tau < 1
    np.testing.assert_allclose(step / MAX_STEP, a + tau * d, atol=1e-4)
    assert _model(J, f, step) < _model(J, f, p_N / ratio)
    assert _model(J, f, step) < _model(J, f, np.zeros(3))


def test_a_cauchy_point_outside_the_box_is_cut_at_the_box():
    """When even the steepest-descent minimiser leaves the box, the step is −g (scaled)
    cut at the box: parallel to the searched Cauchy point, ∞-norm 1 in max_steps."""
    J = np.array([[50.0, 1.0, 0.0], [1.0, 60.0, 0.0], [0.0, 0.0, 0.002]])
    f = np.array([3.0, -1.0, 0.05])
    p_N = np.linalg.solve(J, -f)
    step = dogleg_step(J, f, p_N, MAX_STEP)
    p_C = _cauchy_by_search(J, f)
    assert np.max(np.abs(p_C) / MAX_STEP) > 1
    np.testing.assert_allclose(np.max(np.abs(step) / MAX_STEP), 1.0, rtol=1e-12)
    u, v = step / np.linalg.norm(step), p_C / np.linalg.norm(p_C)
    assert u @ v > 1 - 1e-9


def test_with_the_work_as_merit_the_cauchy_point_minimises_the_weighted_model():
    """With weights W = diag(max_step) (the merit ‖W f‖₂, trust_region.work) the Cauchy
    point is the minimiser of ‖W (f + J p)‖ along its own steepest descent, found by
    search; it differs from the unweighted one, whose descent the force rows dominate
    (here the moment's row, in N m, is the soft DOF's)."""
    J = np.array([[50.0, 1.0, 0.0], [1.0, 60.0, 0.0], [0.0, 0.0, 0.002]])
    f = np.array([3.0, -1.0, 0.05])
    W = MAX_STEP
    p_N = np.linalg.solve(J, -f)
    step = dogleg_step(J, f, p_N, MAX_STEP, W)
    p_C = _cauchy_by_search(W[:, None] * J, W * f)  # the same search on W J, W f
    assert np.max(np.abs(p_C) / MAX_STEP) > 1  # cut at the box, as without weights
    u, v = step / np.linalg.norm(step), p_C / np.linalg.norm(p_C)
    assert u @ v > 1 - 1e-9
    plain = dogleg_step(J, f, p_N, MAX_STEP)
    assert plain @ step / np.linalg.norm(plain) / np.linalg.norm(step) < 0.99  # a different direction
    # the weighted step lowers the weighted model more than the unweighted step does
    assert _model(W[:, None] * J, W * f, step) < _model(W[:, None] * J, W * f, plain)
