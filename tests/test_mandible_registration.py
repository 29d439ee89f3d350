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
