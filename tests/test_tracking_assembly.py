"""The damped, feasible-path fallback of marker tracking (kinematics/assembly.py).

A large-residual fit with a coordinate the markers see only to rounding — a segment
whose markers lie on its long axis but one, 1 µm off — makes the Gauss–Newton kernel
diverge, as a full-body model's forearm did on the Knee Grand Challenge's gait trial.
The tracking solve must still reach the least-squares optimum, checked against an
independent solver: scipy's least squares over the chain's joint rotation vectors (a
minimal parametrisation, no constraints), from many starts.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from openfdk.kinematics.assembly import assemble
from openfdk.kinematics.system import ConstraintSystem
from openfdk.kinematics.tracking import MarkerTracker
from openfdk.model.builder import ModelBuilder

L = 0.4  # m, segment length
POINTS = {"seg0": [(0.05, 0, 0.1), (0, 0.05, -0.1), (-0.04, 0.02, 0.0)],
          "seg1": [(0.05, 0, 0.1), (0, 0.05, -0.1), (-0.04, 0.02, 0.0)],
          "seg2": [(0, 0, 0.15), (0, 0, -0.15), (1e-6, 0, 0.0)]}


def chain():
    """Three segments hanging from the ground by spherical joints, markers POINTS (m)."""
    b = ModelBuilder("chain")
    for k in range(3):
        b.add_body(f"seg{k}", 1.0, [1e-2, 1e-2, 1e-3], position=(0, 0, -L * k - L / 2))
        b.add_frame(f"seg{k}", "top", (0, 0, L / 2))
        b.add_frame(f"seg{k}", "tip", (0, 0, -L / 2))
    b.add_frame("ground", "pivot", (0, 0, 0))
    b.add_joint("j0", "spherical", "ground.pivot", "seg0.top")
    b.add_joint("j1", "spherical", "seg0.tip", "seg1.top")
    b.add_joint("j2", "spherical", "seg1.tip", "seg2.top")
    for body, pts in POINTS.items():
        for i, p in enumerate(pts):
            b.add_marker(f"{body}_m{i}", body, p)
    return b.build()


def forward(rotvecs):
    """Marker positions (9, 3) m for each segment's rotation vector relative to its parent."""
    R, top, out = np.eye(3), np.zeros(3), []
    for k in range(3):
        R = R @ Rotation.from_rotvec(rotvecs[3 * k: 3 * k + 3]).as_matrix()
        centre = top + R @ np.array([0, 0, -L / 2])
        out += [centre + R @ np.array(p) for p in POINTS[f"seg{k}"]]
        top = top + R @ np.array([0, 0, -L])
    return np.array(out)


def measured(seed=1):
    rng = np.random.default_rng(seed)
    q_true = np.array([0.9, 0.4, 0.2, -1.1, 0.5, 0.3, 0.8, -0.6, 0.4])
    return forward(q_true) + rng.normal(0.0, 0.03, (9, 3))  # 3 cm errors: a large-residual fit


def reference_optimum(x):
    """The smallest ½ Σ |p − x|² over 8 random starts of scipy's least squares."""
    rng = np.random.default_rng(0)
    best = None
    for _ in range(8):
        r = least_squares(lambda q: (forward(q) - x).ravel(), rng.normal(0.0, 1.0, 9), xtol=1e-15, ftol=1e-15,
                          gtol=1e-15)
        best = r if best is None or r.cost < best.cost else best
    return best


def test_tracking_reaches_the_optimum_where_gauss_newton_diverges():
    model, x = chain(), measured()
    visible = np.ones(9, bool)
    tracker = MarkerTracker(ConstraintSystem(model))
    start = model.initial_state()
    # the kernel alone, from the reference pose, does not converge: this case needs the fallback
    alone = tracker._gauss_newton(start.copy(), 0.0, x, visible, None)[0]
    assert not alone.converged
    state = start.copy()
    res, K, lam = tracker.solve_positions(state, 0.0, x, visible)
    assert res.converged and res.residual <= 1e-9
    ref = reference_optimum(x)
    p = tracker.markers.positions(state)
    cost = 0.5 * np.sum((p - x) ** 2)
    assert cost <= ref.cost * (1 + 1e-8)
    assert cost >= ref.cost * (1 - 1e-6)  # the same minimum, not a lower one (the constraints hold)
    np.testing.assert_allclose(p, forward(ref.x), atol=1e-6)
    # the multipliers satisfy stationarity: Ψ_q̂ᵀ W Ψ + Φ_q̂ᵀ λ = 0
    _, J, _ = tracker.markers.evaluate(state, 1)
    _, A, _, _ = tracker.system.evaluate(state, 0.0, None, order=1)
    g = J.T @ (p - x).ravel()
    assert np.abs(g + A.T @ lam).max() <= 1e-6 * np.abs(g).max()
    assert np.abs(lam).max() > 0.0
    assert np.all(np.isfinite(K))


def test_assembly_descends_and_keeps_the_joints():
    model, x = chain(), measured(seed=2)
    tracker = MarkerTracker(ConstraintSystem(model))
    state = model.initial_state()
    p0 = tracker.markers.positions(state)
    ok, iterations, cost, res, mu = assemble(tracker, state, 0.0, x, np.ones(9, bool))
    assert ok and iterations > 1 and mu > 0.0
    assert cost < 0.5 * np.sum((p0 - x) ** 2)
    assert res <= 1e-9
    np.testing.assert_allclose(cost, reference_optimum(x).cost, rtol=1e-6)
    # the joints hold: each segment's top at its parent's tip (independent of the solver's rows)
    R = state.R_WB
    for k in (1, 2):
        tip = state.p_WB[k] + R[k] @ np.array([0, 0, -L / 2])
        top = state.p_WB[k + 1] + R[k + 1] @ np.array([0, 0, L / 2])
        np.testing.assert_allclose(tip, top, atol=1e-9)


def _undefined_once(monkeypatch, tracker, message):
    """The Gauss–Newton kernel's first call stops where a measure is undefined (status
    MEASURE_ERROR, as at a rotation-angle measure's gimbal lock); the program's
    reference then raises ``message``. Later calls run the real kernel."""
    import openfdk.kinematics.tracking as tr

    real, calls = tr.tracking_positions, []

    def kernel(*args):
        calls.append(1)
        if len(calls) == 1:
            return tr.MEASURE_ERROR, 3, np.nan, np.nan, 0, 0
        return real(*args)

    def raise_error(e_node, e_kind, state=None):
        raise FloatingPointError(message)

    monkeypatch.setattr(tr, "tracking_positions", kernel)
    monkeypatch.setattr(tracker.system.program, "raise_error", raise_error)


def test_a_measure_undefined_on_gauss_newton_s_path_hands_over_to_the_damped_solve(monkeypatch):
    """DM's patella reached xyz gimbal lock on a Gauss–Newton path from an FDK trial step,
    and the FloatingPointError ended `openfdk run` with a traceback. Now the kernel's
    failure is a failed Gauss–Newton solve: the damped solve takes over from the same
    warm start and reaches the optimum the plain solve finds (the scipy reference's)."""
    model, x = chain(), measured()
    visible = np.ones(9, bool)
    plain = model.initial_state()
    assert MarkerTracker(ConstraintSystem(model)).solve_positions(plain, 0.0, x, visible)[0].converged
    tracker = MarkerTracker(ConstraintSystem(model))
    _undefined_once(monkeypatch, tracker, "angles 'seg1.angles' (xyz): gimbal lock, the middle angle is 90.0 deg")
    state = model.initial_state()
    res, K, _ = tracker.solve_positions(state, 0.0, x, visible)
    assert res.converged and K is not None
    p = tracker.markers.positions(state)
    np.testing.assert_allclose(p, tracker.markers.positions(plain), atol=1e-6)
    np.testing.assert_allclose(0.5 * np.sum((p - x) ** 2), reference_optimum(x).cost, rtol=1e-6)


def test_a_measure_undefined_on_every_path_is_a_failed_frame_naming_it(monkeypatch):
    """When the damped solve meets it too, the frame fails with the measure's message
    (reason ``failed``) and the pose is left at its warm start: no exception."""
    import openfdk.kinematics.tracking as tr

    model, x = chain(), measured()
    tracker = MarkerTracker(ConstraintSystem(model))
    message = "angles 'seg1.angles' (xyz): gimbal lock, the middle angle is 90.0 deg"
    _undefined_once(monkeypatch, tracker, message)

    def undefined(*args, **kwargs):
        raise FloatingPointError(message)

    monkeypatch.setattr(tr, "assemble", undefined)
    state = model.initial_state()
    start = state.get_q().copy()
    res, K, lam = tracker.solve_positions(state, 0.0, x, np.ones(9, bool))
    assert not res.converged and res.message == message and res.reason.value == "failed"
    assert K is None and lam is None
    np.testing.assert_array_equal(state.get_q(), start)
