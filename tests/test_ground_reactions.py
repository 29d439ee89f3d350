"""Force plates of a C3D trial applied to the model (``ground_reactions``): a block
welded to the ground stands on a plate, so the weld's reaction force is, in closed form,
−(m g + F_plate) at every frame (F_plate the reaction on the subject the plate reports,
0 below the threshold); and the assignment of stances to feet, including a plate struck
by both feet, whose frames fail with that reason."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

ezc3d = pytest.importorskip("ezc3d")

from test_force_plates import (ORIGIN_2, POSES, UNITS, channels_for, corners_of, expected,  # noqa: E402
                               known_load, write_plates)

from openfdk.cli import main  # noqa: E402
from openfdk.io.results import read_table  # noqa: E402

MASS = 2.0
MARKERS_B = np.array([[0.05, 0.0, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 0.03]])  # m, body frame
P_WB = np.array([0.25, 0.30, 0.05])  # m: over the plate


def _model(folder, spec):
    data = {
        "name": "block", "gravity": [0, 0, -9.81],
        "bodies": {
            "ground": {"frames": {"anchor": {"position": P_WB.tolist()}}},
            "foot": {"mass": MASS, "inertia": [0.01, 0.01, 0.01], "position": P_WB.tolist(),
                     "markers": {f"M{k + 1}": p.tolist() for k, p in enumerate(MARKERS_B)}},
        },
        "joints": {"fix": {"type": "weld", "parent": "ground.anchor", "child": "foot.origin"}},
        "ground_reactions": spec,
        "analysis": {"marker_cutoff_hz": 0},
    }
    path = folder / "block.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _trial(folder, n_frames=40, ratio=10, feet=None, on_the_subject=False):
    """``on_the_subject``: the channels hold the force on the subject (BTS, Qualisys),
    not the action on the plate."""
    n = n_frames * ratio
    force, p, tz = known_load(n, 8 * ratio, (n_frames - 8) * ratio)
    values = channels_for(2, force, p, tz) * (-1.0 if on_the_subject else 1.0)
    rotation, centre = POSES["floor"]
    plate = {"type": 2, "corners": corners_of(rotation, centre), "origin": ORIGIN_2, "channel": list(range(1, 7))}
    markers = (P_WB + MARKERS_B) * 1000.0
    points = np.repeat(markers[:, None, :], n_frames, axis=1)
    labels = ["M1", "M2", "M3"]
    if feet is not None:  # extra foot markers (n, n_frames, 3) mm
        points = np.concatenate([points, feet[0]], axis=0)
        labels += feet[1]
    path = folder / "trial.c3d"
    write_plates(path, [plate], values, ratio=ratio, units=UNITS[2], points=points, labels=labels)
    return path, expected(2, "floor", force, p, tz)


@pytest.mark.parametrize("chunks, on_the_subject", [([], False), (["--chunks", "2", "--workers", "0"], False),
                                                    ([], True)], ids=["serial", "chunks", "force-on-subject"])
def test_a_plate_under_a_welded_block_gives_the_closed_form_reaction(tmp_path, capsys, chunks, on_the_subject):
    trial, want = _trial(tmp_path, on_the_subject=on_the_subject)
    model = _model(tmp_path, {"plates": {"plate1": {"body": "foot"}}, "threshold_n": 20.0, "cutoff_hz": 0})
    code = main(["run", str(model), str(trial), "--out", str(tmp_path / "out"), "-q", *chunks])
    assert code == 0, capsys.readouterr().err
    forces = read_table(tmp_path / "out" / "forces.csv")
    grf = read_table(tmp_path / "out" / "grf.csv")
    assert (tmp_path / "out" / "plots" / "grf.png").is_file() and (tmp_path / "out" / "grf.sto").is_file()
    t = forces["time"]
    k = np.round(t * 100).astype(int) * 10  # the plate's analog sample at each frame (ratio 10)
    F = want["force"][k]
    loaded = F[:, 2] > 20.0
    F = np.where(loaded[:, None], F, 0.0)
    reaction = np.column_stack([forces[f"fix.{c}.reaction"] for c in "xyz"])
    expected_reaction = -(MASS * np.array([0, 0, -9.81]) + F)
    np.testing.assert_allclose(reaction, expected_reaction, atol=1e-6)
    # grf.csv: the plate's reading at the frames (COP exact where loaded)
    np.testing.assert_allclose(np.column_stack([grf[f"FP1.F{c}_N"] for c in "xyz"]), want["force"][k], atol=1e-9)
    cop = np.column_stack([grf[f"FP1.cop{c}_m"] for c in "xyz"])
    np.testing.assert_allclose(cop[loaded], want["cop"][k][loaded], atol=1e-9)
    assert loaded.sum() > 10 and (~loaded).sum() > 5  # both cases happen
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (stances,) = summary["input"]["ground_reactions"].values()  # the plate's name in the file: FP1
    assert len(stances) == 1 and stances[0]["body"] == "foot"
    notes = summary["input"].get("force_plate_notes", {}).get("FP1", [])
    assert any("force on the subject" in note for note in notes) == on_the_subject
    # the viewer draws the plate's force at its centre of pressure
    from openfdk.viewer.frames import grf_frames
    from openfdk.viewer.results import read_results

    (plate,) = grf_frames(read_results(tmp_path / "out"))
    assert plate["name"] == "FP1"
    assert main(["view", str(tmp_path / "out"), "--out", str(tmp_path / "view.html")]) == 0
    assert "ground reaction" in (tmp_path / "view.html").read_text()


def _feet(n_frames, cop_mm, both):
    """Markers R_HEEL (right foot, over the plate) and L_HEEL, L2, L3 (left foot, 0.4 m
    away) (4, n_frames, 3) mm; with ``both`` the left heel is over the plate and the right
    one away for the second half of the trial."""
    right = np.repeat(cop_mm[None, :], n_frames, axis=0) + np.array([0.0, 0.0, 50.0])
    left = right + np.array([0.0, 400.0, 0.0])
    if both:
        left[n_frames // 2:] = right[n_frames // 2:] + np.array([5.0, 0.0, 0.0])
        right[n_frames // 2:] += np.array([0.0, -300.0, 0.0])
    return np.stack([right, left, left + [30.0, 0, 0], left + [0, 30.0, 0]]), ["R_HEEL", "L_HEEL", "L2", "L3"]


@pytest.mark.parametrize("both", [False, True])
def test_automatic_assignment_and_a_plate_struck_by_both_feet(tmp_path, capsys, both):
    n_frames = 40
    trial, _ = _trial(tmp_path, n_frames=n_frames, feet=_feet(n_frames, POSES["floor"][1], both))
    data = yaml.safe_load(_model(tmp_path, {"plates": {}}).read_text())
    data["bodies"]["ground"]["frames"]["anchor2"] = {"position": [0.6, 0.3, 0.05]}
    data["bodies"]["foot"]["markers"]["R_HEEL"] = {"position": [0.0, 0.0, 0.0], "weight": 0}
    # the heels jump between the feet and the left foot is welded to the ground: the heel
    # markers are named for the assignment only, not tracked (weight 0), or no pose
    # would fit them
    data["bodies"]["foot_l"] = {"mass": 1.0, "inertia": [0.01] * 3, "position": [0.6, 0.3, 0.05],
                                "markers": {"L_HEEL": {"position": [0, 0, 0], "weight": 0},
                                            "L2": {"position": [0.03, 0, 0], "weight": 0},
                                            "L3": {"position": [0, 0.03, 0], "weight": 0}}}
    data["joints"]["fix_l"] = {"type": "weld", "parent": "ground.anchor2", "child": "foot_l.origin"}
    data["ground_reactions"] = {"feet": {"foot": ["R_HEEL"], "foot_l": ["L_HEEL"]}, "cutoff_hz": 0}
    (tmp_path / "two.yaml").write_text(yaml.safe_dump(data))
    code = main(["run", str(tmp_path / "two.yaml"), str(trial), "--out", str(tmp_path / "out"), "--no-plots", "-q"])
    err = capsys.readouterr().err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (stances,) = summary["input"]["ground_reactions"].values()
    assert len(stances) == 1
    forces = read_table(tmp_path / "out" / "forces.csv")
    t0, t1 = stances[0]["start_s"], stances[0]["end_s"]
    inside = (forces["time"] >= t0 - 1e-9) & (forces["time"] <= t1 + 1e-9)
    if not both:
        assert code == 0, err
        assert stances[0]["body"] == "foot" and "nearest foot" in stances[0]["reason"]
        assert np.all(forces["converged"] == 1)
    else:  # never split between the feet: the stance's frames fail with the reason
        assert code == 3, err
        assert stances[0]["body"] is None and "both feet" in stances[0]["reason"]
        assert np.all(forces["converged"][inside] == 0) and np.all(forces["converged"][~inside] == 1)
        assert "struck by both feet" in err


def test_nan_plate_data_fails_those_frames_with_the_reason(tmp_path, capsys):
    import ezc3d as e

    trial, _ = _trial(tmp_path)
    c = e.c3d(str(trial))
    analogs = c["data"]["analogs"]
    analogs[0, 2, 150:170] = np.nan  # Fz of frames 15-16 (10 analog samples per frame)
    c["data"]["analogs"] = analogs
    c.write(str(trial))
    model = _model(tmp_path, {"plates": {"plate1": {"body": "foot"}}, "cutoff_hz": 0})
    code = main(["run", str(model), str(trial), "--out", str(tmp_path / "out"), "--no-plots", "-q"])
    err = capsys.readouterr().err
    assert code == 3 and "non-finite analog data" in err, err
    forces = read_table(tmp_path / "out" / "forces.csv")
    failed = np.flatnonzero(forces["converged"] == 0)
    np.testing.assert_array_equal(failed, [15, 16])


def test_a_trial_whose_plates_never_carry_load_is_reported(tmp_path, capsys):
    """ground_reactions set but no plate ever loaded: the run goes on, the gravity of the
    welded block alone in its reaction, and says why no ground reaction was applied."""
    import ezc3d as e

    trial, _ = _trial(tmp_path)
    c = e.c3d(str(trial))
    c["data"]["analogs"] = np.zeros_like(c["data"]["analogs"])
    c.write(str(trial))
    model = _model(tmp_path, {"plates": {"plate1": {"body": "foot"}}, "cutoff_hz": 0})
    code = main(["run", str(model), str(trial), "--out", str(tmp_path / "out"), "--no-plots", "-q"])
    err = capsys.readouterr().err
    assert code == 0
    assert f"{trial}: none of its 1 force plates is ever loaded above 20 N; ground_reactions applies no load" in err, err
    forces = read_table(tmp_path / "out" / "forces.csv")
    np.testing.assert_allclose(forces["fix.z.reaction"], MASS * 9.81, atol=1e-6)
