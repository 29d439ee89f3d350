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
from openfdk.jobs import load_trajectories
from openfdk.kinematics.system import ConstraintSystem
from openfdk.model.builder import ModelBuilder
from openfdk.io.modelfile import load_model

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


def test_tracking_fdk_residual_assembles_phi_q_once_per_pose(tmp_path, phi_q_counts):
    write_jaw_files(tmp_path, 8)
    model = load_model(tmp_path / "tmj.yaml")
    _, traj = load_trajectories(model, tmp_path / "trial.c3d")
    times = np.asarray(traj.time)
    ctx = fdk_context(model, traj, times)
    state = model.initial_state()
    ctx.tracker.initial_guess(state, ctx.meas[0][0], ctx.meas[0][3])
    k = 3
    ws = FrameWorkspace({j: state for j in ctx.frames_needed(k)})
    alpha = np.array([d.initial for d in model.fdk_dofs])
    phi_q_counts.clear()
    ev = ctx.evaluate(k, alpha, ws)
    assert ev.ok and np.all(np.isfinite(ev.f_fdk))
    solved = (ev.state.get_q().tobytes(), float(times[k]))
    assert phi_q_counts[solved] == 1  # the position stage at the solved pose
    # the Gauss–Newton iterates at t − Δt, t, t + Δt are evaluated inside the compiled
    # kernel (kinematics/frame_kernels.py), once per iterate; in Python, only the solved
    # pose (and the start pose, once per visibility pattern, for observability)
    assert {t for _, t in phi_q_counts} <= set(times[k - 1 : k + 2])
    assert max(phi_q_counts.values()) == 1, phi_q_counts.most_common(3)
    # the analytic Jacobian reads Φ_q̂ at the solved pose from the stages
    phi_q_counts.clear()
    J, _, msg = analytic_jacobian(ctx, k, ev)
    assert msg == "" and np.linalg.norm(J) > 1.0
    assert phi_q_counts[solved] == 0 and len(phi_q_counts) > 0  # only at perturbed poses
    assert max(phi_q_counts.values()) == 1


def test_determinate_fdk_residual_assembles_phi_q_once_per_pose(phi_q_counts):
    b = ModelBuilder("spring", gravity=(0, 0, -9.81))
    b.add_body("block", 2.0, [1e-3] * 3)
    b.add_joint("rail", "prismatic", parent="ground.origin", child="block.origin")
    b.add_measure("z", b._select(b.vector("ground.origin", "block.origin"), [2]))
    b.add_fdk_dof("height", "z", initial=0.0, max_step=0.1)
    add_spring(b, "spring", "z", 500.0)
    model = b.build()
    ctx = fdk_context(model, None, np.array([0.0]))
    ws = FrameWorkspace({0: model.initial_state()})
    ev = ctx.evaluate(0, np.array([-0.01]), ws)
    # weight m g balanced by the spring k α and the FDK residual force: f = −m g − k α
    assert ev.ok
    np.testing.assert_allclose(ev.f_fdk, [2.0 * 9.81 - 500.0 * 0.01], rtol=1e-9)
    assert phi_q_counts and max(phi_q_counts.values()) == 1


def test_tracking_and_inverse_dynamics_run_assembles_phi_q_once_per_pose(tmp_path, phi_q_counts):
    """openfdk run on the POP jaw (tracking + recruitment in one pass): the equilibrium
    takes Φ_q̂ from the kinematic position stage."""
    from openfdk.analysis.run import run_trial

    write_jaw_files(tmp_path, 8)
    model = load_model(tmp_path / "pop.yaml")
    _, traj = load_trajectories(model, tmp_path / "trial.c3d")
    kin, dyn, _ = run_trial(model, traj, np.asarray(traj.time))
    assert kin.converged.all() and dyn.converged.all()
    assert len(phi_q_counts) >= 8 and max(phi_q_counts.values()) == 1, phi_q_counts.most_common(3)
