"""The staged frame pipeline (model/framedata.py): one FDK residual evaluation assembles
Φ_q̂ exactly once at each pose it visits, and the analytic FDK Jacobian reads the
stages' Φ_q̂ instead of evaluating it again at the solved pose."""

from collections import Counter

import numpy as np
import pytest

from openfdk.fdk.analysis import fdk_context
from openfdk.fdk.jacobian import analytic_jacobian
from openfdk.fdk.residual import FrameWorkspace
from openfdk.forces.elements import add_spring
from openfdk.analysis.jobs import load_trajectories
from openfdk.kinematics.system import ConstraintSystem
from openfdk.model.builder import ModelBuilder
from openfdk.io.modelfile import load_model_and_settings

from models import write_jaw_files


@pytest.fixture
def phi_q_counts(monkeypatch):
    """Counter of Φ_q̂ assemblies (ConstraintSystem.evaluate with order ≥ 1) per pose
    (q bytes, t)."""
    counts = Counter()
    original = ConstraintSystem.evaluate

    def counting(self, state, t, alpha=None, order=1):
        if order >= 1:
            counts[(state.get_q().tobytes(), float(t))] += 1
        return original(self, state, t, alpha, order)

    monkeypatch.setattr(ConstraintSystem, "evaluate", counting)
    return counts


def _tracking_fdk_frame(tmp_path):
    """The TMJ FDK context on the synthetic jaw trial, frame k = 3, its warm-start
    workspace and the initial α: (ctx, times (nf,) s, k, ws, alpha (n_fdk,))."""
    write_jaw_files(tmp_path, 8)
    model, settings = load_model_and_settings(tmp_path / "tmj.yaml")
    _, traj = load_trajectories(model, tmp_path / "trial.c3d", settings=settings)
    times = np.asarray(traj.time)
    ctx = fdk_context(model, traj, times, settings=settings)
    state = model.initial_state()
    ctx.tracker.initial_guess(state, ctx.meas[0][0], ctx.meas[0][3])
    k = 3
    ws = FrameWorkspace({j: state for j in ctx.frames_needed(k)})
    alpha = np.array([d.initial for d in model.fdk_dofs])
    return ctx, times, k, ws, alpha


def test_tracking_fdk_residual_assembles_phi_q_once_per_pose(tmp_path, phi_q_counts):
    ctx, times, k, ws, alpha = _tracking_fdk_frame(tmp_path)
    phi_q_counts.clear()
    ev = ctx.evaluate(k, alpha, ws)
    assert ev.ok and np.all(np.isfinite(ev.f_fdk))
    solved = (ev.state.get_q().tobytes(), float(times[k]))
    # the rows at the solved pose come from the velocity kernel's one evaluation (counted
    # with the kernels in the test below); the Gauss–Newton iterates at t − Δt, t, t + Δt
    # are evaluated inside the compiled kernel (kinematics/frame_kernels.py), once per
    # iterate; in Python at most the start pose (once per visibility pattern, observability)
    assert phi_q_counts[solved] == 0
    assert {t for _, t in phi_q_counts} <= set(times[k - 1 : k + 2])
    assert max(phi_q_counts.values(), default=0) <= 1, phi_q_counts.most_common(3)
    # the analytic Jacobian reads Φ_q̂ at the solved pose from the stages, and the tracking
    # Hessian's perturbed poses are evaluated inside its compiled kernel
    # (kinematics/tracking_hessian.py): no assembly through Python at any pose
    phi_q_counts.clear()
    ctx.tracking_curvature = None
    J, _, msg = analytic_jacobian(ctx, k, ev)
    assert msg == "" and np.linalg.norm(J) > 1.0
    assert sum(phi_q_counts.values()) == 0, phi_q_counts.most_common(3)
    S, t_S = ctx.tracking_curvature  # the Hessian was differenced (its second-order terms kept)
    assert t_S == float(times[k]) and np.abs(S).max() > 0.0


def _block_on_spring():
    """A 2 kg block on a vertical rail held by a 500 N/m spring on its height, the FDK
    DOF (determinate): (model, FDK context at t = 0, workspace)."""
    b = ModelBuilder("spring", gravity=(0, 0, -9.81))
    b.add_body("block", 2.0, [1e-3] * 3)
    b.add_joint("rail", "prismatic", parent="ground.origin", child="block.origin")
    b.add_measure("z", b._select(b.vector("ground.origin", "block.origin"), [2]))
    b.add_fdk_dof("height", "z", initial=0.0, max_step=0.1)
    add_spring(b, "spring", "z", 500.0)
    model = b.build()
    ctx = fdk_context(model, None, np.array([0.0]))
    return model, ctx, FrameWorkspace({0: model.initial_state()})


def test_determinate_fdk_residual_assembles_phi_q_once_per_pose(phi_q_counts):
    model, ctx, ws = _block_on_spring()
    ev = ctx.evaluate(0, np.array([-0.01]), ws)
    # weight m g balanced by the spring k α and the FDK residual force: f = −m g − k α
    assert ev.ok
    np.testing.assert_allclose(ev.f_fdk, [2.0 * 9.81 - 500.0 * 0.01], rtol=1e-9)
    assert max(phi_q_counts.values(), default=0) <= 1  # Φ_q̂ from the Newton kernel's check


def test_tracking_and_inverse_dynamics_run_assembles_phi_q_once_per_pose(tmp_path, phi_q_counts):
    """openfdk run on the POP jaw (tracking + recruitment in one pass): the equilibrium
    takes Φ_q̂ from the kinematic position stage."""
    from openfdk.analysis.run import run_trial

    write_jaw_files(tmp_path, 8)
    model, settings = load_model_and_settings(tmp_path / "pop.yaml")
    _, traj = load_trajectories(model, tmp_path / "trial.c3d", settings=settings)
    kin, dyn, _ = run_trial(model, traj, np.asarray(traj.time), settings=settings)
    assert kin.converged.all() and dyn.converged.all()
    assert max(phi_q_counts.values(), default=0) <= 1, phi_q_counts.most_common(3)


@pytest.fixture
def row_evaluations(monkeypatch):
    """Counter of evaluations of the constraint rows (any order) per pose (the bytes of
    p_WB and R_WB), in Python (ConstraintSystem.evaluate / bias / jacobian) and in the
    compiled kernels the FDK residual calls: the rate kernels evaluate the rows once at
    the pose they are given; the Newton kernel's convergence check once at the solved
    pose (counted after the call, at the pose it leaves)."""
    import openfdk.kinematics.determinate as det
    import openfdk.kinematics.tracking as trk

    counts = Counter()

    def key(p_WB, R_WB):
        return p_WB.tobytes() + R_WB.tobytes()

    for name in ("evaluate", "bias", "jacobian"):
        original = getattr(ConstraintSystem, name)

        def counting(self, state, *args, _original=original, **kw):
            counts[key(state.p_WB, state.R_WB)] += 1
            return _original(self, state, *args, **kw)

        monkeypatch.setattr(ConstraintSystem, name, counting)

    def rates(kernel, evaluations):
        def counting(*args):
            counts[key(args[9], args[10])] += evaluations  # (p_WB, R_WB) after the program
            return kernel(*args)
        return counting

    monkeypatch.setattr(det, "determinate_rates", rates(det.determinate_rates, 2))
    monkeypatch.setattr(det, "rates_from_jacobian", rates(det.rates_from_jacobian, 1))
    monkeypatch.setattr(trk, "tracking_rates", rates(trk.tracking_rates, 1))
    newton = det.newton_positions

    def counting_newton(*args):
        out = newton(*args)
        if out[0] == det.OK:
            counts[key(args[9], args[11])] += 1  # the check at the solved pose
        return out

    monkeypatch.setattr(det, "newton_positions", counting_newton)
    return counts


def test_tracking_fdk_evaluation_evaluates_rows_once_at_the_solved_pose(tmp_path, row_evaluations):
    """Whole tracking FDK residual evaluation, kernels included: the rows at the solved
    pose of frame k are evaluated once (the velocity kernel's order-2 evaluation gives
    Φ, Φ_q̂ and the bias); Φ_q̂ read from it equals a fresh evaluation."""
    ctx, times, k, ws, alpha = _tracking_fdk_frame(tmp_path)
    row_evaluations.clear()
    ev = ctx.evaluate(k, alpha, ws)
    assert ev.ok
    solved = ev.state.p_WB.tobytes() + ev.state.R_WB.tobytes()
    assert row_evaluations[solved] == 1, row_evaluations.most_common(3)
    assert max(row_evaluations.values()) == 1
    Phi, A, nu, _ = ctx.system.evaluate(ev.state, times[k], alpha)  # a fresh evaluation
    assert np.abs(A).max() > 0.1
    np.testing.assert_allclose(ev.data.Phi_q, A, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ev.data.Phi, Phi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ev.data.nu, nu, rtol=0, atol=1e-12)


def test_determinate_fdk_evaluation_evaluates_rows_twice_at_the_solved_pose(row_evaluations):
    """Determinate FDK, kernels included: order 1 at the solved pose (the Newton check,
    kept as the position stage) and order 2 for γ once v is known; nothing else."""
    model, ctx, ws = _block_on_spring()
    row_evaluations.clear()
    ev = ctx.evaluate(0, np.array([-0.01]), ws)
    assert ev.ok
    np.testing.assert_allclose(ev.f_fdk, [2.0 * 9.81 - 500.0 * 0.01], rtol=1e-9)
    solved = ev.state.p_WB.tobytes() + ev.state.R_WB.tobytes()
    assert row_evaluations[solved] == 2, row_evaluations.most_common(3)
    assert sum(row_evaluations.values()) == 2


def test_tracking_evaluates_the_markers_once_per_solved_pose(tmp_path, monkeypatch):
    """Marker tracking on the POP jaw: outside the Gauss–Newton kernel, the markers are
    evaluated once per frame, at its solved pose (δ of Eq. 7 and Ψ_q̂ of Eqs. 8–10 both
    come from that evaluation), apart from the one-off observability check."""
    from openfdk.kinematics.analysis import run_tracking
    from openfdk.model.constraints import MarkerSet

    write_jaw_files(tmp_path, 8)
    model, _ = load_model_and_settings(tmp_path / "pop.yaml")
    _, traj = load_trajectories(model, tmp_path / "trial.c3d")
    counts = Counter()
    for name in ("evaluate", "positions"):
        original = getattr(MarkerSet, name)

        def counting(self, state, *args, _original=original, **kw):
            counts[(state.p_WB.tobytes(), state.R_WB.tobytes())] += 1
            return _original(self, state, *args, **kw)

        monkeypatch.setattr(MarkerSet, name, counting)
    kin = run_tracking(model, traj)
    assert kin.converged.all()
    n = len(kin.time)
    assert n <= sum(counts.values()) <= n + 1  # + the observability check, once per pattern
    assert max(counts.values()) == 1, counts.most_common(2)
