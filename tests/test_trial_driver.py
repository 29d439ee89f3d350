"""The one trial driver (openfdk.trial): its results against straightforward per-frame
loops written here, checkpoints with kill -9 and --resume (identical final files), and
Ctrl-C (partial results, marked)."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from openfdk.analysis.run import run_trial
from openfdk.cli import main
from openfdk.analysis.jobs import load_trajectories
from openfdk.io.modelfile import load_model_and_settings
from openfdk.trial.status import FrameStatus, Reason

from models import write_jaw_files

N_FRAMES = 12


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_jaw_files(tmp_path_factory.mktemp("driver"), 160)


def _central_rates(delta, dt):
    """δ̇, δ̈ (nf, nm, 3) by central differences, one-sided first derivative at the ends
    (every frame converged, every marker visible)."""
    d1, d2 = np.zeros_like(delta), np.zeros_like(delta)
    d1[1:-1] = (delta[2:] - delta[:-2]) / (2 * dt)
    d2[1:-1] = (delta[2:] - 2 * delta[1:-1] + delta[:-2]) / dt**2
    d1[0], d1[-1] = (delta[1] - delta[0]) / dt, (delta[-1] - delta[-2]) / dt
    return d1, d2


def test_tracking_and_inverse_dynamics_equal_a_plain_per_frame_loop(files):
    """POP jaw: marker tracking (Eqs. 4–10) and recruitment (Eq. 11) frame by frame with
    no warm starts, written out here, against the driver's run (one pass, warm starts).
    The window is the trial's first N_FRAMES samples: its first frame is the trial's and
    has one-sided rates, its last takes the trial's next sample as its neighbour."""
    from openfdk.dynamics.inverse import InverseDynamics
    from openfdk.kinematics.system import ConstraintSystem
    from openfdk.kinematics.tracking import MarkerTracker

    model, settings = load_model_and_settings(files / "pop.yaml")
    _, traj = load_trajectories(model, files / "trial.c3d", settings=settings)
    times = np.asarray(traj.time)[:N_FRAMES]
    kin, dyn, fdk = run_trial(model, traj, times, settings=settings)
    assert fdk is None and kin.converged.all() and dyn.converged.all()
    assert all(r.status is FrameStatus.CONVERGED and r.reason is Reason.CONVERGED for r in kin.reports)

    tracker = MarkerTracker(ConstraintSystem(model))
    state = model.initial_state()
    # the window's frames and the trial's sample after it (the last frame's neighbour)
    with_next = np.asarray(traj.time)[:N_FRAMES + 1]
    meas = [traj.evaluate(t) for t in with_next]
    q, delta = [], []
    for k, t in enumerate(with_next):
        x, _, _, vis = meas[k]
        tracker.initial_guess(state, x, vis)  # from the markers alone, every frame
        res, _, _ = tracker.solve_positions(state, t, x, vis)
        assert res.converged
        q.append(state.get_q())
        delta.append(tracker.residuals(state, x))
    q, delta = np.array(q), np.array(delta)
    np.testing.assert_allclose(kin.q, q[:N_FRAMES], atol=1e-9)
    d1, d2 = _central_rates(delta, times[1] - times[0])
    solver = InverseDynamics(model)
    for k, t in enumerate(times):
        x, xd, xdd, vis = meas[k]
        state.set_q(q[k])
        K = tracker.kkt_matrix(state, t, vis)
        v, vd = tracker.solve_velocities_accelerations(state, t, K, vis, xd, xdd, d1[k], d2[k])
        np.testing.assert_allclose(kin.v[k], v, atol=1e-7 * np.max(np.abs(kin.v)))
        np.testing.assert_allclose(kin.vdot[k], vd, atol=1e-6 * np.max(np.abs(kin.vdot)))
        fr = solver.frame(state, kin.vdot[k], t)  # recruitment from a cold start
        assert fr.converged
        np.testing.assert_allclose(dyn.forces[k], fr.f, atol=1e-5 * np.max(np.abs(fr.f)))
    # results are built once and cannot be changed afterwards
    with pytest.raises(ValueError):
        kin.q[0, 0] = 1.0
    with pytest.raises(ValueError):
        dyn.forces[0, 0] = 1.0


def test_fdk_equals_a_plain_newton_loop_with_central_differences(files):
    """TMJ jaw: per frame, Newton on f^FDK(α) = 0 with a central-difference Jacobian
    (the paper's method, written here, no line search, no Jacobian reuse, cold
    recruitment). Both stop at max |f^FDK| < tol, so α agrees to ‖J⁻¹‖·2 tol."""
    from openfdk.fdk.analysis import fdk_context
    from openfdk.fdk.residual import FrameWorkspace
    from openfdk.fdk.settings import fdk_settings

    model, settings = load_model_and_settings(files / "tmj.yaml")
    _, traj = load_trajectories(model, files / "trial.c3d", settings=settings)
    times = np.asarray(traj.time)[:6]
    kin, dyn, res = run_trial(model, traj, times, settings=settings)
    assert res.converged.all() and all(r.reason is Reason.CONVERGED for r in res.reports)
    tol = fdk_settings(model, settings).tolerance
    ctx = fdk_context(model, traj, times, settings=settings)
    state = model.initial_state()
    ctx.tracker.initial_guess(state, ctx.meas[0][0], ctx.meas[0][3])
    alpha = np.array([d.initial for d in model.fdk_dofs])
    h = 2e-7
    for k in range(len(times)):
        ws = FrameWorkspace({j: state for j in ctx.frames_needed(k)})
        for _ in range(30):
            ev = ctx.evaluate(k, alpha, ws)
            assert ev.ok
            J = np.zeros((len(alpha), len(alpha)))
            for j in range(len(alpha)):
                e = np.eye(len(alpha))[j] * h
                J[:, j] = (ctx.evaluate(k, alpha + e, ws.copy()).f_fdk - ctx.evaluate(k, alpha - e, ws.copy()).f_fdk) / (2 * h)
            if ev.norm < tol:
                break
            alpha = alpha - np.linalg.solve(J, ev.f_fdk)
        assert ev.norm < tol
        bound = 2 * tol * np.linalg.norm(np.linalg.inv(J), 2)
        assert np.max(np.abs(res.alpha[k] - alpha)) <= bound, k
        np.testing.assert_allclose(dyn.forces[k], ev.frame.f, atol=50 * tol, rtol=0)
        state = ws.states[k]


def _run(args):
    return subprocess.Popen([sys.executable, "-m", "openfdk.cli", "run", *map(str, args), "--no-progress", "--no-plots"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(path, proc, timeout=300):
    t0 = time.monotonic()
    while not path.exists():
        assert proc.poll() is None, f"the run ended before {path.name} appeared: {proc.communicate()}"
        assert time.monotonic() - t0 < timeout
        time.sleep(0.01)


def _summary_without_timing(path):
    s = json.loads(path.read_text())
    for part in s.values():
        if isinstance(part, dict):
            for key in ("wall_time_s", "frames_per_second"):
                part.pop(key, None)
    return s


@pytest.mark.slow
@pytest.mark.parametrize("model_name, n_frames", [("tmj.yaml", 60), ("pop.yaml", 160)])
def test_kill_9_then_resume_gives_the_uninterrupted_files(files, tmp_path, model_name, n_frames):
    """openfdk run killed with SIGKILL after a few checkpoints, then --resume: the final
    kinematics.csv and forces.csv equal an uninterrupted run's byte for byte (and the
    summary, apart from timings)."""
    end = (n_frames - 1) / 100.0
    common = [files / model_name, files / "trial.c3d", "--end", end, "--checkpoint-frames", 4]
    whole = tmp_path / "whole"
    assert main(["run", *map(str, common), "--out", str(whole), "--no-progress", "--no-plots"]) == 0
    assert not (whole / ".checkpoint").exists()  # removed once the final files are written

    out = tmp_path / "killed"
    proc = _run([*common, "--out", out])
    _wait_for(out / ".checkpoint" / "part-000002.npz", proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "forces.csv").exists()  # killed midway: nothing final yet
    parts = sorted((out / ".checkpoint").glob("part-*.npz"))
    assert 3 <= len(parts) < n_frames // 4
    proc = _run([*common, "--out", out, "--resume"])
    _stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr
    for name in ("kinematics.csv", "forces.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    assert _summary_without_timing(out / "summary.json") == _summary_without_timing(whole / "summary.json")
    assert not (out / ".checkpoint").exists()


@pytest.mark.slow
def test_sigterm_writes_the_finished_frames_marked_partial(files, tmp_path):
    """SIGTERM (a batch system's time limit, ``timeout``) stops the run as Ctrl-C does:
    the finished frames are written, marked partial, exit 130 — not killed with nothing."""
    n_frames = 160
    out = tmp_path / "terminated"
    proc = _run([files / "pop.yaml", files / "trial.c3d", "--end", (n_frames - 1) / 100.0, "--checkpoint-frames", 4,
                 "--out", out])
    _wait_for(out / ".checkpoint" / "part-000002.npz", proc)
    proc.send_signal(signal.SIGTERM)
    _stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["partial"] is True and 12 <= summary["frames_finished"] < n_frames
    assert len((out / "forces.csv").read_text().splitlines()) == summary["frames_finished"] + 1


@pytest.mark.slow
def test_ctrl_c_writes_the_finished_frames_marked_partial(files, tmp_path):
    n_frames = 160
    common = [files / "pop.yaml", files / "trial.c3d", "--end", (n_frames - 1) / 100.0, "--checkpoint-frames", 4]
    out = tmp_path / "interrupted"
    proc = _run([*common, "--out", out])
    _wait_for(out / ".checkpoint" / "part-000002.npz", proc)
    proc.send_signal(signal.SIGINT)
    _stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr and "partial" in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["partial"] is True and summary["frames_planned"] == n_frames
    done = summary["frames_finished"]
    assert 12 <= done < n_frames
    assert summary["kinematics"]["frames"] == summary["inverse_dynamics"]["frames"] == done
    rows = (out / "forces.csv").read_text().splitlines()
    assert len(rows) == done + 1 and len((out / "kinematics.csv").read_text().splitlines()) == done + 1
    # the finished frames are those of a complete run
    whole = tmp_path / "whole"
    assert main(["run", *map(str, common), "--out", str(whole), "--no-progress", "--no-plots"]) == 0
    assert (whole / "forces.csv").read_text().splitlines()[: done + 1] == rows
    # and the run can be continued from its last checkpoint
    proc = _run([*common, "--out", out, "--resume"])
    assert proc.wait(timeout=600) == 0
    assert (out / "forces.csv").read_bytes() == (whole / "forces.csv").read_bytes()


def test_bad_checkpoint_options_are_refused(files, tmp_path, capsys):
    base = ["run", str(files / "pop.yaml"), str(files / "trial.c3d"), "--out", str(tmp_path / "o"), "--no-progress", "--no-plots"]
    assert main([*base, "--checkpoint-frames", "0"]) == 2
    assert "--checkpoint-frames must be >= 1" in capsys.readouterr().err


def test_checkpoints_of_another_run_are_refused(tmp_path):
    from openfdk.trial.checkpoint import CheckpointError, Checkpoints

    Checkpoints(tmp_path / "c", "run-a").save([(0, {"x": 1.0})], None, 1)
    with pytest.raises(CheckpointError, match="belongs to another run"):
        Checkpoints(tmp_path / "c", "run-b").load()
    saved = Checkpoints(tmp_path / "c", "run-a").load()
    assert saved.next_frame == 1 and saved.records == [(0, {"x": 1.0})]


def test_a_changed_mesh_refuses_the_resume(tmp_path, capsys):
    """The checkpoint fingerprint covers the meshes the model refers to: the same model
    and trial with one fossa mesh moved by 0.1 mm give another fingerprint, and
    `openfdk run --resume` on the old checkpoint exits 2 naming the checkpoint."""
    import trimesh

    from openfdk.cli.commands import _run_checkpoints, build_parser
    from openfdk.io.fingerprint import referenced_files

    write_jaw_files(tmp_path, 10)
    out = tmp_path / "o"
    argv = ["run", str(tmp_path / "tmj.yaml"), str(tmp_path / "trial.c3d"), "--out", str(out), "--no-progress",
            "--no-plots"]
    args = build_parser().parse_args(argv)
    assert sorted(name for name, _ in referenced_files(args.model)) == [
        "meshes/condyle_l.stl", "meshes/condyle_r.stl", "meshes/fossa_l.stl", "meshes/fossa_r.stl"]
    before = _run_checkpoints(args)
    assert _run_checkpoints(args).fingerprint == before.fingerprint   # same inputs, same fingerprint
    before.save([], None, 0)                                           # a checkpoint of the old inputs
    mesh = trimesh.load(tmp_path / "meshes" / "fossa_r.stl")
    mesh.apply_translation([0.0, 0.0, 1e-4])
    mesh.export(tmp_path / "meshes" / "fossa_r.stl")
    assert _run_checkpoints(args).fingerprint != before.fingerprint
    assert main([*argv, "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "part-000000.npz: the checkpoint belongs to another run" in err[0]
    assert not (out / "forces.csv").exists()


def test_chunked_run_keeps_finished_chunks_and_resume_reuses_them(tmp_path, capsys, monkeypatch):
    """`openfdk run --chunks 3`: interrupted while solving chunk 2 (exit 130), the first
    two chunks are kept in OUT/.checkpoint; `--resume` solves only chunk 2 and the files
    equal an uninterrupted chunked run's byte for byte; the checkpoint is then removed.
    A chunk of another run (other --overlap) is refused."""
    import openfdk.study.case as case_module

    write_jaw_files(tmp_path, 30)
    solve = case_module.segment_task
    solved = []

    def counting(case, k, checks=True):
        if k == 2 and "stop" in solved:
            raise KeyboardInterrupt
        solved.append(k)
        return solve(case, k, checks)

    monkeypatch.setattr(case_module, "segment_task", counting)
    common = ["run", str(tmp_path / "pop.yaml"), str(tmp_path / "trial.c3d"), "--chunks", "3", "--workers", "0",
              "--no-progress", "--no-plots"]
    whole, out = tmp_path / "whole", tmp_path / "out"
    assert main([*common, "--out", str(whole)]) == 0 and solved == [0, 1, 2]
    assert not (whole / ".checkpoint").exists()
    solved[:] = ["stop"]
    assert main([*common, "--out", str(out)]) == 130
    assert solved == ["stop", 0, 1]
    assert sorted(p.name for p in (out / ".checkpoint").glob("*.npz")) == ["chunk-000000.npz", "chunk-000001.npz"]
    assert not (out / "forces.csv").exists()
    solved[:] = []
    assert main([*common, "--out", str(out), "--resume"]) == 0
    assert solved == [2]
    for name in ("kinematics.csv", "forces.csv"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    assert not (out / ".checkpoint").exists()
    # another run's chunk is refused
    solved[:] = ["stop"]
    other = tmp_path / "other"
    assert main([*common, "--out", str(other)]) == 130
    capsys.readouterr()
    assert main([*common, "--out", str(other), "--resume", "--overlap", "3"]) == 2
    assert "chunk-000000.npz: the checkpoint belongs to another run" in capsys.readouterr().err


class _Step:
    """A driver step that records its frame index and raises ``error`` at frame 3."""

    def __init__(self, error):
        self.error = error

    def fields(self):
        return {"value": ((), float, np.nan)}

    def step(self, k):
        if k == 3:
            raise self.error
        return [(k, {"value": float(k)})]

    def finish(self):
        return []

    def carry(self):
        return None


def _kernel_error(cause):
    """A SystemError as a compiled kernel raises it when ``cause`` happened inside it."""
    try:
        try:
            raise cause
        except BaseException as inner:
            raise SystemError("returned a result with an exception set") from inner
    except SystemError as exc:
        return exc


def test_an_interrupt_inside_a_compiled_kernel_keeps_the_finished_frames():
    """A second Ctrl-C inside a compiled kernel surfaces as SystemError (caused by the
    KeyboardInterrupt): the driver stops with the three finished frames, as for Ctrl-C
    between frames; any other SystemError is not taken for an interrupt."""
    from openfdk.trial.driver import TrialInterrupted, drive

    with pytest.raises(TrialInterrupted) as info:
        drive(_Step(_kernel_error(KeyboardInterrupt())), 6, lambda rec: rec.frames_done)
    assert info.value.partial == 3 and info.value.frames_planned == 6
    with pytest.raises(SystemError):
        drive(_Step(_kernel_error(ValueError("bad"))), 6, lambda rec: rec.frames_done)


def test_a_checkpoint_s_poses_of_another_model_s_structure_do_not_fit():
    """A BodyStates in a checkpoint's solver state (untrusted) fits the step's only with the
    same bodies and q̂ columns: those are the model's structure, and the compiled
    kernels index the pose arrays with them. Poses of the same shape with other columns
    (a crafted part) are refused, as any state of another structure; a copy of the
    step's own fits, also where the fresh state holds None."""
    from openfdk.model.builder import ModelBuilder
    from openfdk.trial.driver import _examples, _fits

    b = ModelBuilder("two")
    for name in ("a", "b"):
        b.add_body(name, 1.0, [1e-2, 1e-2, 1e-2])
    state = b.build().initial_state()
    template = (state, None)
    examples = _examples(template)
    assert _fits((state.copy(), None), template, examples)
    assert _fits((state.copy(), {0: state.copy()}), template, examples)  # where the fresh state holds None
    crafted = state.copy()
    crafted.column = crafted.column[::-1] + 1000  # same shape and dtype, other columns
    assert crafted.column.shape == state.column.shape and crafted.column.dtype == state.column.dtype
    assert not _fits((crafted, None), template, examples)
    assert not _fits((state.copy(), {0: crafted}), template, examples)


@pytest.mark.parametrize("what", ["pivot", "envelope", "multipliers"])
def test_a_resumed_fdk_run_refuses_crafted_kkt_factors(files, tmp_path, capsys, what):
    """An FDK run's checkpoint carries the last solved frame's KKT factors. A part whose
    pivots or envelope ends point outside the matrix, or whose multipliers have another
    length, rehashed as an attacker would, is refused on --resume in one line, before
    any compiled solve reads it (the solves do not check bounds)."""
    import hashlib
    import io

    from cli_helpers import error_line, run_cli
    from openfdk.analysis.jobs import run_job
    from openfdk.cli.commands import _run_checkpoints, build_parser

    out = tmp_path / "out"
    argv = [files / "tmj.yaml", files / "trial.c3d", "--out", out, "--no-progress", "--no-plots", "--end", "0.07",
            "--checkpoint-frames", "4"]
    ck = _run_checkpoints(build_parser().parse_args(["run", *map(str, argv)]))
    run_job(files / "tmj.yaml", files / "trial.c3d", progress=False, end=0.07, checkpoints=ck, rim_check=False)
    part = sorted((out / ".checkpoint").glob("part-*.npz"))[-1]  # (the last part's state is resumed)
    with np.load(part, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    model, _ = load_model_and_settings(files / "tmj.yaml")
    n = model.initial_state().n_coords
    size = max(a.shape[0] for a in arrays.values() if a.ndim == 2 and a.shape[0] == a.shape[1])  # the KKT's n + m
    index = [k for k, a in arrays.items() if a.dtype == np.int64 and a.shape == (size,)]
    # (arrays are stored in the order encoded, the carried factors last: LU, pivots,
    # envelope starts, ends and λ of each pose)
    lam = sorted((k for k, a in arrays.items() if k.startswith("a") and a.dtype == float and a.shape == (size - n,)),
                 key=lambda k: int(k[1:]))[-1:]
    assert size > n and len(index) >= 3 and lam  # (each pose's pivots, envelope starts and ends, λ)
    if what == "pivot":
        arrays[index[0]] = arrays[index[0]] + 10 ** 6
    elif what == "envelope":
        arrays[index[-1]] = arrays[index[-1]] - 10 ** 6
    else:
        arrays[lam[0]] = np.append(arrays[lam[0]], 1.0)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    data = buf.getvalue()
    part.write_bytes(data)
    side = part.with_suffix(".json")
    doc = json.loads(side.read_text())
    doc["sha256"] = hashlib.sha256(data).hexdigest()
    side.write_text(json.dumps(doc))
    code, _, err = run_cli(capsys, "run", *argv, "--resume")
    assert code == 2
    line = error_line(err)
    assert ".checkpoint: the checkpoint does not fit this run (ValueError: KKT" in line, line
