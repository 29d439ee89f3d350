"""The study sections of a subject folder (trials, registration, condyle_point,
muscle_calibration, hyoid): parsing, errors that name the entry, the missing-file error
of `openfdk subject study`, and the settable condyle point."""

import shutil

import numpy as np
import pytest
import yaml

from openfdk.cli import main
from openfdk.io.c3d import MarkerTrial
from openfdk.mandible import SubjectError, create_subject, load_subject

MM = 1e-3


@pytest.fixture(scope="module")
def subject_dir(tmp_path_factory):
    return create_subject(tmp_path_factory.mktemp("protocol") / "virtual", resolution="coarse")


def _with(subject_dir, tmp_path, **sections):
    target = tmp_path / "copy"
    shutil.copytree(subject_dir, target)
    path = target / "subject.yaml"
    data = yaml.safe_load(path.read_text())
    data.update(sections)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return target


def test_defaults_without_study_sections(subject_dir):
    p = load_subject(subject_dir).protocol
    assert list(p.trials) == ["reference", "chewing", "protrusion", "open_close"]
    assert p.tasks == ("chewing", "protrusion", "open_close")
    assert p.trials["reference"].kind == "static" and p.static_trial == "reference"
    assert p.trials["chewing"].file == subject_dir / "trials" / "chewing.c3d"
    assert p.registration_method == "braces" and p.static_pose is None
    assert dict(p.condyle_points) == {"r": "condyle_top_r", "l": "condyle_top_l"}
    assert p.calibration_opening == pytest.approx(np.deg2rad(22.5))
    np.testing.assert_allclose(p.calibration_translation, [10 * MM, 0, -5.5 * MM])


def test_trials_section_names_kinds_windows_and_cycles(subject_dir, tmp_path):
    folder = _with(subject_dir, tmp_path, trials={
        "reference": "trials/Static 01.c3d",
        "chewing": {"file": "trials/chew.c3d", "window": [1.5, 18.0]},
        "wide_open": {"file": "other/wide.c3d", "kind": "open_close", "cycles": "all"},
        "protrusion": {"file": "trials/p.c3d", "cycles": 3}},
        registration={"method": "static_trial", "static_pose": {"opening": 4.6, "translation": [0, 0, -1]}},
        condyle_point={"r": "molar_r"})
    p = load_subject(folder).protocol
    assert p.tasks == ("chewing", "wide_open", "protrusion")
    assert p.trials["wide_open"].kind == "open_close" and p.trials["wide_open"].cycles == "all"
    assert p.trials["wide_open"].file == folder / "other" / "wide.c3d"
    assert p.trials["chewing"].window == (1.5, 18.0) and p.trials["protrusion"].cycles == 3
    assert p.static_trial == "reference" and p.registration_method == "static_trial"
    assert p.static_pose["opening"] == pytest.approx(np.deg2rad(4.6))
    np.testing.assert_allclose(p.static_pose["translation"], [0, 0, -MM])
    assert dict(p.condyle_points) == {"r": "molar_r", "l": "condyle_top_l"}


@pytest.mark.parametrize("sections,message", [
    ({"trials": {"bite": "trials/bite.c3d"}}, r"trials\.bite: missing 'kind'"),
    ({"trials": {"chewing": {"file": "a.c3d", "kind": "yawning"}}}, r"trials\.chewing\.kind: unknown kind 'yawning'"),
    ({"trials": {"chewing": {"file": "a.c3d", "window": [5, 2]}}}, r"trials\.chewing\.window: expected \[start, end\]"),
    ({"trials": {"chewing": {"file": "a.c3d", "cycles": 0}}}, r"trials\.chewing\.cycles: expected a whole number"),
    ({"trials": {"reference": {"file": "s.c3d", "cycles": 2}}}, r"trials\.reference: a static trial takes no"),
    ({"trials": {"chewing": {"file": "a.c3d", "speed": 2}}}, r"trials\.chewing\.speed: unknown key"),
    ({"trials": {"chew/1": "a.c3d"}}, r"trials\.chew/1: a task name may hold"),
    ({"registration": {"method": "laser"}}, r"registration\.method: expected 'braces' or 'static_trial'"),
    ({"registration": {"static_pose": {"opening": 4}}}, r"registration\.static_pose: only used with method"),
    ({"registration": {"method": "static_trial", "static_trial": "chewing"}},
     r"registration\.static_trial: 'chewing' is not a static trial"),
    ({"condyle_point": {"l": "condyle_centre_l"}}, r"condyle_point\.l: unknown landmark 'condyle_centre_l'"),
    ({"hyoid": {"muscles": ["digastric_x"]}}, r"hyoid\.muscles: unknown muscle"),
    ({"hyoid": {"follow": 1.5}}, r"hyoid\.follow: must be in \[0.0, 1.0\]"),
])
def test_bad_study_sections_name_the_entry(subject_dir, tmp_path, sections, message):
    folder = _with(subject_dir, tmp_path, **sections)
    with pytest.raises(SubjectError, match=message) as info:
        load_subject(folder)
    assert "subject.yaml" in str(info.value)


def test_missing_trial_file_names_the_task_and_the_file(subject_dir, tmp_path, capsys):
    """`openfdk subject study` on a subject whose trials: names a missing file: exit 2,
    one line naming the task entry and the file; nothing analysed."""
    folder = _with(subject_dir, tmp_path, trials={"chewing": {"file": "trials/Chew_01.c3d"}})
    out = tmp_path / "study"
    assert main(["subject", "study", str(folder), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "trials.chewing: file 'trials/Chew_01.c3d' not found" in err[0] and "subject.yaml" in err[0]
    assert not (out / "models").exists()


def test_condyle_point_is_settable(subject_dir, tmp_path):
    """A landmark 3 mm below each condyle top as the compared point: the measured series
    of a static trial 5° open is R_SM c + p_SM of that point (truth of the static pose)."""
    from openfdk.mandible.experiment import simulate_task, true_marker_positions
    from openfdk.mandible.generator import load_anatomy
    from openfdk.mandible.registration import register_from_braces
    from openfdk.mandible.study import measured_series
    from openfdk.mandible.truth import TrueJoint, TruthOptions

    base = load_subject(subject_dir)
    landmarks = yaml.safe_load((subject_dir / "subject.yaml").read_text())["landmarks"]
    for side in ("r", "l"):
        landmarks[f"condyle_centre_{side}"] = [float(v) for v in np.add(landmarks[f"condyle_top_{side}"], [0.0, 0.0, -3.0])]
    folder = _with(subject_dir, tmp_path, landmarks=landmarks,
                   condyle_point={"r": "condyle_centre_r", "l": "condyle_centre_l"})
    subject = load_subject(folder)
    np.testing.assert_allclose(subject.condyle_point("r"), base.condyle_top("r") - [0, 0, 3 * MM], atol=1e-12)
    rng = np.random.default_rng(2)
    anatomy = load_anatomy(folder)
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, subject.cartilage_offset, TruthOptions.exact(), rng)
    markers = true_marker_positions(subject, TruthOptions.exact(), rng)
    truth = simulate_task(subject, joint, markers, "reference", rng=rng, static_opening_deg=5.0)
    trial = MarkerTrial(subject.marker_labels, 100.0, truth.time, truth.markers_L, "static")
    _, points, _ = measured_series(subject, register_from_braces(subject), trial, cutoff_hz=None)
    for side, tag in (("right", "r"), ("left", "l")):
        expected = truth.R_SM[0] @ subject.condyle_point(tag) + truth.p_SM[0]
        np.testing.assert_allclose(points[side], np.tile(expected, (len(truth.time), 1)), atol=1e-9)
        # and not the condyle top: 5° about the axis moves the two points differently
        top = truth.R_SM[0] @ subject.condyle_top(tag) + truth.p_SM[0]
        assert np.linalg.norm(expected - top) > 2.5 * MM


def test_a_failing_task_is_reported_and_the_others_are_written(subject_dir, tmp_path, capsys):
    """A task whose record holds no movement (the static trial declared as chewing)
    fails; summary.json names it with the reason, the other task's tables and figures
    are written, and the command exits 3 (completed with failures) after saying so."""
    import csv
    import json

    from openfdk.mandible.experiment import record_experiment

    folder = _with(subject_dir, tmp_path, trials={
        "reference": "trials/reference.c3d",
        "still": {"file": "trials/reference.c3d", "kind": "chewing"},
        "open_close": "trials/open_close.c3d"})
    record_experiment(folder, tasks=("open_close",), cycles=3)
    out = tmp_path / "study"
    code = main(["subject", "study", str(folder), "--out", str(out), "--cycles", "2", "--no-parameter-study",
                 "--no-progress"])
    assert code == 3  # completed with failures (issue 16's exit codes), not bad input
    err = capsys.readouterr().err
    assert "task 'still' failed" in err
    assert "openfdk: 1 task(s) failed" in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] == ["open_close"] and list(summary["failed"]) == ["still"]
    assert "no periodic movement" in summary["failed"]["still"]
    rows = list(csv.DictReader(open(out / "table1.csv")))
    assert {r["task"] for r in rows} == {"open_close"} and {r["n_cycles"] for r in rows} == {"2"}
    assert (out / "figures" / "open_close_kinematics.png").is_file()
    assert not (out / "figures" / "still_kinematics.png").exists()


def test_static_pose_takes_the_rotation_and_translation_registration_yaml_reports(subject_dir, tmp_path):
    """The static pose a braces registration measures, written to registration.yaml
    (R_SM rounded to 9 digits, p_SM in mm to 6), pasted as it is into
    registration.static_pose: the static_trial registration uses that pose (to the
    printed digits), and carries the static trial's mandible markers to the subject's
    braces as the braces registration does. A rotation in the file's length unit
    ({rotation, translation}) is read too; a matrix that is not a rotation is refused."""
    from openfdk.mandible.experiment import simulate_task, true_marker_positions
    from openfdk.mandible.generator import load_anatomy
    from openfdk.mandible.registration import register_from_braces
    from openfdk.mandible.study import register_subject, static_pose
    from openfdk.mandible.truth import TrueJoint, TruthOptions

    base = load_subject(subject_dir)
    rng = np.random.default_rng(2)
    anatomy = load_anatomy(subject_dir)
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, base.cartilage_offset, TruthOptions.exact(), rng)
    markers = true_marker_positions(base, TruthOptions.exact(), rng)
    truth = simulate_task(base, joint, markers, "reference", rng=rng, static_opening_deg=4.6)
    trial = MarkerTrial(base.marker_labels, 100.0, truth.time, truth.markers_L, "static.c3d")
    reported = yaml.safe_load(yaml.safe_dump(register_from_braces(base, trial).to_dict()))["static_pose"]
    folder = _with(subject_dir, tmp_path, trials={"reference": {"file": "trials/static.c3d", "kind": "static"}},
                   registration={"method": "static_trial", "static_pose": reported})
    from openfdk.io.c3d import write_c3d

    (folder / "trials").mkdir(exist_ok=True)
    write_c3d(folder / "trials" / "static.c3d", base.marker_labels, truth.markers_L, 100.0, units="mm")
    subject = load_subject(folder)
    pose = static_pose(subject)
    np.testing.assert_allclose(pose.R_SM, truth.R_SM[0], atol=2e-9)
    np.testing.assert_allclose(pose.p_SM, truth.p_SM[0], atol=2e-9)
    reg = register_subject(subject)
    assert reg.method == "static_trial"
    # float32 C3D coordinates (lab positions near 1 m: ≈ 6e-8 m resolution)
    np.testing.assert_allclose(reg["mandible"][1], base.braces["mandible"].positions, atol=1e-6)
    folder2 = _with(subject_dir, tmp_path / "b", registration={"method": "static_trial", "static_pose": {
        "rotation": reported["R_SM"], "translation": reported["p_SM_mm"]}})
    np.testing.assert_allclose(static_pose(load_subject(folder2)).p_SM, truth.p_SM[0], atol=2e-9)
    bad = dict(reported, R_SM=[[1, 0, 0], [0, 1, 0], [0, 0, 2]])
    with pytest.raises(SubjectError, match=r"registration\.static_pose\.R_SM: expected a rotation matrix"):
        load_subject(_with(subject_dir, tmp_path / "c", registration={"method": "static_trial", "static_pose": bad}))
