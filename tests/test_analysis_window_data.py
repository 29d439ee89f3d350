"""The frames of a run lie within the data its inputs are sampled over: a motion file's
coordinates (spline drivers) and the measured loads. Frames outside are left out with one
warning, or the run is refused in one line when none is left; a kinematics pass, which
uses no loads, is not cut to the loads' data. (Found on DM's tmf_slow1 two stages: a
window past the first pass's samples stopped the run half way with a spline error.)

Independent references: the frames are the motion's 100 Hz samples within the window,
counted by hand, and the coordinates there are the fixture's closed-form motion."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.cli import main
from openfdk.fixtures.full_body_osim import (
    full_body_coordinates,
    write_full_body_motion,
    write_full_body_osim,
    write_full_body_trial,
)
from openfdk.io.storage import write_storage
from test_load_filter import LOADS_XML  # the ExternalLoads of one ground reaction on calcn_r

@pytest.fixture(scope="module")
def body(tmp_path_factory):
    folder = tmp_path_factory.mktemp("window_data")
    return folder, write_full_body_osim(folder / "body.osim")


def _table(path):
    return np.genfromtxt(path, delimiter=",", names=True)


def test_frames_past_a_motion_files_samples_are_left_out(body, tmp_path, monkeypatch, capsys):
    folder, model = body
    monkeypatch.chdir(tmp_path)
    motion = write_full_body_motion(tmp_path, np.arange(21) / 100.0)  # 0 – 0.2 s at 100 Hz
    code = main(["kinematics", str(model), "--motion", str(motion), "--start", "0.1", "--end", "0.5",
                 "--out", str(tmp_path / "k"), "-q"])
    err = capsys.readouterr().err
    assert code == 0, err
    # the window's 100 Hz grid has 41 frames, 0.10 – 0.50 s; the file's samples end at 0.20 s
    assert "the 30 frame(s) outside the drivers' samples (a motion file's coordinates: 0–0.2 s) are left out" in err
    table = _table(tmp_path / "k" / "coordinates.csv")
    np.testing.assert_allclose(table["time"], np.arange(10, 21) / 100.0, rtol=0, atol=1e-12)
    q = full_body_coordinates(table["time"])
    np.testing.assert_allclose(table["knee_angle_r_rad"], q["knee_angle_r"], rtol=0, atol=1e-9)
    assert np.ptp(table["knee_angle_r_rad"]) > 0.01  # the frames move
    # a window wholly past the samples: one line, nothing computed
    code = main(["kinematics", str(model), "--motion", str(motion), "--start", "0.3", "--end", "0.5",
                 "--out", str(tmp_path / "k2"), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "no frame within the drivers' samples (a motion file's coordinates: 0–0.2 s)" in err[0]
    assert not (tmp_path / "k2" / "coordinates.csv").exists()


def test_a_kinematics_pass_is_not_cut_to_the_loads_data(body, tmp_path, monkeypatch, capsys):
    folder, model = body
    monkeypatch.chdir(tmp_path)
    trc, times, _, _ = write_full_body_trial(model, tmp_path / "walk.trc", n_frames=60, noise_m=0.0)  # 0 – 0.59 s
    t = 0.2 + np.arange(2001) / 10_000.0  # the loads' samples: 0.2 – 0.4 s
    zero = 0 * t
    write_storage(tmp_path / "grf.mot", t, {"g_vx": zero, "g_vy": 300 + zero, "g_vz": zero, "g_px": zero,
                                            "g_py": zero, "g_pz": zero, "g_tx": zero, "g_ty": zero, "g_tz": zero},
                  name="grf")
    (tmp_path / "loads.xml").write_text(LOADS_XML)
    args = [str(model), str(trc), "--external-loads", str(tmp_path / "loads.xml"), "--cutoff", "0"]
    assert main(["kinematics", *args, "--out", str(tmp_path / "k"), "-q"]) == 0
    err = capsys.readouterr().err
    assert "left out" not in err, err
    np.testing.assert_allclose(_table(tmp_path / "k" / "kinematics.csv")["time"], times, rtol=0, atol=1e-9)
    # a run applies the loads: its frames are the trial's samples within their data
    (tmp_path / "reserves.yaml").write_text("reserves: {optimal_force: 1000.0}\n")
    assert main(["run", *args, "--ignore", "forces", "--with", str(tmp_path / "reserves.yaml"),
                 "--out", str(tmp_path / "r"), "--no-plots", "-q"]) == 0
    err = capsys.readouterr().err
    assert "the 39 trial sample(s) outside the measured loads' data (0.2–0.4 s) are left out" in err, err
    np.testing.assert_allclose(_table(tmp_path / "r" / "kinematics.csv")["time"], np.arange(20, 41) / 100.0,
                               rtol=0, atol=1e-9)
    # the loads as applied are recorded per frame (world, N and m), and summary.json says
    # which body each acts on and which way gravity points (openfdk cycles reads them)
    import json

    forces = _table(tmp_path / "r" / "forces.csv")
    ok = forces["converged"] == 1
    assert ok.sum() == 21
    np.testing.assert_allclose(forces["grf_rexternal_Fy_N"][ok], 300.0, rtol=0, atol=1e-9)
    for c in ("Fx_N", "Fz_N", "px_m", "py_m", "pz_m"):
        np.testing.assert_allclose(forces[f"grf_rexternal_{c}"][ok], 0.0, rtol=0, atol=1e-9)
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["input"]["external_loads"] == {"grf_r": {"body": "calcn_r"}}
    np.testing.assert_allclose(summary["input"]["gravity_W_m_s2"], [0.0, -9.80665, 0.0], rtol=0, atol=1e-12)
