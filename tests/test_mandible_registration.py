"""Brace registration (openfdk.mandible.registration) on a virtual subject whose static
trial holds the mouth 5° open: from the subject's braces, and from the static trial
with its known static pose, both reproduce the true brace-to-bone transform; assuming
occlusion does not."""

import warnings

import numpy as np
import pytest

from openfdk.io.c3d import MarkerTrial
from openfdk.mandible.experiment import simulate_task, true_marker_positions
from openfdk.mandible.generator import create_subject, load_anatomy
from openfdk.mandible.registration import (RegistrationError, RegistrationWarning, StaticPose, register,
                                           register_from_braces, register_from_static_trial)
from openfdk.mandible.subject import load_subject
from openfdk.mandible.truth import TrueJoint, TruthOptions

OPENING_DEG = 5.0


def _static(subject, options, seed=0):
    """Noise-free static trial 5° open (condyles on the true fossae), as a MarkerTrial,
    with the true markers (body frames) and the true mean static pose R_SM, p_SM."""
    anatomy = load_anatomy(subject.directory)
    rng = np.random.default_rng(seed)
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, subject.cartilage_offset, options, rng)
    markers = true_marker_positions(subject, options, rng)
    truth = simulate_task(subject, joint, markers, "reference", head_motion=True, rng=rng,
                          static_opening_deg=OPENING_DEG)
    trial = MarkerTrial(subject.marker_labels, 100.0, truth.time, truth.markers_L, "static.c3d")
    return trial, markers, truth


@pytest.fixture(scope="module")
def subject(tmp_path_factory):
    return load_subject(create_subject(tmp_path_factory.mktemp("reg") / "subject", resolution="coarse"))


def test_given_braces_are_the_true_transform_and_the_static_trial_measures_5_degrees(subject):
    """Exact truth: the true markers are the subject's braces, so the registration from
    the braces is the true brace-to-bone transform exactly; the static trial (held still,
    head swaying) is fitted by both braces to round-off, and the static pose the fits
    measure is the true 5° opening (R_SM of the truth, p_SM within 1e-9 m)."""
    trial, markers, truth = _static(subject, TruthOptions.exact())
    reg = register_from_braces(subject, trial)
    assert reg.method == "braces" and not reg.warnings
    for body in ("skull", "mandible"):
        np.testing.assert_array_equal(reg[body][1], markers[body])
        assert reg.rms_m[body] < 1e-9
    # the truth holds the mandible still relative to the skull during the static trial
    np.testing.assert_allclose(reg.static_pose.R_SM, truth.R_SM[0], atol=1e-9)
    np.testing.assert_allclose(reg.static_pose.p_SM, truth.p_SM[0], atol=1e-9)
    # rotation angle of R_SM: the prescribed opening (roll from the contact solve is tiny)
    assert reg.static_pose.opening_deg() == pytest.approx(OPENING_DEG, abs=0.05)
    assert "only checks" in reg.assumption


def test_static_trial_with_the_known_pose_reproduces_the_truth_and_occlusion_does_not(subject):
    """Exact truth, static trial 5° open with head sway: the static-trial method with
    the true static pose recovers the true brace-to-bone transform of both braces;
    assuming occlusion puts every mandible marker millimetres away, and says so."""
    trial, markers, truth = _static(subject, TruthOptions.exact(), seed=3)
    pose = StaticPose(truth.R_SM[0], truth.p_SM[0], "true static pose")
    reg = register_from_static_trial(subject, trial, pose)
    for body in ("skull", "mandible"):
        np.testing.assert_allclose(reg[body][1], markers[body], atol=1e-9)
    assert reg.assumption.startswith("static pose given") and reg.rms_m["mandible"] < 1e-9
    occluded = register_from_static_trial(subject, trial)
    error = np.linalg.norm(occluded["mandible"][1] - markers["mandible"], axis=1)
    # 5° about the intercondylar axis moves a marker ≈ 100–140 mm away by 9–12 mm
    assert error.min() > 5e-3
    assert "occlusion" in occluded.assumption and occluded.rms_m["mandible"] < 1e-9
    np.testing.assert_allclose(occluded["skull"][1], markers["skull"], atol=1e-9)


def test_static_trial_cannot_see_a_brace_scan_bias(subject):
    """With the braces of subject.yaml off by a rigid 0.3 mm / 0.1° (the virtual
    experiment's default bias), the brace fits of the static trial still have a
    round-off RMS (a rigid bias does not show in a rigid fit) and the registration from
    the braces keeps that bias: between 0.2 and 1 mm on the mandible markers."""
    options = TruthOptions(registration_translation=0.3, registration_rotation=0.1)
    trial, markers, _ = _static(subject, options, seed=5)
    given = register_from_braces(subject, trial)
    assert max(given.rms_m.values()) < 1e-9
    assert 2e-4 < np.max(np.linalg.norm(given["mandible"][1] - markers["mandible"], axis=1)) < 1e-3


def test_static_pose_from_an_incisal_gap(subject):
    """from_incisal_gap: the incisal point drops by exactly the gap (rotation about the
    intercondylar axis, which stays fixed)."""
    pose = StaticPose.from_incisal_gap(subject, 6.0e-3)
    incisor = subject.landmarks["incisal_point"]
    moved = pose.R_SM @ incisor + pose.p_SM
    assert incisor[2] - moved[2] == pytest.approx(6.0e-3, abs=1e-12)
    for side in ("r", "l"):
        top = subject.condyle_top(side)
        centre = 0.5 * (subject.condyle_top("r") + subject.condyle_top("l"))
        on_axis = np.array([centre[0], top[1], centre[2]])
        np.testing.assert_allclose(pose.R_SM @ on_axis + pose.p_SM, on_axis, atol=1e-12)
    with pytest.raises(RegistrationError, match="cannot be reached"):
        StaticPose.from_incisal_gap(subject, 1.0)


def test_rms_above_1_mm_warns_and_bad_inputs_raise(subject):
    """One skull-brace marker 4 mm off: a RegistrationWarning naming the brace and the
    RMS; 0.2 mm off: none. No static trial for the static method: an error."""
    trial, _, _ = _static(subject, TruthOptions.exact())
    labels = subject.braces["skull"].labels
    for shift, warns in ((4e-3, True), (2e-4, False)):
        moved = trial.positions.copy()
        moved[:, trial.labels.index(labels[0]), 0] += shift
        bad = MarkerTrial(trial.labels, trial.rate, trial.time, moved, "moved.c3d")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            reg = register_from_braces(subject, bad)
        hits = [w for w in caught if issubclass(w.category, RegistrationWarning)]
        assert bool(hits) == warns
        if warns:
            assert "skull brace" in str(hits[0].message) and "RMS" in str(hits[0].message)
            assert reg.rms_m["skull"] > 1e-3 and reg.warnings
    with pytest.raises(RegistrationError, match="needs a static trial"):
        register(subject, None, "static_trial")
    with pytest.raises(RegistrationError, match="unknown registration method"):
        register(subject, trial, "laser")


def _in_frame(subject, R, t):
    """The subject with both braces given in another frame: x' = R x + t (the brace
    scan's frame instead of the subject frame)."""
    import dataclasses
    from types import MappingProxyType

    braces = {b: dataclasses.replace(subject.braces[b], positions=subject.braces[b].positions @ R.T + t)
              for b in ("skull", "mandible")}
    return dataclasses.replace(subject, braces=MappingProxyType(braces))


def test_braces_in_the_wrong_frame_fit_as_well_but_the_static_pose_check_warns(subject):
    """Both braces given in a frame T (10°/5° turned, 110 mm behind and 40 mm above the
    subject frame): each brace still fits the static trial to round-off (a rigid
    change of both nominal geometries is invisible to a rigid fit), but the brace fits
    then measure T P T⁻¹ instead of the true static pose P (the true 5° opening). The
    condyle-top shift and the incisal drop the check reports are those of T P T⁻¹,
    derived here from P and T alone; they put the condyles millimetres away from their
    fossae, so a RegistrationWarning with the numbers fires. The correct braces: no
    warning, joint spaces within 0.3 mm of the reference pose's."""
    from openfdk.numerics.spatial import rotation_matrix_xyz

    trial, _, truth = _static(subject, TruthOptions.exact(), seed=7)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        good = register_from_braces(subject, trial)
    assert not [w for w in caught if issubclass(w.category, RegistrationWarning)] and not good.warnings
    check = good.pose_check
    assert check.plausible
    for side in ("r", "l"):
        reference, static = check.joint_space_m[side]
        assert abs(static - reference) < 3e-4
    R_T, t_T = rotation_matrix_xyz(np.deg2rad([0.0, 10.0, 5.0])), np.array([-0.110, 0.0, 0.040])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        wrong = register_from_braces(_in_frame(subject, R_T, t_T), trial)
    for body in ("skull", "mandible"):
        assert wrong.rms_m[body] < 1e-9                       # the fits cannot see it
    # the scan-frame coordinates are taken as subject-frame ones, so the fits measure
    # M = T P T⁻¹: R_M = R_T R_P R_Tᵀ, p_M = R_T p_P + t_T − R_M t_T
    P_R, P_p = truth.R_SM[0], truth.p_SM[0]
    M_R = R_T @ P_R @ R_T.T
    M_p = R_T @ P_p + t_T - M_R @ t_T
    np.testing.assert_allclose(wrong.static_pose.R_SM, M_R, atol=1e-9)
    np.testing.assert_allclose(wrong.static_pose.p_SM, M_p, atol=1e-9)
    incisor = subject.landmarks["incisal_point"]
    for side in ("r", "l"):
        top = subject.condyle_top(side)
        np.testing.assert_allclose(wrong.pose_check.condyle_shift_m[side], M_R @ top + M_p - top, atol=1e-9)
    assert wrong.pose_check.incisal_gap_m == pytest.approx(-(M_R @ incisor + M_p - incisor)[2], abs=1e-9)
    assert not wrong.pose_check.plausible
    hits = [str(w.message) for w in caught if issubclass(w.category, RegistrationWarning)]
    assert len(hits) == 1 and "implausible" in hits[0] and "subject frame" in hits[0]
    assert "farther from its fossa" in hits[0] and "mm" in hits[0]
    assert wrong.to_dict()["static_pose_check"]["plausible"] is False
    assert wrong.to_dict()["static_pose_check"]["problems"]


def test_static_pose_check_limits_follow_their_definitions(subject):
    """The check on poses built by hand: the reference pose and a 5° opening about the
    intercondylar axis are plausible (condyle tops on the axis do not move); the
    mandible lowered by 3 mm moves each condyle 3 mm from its fossa (3 mm > 2 mm); an
    opening whose incisal drop is just above max_incisal_gap fails on the incisors
    only."""
    from openfdk.mandible.registration import check_static_pose

    assert check_static_pose(subject, StaticPose.occlusion()).plausible
    five = check_static_pose(subject, StaticPose.from_opening(subject, 5.0))
    assert five.plausible
    lowered = check_static_pose(subject, StaticPose(np.eye(3), np.array([0.0, 0.0, -3e-3])))
    for side in ("r", "l"):
        reference, static = lowered.joint_space_m[side]
        # a vertical drop d changes the smallest distance by between d cos(45°) and d
        # (the closest fossa point faces the eminence's slope, ≤ 45°)
        assert 3e-3 * np.cos(np.pi / 4) - 1e-4 < static - reference < 3e-3 + 1e-4
    assert len(lowered.problems) == 2 and all("farther from its fossa" in p for p in lowered.problems)
    wide = check_static_pose(subject, StaticPose.from_incisal_gap(subject, 8e-3), max_incisal_gap=7e-3)
    assert wide.incisal_gap_m == pytest.approx(8e-3, abs=1e-12)
    assert len(wide.problems) == 1 and "8.0 mm apart" in wide.problems[0]
