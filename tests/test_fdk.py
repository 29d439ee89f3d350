"""Force-dependent kinematics (paper Fig. 1) against closed forms, and the analytic
Jacobian against central differences."""

from dataclasses import replace

import numpy as np
import pytest

from openfdk.contact.sections import add_contact
from openfdk.contact.shapes import flat_patch, sphere_cap
from openfdk.fdk.analysis import run_fdk
from openfdk.fdk.warm_start import HISTORY
from openfdk.forces.elements import add_external_load, add_spring
from openfdk.model.builder import ModelBuilder
from openfdk.model.timefunctions import Constant, SplineThroughData

G = 9.81


def _slider(mass=2.0, stiffness=500.0):
    b = ModelBuilder("spring", gravity=(0, 0, -G))
    b.add_body("block", mass, [1e-3] * 3)
    b.add_joint("rail", "prismatic", parent="ground.origin", child="block.origin")
    b.add_measure("z", b._select(b.vector("ground.origin", "block.origin"), [2]))
    b.add_fdk_dof("height", "z", initial=0.0, max_step=0.1)
    add_spring(b, "spring", "z", stiffness)
    return b.build()


@pytest.mark.parametrize("jacobian", ["analytic", "central"])
def test_body_on_linear_spring_settles_at_mg_over_k(jacobian):
    m, k = 2.0, 500.0
    res = run_fdk(_slider(m, k), None, np.linspace(0, 1, 4), jacobian=jacobian)
    assert res.converged.all()
    np.testing.assert_allclose(res.alpha[:, 0], -m * G / k, atol=1e-3 / k)  # force tolerance / stiffness
    assert np.all(np.abs(res.f_fdk) < 1e-3)


def _block_on_floor(mass=1.0, p=1e8, size=0.01, floor_z=None, lift=None):
    """A 10 mm × 10 mm flat face (bottom of a block, 5 mm below its centre of mass) on a
    floor body; the block slides vertically (prismatic) and its height is an FDK DOF."""
    b = ModelBuilder("block on floor", gravity=(0, 0, -G))
    b.add_body("floor", 10.0, [1, 1, 1], position=[0, 0, 0], equilibrium=False)  # moved by its driver
    b.add_body("block", mass, [1e-4] * 3, position=[0, 0, 0.005])
    bottom = flat_patch(size, size, size / 20)
    down = np.diag([1.0, -1.0, -1.0])  # normals down, face 5 mm below the centre of mass
    from openfdk.contact.mesh import surface_mesh

    bottom = surface_mesh(bottom.vertices_B @ down.T + [0, 0, -0.005], bottom.faces[:, ::-1], name="bottom")
    add_contact(b, "floor", "block", bottom, "floor", flat_patch(0.05, 0.05, 0.002, name="floor"), p)
    b.add_measure("floor_z", b._select(b.point("floor.origin"), [2]))
    b.add_measure("floor_angles", b.angles("ground.origin", "floor.origin"))
    b.add_joint("floor_rail", "prismatic", parent="ground.origin", child="floor.origin")
    b.add_driver("floor_height", "floor_z", floor_z or Constant([0.0]))
    b.add_joint("rail", "prismatic", parent="floor.origin", child="block.origin")
    b.add_measure("height", b._select(b.vector("floor.origin", "block.origin"), [2]))
    b.add_fdk_dof("height", "height", initial=0.005, max_step=0.002)
    if lift is not None:
        add_external_load(b, "lift", "block.origin", force=lift)
    return b.build()


@pytest.mark.parametrize("jacobian", ["analytic", "central"])
def test_block_on_elastic_foundation_penetrates_mg_over_pA(jacobian):
    m, p, size = 1.0, 1e8, 0.01
    res = run_fdk(_block_on_floor(m, p, size), None, np.array([0.0, 0.1]), jacobian=jacobian)
    assert res.converged.all(), res.messages
    delta = m * G / (p * size**2)  # 0.98 mm
    np.testing.assert_allclose(0.005 - res.alpha[:, 0], delta, rtol=1e-6)


def test_sphere_in_cup_under_sideways_load_rolls_to_equilibrium_angle():
    """A ball (radius r) in a spherical cup (radius R) under gravity and a sideways
    force F: frictionless contact forces act along the cup's normals, i.e. through the
    cup's centre, so the ball's centre settles on the ray from the cup's centre at
    tan θ = F / (m g) from the vertical."""
    m, F, r, R = 0.5, 2.0, 0.008, 0.012
    b = ModelBuilder("ball in cup", gravity=(0, 0, -G))
    b.add_body("ball", m, [1e-5] * 3, position=[0, 0, -(R - r)])
    ball = sphere_cap(r, np.deg2rad(80), 0.0004, pole=(0, 0, -1), name="ball")
    cup = sphere_cap(R, np.deg2rad(70), 0.0005, pole=(0, 0, -1), inward=True, name="cup")
    add_contact(b, "cup", "ball", ball, "ground", cup, 2e9)
    add_external_load(b, "push", "ball.origin", force=[F, 0.0, 0.0])
    b.add_driver("no_rotation", b.angles("ground.origin", "ball.origin"), Constant([0.0, 0.0, 0.0]), reaction=True)
    position = b.add_measure("position", b.point("ball.origin"))
    for j, axis in enumerate("xyz"):
        b.add_fdk_dof(f"ball_{axis}", position, initial=[0.0, 0.0, -(R - r) - 2e-4][j], component=j, max_step=0.002)
    model = b.build()
    res = run_fdk(model, None, np.array([0.0]), jacobian="analytic")
    assert res.converged.all(), res.messages
    x, y, z = res.alpha[0]
    theta = np.arctan2(x, -z)
    assert abs(y) < 1e-6
    assert np.degrees(theta) == pytest.approx(np.degrees(np.arctan2(F, m * G)), abs=0.05)
    assert np.hypot(x, z) > R - r  # pressed into the cup


def test_frame_without_restoring_force_is_flagged_and_run_continues():
    """For three frames a 20 N lift (more than the block's weight) pulls the block off
    the floor: with no contact and no spring nothing restores the FDK DOF, so those
    frames are flagged (not hidden) and the others converge."""
    times = np.arange(10) * 0.01
    lift = np.where((times > 0.025) & (times < 0.055), 20.0, 0.0)
    model = _block_on_floor(lift=SplineThroughData(times, np.c_[0 * lift, 0 * lift, lift]))
    res = run_fdk(model, None, times, jacobian="analytic")
    failed = set(np.flatnonzero(~res.converged))
    assert failed == {3, 4, 5}
    for k in failed:
        assert res.reasons[k] in ("singular", "line_search", "iteration_limit")
        assert res.messages[k].startswith(f"frame {k} ")
    assert any("no restoring force along ['height']" in res.messages[k] for k in failed)
    summary = res.summary()
    assert summary["converged_frames"] == 7 and len(summary["failed_frames"]) == 3
    np.testing.assert_allclose(0.005 - res.alpha[[0, 1, 2, 6, 7, 8, 9], 0], G / (1e8 * 1e-4), rtol=1e-6)


@pytest.fixture(scope="module")
def tmj(tmp_path_factory):
    """(Model, AnalysisSettings) of the TMJ FDK model, recruitment solved to 1e-13."""
    from openfdk.io.modelfile import model_and_settings_from_dict
    from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, write_jaw_meshes

    d = write_jaw_meshes(tmp_path_factory.mktemp("tmj"))
    data = jaw_fdk_model_dict(str(d))
    data["recruitment"]["tolerance"] = 1e-13
    return model_and_settings_from_dict(data, "tmj.yaml", base_dir="/")


@pytest.fixture(scope="module")
def tmj_model(tmj):
    return tmj[0]


@pytest.fixture(scope="module")
def tmj_settings(tmj):
    return tmj[1]


def _tmj_context(model, settings, n_frames=30):
    from openfdk.analysis.inverse_dynamics import InverseDynamics
    from openfdk.fdk.residual import FDKContext
    from openfdk.io.c3d import MarkerTrial
    from openfdk.io.markers import MarkerTrajectories
    from openfdk.kinematics.system import ConstraintSystem
    from openfdk.kinematics.tracking import MarkerTracker, TrackingSettings
    from openfdk.fixtures.synthetic_jaw import jaw_markers

    t, labels, x, _ = jaw_markers(n_frames, noise=1e-4, seed=3)
    traj = MarkerTrajectories(MarkerTrial(tuple(labels), 100.0, t, x), cutoff_hz=8.0)
    system = ConstraintSystem(model)
    tracker = MarkerTracker(system, TrackingSettings(tol_step=1e-13, tol_constraint=1e-13, max_iter=60))
    return FDKContext(model, InverseDynamics(model, system, settings), tracker, [traj.evaluate(tt) for tt in t], t), traj, t


def test_analytic_jacobian_matches_central_differences_on_tmj_model(tmj_model, tmj_settings):
    """At several frames and α (in contact), the chain-rule Jacobian agrees with central
    differences of full residual evaluations (inner solvers tight) to 1e-4 relative."""
    from openfdk.fdk.jacobian import analytic_jacobian, central_jacobian
    from openfdk.fdk.residual import FrameWorkspace

    ctx, _, _ = _tmj_context(tmj_model, tmj_settings)
    state0 = tmj_model.initial_state()
    ctx.tracker.initial_guess(state0, ctx.meas[0][0], ctx.meas[0][3])
    checked = 0
    for k, alpha in [(5, [-6e-4, -6e-4, 0.0]), (15, [-5e-4, -7e-4, 2e-5]), (25, [-7e-4, -5e-4, -3e-5])]:
        ws = FrameWorkspace({j: state0 for j in ctx.frames_needed(k)})
        ev = ctx.evaluate(k, np.array(alpha), ws)
        assert ev.ok, ev.message
        Ja, _, msg = analytic_jacobian(ctx, k, ev)
        assert msg == ""
        Jc, n_ev, msg = central_jacobian(ctx, k, ev, ws, [2e-7, 2e-7, 2e-7])
        assert msg == "" and n_ev == 6
        scale = np.abs(Jc).max()
        assert scale > 1e4  # N/m: contact stiffness dominates
        assert np.abs(Ja - Jc).max() < 1e-4 * scale, (Ja, Jc)
        checked += 1
    assert checked == 3


def test_analytic_jacobian_does_not_depend_on_its_difference_step(tmj_model, tmj_settings, monkeypatch):
    """The geometry's change along each u_j is a central difference: its error is O(h²),
    so steps of 1e-6 and 3e-7 give the same J to 1e-8 relative (1.3e-10 measured; a
    forward difference errs by O(h): 7.6e-7 here, and on the DM knee the recruitment
    amplifies such an error into a 6-fold wrong soft mode, docs/fdk.md)."""
    from openfdk.fdk import jacobian
    from openfdk.fdk.residual import FrameWorkspace

    ctx, _, _ = _tmj_context(tmj_model, tmj_settings)
    state0 = tmj_model.initial_state()
    ctx.tracker.initial_guess(state0, ctx.meas[0][0], ctx.meas[0][3])
    k = 15
    ws = FrameWorkspace({j: state0 for j in ctx.frames_needed(k)})
    ev = ctx.evaluate(k, np.array([-5e-4, -7e-4, 2e-5]), ws)
    assert ev.ok, ev.message
    J = {}
    for step in (1e-6, 3e-7):
        monkeypatch.setattr(jacobian, "STEP", step)
        J[step], _, msg = jacobian.analytic_jacobian(ctx, k, ev)
        assert msg == ""
    scale = np.abs(J[1e-6]).max()
    assert scale > 1e4
    assert np.abs(J[3e-7] - J[1e-6]).max() < 1e-8 * scale


def test_analytic_and_central_fdk_converge_to_same_alpha(tmj_model, tmj_settings):

    _, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=20)
    # a fresh Jacobian at every iteration, as in the paper
    ra = run_fdk(tmj_model, traj, t, tmj_settings, jacobian="analytic", reuse_jacobian=False)
    rc = run_fdk(tmj_model, traj, t, tmj_settings, jacobian="central", reuse_jacobian=False)
    assert ra.converged.all() and rc.converged.all()
    # α agree to the force tolerance over the joint stiffness (≥ 1e4 N/m): < 1e-7 m
    np.testing.assert_allclose(ra.alpha, rc.alpha, atol=1e-7)
    assert np.all(ra.alpha[:, :2] < 0)  # condyles pressed into their fossae through the 1 mm layer
    assert ra.evaluations.mean() <= 4 < rc.evaluations.mean()


@pytest.mark.parametrize("jacobian", ["analytic", "central"])
def test_reused_broyden_jacobian_converges_to_the_fresh_jacobian_alpha(tmj_model, tmj_settings, jacobian):
    """Carrying J between iterations and frames (Broyden updates) is a different path to
    the same root: α agree within what two solutions with max |f^FDK| < tolerance can
    differ by, 2 tolerance Σ_j |J⁻¹|_ij per DOF (J analytic at the fresh solution: about
    5e-8 m along the stiff normals, 1–2e-6 m along the soft medio-lateral DOF of about
    1 N/mm), with far fewer Jacobians."""
    from openfdk.fdk.jacobian import analytic_jacobian
    from openfdk.fdk.residual import FrameWorkspace

    ctx, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=20)
    fresh = run_fdk(tmj_model, traj, t, tmj_settings, jacobian=jacobian, reuse_jacobian=False)
    reused = run_fdk(tmj_model, traj, t, tmj_settings, jacobian=jacobian, reuse_jacobian=True)
    assert fresh.converged.all() and reused.converged.all()
    assert np.abs(reused.f_fdk).max() < reused.settings.tolerance
    state0 = tmj_model.initial_state()
    ctx.tracker.initial_guess(state0, ctx.meas[0][0], ctx.meas[0][3])
    for k in range(len(t)):
        ws = FrameWorkspace({j: state0 for j in ctx.frames_needed(k)})
        ev = ctx.evaluate(k, fresh.alpha[k], ws)
        J, _, _ = analytic_jacobian(ctx, k, ev)
        bound = 2 * reused.settings.tolerance * np.abs(np.linalg.inv(J)).sum(axis=1)
        assert np.all(np.abs(reused.alpha[k] - fresh.alpha[k]) <= bound), (k, reused.alpha[k] - fresh.alpha[k], bound)
        state0 = ev.state
    # at least one J per frame when fresh (frames that start converged need none)
    assert fresh.jacobians.sum() >= np.count_nonzero(fresh.iterations)
    assert reused.jacobians.sum() < 0.5 * fresh.jacobians.sum()
    assert reused.summary()["mean_jacobians_per_frame"] == reused.jacobians.mean()


def test_broyden_update_meets_the_secant_condition_and_keeps_the_orthogonal_action():
    from openfdk.fdk.newton import _broyden

    rng = np.random.default_rng(3)
    J = rng.normal(size=(3, 3))
    s, y = rng.normal(size=3), rng.normal(size=3)
    J1 = _broyden(J, s, y)
    np.testing.assert_allclose(J1 @ s, y, atol=1e-12)  # secant condition
    v = np.cross(s, rng.normal(size=3))  # v ⟂ s
    np.testing.assert_allclose(J1 @ v, J @ v, atol=1e-12)
    assert np.linalg.matrix_rank(J1 - J) == 1
    np.testing.assert_array_equal(_broyden(J, np.zeros(3), y), J)  # no step: no update


def test_run_cli_does_fdk_when_the_model_declares_fdk_dofs(tmp_path):
    """`openfdk run` on a model file with fdk_dofs and a C3D trial: forces.csv has α and
    f^FDK per frame, summary.json the FDK convergence rate and evaluations per frame."""
    import csv
    import json

    import yaml

    from openfdk.cli import main
    from openfdk.io.c3d import write_c3d
    from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes

    write_jaw_meshes(tmp_path / "meshes")
    (tmp_path / "jaw.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes")))
    t, labels, x, _ = jaw_markers(25, noise=1e-4)
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "jaw.yaml"), str(tmp_path / "trial.c3d"), "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fdk"]["convergence_rate"] == 1.0
    assert summary["fdk"]["mean_residual_evaluations_per_frame"] >= 1 and summary["fdk"]["mean_residual_evaluations_per_frame"] <= 4
    rows = list(csv.DictReader(open(out / "forces.csv")))
    assert len(rows) == 25
    for r in rows:
        assert abs(float(r["fdk.tmj_r_normal.residual"])) < 1e-3
        assert float(r["fdk.tmj_r_normal.alpha"]) < 0
        assert float(r["tmj_r.Fz_N"]) < -1.0  # the fossa pushes the condyle down
        assert r["fdk_converged"] == "1"


def test_a_cold_frame_gets_cold_max_iterations_and_a_failed_frame_hands_on_its_best_iterate():
    """The slider on a linear spring with max_step 1 mm: from α = 0 the equilibrium
    α* = −m g / k = −39.24 mm is 40 clipped Newton steps away (each step is the full
    Newton step −f/k cut to 1 mm; the last one is 0.24 mm). The first frame is cold (no
    converged previous frame): with the default cold_max_iterations (100) it converges in
    exactly 40 iterations although max_iterations is 25, and every later frame, warm, in
    at most 1. With cold_max_iterations 25 the first frame stops at the limit at α = −25 mm
    (its best iterate, 25 steps), and the second frame, cold too, starts from there: 15
    more steps, not 40 from the initial value."""
    m, k = 2.0, 500.0
    b = ModelBuilder("spring", gravity=(0, 0, -G))
    b.add_body("block", m, [1e-3] * 3)
    b.add_joint("rail", "prismatic", parent="ground.origin", child="block.origin")
    b.add_measure("z", b._select(b.vector("ground.origin", "block.origin"), [2]))
    b.add_fdk_dof("height", "z", initial=0.0, max_step=1e-3)
    add_spring(b, "spring", "z", k)
    model = b.build()
    times = np.linspace(0, 1, 4)
    res = run_fdk(model, None, times, max_iterations=25)
    assert res.converged.all(), res.messages
    np.testing.assert_allclose(res.alpha[:, 0], -m * G / k, atol=1e-3 / k)
    assert res.iterations[0] == 40 and np.all(res.iterations[1:] <= 1)
    res = run_fdk(model, None, times, max_iterations=25, cold_max_iterations=25, restart=False)
    assert not res.converged[0] and res.reasons[0] == "iteration_limit"
    assert res.alpha[0, 0] == pytest.approx(-0.025, abs=1e-12)
    assert res.converged[1:].all() and res.iterations[1] == 15
    np.testing.assert_allclose(res.alpha[1:, 0], -m * G / k, atol=1e-3 / k)


def test_the_window_s_first_frame_after_a_lead_in_is_the_cold_start_s_root(tmj_model, tmj_settings, monkeypatch):
    """Marker tracking, a window from the trial's 7th frame: the first frame is solved
    after a lead-in over the 6 frames before it (fdk/approach.py, cut at the trial's
    start), and every frame's α equals that of the same window solved cold from the
    initial values without the approach, to the force tolerance over the joint stiffness
    (< 1e-7 m); the lead-in frames' evaluations count towards the first frame's. The
    first frame itself gets the cold iteration limit. Its rates and the last frame's are
    central (the trial's samples outside the window are their neighbours), so every
    frame also equals the same frame of a run over the trial from its start; and the
    lead-in's frames join the history as frames −6 … −1, so frame 1 starts from an
    extrapolation. (The transient start, tried before the lead-in, is made to fail here:
    the next test is its own.)"""
    from openfdk.fdk import approach
    from openfdk.fdk.analysis import FDKStep, fdk_context
    from dataclasses import replace

    from openfdk.fdk.settings import fdk_settings
    from openfdk.trial import drive

    _, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=20)
    window = t[6:12]
    from openfdk.fdk import analysis

    transient = approach.solve_transient
    monkeypatch.setattr(approach, "solve_transient", lambda ctx, k, a0, ws, s, *rest: transient(
        ctx, k, a0, ws, replace(s, max_iterations=1), *rest))  # one step: it fails

    limits, solve = [], approach.solve_frame
    monkeypatch.setattr(approach, "solve_frame",
                        lambda ctx, k, a0, ws, s, *rest: limits.append(s.max_iterations) or solve(ctx, k, a0, ws, s, *rest))
    marched, step_solve = [], analysis.solve_frame
    monkeypatch.setattr(analysis, "solve_frame", lambda ctx, k, a0, ws, s, *rest: (
        marched.append(s.max_iterations) if ctx.times[k] < window[0] else None) or step_solve(ctx, k, a0, ws, s, *rest))
    led = run_fdk(tmj_model, traj, window, tmj_settings)
    assert limits == [fdk_settings(tmj_model, tmj_settings).cold_max_iterations]
    # the marched frames are stepping stones: even the lead-in's cold first one gets the
    # ordinary limit (a stalled one hands its best iterate on)
    assert len(marched) == 6 and set(marched) == {fdk_settings(tmj_model, tmj_settings).max_iterations}
    cold = _cold_window(tmj_model, tmj_settings, traj, window)
    assert led.converged.all() and all(r.converged for r in cold[2])
    atol = ROOTS_APART
    assert np.all(np.abs(led.alpha - cold[0]) <= atol)
    assert np.any(np.abs(led.alpha[0]) > 1e-5)  # a real displacement, not the initial values
    assert led.evaluations[0] >= 6 + 1 and led.restarts[0] == 0
    whole = run_fdk(tmj_model, traj, t[:13], tmj_settings)
    assert whole.converged.all()
    assert np.all(np.abs(led.alpha - whole.alpha[6:12]) <= atol)
    settings = fdk_settings(tmj_model, tmj_settings)
    step = FDKStep(tmj_model, fdk_context(tmj_model, traj, window, settings=tmj_settings), settings,
                   approach.approach_for(tmj_model, traj))
    drive(step, 1, lambda rec: None)
    frames = [f for f, _ in step.history]
    assert frames == list(range(-(HISTORY - 1), 1))  # the last lead-in frames, then frame 0
    # frame −1 is frame 5 of the trial, marched to 0.1 N only: ~1e-6 m on the two stiff DOFs,
    # ~6e-5 m on the soft medio-lateral one
    np.testing.assert_allclose(step.history[-2][1][:2], whole.alpha[5][:2], atol=5e-6)
    assert abs(step.history[-2][1][2] - whole.alpha[5][2]) < 2e-4


#: two roots each within the force tolerance (1 mN) are apart by up to 2 mN over the
#: stiffness: < 1e-7 m on the TMJ's two stiff DOFs; the soft medio-lateral one moves
#: 6e-5 m per 0.1 N, 1.2e-6 m per 2 mN
ROOTS_APART = np.array([1e-7, 1e-7, 1.2e-6])


def _cold_window(model, overrides, traj, window):
    """(α (nf, n_fdk), evaluations (nf,), reports) of ``window`` solved without the
    approach: its first frame cold from the initial values by Newton's method."""
    from openfdk.fdk.analysis import FDKStep, fdk_context
    from openfdk.fdk.settings import fdk_settings
    from openfdk.trial import drive

    settings = fdk_settings(model, overrides)
    step = FDKStep(model, fdk_context(model, traj, window, settings=overrides), settings, approach=None)
    return drive(step, len(window), lambda rec: (rec.array("fdk.alpha"), rec.array("fdk.evaluations"),
                                                rec.objects("fdk.report")))


def test_the_window_s_first_frame_by_the_transient_start_is_the_cold_start_s_root(tmj_model, tmj_settings,
                                                                                  monkeypatch):
    """The window's first frame by pseudo-transient continuation from the initial values
    (fdk/transient.py), before any lead-in: no frame before the window is solved, every
    frame's α equals that of the same window solved cold by Newton's method to the force
    tolerance over the joint stiffness, and frame 1, which has no velocity to
    extrapolate, is solved by the transient solver too. Its steps take a fresh Jacobian
    first, then the contacts' part taken again at each step's pose (the jaw's two TMJ
    contacts), a fresh one at least every FRESH_EVERY-th step."""
    from openfdk.fdk import analysis, approach, transient as transient_module

    _, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=20)
    window = t[6:12]
    jacobians = []  # "J": a fresh one, "r": the contacts' part taken again (None: a fresh one follows)
    refreshed, fresh = transient_module.refreshed_split, transient_module._jacobian
    monkeypatch.setattr(transient_module, "refreshed_split", lambda *a: jacobians.append("r") or refreshed(*a))
    monkeypatch.setattr(transient_module, "_jacobian", lambda *a: jacobians.append("J") or fresh(*a))
    transient, times = approach.solve_transient, []
    monkeypatch.setattr(approach, "solve_transient", lambda ctx, k, *rest: times.append(("transient", ctx.times[k]))
                        or transient(ctx, k, *rest))
    for module in (analysis, approach):
        monkeypatch.setattr(module, "solve_frame", lambda ctx, k, *rest, solve=module.solve_frame: times.append(
            ("newton", ctx.times[k])) or solve(ctx, k, *rest))
    led = run_fdk(tmj_model, traj, window, tmj_settings)
    solved = list(times)  # (not the cold window's solves below)
    cold = _cold_window(tmj_model, tmj_settings, traj, window)
    assert led.converged.all() and all(r.converged for r in cold[2])
    assert np.all(np.abs(led.alpha - cold[0]) <= ROOTS_APART)
    assert np.any(np.abs(led.alpha[0]) > 1e-5)  # a real displacement, not the initial values
    assert solved[:2] == [("transient", window[0]), ("transient", window[1])], solved
    assert min(x for _, x in solved) == window[0]  # no lead-in, no sub-steps
    assert all(x > window[1] for _, x in solved[2:])
    assert led.restarts[0] == 0 and led.evaluations[0] >= 2
    order = "".join(jacobians)
    assert order.startswith("J") and order.count("r") >= 2, order
    assert "r" * transient_module.FRESH_EVERY not in order, order


def test_poses_moved_along_dq_dalpha_start_the_tracking_nearer_and_give_the_same_residual(tmj_model, tmj_settings):
    """FrameWorkspace.predict: after a Jacobian at α, the poses for an evaluation at
    α + Δα start moved by dq̂/dα Δα. The residual equals the one from the unmoved poses
    (both solves converge to the same tracking optimum: to 1e-6 N), the moved poses are
    nearer the solved ones than the unmoved (first-order prediction), and the tracking
    needs fewer Gauss–Newton iterations."""
    from openfdk.fdk.jacobian import analytic_jacobian
    from openfdk.fdk.residual import FrameWorkspace

    ctx, _, _ = _tmj_context(tmj_model, tmj_settings)
    state0 = tmj_model.initial_state()
    ctx.tracker.initial_guess(state0, ctx.meas[5][0], ctx.meas[5][3])
    ws = FrameWorkspace({j: state0 for j in ctx.frames_needed(5)})
    alpha = np.array([-8.6e-4, -8.6e-4, -1e-5])
    ev = ctx.evaluate(5, alpha, ws)
    ev = ctx.evaluate(5, alpha, ws)
    analytic_jacobian(ctx, 5, ev)
    assert ev.dq_dalpha is not None and np.abs(ev.dq_dalpha).max() > 0
    step = np.array([3e-6, -2e-6, 5e-6])
    plain, moved = ws.copy(), ws.copy()
    moved.alpha, moved.dq_dalpha = alpha.copy(), ev.dq_dalpha
    iterations = []
    solve = ctx.tracker.solve_positions

    def counted(*a, **k):
        out = solve(*a, **k)
        iterations.append(out[0].iterations)
        return out

    ctx.tracker.solve_positions = counted
    try:
        start = moved.copy()
        start.predict(alpha + step)
        e_plain = ctx.evaluate(5, alpha + step, plain)
        n_plain, iterations[:] = sum(iterations), []
        e_moved = ctx.evaluate(5, alpha + step, moved)
        n_moved = sum(iterations)
    finally:
        del ctx.tracker.solve_positions
    np.testing.assert_allclose(e_moved.f_fdk, e_plain.f_fdk, atol=1e-6)
    far = np.max(np.abs(ws.states[5].p_WB - plain.states[5].p_WB))
    near = np.max(np.abs(start.states[5].p_WB - plain.states[5].p_WB))
    assert far > 1e-7 and near < 0.1 * far
    assert n_moved < n_plain


def test_run_fdk_and_openfdk_run_drive_the_same_step_bit_for_bit(tmj_model, tmj_settings):
    """``run_fdk`` (the API) and ``run_trial`` (``openfdk run``) build their FDKStep with
    one function (fdk.analysis.fdk_step), so marker tracking with FDK over the same window
    gives identical α, residuals and evaluation counts. (On DM's og4 heel strike the two
    had differed: the API's absorbed-muscle check had warmed the wrapping's geodesic
    starts, and frames there are chaotic enough for 1e-13 m to decide convergence.)"""
    from openfdk.analysis.run import run_trial

    _, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=12)
    api = run_fdk(tmj_model, traj, t[4:9], tmj_settings)
    cli = run_trial(tmj_model, traj, t[4:9], settings=tmj_settings)[2]
    assert api.converged.all() and cli.converged.all()
    assert np.array_equal(api.alpha, cli.alpha) and np.array_equal(api.f_fdk, cli.f_fdk)
    assert np.array_equal(api.evaluations, cli.evaluations)
    assert np.any(np.abs(api.alpha) > 1e-5)  # the DOFs moved: a real solve, not the initial values


def test_a_frame_whose_recruitment_fails_says_so(tmp_path):
    """The TMJ model with every muscle a millionth as strong: no force set within the
    bounds balances the jaw, so each FDK frame fails with the reason ``recruitment`` and
    a message that says the recruitment failed and why (the phase-1 LP's unbalanced row),
    never that a feasible problem was infeasible."""
    from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, write_jaw_meshes
    from openfdk.io.modelfile import model_and_settings_from_dict

    data = jaw_fdk_model_dict(str(write_jaw_meshes(tmp_path)))
    for muscle in data["muscles"].values():
        muscle["max_isometric_force"] *= 1e-6
    model, settings = model_and_settings_from_dict(data, "weak.yaml", base_dir="/")
    _, traj, t = _tmj_context(model, settings, n_frames=3)
    res = run_fdk(model, traj, t, settings)
    assert not res.converged.any()
    assert all(r.reason.value == "recruitment" for r in res.reports), [r.reason for r in res.reports]
    assert all("recruitment failed: equilibrium cannot be met: not enough strength for row" in m
               for m in res.messages), res.messages


def test_a_one_frame_window_has_the_trial_s_neighbours_and_equals_the_frame_in_a_longer_window(tmj_model,
                                                                                             tmj_settings):
    """``--start`` = ``--end``: a one-frame window's frame spacing is the trial's sample
    interval (kinematics.tracking.window_spacing), so its residual rates (Eq. 7) are
    central over the trial's samples either side, as inside any longer window. Tracking
    alone: q, v and v̇ equal those of the same frame in a five-frame window (the same
    position solve; v, v̇ to 1e-9 of their size). FDK: α equals the same frame's in a
    three-frame window to two tolerances over the stiffness (the bounds of the lead-in
    test), and so does its v̇ to 1e-5 of its size. Before, the one-frame window had no
    neighbours and zero residual rates: its v differed by 7e-4 and its v̇ by 3e-3 of
    their size."""
    from openfdk.kinematics.analysis import run_tracking
    from openfdk.kinematics.tracking import window_spacing

    _, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=20)
    assert window_spacing(t[8:9], traj) == pytest.approx(0.01, rel=1e-9)
    assert window_spacing(t[8:11]) == pytest.approx(0.01, rel=1e-9) and window_spacing(t[8:9]) is None
    alpha = np.zeros(len(tmj_model.fdk_dofs))
    one = run_tracking(tmj_model, traj, t[8:9], alpha=alpha)
    five = run_tracking(tmj_model, traj, t[6:11], alpha=alpha)
    assert one.converged.all() and five.converged.all()
    np.testing.assert_allclose(one.q[0], five.q[2], rtol=0, atol=1e-9)
    scale_v, scale_a = np.abs(five.v[2]).max(), np.abs(five.vdot[2]).max()
    assert scale_v > 1e-3 and scale_a > 1e-2  # a moving jaw
    np.testing.assert_allclose(one.v[0], five.v[2], rtol=0, atol=1e-9 * scale_v + 1e-12)
    np.testing.assert_allclose(one.vdot[0], five.vdot[2], rtol=0, atol=1e-9 * scale_a + 1e-12)
    led = run_fdk(tmj_model, traj, t[8:9], tmj_settings)
    three = run_fdk(tmj_model, traj, t[7:10], tmj_settings)
    assert led.converged.all() and three.converged.all()
    atol = np.array([1e-7, 1e-7, 1.2e-6])
    assert np.all(np.abs(led.alpha[0] - three.alpha[1]) <= atol), np.abs(led.alpha[0] - three.alpha[1])
    # the FDK frame's v̇ with its α: as the longer window's to what α's gap moves it (the
    # zero residual rates of before left it 3e-3 of its size off)
    vdot_1, vdot_3 = led.kinematics.vdot[0], three.kinematics.vdot[1]
    assert np.abs(vdot_1 - vdot_3).max() < 1e-5 * np.abs(vdot_3).max()


def test_the_neighbouring_frames_poses_stop_earlier_and_leave_the_residual_as_it_was(tmj_model, tmj_settings,
                                                                                    monkeypatch):
    """The position solves at t ± Δt stop at NEIGHBOUR_TOLERANCE times the tracking's step
    tolerance (fdk/residual.py): their poses enter f^FDK only through the residual rates
    of Eq. 7, an error e there moving δ̈ by e / Δt². With the tracker's tol_step 1e-13 m the
    neighbours stop at 1e-10 m: their δ differ from the tight solves' by at most a few
    times that, δ̈ by 1e-10 / 0.01² = 1e-6 m/s², which on the jaw (0.4 kg, 5 cm lever arms)
    moves f^FDK by well under 1e-6 N. The frame itself is solved as tightly as before (its
    pose moves the contacts' forces by their stiffness), and the neighbours take fewer
    Gauss–Newton iterations."""
    import openfdk.fdk.residual as residual
    from openfdk.fdk.residual import FrameWorkspace

    assert residual.NEIGHBOUR_TOLERANCE > 1.0
    ctx, _, t = _tmj_context(tmj_model, tmj_settings)
    state0 = tmj_model.initial_state()
    ctx.tracker.initial_guess(state0, ctx.meas[5][0], ctx.meas[5][3])
    alpha = np.array([-8.6e-4, -8.6e-4, -1e-5])
    warm = ctx.evaluate(5, alpha, FrameWorkspace({j: state0 for j in ctx.frames_needed(5)}))
    solve = ctx.tracker.solve_positions
    out = {}
    for factor in (residual.NEIGHBOUR_TOLERANCE, 1.0):
        monkeypatch.setattr(residual, "NEIGHBOUR_TOLERANCE", factor)
        calls = []

        def counted(state, t_j, *a, **k):
            res = solve(state, t_j, *a, **k)
            calls.append((t_j, res[0].iterations, k.get("tol_step", a[4] if len(a) > 4 else None)))
            return res

        ctx.tracker.solve_positions = counted
        try:
            # from the warm poses moved a little (as a Newton step's evaluation starts)
            ws = FrameWorkspace({j: warm.state.copy() for j in ctx.frames_needed(5)})
            ev = ctx.evaluate(5, alpha + np.array([2e-6, -1e-6, 3e-6]), ws)
        finally:
            del ctx.tracker.solve_positions
        assert ev.ok
        centre = [c for c in calls if c[0] == t[5]]
        others = [c for c in calls if c[0] != t[5]]
        assert len(centre) == 1 and len(others) == 2
        assert centre[0][2] is None  # the frame's own pose: the tracking's tolerance
        out[factor] = (ev.f_fdk.copy(), sum(c[1] for c in others), [c[2] for c in others])
    (f_loose, n_loose, tols), (f_tight, n_tight, tight_tols) = out.values()
    assert tols == [pytest.approx(1e-10, rel=1e-12)] * 2 and tight_tols == [pytest.approx(1e-13, rel=1e-12)] * 2
    assert n_loose < n_tight
    assert np.abs(f_tight).max() > 1e-3  # (away from the root: the residual is not zero)
    np.testing.assert_allclose(f_loose, f_tight, rtol=0, atol=1e-6)


def test_failed_frames_solved_again_backward_with_marker_tracking_are_the_forward_roots(tmj_model, tmj_settings,
                                                                                         monkeypatch):
    """Marker tracking, 10 frames: frames 3 and 4 are made to fail (one Newton iteration
    each from half a max_step off their warm starts, no other start); frame 5 then converges cold from frame 4's best iterate, and the
    sweep back solves frame 4 from frame 5's solution (its poses moved along its dq̂/dα,
    t ± Δt included) and frame 3 from frame 4's. Each equals the frame as the
    undisturbed forward run solved it, to the force tolerance over the joint stiffness
    (the bounds of the lead-in test above); both are flagged ``fdk.backward``, the sweep
    takes the ordinary iteration limit, and the forward frames after it are the forward
    run's too."""
    from openfdk.fdk import analysis
    from openfdk.fdk.analysis import FDKStep, fdk_context
    from openfdk.fdk.settings import fdk_settings
    from openfdk.trial import drive

    _, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=12)
    window = t[1:11]
    settings = fdk_settings(tmj_model, tmj_settings)
    forward = drive(FDKStep(tmj_model, fdk_context(tmj_model, traj, window, settings=tmj_settings), settings),
                    len(window), lambda rec: (rec.array("fdk.alpha"), rec.objects("fdk.report")))
    assert all(r.converged for r in forward[1])
    calls, solve = [], analysis.solve_frame

    def first_fails(ctx, k, a0, ws, s, *rest):
        calls.append((k, s.max_iterations))
        if k in (3, 4) and [c[0] for c in calls].count(k) == 1:
            # the forward solve: one iteration from half a max_step off, not converged
            a0, s = a0 + 0.5 * np.asarray(s.max_step), replace(s, max_iterations=1)
        return solve(ctx, k, a0, ws, s, *rest)

    monkeypatch.setattr(analysis, "solve_frame", first_fails)
    monkeypatch.setattr(analysis, "solve_restarts", lambda *args: [])  # no other start for them
    rec = drive(FDKStep(tmj_model, fdk_context(tmj_model, traj, window, settings=tmj_settings), settings),
                len(window), lambda rec: rec)
    assert [k for k, _ in calls] == [0, 1, 2, 3, 4, 5, 4, 3, 6, 7, 8, 9]
    assert calls[6][1] == calls[7][1] == settings.max_iterations  # the sweep: warm, the ordinary limit
    assert all(r.converged for r in rec.objects("fdk.report"))
    assert rec.array("fdk.backward").tolist() == [0, 0, 0, 1, 1, 0, 0, 0, 0, 0]
    atol = np.array([1e-7, 1e-7, 1.2e-6])
    assert np.all(np.abs(rec.array("fdk.alpha") - forward[0]) <= atol)
    assert np.all(np.abs(forward[0][3:5, :2]) > 1e-5)  # real displacements, not the initial values


def test_an_evaluation_where_the_kinematics_are_undefined_fails_and_names_why(tmj_model, tmj_settings):
    """A stage of the kinematics that raises FloatingPointError at a trial α (a
    rotation-angle measure at gimbal lock: DM's patella under the elastic-tendon overlay,
    which ended `openfdk run` with a traceback) makes a failed evaluation, refused like any
    other: ok False, stage ``kinematics``, the measure's message. Elsewhere the same
    context evaluates as before."""
    from openfdk.fdk.residual import FrameWorkspace

    ctx, _, _ = _tmj_context(tmj_model, tmj_settings)
    state0 = tmj_model.initial_state()
    ctx.tracker.initial_guess(state0, ctx.meas[5][0], ctx.meas[5][3])
    alpha = np.array([-8.6e-4, -8.6e-4, -1e-5])
    solve = ctx.tracker.solve_positions

    def undefined_beyond(state, t, x, vis, a, *args):
        if a[2] > 1e-3:
            raise FloatingPointError("angles 'pf_r.angles' (xyz): gimbal lock, the middle angle is -90.0 deg")
        return solve(state, t, x, vis, a, *args)

    ctx.tracker.solve_positions = undefined_beyond
    try:
        ok = ctx.evaluate(5, alpha, FrameWorkspace({j: state0 for j in ctx.frames_needed(5)}))
        bad = ctx.evaluate(5, alpha + [0.0, 0.0, 2e-3], FrameWorkspace({j: state0 for j in ctx.frames_needed(5)}))
    finally:
        del ctx.tracker.solve_positions
    assert ok.ok and np.all(np.isfinite(ok.f_fdk)) and np.abs(ok.f_fdk).max() > 0
    assert not bad.ok and bad.stage == "kinematics" and np.all(np.isnan(bad.f_fdk)) and bad.norm == np.inf
    assert bad.message == "kinematics failed: angles 'pf_r.angles' (xyz): gimbal lock, the middle angle is -90.0 deg"


def test_a_checkpoint_s_carried_factors_of_another_model_are_refused(tmj_model, tmj_settings):
    """FDKStep.carry holds the last solved frame's poses and KKT factors (a resumed run
    then writes the uninterrupted run's files, tests/test_trial_driver.py). Restored from
    a checkpoint (untrusted), factors sized for another model are a ValueError, which the
    resume reports as a checkpoint that does not fit the run."""
    from openfdk.fdk.analysis import FDKStep, fdk_context
    from openfdk.fdk.settings import fdk_settings
    from openfdk.kinematics.tracking import KKTFactors

    _, traj, t = _tmj_context(tmj_model, tmj_settings, n_frames=20)
    ctx = fdk_context(tmj_model, traj, t[6:9], settings=tmj_settings)
    step = FDKStep(tmj_model, ctx, fdk_settings(tmj_model, tmj_settings), approach=None)
    size = ctx.system.n_coords + ctx.system.n_rows
    carry = step.carry()
    assert carry[8] is None  # nothing solved yet
    state = tmj_model.initial_state()
    fits = KKTFactors(size).saved()
    step.restore(carry[:8] + ((0, {0: state}, {0: fits}),) + carry[9:])
    assert step.solved[0] == 0 and step.solved[1].factors[0].LU.shape == (size, size)
    other = KKTFactors(size + 6).saved()
    with pytest.raises(ValueError, match="another size"):
        step.restore(carry[:8] + ((0, {0: state}, {0: other}),) + carry[9:])
