"""The whole mandible study on a realistic virtual subject (`openfdk subject record
--realistic --quick`): static trial 4.6° open, slow protrusion (2.75 s), 3 wide
open–close cycles (incisal opening ≈ 45 mm) where 5 are requested, chewing with a
12 mm lateral excursion inside a time window, non-standard file names declared in
`trials:`, 9 extra markers and marker gaps. The study runs through the CLI unchanged."""

import csv
import json

import numpy as np
import pytest
import yaml

from openfdk.cli import main
from openfdk.io.c3d import read_c3d
from openfdk.mandible.experiment import load_truth
from openfdk.mandible.subject import load_subject


@pytest.fixture(scope="module")
def realistic(tmp_path_factory):
    root = tmp_path_factory.mktemp("realistic")
    subject = root / "subject"
    assert main(["subject", "create", str(subject), "--resolution", "coarse"]) == 0
    assert main(["subject", "record", str(subject), "--realistic", "--quick"]) == 0
    out = root / "study"
    code = main(["subject", "study", str(subject), "--out", str(out), "--no-parameter-study", "--no-progress"])
    assert code == 0
    return subject, out


def _rows(path):
    return list(csv.DictReader(open(path)))


def test_recordings_are_realistic(realistic):
    """What the recordings hold, checked on the files and the truth: 17 markers with
    gaps, a static trial 3–6° open, wide movements, slow protrusion."""
    subject_dir, _ = realistic
    subject = load_subject(subject_dir)
    trials = subject.protocol.trials
    assert [spec.relative for spec in trials.values()] == [
        "trials/S01_static_braces.c3d", "trials/S01_chew_gum_01.c3d", "trials/S01_protrusion_slow.c3d",
        "trials/S01_open_close_max.c3d"]
    chew = read_c3d(trials["chewing"].file)
    assert chew.n_markers == 17 and np.isnan(chew.positions).any()
    static = load_truth(subject_dir, "reference")
    assert 3.0 < np.degrees(np.median(static["opening_rad"])) < 6.0
    closed = subject.landmarks["incisal_point"]
    oc = load_truth(subject_dir, "open_close")
    assert 42e-3 < closed[2] - oc["incisor_z_m"].min() < 47e-3          # incisal opening ≈ 45 mm
    assert oc["cycle"].max() == 2                                        # 3 cycles
    pro = load_truth(subject_dir, "protrusion")
    assert 9e-3 < pro["incisor_x_m"].max() - closed[0] < 11e-3          # protrusion ≈ 10 mm
    periods = np.diff([pro["time_s"][pro["cycle"] == k][0] for k in range(3)])
    assert np.all((periods > 2.5) & (periods < 3.0))
    chewing = load_truth(subject_dir, "chewing")
    assert 10e-3 < np.ptp(chewing["incisor_y_m"]) < 13e-3               # lateral excursion ≈ 12 mm
    info = yaml.safe_load((subject_dir / "truth" / "truth.yaml").read_text())
    assert info["realistic"] is True


def test_every_task_completes_with_tables_and_feasible_frames(realistic, capsys):
    _, out = realistic
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] == ["chewing", "protrusion", "open_close"] and summary["failed"] == {}
    # open–close: 3 of the 5 requested cycles, said in summary.json and in the tables
    assert summary["cycles"]["open_close"]["analysed"] == 3 and summary["cycles"]["open_close"]["requested"] == 5
    assert "3 complete cycle(s) of the 5 requested" in summary["cycles"]["open_close"]["warning"]
    assert summary["cycles"]["protrusion"]["analysed"] == 2                 # its own count in trials:
    assert summary["cycles"]["chewing"]["analysed"] == 5
    t1, t2 = _rows(out / "table1.csv"), _rows(out / "table2.csv")
    assert len(t1) == len(t2) == 3 * 2 * 3
    n = {row["task"]: int(row["n_cycles"]) for row in t1}
    assert n == {"chewing": 5, "protrusion": 2, "open_close": 3}
    for task, runs in summary["runs"].items():
        for model in ("POP", "FDK"):
            assert summary["feasible_share"][task][model] == pytest.approx(
                runs[model]["forces_converged"] / runs[model]["frames"])
            assert runs[model]["failed_frames"]["frames"] == runs[model]["frames"] - runs[model]["forces_converged"]
            if (task, model) == ("open_close", "POP"):
                continue            # infeasible at the widest openings: test_pop_fails_only_at_the_widest_openings
            # POP and FDK feasible on >= 99.5 % of the frames
            assert runs[model]["forces_converged"] >= 0.995 * runs[model]["frames"], (task, model)
    # the registration in use is written with the study
    registration = yaml.safe_load((out / "registration.yaml").read_text())
    assert registration["method"] == "braces" and registration["rms_mm"]["mandible"] < 1.0
    assert 3.0 < registration["static_pose"]["rotation_deg"] < 6.0


def test_pop_fails_only_at_the_widest_openings(realistic):
    """With Thelen's passive strain (0.6) the stretched closers' passive tension exceeds
    what the openers can balance near the widest opening (issue 28: the paper's forces
    chosen over the widest openings' feasibility). Every POP open–close frame whose true
    incisal opening (truth/open_close.csv, the incisor's distance from its closed
    position) is below 40 mm is feasible; the failed frames are the ones summary.json
    lists (count and time spans), none hidden; forces.csv marks them infeasible."""
    subject_dir, out = realistic
    rows = _rows(out / "open_close" / "pop" / "forces.csv")
    time = np.array([float(r["time"]) for r in rows])
    failed = np.array([r["converged"] != "1" for r in rows])
    truth = load_truth(subject_dir, "open_close")
    closed = load_subject(subject_dir).landmarks["incisal_point"]
    incisor = np.stack([truth[f"incisor_{a}_m"] for a in "xyz"], axis=1)
    opening = np.interp(time, truth["time_s"], np.linalg.norm(incisor - closed, axis=1))
    assert not failed[opening < 40e-3].any()
    summary = json.loads((out / "summary.json").read_text())["runs"]["open_close"]["POP"]["failed_frames"]
    assert summary["frames"] == int(failed.sum())
    spans = summary["spans_s"]
    listed = np.zeros_like(failed)
    for a, b in spans:
        listed |= (time >= a - 1e-6) & (time <= b + 1e-6)
    np.testing.assert_array_equal(listed, failed)
    assert all(r["status"].startswith("infeasible") for r, f in zip(rows, failed) if f)


def test_table2_is_in_the_papers_range(realistic):
    """Every Table 2 row's RMSD (POP vs FDK) inside [0.5, 30] N (the paper's rows span
    0.75–24.7 N), and open–close loads each TMJ with tens of newtons (FDK median ≥
    10 N over the analysed frames)."""
    _, out = realistic
    rmsd = [float(r["POP_RMSD_mean"]) for r in _rows(out / "table2.csv")]
    assert 0.5 <= min(rmsd) and max(rmsd) <= 30.0, rmsd
    rows = _rows(out / "open_close" / "fdk" / "forces.csv")
    for tag in "rl":
        F = np.array([[float(r[f"tmj_{tag}.F{c}_N"]) for c in "xyz"] for r in rows])
        assert np.nanmedian(np.linalg.norm(F, axis=1)) >= 10.0


def test_pop_kinematics_match_the_measured_ones(realistic):
    """POP condyle kinematics vs the brace measurement: RMSD < 1 mm on every row and
    r² ≥ 0.95 on every AP and SI row (the paper's Table 1 accuracy)."""
    _, out = realistic
    for row in _rows(out / "table1.csv"):
        assert float(row["POP_RMSD_mean"]) < 1.0, row
        if row["direction"] in ("AP", "SI"):
            assert float(row["POP_r2_mean"]) >= 0.95, row


def test_fdk_solves_99_5_percent_of_the_wide_chewing_frames(realistic):
    _, out = realistic
    runs = json.loads((out / "summary.json").read_text())["runs"]["chewing"]["FDK"]
    assert runs["forces_converged"] >= 0.995 * runs["frames"]


def test_fdk_restart_finds_the_root_where_the_warm_start_stalls_in_the_wide_chewing(realistic, tmp_path, capsys):
    """The mechanism of docs/fdk.md "Restarts" on the wide chewing: where the solution
    jumps by mm along the soft medio-lateral DOF between two frames, Newton from the
    run's warm start (the previous frame's α: the mandible FDK model continues without
    extrapolating) stalls at a non-root minimiser of ‖f^FDK‖ (≫ tolerance, mm away from
    the root); the study's restarted α is a root of a fresh evaluation."""
    from openfdk.fdk.analysis import FDKStep, fdk_context
    from openfdk.fdk.newton import solve_frame
    from openfdk.fdk.residual import FrameWorkspace
    from openfdk.fdk.settings import fdk_settings
    from openfdk.io.modelfile import load_model_and_settings
    from openfdk.analysis.jobs import analysis_inputs

    subject_dir, out = realistic
    rows = _rows(out / "chewing" / "fdk" / "forces.csv")
    restarted = [i for i, r in enumerate(rows) if int(r["fdk_restarts"]) > 0]
    assert restarted and all(rows[i]["fdk_converged"] == "1" for i in restarted)
    ml = np.array([float(r["fdk.tmj_ml.alpha"]) for r in rows])
    i = max(restarted, key=lambda j: abs(ml[j] - ml[j - 1]))   # the restarted frame with the largest jump
    assert abs(ml[i] - ml[i - 1]) > 1e-3                       # a jump of > 1 mm in 10 ms
    t = float(rows[i]["time"])
    model, file_settings = load_model_and_settings(out / "models" / "fdk.yaml")
    trial = load_subject(subject_dir).protocol.trials["chewing"].file
    traj, times, _ = analysis_inputs(model, trial, None, t - 0.1, t + 0.02, file_settings)
    ctx = fdk_context(model, traj, times, settings=file_settings)
    settings = fdk_settings(model, file_settings)
    step = FDKStep(model, ctx, settings)
    k = int(np.argmin(np.abs(times - t)))
    for j in range(k):
        step.step(j)
    ws = FrameWorkspace({j: step.last_state for j in ctx.frames_needed(k)})
    # the run's warm start: α_{k−1} (the mandible FDK model continues, extrapolate: false)
    a0 = 2 * step.history[-1][1] - step.history[-2][1] if settings.extrapolate else step.history[-1][1]
    stalled = solve_frame(ctx, k, a0, ws.copy(), settings, step.warm, step.J_carry)
    assert not stalled.converged and stalled.best.norm > 100 * settings.tolerance
    root = np.array([float(rows[i][f"fdk.{d.name}.alpha"]) for d in model.fdk_dofs])
    assert abs(stalled.best.alpha[2] - root[2]) > 1e-3
    ev = ctx.evaluate(k, root, ws.copy(), step.warm)
    assert ev.ok and ev.norm < 2 * settings.tolerance
    # `openfdk run` over the same frames says that a frame was restarted
    code = main(["run", str(out / "models" / "fdk.yaml"), str(trial), "--start", f"{t - 0.1:.2f}", "--end",
                 f"{t + 0.01:.2f}", "--out", str(tmp_path / "run"), "--no-plots", "--no-progress"])
    assert code == 0
    assert "frame(s) restarted from another starting α" in capsys.readouterr().out


def test_fdk_medio_lateral_jumps_are_reported_and_checked(realistic):
    """summary.json reports the FDK medio-lateral DOF's largest frame-to-frame jump per
    task, equal to the largest |Δα| of the run's forces.csv; at the largest jumps the
    continuation check re-solves the run (its previous and reported α equal the run's,
    within 0.05 mm) and says whether a root near the previous frame's α exists."""
    _, out = realistic
    summary = json.loads((out / "summary.json").read_text())
    for task in summary["completed"]:
        rows = _rows(out / task / "fdk" / "forces.csv")
        time = np.array([float(r["time"]) for r in rows])
        ml = 1e3 * np.array([float(r["fdk.tmj_ml.alpha"]) for r in rows])
        jumps = summary["runs"][task]["FDK"]["ml_jumps"]
        assert summary["fdk_ml_jump_max_mm"][task] == jumps["max_mm"]
        assert jumps["max_mm"] == pytest.approx(np.nanmax(np.abs(np.diff(ml))), abs=1e-3)
        assert jumps["count"] == int(np.sum(np.abs(np.diff(ml)) > 0.5))
        for check in jumps["continuation_check"]:
            k = int(np.argmin(np.abs(time - check["t_s"])))
            assert check["previous_mm"] == pytest.approx(ml[k - 1], abs=0.05)
            assert check["reported_mm"] == pytest.approx(ml[k], abs=0.05)
            assert check["second_root"] == (check["continued_converged"]
                                            and abs(check["continued_mm"] - check["reported_mm"]) > 0.3)
