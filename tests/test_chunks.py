"""Long trials in chunks: segment planning, and chunked vs serial runs of one trial on
the TMJ-like FDK model and on the POP jaw (tracking + inverse dynamics), in this process
and on a 2-worker LocalCluster on loopback."""

import json

import numpy as np
import pytest

from openfdk.fdk.analysis import run_fdk
from openfdk.analysis.jobs import load_trajectories, run_job
from openfdk.io.modelfile import load_model_and_settings
from openfdk.study.chunks import plan_segments
from openfdk.study.cli import run_chunked_job

from models import write_jaw_files

N_FRAMES = 24
FDK_DOFS = ("tmj_r_normal", "tmj_l_normal", "ml_shift")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_jaw_files(tmp_path_factory.mktemp("chunks"), N_FRAMES)


@pytest.fixture(scope="module")
def serial_fdk(files):
    return run_job(files / "tmj.yaml", files / "trial.c3d", progress=False)


def _alpha(dyn):
    return np.column_stack([dyn.extra["columns"][f"fdk.{d}.alpha"] for d in FDK_DOFS])


def test_segments_cover_the_trial_once_and_see_their_neighbours():
    for n, k, overlap in [(24, 3, 5), (10, 10, 0), (7, 2, 2), (100, 7, 4)]:
        segs = plan_segments(n, k, overlap)
        kept = np.concatenate([np.arange(s.keep_start, s.keep_stop) for s in segs])
        np.testing.assert_array_equal(kept, np.arange(n))  # every frame kept exactly once, in order
        lengths = [s.keep_stop - s.keep_start for s in segs]
        assert max(lengths) - min(lengths) <= 1
        for s in segs:
            # overlap warm-up frames + the left neighbour before, the right neighbour after
            assert s.solve_start == max(0, s.keep_start - overlap - 1)
            assert s.solve_stop == min(n, s.keep_stop + 1)
    with pytest.raises(ValueError, match="cannot split 5 frames into 6 chunks"):
        plan_segments(5, 6)
    with pytest.raises(ValueError, match="chunks must be"):
        plan_segments(5, 0)


def test_chunked_fdk_agrees_with_serial_to_the_fdk_tolerance(files, serial_fdk):
    """Each frame is a root of f^FDK(α) to |f| < tol, so two runs may differ by at most
    |Δα| ≤ ‖J⁻¹‖ · 2 tol (J = ∂f^FDK/∂α, measured here by central differences at every
    frame of the serial solution); forces then differ by the FDK tolerance order."""
    from openfdk.analysis.inverse_dynamics import InverseDynamics
    from openfdk.fdk.jacobian import central_jacobian
    from openfdk.fdk.residual import FDKContext, FrameWorkspace
    from openfdk.fdk.settings import fdk_settings
    from openfdk.kinematics.system import ConstraintSystem
    from openfdk.kinematics.tracking import MarkerTracker, TrackingSettings

    kin, dyn, info = serial_fdk
    kc, dc, ic = run_chunked_job(files / "tmj.yaml", files / "trial.c3d", 3, workers=0, progress=False, overlap=2)
    assert ic["chunks"] == 3 and [s["keep"] for s in ic["segments"]] == [[0, 8], [8, 16], [16, 24]]
    np.testing.assert_array_equal(kc.time, kin.time)
    # each segment's first kept frame and its cold start (overlap + 1 = 3 frames before)
    assert [s["keep_from_s"] for s in ic["segments"]] == [kin.time[0], kin.time[8], kin.time[16]]
    assert [s["cold_start_s"] for s in ic["segments"]] == [kin.time[0], kin.time[5], kin.time[13]]
    model, settings = load_model_and_settings(files / "tmj.yaml")
    tol = fdk_settings(model, settings).tolerance
    assert info["fdk"]["converged_frames"] == N_FRAMES and ic["fdk"]["converged_frames"] == N_FRAMES
    f_chunked = np.column_stack([dc.extra["columns"][f"fdk.{d}.residual"] for d in FDK_DOFS])
    assert np.all(np.abs(f_chunked) < tol)

    # ‖J⁻¹‖ at every frame of the serial solution (central differences, h = 0.2 µm)
    _, traj = load_trajectories(model, files / "trial.c3d", settings=settings)
    system = ConstraintSystem(model)
    ctx = FDKContext(model, InverseDynamics(model, system, settings), MarkerTracker(system, TrackingSettings()),
                     [traj.evaluate(t) for t in kin.time], kin.time)
    alpha_s, alpha_c = _alpha(dyn), _alpha(dc)
    state = model.initial_state()
    ctx.tracker.initial_guess(state, ctx.meas[0][0], ctx.meas[0][3])
    for k in range(N_FRAMES):
        ws = FrameWorkspace({j: state for j in ctx.frames_needed(k)})
        ev = ctx.evaluate(k, alpha_s[k], ws)
        J, _, msg = central_jacobian(ctx, k, ev, ws, [2e-7] * 3)
        assert msg == "" and np.linalg.norm(J) > 1.0  # a real restoring stiffness (N/m)
        bound = 2 * tol * np.linalg.norm(np.linalg.inv(J), 2)
        assert np.max(np.abs(alpha_c[k] - alpha_s[k])) <= bound, k
        state = ws.states[k]
    # muscle and contact forces: both solutions balance the same loads to the tolerance
    np.testing.assert_allclose(dc.forces, dyn.forces, atol=50 * tol, rtol=0)
    for c in ("tmj_r.Fz_N", "tmj_l.Fz_N"):
        np.testing.assert_allclose(dc.extra["columns"][c], dyn.extra["columns"][c], atol=50 * tol, rtol=0)


def test_segment_ends_use_the_real_neighbouring_frames(files, serial_fdk):
    """Velocities and accelerations come from the residuals at t ± Δt (Eq. 7): the
    boundary frames of chunks equal the serial ones. So does the last frame of a window
    run on its own: FDK takes the trial's sample after the window as its neighbour
    (fdk/residual.py, window_measurements); with the one-sided difference it had before,
    its accelerations differed by more than 1e-3 of their scale."""
    kin, _dyn, _ = serial_fdk
    kc, _, _ = run_chunked_job(files / "tmj.yaml", files / "trial.c3d", 2, workers=0, progress=False, overlap=0)
    boundary = [11, 12]  # last frame of chunk 0 and first of chunk 1
    scale = np.max(np.abs(kin.vdot))
    # chunk 1's first frame is solved after a lead-in (fdk/approach.py), the serial one from
    # its predecessor: two roots within the FDK tolerance, whose soft medio-lateral α
    # differ by up to ~1e-6 m; 1e-5 of the scale is still 100 times below the one-sided
    # difference checked at the end
    np.testing.assert_allclose(kc.vdot[boundary], kin.vdot[boundary], atol=1e-5 * scale)
    np.testing.assert_allclose(kc.v[boundary], kin.v[boundary], atol=1e-6 * np.max(np.abs(kin.v)))
    # the same segment run as a window of the trial: its last frame sees the trial's next sample
    model, settings = load_model_and_settings(files / "tmj.yaml")
    _, traj = load_trajectories(model, files / "trial.c3d", settings=settings)
    window = run_fdk(model, traj, kin.time[:12], settings)
    np.testing.assert_allclose(window.kinematics.vdot[11], kin.vdot[11], atol=1e-5 * scale)
    np.testing.assert_allclose(window.kinematics.v[11], kin.v[11], atol=1e-6 * np.max(np.abs(kin.v)))


def test_chunked_tracking_and_inverse_dynamics_without_fdk(files):
    """The POP jaw (marker tracking + recruitment, no FDK DOFs): chunks equal the serial run."""
    kin, dyn, _ = run_job(files / "pop.yaml", files / "trial.c3d", progress=False)
    kc, dc, ic = run_chunked_job(files / "pop.yaml", files / "trial.c3d", 4, workers=0, progress=False)
    assert "fdk" not in ic and kc.converged.all() and dc.converged.all()
    np.testing.assert_allclose(kc.q, kin.q, atol=1e-9)
    np.testing.assert_allclose(kc.vdot, kin.vdot, atol=1e-6 * np.max(np.abs(kin.vdot)))
    # recruitment is solved to its own tolerance: compare forces relative to their scale
    np.testing.assert_allclose(dc.forces, dyn.forces, atol=1e-5 * np.nanmax(np.abs(dyn.forces)))


def test_failed_frame_messages_keep_the_trial_numbering():
    """Messages that name a frame use the trial's numbering after stitching: they are
    made from the structured per-frame reports, not renumbered text."""
    from openfdk.kinematics.analysis import KinematicsResult
    from openfdk.study.chunks import Segment, _stitch_object
    from openfdk.trial.status import FrameReport, Reason

    def segment_result(time, reports):
        nf = len(time)
        ok = np.array([r.converged for r in reports])
        return KinematicsResult("m", ("jaw",), (), time, np.zeros((nf, 7)), np.zeros((nf, 6)), np.zeros((nf, 6)),
                                np.zeros((nf, 0, 3)), np.zeros(nf), np.zeros(nf, int), ok, tuple(reports),
                                np.zeros(0))

    bad = FrameReport.failed(Reason.UNOBSERVABLE, "the pose cannot be determined")
    good = FrameReport.ok()
    t = np.arange(20) * 0.01
    # segment 1 keeps frames 10..19 and solves 7..19 (its local frame 6 is trial frame 13)
    segs = [Segment(0, 0, 10, 0, 11), Segment(1, 10, 20, 7, 20)]
    parts = [segment_result(t[0:11], [good] * 11),
             segment_result(t[7:20], [good] * 6 + [bad] + [good] * 6)]
    kin = _stitch_object(parts, segs, 1.0)
    assert parts[1].messages[6] == "frame 6 (t = 0.1300 s): the pose cannot be determined"
    assert kin.messages[13] == "frame 13 (t = 0.1300 s): the pose cannot be determined"
    assert [i for i, m in enumerate(kin.messages) if m] == [13]
    assert kin.reports[13].reason is Reason.UNOBSERVABLE and not kin.converged[13]


def test_chunked_run_on_a_local_cluster_writes_the_run_outputs(files, serial_fdk, tmp_path):
    _kin, dyn, _info = serial_fdk
    out = tmp_path / "run"
    _kc, dc, _ic = run_chunked_job(files / "tmj.yaml", files / "trial.c3d", 2, out, workers=2, progress=False)
    tol = 1e-3
    np.testing.assert_allclose(dc.forces, dyn.forces, atol=50 * tol, rtol=0)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fdk"]["converged_frames"] == N_FRAMES and summary["input"]["chunks"] == 2
    header = (out / "forces.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "time" and "fdk.tmj_r_normal.alpha" in header
    assert len((out / "kinematics.csv").read_text().splitlines()) == N_FRAMES + 1


def test_a_tracking_window_s_edge_frames_see_the_trial_s_neighbouring_samples(files):
    """Marker tracking without FDK (the POP jaw): a window's first and last frames take
    their residual rates (Eq. 7) from the poses at the trial's samples just outside the
    window, so their v and v̇ equal those of the same frames in a run over the whole
    trial (the poses are the same solves: to the tracking's tolerance, here 1e-11 of the
    scale). With one-sided differences they differed by 5e-5 and 2e-4 (v) and 1e-3 and
    5e-3 (v̇) of the scale."""
    from openfdk.io.modelfile import load_model_and_settings as load
    from openfdk.kinematics.analysis import run_tracking

    model, settings = load(files / "pop.yaml")
    _, traj = load_trajectories(model, files / "trial.c3d", settings=settings)
    whole = run_tracking(model, traj, progress=False)
    a, b = 5, 15
    window = run_tracking(model, traj, whole.time[a:b + 1], progress=False)
    assert whole.converged.all() and window.converged.all()
    scale_v, scale_a = np.max(np.abs(whole.v)), np.max(np.abs(whole.vdot))
    for i, j in ((0, a), (b - a, b)):
        np.testing.assert_allclose(window.v[i], whole.v[j], atol=1e-9 * scale_v)
        np.testing.assert_allclose(window.vdot[i], whole.vdot[j], atol=1e-8 * scale_a)
    # the trial's own first frame has no sample before it: one-sided there, in both
    first = run_tracking(model, traj, whole.time[:6], progress=False)
    np.testing.assert_allclose(first.vdot[0], whole.vdot[0], atol=1e-8 * scale_a)
