"""The command line end to end: kinematics from a C3D trial, run, demo, bench; bad
input gives exit code 2 and a one-line reason naming the offending item."""

import json

import numpy as np
import pytest
import yaml

from openfdk.cli import main
from openfdk.io.c3d import write_c3d
from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict


@pytest.fixture
def two_body_files(tmp_path):
    model = tmp_path / "two_body.yaml"
    model.write_text(yaml.safe_dump(two_body_model_dict()))
    t, labels, x, truth = synthetic_markers(120, rate=100.0, noise=0.0)
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0, units="mm")
    return model, tmp_path / "trial.c3d", (t, labels, x, truth)


def test_kinematics_cli_writes_csv_and_summary(two_body_files, tmp_path, capsys):
    model, trial, (t, labels, x, truth) = two_body_files
    out = tmp_path / "out"
    assert main(["kinematics", str(model), str(trial), "--out", str(out), "--no-progress", "--cutoff", "0"]) == 0
    header = (out / "kinematics.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "time"
    assert "jaw.x_m" in header and "J1.residual_x_m" in header and "converged" in header
    data = np.genfromtxt(out / "kinematics.csv", delimiter=",", names=True, usecols=range(len(header) - 1))
    # exact markers (no noise, no filter): the tracked jaw equals the true motion to the
    # C3D float32 storage precision (~1e-7 of 0.1 m)
    np.testing.assert_allclose(data["jawx_m"], truth["jaw"][0][:, 0], atol=2e-6)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kinematics"]["frames"] == 120 and summary["kinematics"]["converged_frames"] == 120


def test_missing_marker_is_named(two_body_files, tmp_path, capsys):
    model, trial, (t, labels, x, truth) = two_body_files
    labels = list(labels)
    labels[6] = "J3_renamed"
    write_c3d(tmp_path / "renamed.c3d", labels, x, 100.0)
    code = main(["kinematics", str(model), str(tmp_path / "renamed.c3d"), "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert "J3" in err and "renamed.c3d" in err
    assert len(err.splitlines()) == 1


def test_truncated_c3d_is_reported(two_body_files, tmp_path, capsys):
    model, trial, _ = two_body_files
    data = trial.read_bytes()
    bad = tmp_path / "cut.c3d"
    bad.write_bytes(data[: len(data) - 3000])
    code = main(["kinematics", str(model), str(bad), "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "cut.c3d" in err and "truncated" in err


def test_malformed_model_is_reported(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("bodies: {jaw: {mass: 1, inertia: [1, 1, 1], positon: [0, 0, 0]}}\n")
    assert main(["check", str(bad)]) == 2
    assert "bad.yaml: bodies.jaw.positon: unknown key" in capsys.readouterr().err


def test_occluded_body_frames_are_flagged_and_run_continues(two_body_files, tmp_path):
    """All four jaw markers occluded for 10 frames: those frames are flagged with a
    message naming the body; the frames before and after converge."""
    model, trial, (t, labels, x, truth) = two_body_files
    x = x.copy()
    x[50:60, 4:8] = np.nan
    write_c3d(tmp_path / "occluded.c3d", labels, x, 100.0)
    out = tmp_path / "o"
    # 10 of 120 frames failed, more than the default --max-failed 0.01: exit 3
    assert main(["kinematics", str(model), str(tmp_path / "occluded.c3d"), "--out", str(out), "--no-progress"]) == 3
    summary = json.loads((out / "summary.json").read_text())["kinematics"]
    failed = {f["frame"] for f in summary["failed_frames"]}
    # the spline cannot bridge the gap: samples 50..59 are missing, so t in (49, 60) is not visible
    assert failed == set(range(50, 60))
    assert all("jaw" in f["reason"] and "cannot be determined" in f["reason"] for f in summary["failed_frames"])
    assert summary["converged_frames"] == 110


def test_run_cli_inverse_dynamics(tmp_path, request):
    out = tmp_path / "sc"
    assert main(["run", str(request.config.rootpath / "examples/slider_crank.yaml"), "--out", str(out), "--no-progress"]) == 0
    header = (out / "forces.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "time" and "crank_drive.reaction" in header


def test_kinematics_demo_quick(tmp_path):
    """The two-body tracking example (synthetic C3D with noise and a gap) end to end."""
    from openfdk.cli.demo_kinematics import run_kinematics_demo

    out = tmp_path / "demo"
    numbers = run_kinematics_demo(out, quick=True, progress=False)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["demo"]["converged_frames"] == summary["demo"]["frames"] == numbers["frames"]
    assert numbers["jaw_position_rms_error_mm"] < 0.5  # 0.2 mm marker noise
    assert (out / "kinematics.png").stat().st_size > 10_000


def test_bench_quick_json(capsys):
    assert main(["bench", "--quick", "--json", "--only", "kinematics"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    names = {r["name"] for r in lines}
    assert "kinematics_tracking_2body_8markers_fps" in names
    assert all(r["value"] > 0 and r["unit"] for r in lines)


def test_run_reads_the_model_file_once_for_the_run_its_outputs_and_its_figures(tmp_path, request, monkeypatch):
    """``openfdk run`` builds the model once: the run, measures.csv, the generalized forces
    and the figures (the FDK DOFs' units) share it. Each build of the
    slider-crank counts here; the figures are written and name their units."""
    import openfdk.io.modelfile as modelfile

    built = []
    load = modelfile.load_model_and_settings
    monkeypatch.setattr(modelfile, "load_model_and_settings", lambda path: built.append(path) or load(path))
    import openfdk.analysis.jobs as jobs

    monkeypatch.setattr(jobs, "load_model_and_settings", modelfile.load_model_and_settings)
    out = tmp_path / "sc"
    assert main(["run", str(request.config.rootpath / "examples/slider_crank.yaml"), "--out", str(out), "--no-progress"]) == 0
    assert len(built) == 1
    assert (out / "plots" / "kinematics.png").is_file() and (out / "measures.csv").is_file()
