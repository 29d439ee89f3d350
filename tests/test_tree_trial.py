"""The compiled trial of a coordinate-driven tree (openfdk.analysis.tree_trial) on the
full-body model (oblique ankle and subtalar axes, spline-coupled knee translations,
offset mtp frames) with two ground reactions:

* against the frame-by-frame formulation of the same run — Newton on Φ = 0, Φ_q̂ v = ν
  and Φ_q̂ v̇ = γ (Eqs. 2–3), C and d assembled and solved by the recruitment layer —
  which shares none of the forward kinematics;
* its velocities and accelerations against central differences in time of its own
  poses and velocities (the chain rule through the axes' functions, independently of
  the constraint rows).
"""

import numpy as np
import pytest

from openfdk.analysis import run as run_module
from openfdk.analysis.run import run_trial
from openfdk.bench.full_body_id import write_inputs
from openfdk.io.modelfile import load_model_and_settings
from openfdk.io.opensim.overlay import register
from openfdk.io.storage import read_storage
from openfdk.kinematics.system import ConstraintSystem
from openfdk.kinematics.tree_kinematics import tree_forward, tree_plan

N_FRAMES = 25


@pytest.fixture(scope="module")
def full_body(tmp_path_factory):
    folder = tmp_path_factory.mktemp("full_body")
    model_path, motion, loads = write_inputs(folder, quick=True)
    register(model_path, external_loads=loads, motion=motion)
    model, settings = load_model_and_settings(model_path)
    times = np.asarray(read_storage(motion)[0], float)[10 : 10 + N_FRAMES]
    return model, settings, times


def test_compiled_trial_equals_the_frame_by_frame_run(full_body, monkeypatch):
    model, settings, times = full_body
    kin, dyn, _ = run_trial(model, None, times, settings=settings)
    assert np.all(kin.iterations == 0) and np.all(kin.converged) and np.all(dyn.converged)  # the compiled path
    monkeypatch.setattr(run_module, "tree_trial", lambda *args: (None, "the test asks for the trial driver"))
    kin_ref, dyn_ref, _ = run_trial(model, None, times, settings=settings)
    assert np.all(kin_ref.iterations > 0) and np.all(dyn_ref.converged)  # Newton's path
    assert np.max(np.abs(kin.q - kin_ref.q)) < 1e-9  # m and quaternions (the same hemisphere)
    for ours, ref in ((kin.v, kin_ref.v), (kin.vdot, kin_ref.vdot)):
        assert np.max(np.abs(ours - ref)) < 1e-8 * np.max(np.abs(ref))
    scale = np.max(np.abs(dyn_ref.forces))
    assert scale > 100.0  # body weight carried by the joints
    assert np.max(np.abs(dyn.forces - dyn_ref.forces)) < 1e-8 * scale
    assert dyn.column_names == dyn_ref.column_names
    assert np.max(np.abs(kin.constraint_violation)) < 1e-12
    # the measured loads as applied (forces.csv's <load>.external_*), from the loads' samples
    # and the poses at once, as the frame-by-frame path records them from its kernel
    ours, ref = dyn.extra["columns"], dyn_ref.extra["columns"]
    loads = sorted(k for k in ref if ".external_" in k)
    assert len(loads) == 6 * len(model.external_loads) and sorted(k for k in ours if ".external_" in k) == loads
    for key in loads:
        np.testing.assert_allclose(ours[key], ref[key], rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(ref[key]))),
                                   err_msg=key)


def _forward(plan, system, state, t):
    f, df, ddf = (np.array(x) for x in system.targets(t))
    vdot = np.zeros(state.n_coords)
    tree_forward(*plan.args, state.column, f, df, ddf, state.p_WB, state.quat_WB, state.R_WB, state.w_BB,
                 state.v_WB, vdot)
    return state.p_WB.copy(), state.R_WB.copy(), state.v_WB.copy(), state.w_BB.copy(), vdot


def test_forward_kinematics_rates_are_the_time_derivatives_of_its_poses(full_body):
    model, _, times = full_body
    system = ConstraintSystem(model)
    plan, why = tree_plan(model, system)
    assert plan is not None, why
    state = model.initial_state()
    t, h = float(times[N_FRAMES // 2]) + 0.003, 1e-5  # between samples of the motion's splines
    p0, R0, v0, w0, a0 = _forward(plan, system, state, t)
    pm, Rm, vm, wm, _ = _forward(plan, system, state, t - h)
    pp, Rp, vp, wp, _ = _forward(plan, system, state, t + h)
    assert np.max(np.abs(v0)) > 0.5 and np.max(np.abs(w0)) > 0.5  # a moving pose
    moving = state.moving
    for i in moving:
        c = state.column[i]
        assert np.allclose((pp[i] - pm[i]) / (2 * h), v0[i], atol=1e-7)
        # ω̃' = Rᵀ Ṙ
        W = R0[i].T @ (Rp[i] - Rm[i]) / (2 * h)
        assert np.allclose([W[2, 1], W[0, 2], W[1, 0]], w0[i], atol=1e-6)
        assert np.allclose((vp[i] - vm[i]) / (2 * h), a0[c : c + 3], atol=1e-5)
        assert np.allclose((wp[i] - wm[i]) / (2 * h), a0[c + 3 : c + 6], atol=1e-5)
    assert np.max(np.abs(a0)) > 1.0


def test_models_outside_the_tree_path_say_why(full_body):
    from dataclasses import replace

    model, _, _ = full_body
    # without its joint records the rows are no longer known to be a SpatialTransform's
    plan, why = tree_plan(replace(model, joints=()), ConstraintSystem(model))
    assert plan is None and "joint" in why


def test_loads_given_in_the_body_are_recorded_in_the_world_as_the_kernel_applies_them(full_body, monkeypatch):
    """A load whose force and point are given in its body's frame F (OpenSim's
    force_expressed_in_body = the body): the compiled trial records F_W = R_WB R_BF F_F
    and p_W = r_WB + R_WB p_BF + R_WB R_BF p_F from all poses at once; the frame-by-frame
    path takes them from the kernel that applies the load."""
    from dataclasses import replace

    from openfdk.numerics.spatial import rotation_matrix_xyz

    model, settings, times = full_body
    R_BF = rotation_matrix_xyz([0.3, -0.5, 1.1])
    loads = tuple(replace(load, force_frame="body", point_frame="body", p_BF=np.array([0.01, -0.02, 0.03]),
                          R_BF=R_BF) for load in model.external_loads)
    model = replace(model, external_loads=loads)
    times = times[:6]
    kin, dyn, _ = run_trial(model, None, times, settings=settings)
    assert np.all(kin.iterations == 0)  # the compiled path
    monkeypatch.setattr(run_module, "tree_trial", lambda *args: (None, "the test asks for the trial driver"))
    _, dyn_ref, _ = run_trial(model, None, times, settings=settings)
    ours, ref = dyn.extra["columns"], dyn_ref.extra["columns"]
    keys = sorted(k for k in ref if ".external_" in k)
    assert len(keys) == 12
    for key in keys:
        np.testing.assert_allclose(ours[key], ref[key], rtol=0, atol=1e-9 * max(1.0, np.max(np.abs(ref[key]))),
                                   err_msg=key)
    # rotated: the world components differ from the samples as given
    F_x = ours[f"{loads[0].name}.external_Fx_N"]
    assert np.max(np.abs(F_x - np.array([loads[0].force.derivatives(t)[0][0] for t in times]))) > 1.0
