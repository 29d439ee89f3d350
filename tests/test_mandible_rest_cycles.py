"""Cycles are found relative to each record's own rest pose (issue 28): a virtual
subject whose braces hold the mouth 4° open at rest protrudes 5 mm toward
incisor-to-incisor (closing 3° on the way). Measured from the CT's incisal point, the
incisor starts 8 mm away (behind and below it), passes close to it and moves away
again, so that distance has two minima per cycle; measured from the rest pose it has
one."""

import numpy as np
import pytest

from openfdk.io.c3d import write_c3d
from openfdk.mandible.cycles import find_cycles
from openfdk.mandible.experiment import simulate_task, true_marker_positions
from openfdk.mandible.generator import create_subject, load_anatomy
from openfdk.mandible.registration import register_from_braces
from openfdk.mandible.study import measured_series, opening_signal, rest_incisor, task_cycles
from openfdk.mandible.subject import load_subject
from openfdk.mandible.truth import TrueJoint, TruthOptions

CYCLES = 7
REST_OPENING_DEG = 4.0
PROTRUSION = {"translation_mm": 5.0, "opening_deg": -3.0}


@pytest.fixture(scope="module")
def resting_open(tmp_path_factory):
    """A coarse virtual subject with a protrusion record (7 cycles, 2.75 s each) that
    rests 4° open, 0.15 mm marker noise; returns (subject, truth)."""
    folder = create_subject(tmp_path_factory.mktemp("rest") / "subject", resolution="coarse")
    subject = load_subject(folder)
    anatomy = load_anatomy(folder)
    rng = np.random.default_rng(4)
    options = TruthOptions.exact()
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, subject.cartilage_offset, options, rng)
    markers = true_marker_positions(subject, options, rng)
    truth = simulate_task(subject, joint, markers, "protrusion", cycles=CYCLES, rng=rng, frequency=1 / 2.75,
                          amplitudes=PROTRUSION, rest_opening_deg=REST_OPENING_DEG)
    noisy = truth.markers_L + np.random.default_rng(5).normal(0.0, 0.15e-3, truth.markers_L.shape)
    (folder / "trials").mkdir(exist_ok=True)
    write_c3d(folder / "trials" / "protrusion.c3d", subject.marker_labels, noisy, 100.0, units="mm")
    return subject, truth


def _true_starts(truth):
    """Times (s) at which the true cycles start (cycle index steps up)."""
    return truth.time[np.flatnonzero(np.diff(truth.cycle) > 0) + 1]


def test_protrusion_resting_4_degrees_open_gives_its_7_cycles(resting_open):
    """task_cycles finds the 7 recorded cycles, each starting within 0.2 s after the
    true start (the onset rule starts a cycle when the incisor has left the rest band,
    docs/mandible-study-outputs.md "Cycles"), and reports the rest pose: the incisal
    point of a 4° rotation about the intercondylar axis, r (sin ψ' − sin ψ) below and
    r (cos ψ − cos ψ') behind the CT's (r, ψ: the incisor's distance and angle from
    the axis)."""
    subject, truth = resting_open
    reg = register_from_braces(subject)
    found = task_cycles(subject, reg, "protrusion", n_cycles=None)
    assert found.found == CYCLES and len(found.cycles) == CYCLES
    starts = found.time[[a for a, _ in found.cycles]]
    lag = starts - _true_starts(truth)
    assert np.all(lag > -0.02) and np.all(lag < 0.2)
    axis = 0.5 * (subject.condyle_top("r") + subject.condyle_top("l"))
    x, _, z = subject.landmarks["incisal_point"] - axis
    r, psi = np.hypot(x, z), np.arctan2(z, x)
    turned = psi - np.deg2rad(REST_OPENING_DEG)          # opening turns the incisor down
    expected = np.array([r * (np.cos(turned) - np.cos(psi)), 0.0, r * (np.sin(turned) - np.sin(psi))])
    # the truth seats the condyles on the fossae, which moves the axis by < 0.3 mm
    np.testing.assert_allclose(found.rest_offset, expected, atol=0.4e-3)


def test_the_ct_incisal_point_splits_that_protrusion(resting_open):
    """The same record measured from the CT's incisal point (the signal before issue
    28): the distance dips between rest and full protrusion, and the cycle finder
    returns more than 7 cycles; from the rest incisal point (rest_incisor) exactly 7."""
    subject, truth = resting_open
    reg = register_from_braces(subject)
    time, condyles, incisor = measured_series(subject, reg, subject.protocol.trial("protrusion").file)
    ct = find_cycles(time, opening_signal(subject, incisor))
    assert len(ct.cycles) > CYCLES
    rest = rest_incisor(subject, condyles, incisor)
    assert len(find_cycles(time, opening_signal(subject, incisor, rest)).cycles) == CYCLES


def test_a_subjects_trial_with_a_marker_beyond_the_lab_is_refused(resting_open, tmp_path, monkeypatch):
    """The study's marker-only series read a subject's C3D with read_c3d directly, past
    the check every other trial gets (stop 72's sweep): a coordinate beyond 1 km is a
    corrupt number, refused in one line naming the frame, the time and the marker.
    openfdk's writer refuses such a file itself: its bound is lifted to write it."""
    from openfdk.io.c3d import C3DError, read_c3d

    subject, _ = resting_open
    good = read_c3d(subject.protocol.trial("protrusion").file)
    far = good.positions.copy()
    far[3, 2, 1] = 2.0e3  # m
    path = tmp_path / "far.c3d"
    monkeypatch.setattr("openfdk.io.c3d.MAX_LAB_COORDINATE_M", 1e9)
    write_c3d(path, good.labels, far, good.rate, units="mm")
    with pytest.raises(C3DError, match=rf"far\.c3d: frame 4 \(time 0\.03 s\): marker '{good.labels[2]}': "
                                       r"y = 2000 m is beyond 1000 m from the origin"):
        measured_series(subject, register_from_braces(subject), path)
