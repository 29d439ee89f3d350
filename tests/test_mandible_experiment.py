"""The virtual experiment: ground truth on the true joint, C3D markers, motion ranges.

Independent checks: exact point–mesh signed distances (libigl) instead of the contact
solver's vertical gap; a rigid fit of the C3D markers against the written true poses
with a tolerance derived from float32 storage; motion ranges from the published values
(shared/reference/mandible-reference-data.md, "Jaw motion").
"""

import igl
import numpy as np
import pytest
import trimesh

from openfdk.io.c3d import read_c3d
from openfdk.mandible import (
    TruthOptions,
    create_subject,
    load_subject,
    load_truth,
    measured_condyle_kinematics,
    record_experiment,
    rigid_fit,
)
from openfdk.mandible.experiment import (
    load_true_joint,
    simulate_task,
    true_marker_positions,
)
from openfdk.mandible.generator import load_anatomy
from openfdk.mandible.geometry import fossa_mesh
from openfdk.mandible.truth import TrueJoint
from openfdk.numerics.spatial import rotation_matrix

TASKS = ("reference", "chewing", "protrusion", "open_close")
MM = 1e-3


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Coarse subject, default truth differences, 2 cycles per task."""
    folder = create_subject(tmp_path_factory.mktemp("exp") / "virtual", resolution="coarse")
    written = record_experiment(folder, cycles=2, seed=1)
    return folder, written


@pytest.fixture(scope="module")
def exact(tmp_path_factory):
    """Default-resolution subject, truth = model, no marker noise, 1 cycle per task."""
    folder = create_subject(tmp_path_factory.mktemp("exact") / "virtual")
    record_experiment(folder, cycles=1, noise_mm=0.0, truth=TruthOptions.exact(), seed=2)
    return folder


def _poses(truth, name):
    q = np.column_stack([truth[f"{name}_q{i}"] for i in range(4)])
    p = np.column_stack([truth[f"{name}_p{a}_m"] for a in "xyz"])
    return np.array([rotation_matrix(qi) for qi in q]), p


def _vec(truth, name):
    return np.column_stack([truth[f"{name}_{a}_m"] for a in "xyz"])


def test_written_files(recorded):
    folder, written = recorded
    for task in TASKS:
        assert written[f"trials/{task}.c3d"].is_file() and written[f"truth/{task}.csv"].is_file()
        trial = read_c3d(written[f"trials/{task}.c3d"])
        assert trial.rate == 100.0 and len(trial.labels) == 8
        assert trial.n_frames == len(load_truth(folder, task)["time_s"])
    assert written["truth/README.md"].read_text().startswith("# Ground truth")


# --------------------------------------------------------------------------------------
# Ground truth on the true joint
# --------------------------------------------------------------------------------------

def test_condyles_stay_on_the_true_fossa_through_the_true_layer(recorded):
    """Every frame of every task: the exact signed distance (libigl, pseudonormal sign,
    positive in the joint space) of the true offset condyle surface to a 0.25 mm mesh
    of the true fossa has its minimum within ±0.05 mm of zero.

    Only sample points whose vertical gap to the true fossa is below 0.3 mm are sent to
    libigl (a point further below a height field with slopes ≤ 56° is ≥ 0.3 cos 56° =
    0.17 mm away, so the filter cannot hide a violation; penetrating points are kept).
    Discretisation: fossa mesh sagitta ≤ h²/8 · max|Z''| ≈ 0.002 mm; condyle sampling
    on a 35 × 35 parameter grid (≤ 0.53 mm spacing) adds ≤ ½ κ (h/2)² ≈ 0.003 mm.
    """
    folder, _ = recorded
    joint, _ = load_true_joint(folder)
    u = np.linspace(-0.9, 0.9, 35)
    s = np.stack(np.meshgrid(u, u, indexing="ij"), axis=-1).reshape(-1, 2)
    s = s[np.hypot(*s.T) <= 0.9]
    worst = 0.0
    for side in ("r", "l"):
        V, F = fossa_mesh(joint.fossae[side], 145, 137, height=lambda x, y, side=side: joint.fossa_height(side, x, y))
        points_M = joint.offset_points(side, s)
        for task in TASKS:
            truth = load_truth(folder, task)
            R, p = _poses(truth, "mandible_in_skull")
            P = np.einsum("nij,kj->nki", R, points_M) + p[:, None]          # (frames, K, 3)
            vertical = joint.fossa_height(side, P[..., 0], P[..., 1]) - P[..., 2]
            near = vertical < 0.3e-3
            assert np.all(near.any(axis=1)), (task, side, "a condyle lost contact")
            frame = np.nonzero(near)[0]
            d = igl.signed_distance(P[near], V, F, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)[0]
            closest = np.full(len(p), np.inf)
            np.minimum.at(closest, frame, d)
            worst = max(worst, np.max(np.abs(closest)))
            assert np.max(np.abs(closest)) < 0.05e-3, (task, side, np.argmax(np.abs(closest)))
    assert worst > 0.0


def test_the_true_layer_is_the_documented_disc(recorded):
    """L + excess at the antero-superior (n₁ = 1/√2), superior and postero-superior
    normals of the condyle (closed form: on the e1–e3 section of the ellipsoid the
    normal is 45° from vertical where ŭ/b = ŵ/c, i.e. ŭ = b/√(b² + c²))."""
    folder, _ = recorded
    joint, _ = load_true_joint(folder)
    options = TruthOptions()
    b, _, c = joint.condyles["r"].semi_axes
    u45 = b / np.hypot(b, c)
    s = np.array([[u45, 0.0], [0.0, 0.0], [-u45, 0.0]])
    expected = 1e-3 + MM * np.array([options.disc_excess_anterior, options.disc_excess_superior,
                                     options.disc_excess_posterior])
    np.testing.assert_allclose(joint.disc_thickness("r", s), expected, atol=1e-12)
    assert joint.fossa_errors["r"].rms == pytest.approx(0.2e-3)


def test_symmetric_subject_open_close_is_left_right_symmetric(recorded):
    folder, _ = recorded
    subject, anatomy = load_subject(folder), load_anatomy(folder)
    options = TruthOptions(segmentation_error_rms=0.0)          # the disc stays on (symmetric)
    rng = np.random.default_rng(5)
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, subject.cartilage_offset, options, rng)
    markers = true_marker_positions(subject, options, rng)
    truth = simulate_task(subject, joint, markers, "open_close", cycles=1, rng=rng)
    right, left = truth.condyle_S[:, 0], truth.condyle_S[:, 1]
    np.testing.assert_allclose(right * [1, -1, 1], left, atol=1e-9)
    np.testing.assert_allclose(truth.roll, 0.0, atol=1e-8)
    assert np.ptp(right[:, 0]) > 5e-3                              # it did move


# --------------------------------------------------------------------------------------
# Published motion ranges, per cycle, from the truth
# --------------------------------------------------------------------------------------

def _cycle_extremes(folder, task):
    truth = load_truth(folder, task)
    cycle = truth["cycle"].astype(int)
    closed = 0                                                    # rest frame
    incisor = _vec(truth, "incisor") - _vec(truth, "incisor")[closed]
    cond = {s: _vec(truth, f"condyle_{s}") - _vec(truth, f"condyle_{s}")[closed] for s in "rl"}
    for k in range(cycle.max() + 1):
        m = cycle == k
        yield truth, m, incisor[m], {s: c[m] for s, c in cond.items()}


def test_open_close_ranges(recorded):
    folder, _ = recorded
    for truth, m, incisor, cond in _cycle_extremes(folder, "open_close"):
        assert 20e-3 <= -incisor[:, 2].min() <= 25e-3                # incisal opening 20–25 mm
        for side in "rl":
            assert 5e-3 <= cond[side][:, 0].max() <= 8e-3            # forward 5–8 mm
            assert 4e-3 <= -cond[side][:, 2].min() <= 7e-3           # down 4–7 mm
        # rotation first: when the opening angle reaches half its peak, the condyles
        # have made well under half their forward travel (q² profile: a quarter)
        opening = truth["opening_rad"][m]
        half = np.argmax(opening >= 0.5 * opening.max())
        assert cond["r"][half, 0] < 0.35 * cond["r"][:, 0].max()


def test_protrusion_ranges(recorded):
    folder, _ = recorded
    for _, m, incisor, cond in _cycle_extremes(folder, "protrusion"):
        assert 8e-3 <= incisor[:, 0].max() <= 10e-3                  # incisor 8–10 mm forward
        assert 1e-3 <= -incisor[:, 2].min() <= 5e-3                  # "a few mm" down
        for side in "rl":
            assert 8e-3 <= cond[side][:, 0].max() <= 10e-3           # condyles 8–10 mm forward
            assert 5e-3 <= -cond[side][:, 2].min() <= 8e-3           # 5–8 mm down


def test_chewing_ranges(recorded):
    folder, _ = recorded
    truth = load_truth(folder, "chewing")
    periods = [np.ptp(truth["time_s"][truth["cycle"] == k]) + 0.01 for k in range(2)]
    assert all(1 / 1.6 <= T <= 1 / 1.0 for T in periods)            # 1–1.6 Hz
    for _, m, incisor, cond in _cycle_extremes(folder, "chewing"):
        assert 15e-3 <= -incisor[:, 2].min() <= 20e-3                # vertical 15–20 mm
        assert 5e-3 <= incisor[:, 1].max() <= 14e-3                  # lateral 5–14 mm (to the left)
        working, balancing = cond["l"], cond["r"]                   # left-side chewing
        assert np.linalg.norm(working, axis=1).max() < 2e-3          # moves little
        assert balancing[:, 0].max() > 4e-3                          # forward
        assert -balancing[:, 2].min() > 3e-3                         # down
        assert balancing[:, 1].max() > 0.5e-3                        # medially (+y on the right)


def test_default_protocol_has_five_varying_cycles(recorded):
    folder, _ = recorded
    subject, anatomy = load_subject(folder), load_anatomy(folder)
    rng = np.random.default_rng(0)
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, subject.cartilage_offset, TruthOptions(), rng)
    truth = simulate_task(subject, joint, true_marker_positions(subject, TruthOptions(), rng),
                          "protrusion", rng=rng)
    assert truth.cycle.max() == 4                                    # five cycles (0..4)
    peaks = [truth.condyle_S[truth.cycle == k, 0, 0].max() for k in range(5)]
    assert np.ptp(peaks) > 1e-5                                      # cycle-to-cycle variation
    durations = [np.sum(truth.cycle == k) for k in range(5)]
    assert len(set(durations)) > 1


# --------------------------------------------------------------------------------------
# Markers, registration, the brace measurement
# --------------------------------------------------------------------------------------

def test_markers_reproduce_the_true_poses(exact):
    """No noise, no registration difference: a rigid fit of the C3D markers with the
    subject's marker positions gives the true poses to float32 precision.

    Tolerance: C3D stores mm as float32; each coordinate is off by at most ε = ½ ulp of
    the largest coordinate. For 4 markers at (±c, ±c) on a plate (c = 22 mm), the
    first-order Kabsch rotation error is δθ = M⁻¹ Σ a_i × e_i with M = Σ(|a|² I − a aᵀ)
    (smallest eigenvalue 4c²), so δθ ≤ 4·√2c·√3ε / 4c² = √6 ε/c, and a point at
    distance L from the marker centroid moves by ≤ √3 ε + L √6 ε / c.
    """
    subject = load_subject(exact)
    for task in TASKS:
        trial = read_c3d(exact / "trials" / f"{task}.c3d")
        truth = load_truth(exact, task)
        eps = 0.5 * float(np.spacing(np.float32(np.abs(trial.positions).max() / MM))) * MM
        c = 0.022
        for body, name in (("skull", "skull"), ("mandible", "mandible")):
            brace = subject.braces[body]
            R_fit, p_fit = rigid_fit(brace.positions, trial.select(brace.labels).positions)
            R_true, p_true = _poses(truth, name)
            # |ΔR e_k| ≤ δθ ≤ √6 ε / c (first order; ×1.5 for the neglected higher orders)
            assert np.max(np.linalg.norm(R_fit - R_true, axis=1)) < 1.5 * np.sqrt(6) * eps / c
            # the brace markers (L ≤ √2 c from the centroid): ≤ (√3 + 2√3) ε
            a = brace.positions
            err = (np.einsum("nij,kj->nki", R_fit - R_true, a) + (p_fit - p_true)[:, None])
            tol = (np.sqrt(3) + np.sqrt(2) * np.sqrt(6)) * eps
            assert np.max(np.linalg.norm(err, axis=2)) < tol
            assert tol < 1e-6
        # the measured condyle points (L ≈ 0.14 m from the mandible brace, 0.14 m from
        # the skull brace: both fits contribute)
        time, p_r, p_l = measured_condyle_kinematics(subject, trial)
        for p, side in ((p_r, "r"), (p_l, "l")):
            L = 0.2
            tol = 2 * (np.sqrt(3) + L * np.sqrt(6) / c) * eps
            assert np.max(np.linalg.norm(p - _vec(truth, f"condyle_{side}"), axis=1)) < tol
        np.testing.assert_allclose(time, truth["time_s"], atol=1e-12)


def test_zero_differences_make_the_model_the_truth(exact):
    """TruthOptions.exact(): the folder's STL surfaces are the true surfaces, the true
    layer is the folder's uniform cartilage offset, and the registration is exact."""
    subject = load_subject(exact)
    joint, true_markers = load_true_joint(exact)
    for body in ("skull", "mandible"):
        np.testing.assert_array_equal(true_markers[body], subject.braces[body].positions)
    for side in ("r", "l"):
        condyle, fossa = subject.surfaces[f"condyle_{side}"], subject.surfaces[f"fossa_{side}"]
        # STL vertices (float32 mm) lie on the true bone surfaces
        assert np.max(np.abs(joint.condyles[side].implicit(condyle.vertices))) < 1e-5
        z = joint.fossa_height(side, fossa.vertices[:, 0], fossa.vertices[:, 1])
        assert np.max(np.abs(z - fossa.vertices[:, 2])) < 1e-8
        s = joint.condyles[side].parameters_of(condyle.vertices)
        np.testing.assert_allclose(joint.layer_thickness(side, s), subject.cartilage_offset, atol=1e-15)
    # and the model's own contact (STL condyle offset by the folder's layer along its
    # vertex normals vs the STL fossa) touches at every frame, to mesh precision:
    # tolerance as in test_condyle_sits_in_the_fossa_through_the_cartilage_layer;
    # vertices more than 0.3 mm below the fossa are skipped (see the test above)
    for side in ("r", "l"):
        c, f = subject.surfaces[f"condyle_{side}"], subject.surfaces[f"fossa_{side}"]
        cm, fm = (trimesh.Trimesh(m.vertices, m.faces, process=False) for m in (c, f))
        offset = c.vertices + subject.cartilage_offset * cm.vertex_normals
        hc, hf = cm.edges_unique_length.max(), fm.edges_unique_length.max()
        tol = hc ** 2 / (8 * 4.05e-3) + hf ** 2 / (8 * 3.2e-3) + (hc / 2) ** 2 / (2 * 4.05e-3)
        for task in TASKS:
            R, p = _poses(load_truth(exact, task), "mandible_in_skull")
            P = np.einsum("nij,kj->nki", R, offset) + p[:, None]
            near = joint.fossa_height(side, P[..., 0], P[..., 1]) - P[..., 2] < 0.3e-3
            d = igl.signed_distance(P[near], f.vertices, f.faces, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)[0]
            closest = np.full(len(p), np.inf)
            np.minimum.at(closest, np.nonzero(near)[0], d)
            assert np.max(np.abs(closest)) < tol, (task, side, np.max(np.abs(closest)), tol)


def test_default_differences_bias_the_brace_measurement(recorded):
    """With the default TruthOptions the registered markers are 0.2–0.5 mm off the true
    ones, and the brace-measured condyles differ from the truth by a sub-millimetre
    bias plus noise (but are not exact)."""
    folder, _ = recorded
    subject = load_subject(folder)
    _, true_markers = load_true_joint(folder)
    for body in ("skull", "mandible"):
        offsets = np.linalg.norm(true_markers[body] - subject.braces[body].positions, axis=1)
        assert np.all((0.2e-3 <= offsets) & (offsets <= 0.5e-3))
    truth = load_truth(folder, "open_close")
    _, p_r, _ = measured_condyle_kinematics(subject, folder / "trials" / "open_close.c3d")
    error = p_r - _vec(truth, "condyle_r")
    assert 0.05e-3 < np.linalg.norm(error.mean(axis=0)) < 1.5e-3
    assert np.sqrt(np.mean(error ** 2)) < 1.5e-3


def test_rigid_fit_recovers_a_known_transform_with_gaps():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(5, 3)) * 0.03
    R = np.array([rotation_matrix(q / np.linalg.norm(q)) for q in rng.normal(size=(6, 4))])
    p = rng.normal(size=(6, 3))
    b = np.einsum("nij,kj->nki", R, a) + p[:, None]
    b[2, 1] = np.nan                                                 # one gap: 4 markers left
    b[3, :3] = np.nan                                                # 2 markers: no fit
    R_fit, p_fit = rigid_fit(a, b)
    ok = [0, 1, 2, 4, 5]
    np.testing.assert_allclose(R_fit[ok], R[ok], atol=1e-12)
    np.testing.assert_allclose(p_fit[ok], p[ok], atol=1e-12)
    assert np.all(np.isnan(R_fit[3])) and np.all(np.isnan(p_fit[3]))
    # a reflection is never returned
    assert np.allclose(np.linalg.det(R_fit[ok]), 1.0)


def test_record_rejects_bad_options(recorded, tmp_path):
    import shutil

    folder, _ = recorded
    with pytest.raises(ValueError, match="unknown task"):
        record_experiment(folder, tasks=("yawning",))
    with pytest.raises(ValueError, match="cycles"):
        record_experiment(folder, cycles=0)
    copy = tmp_path / "real"
    shutil.copytree(folder, copy)
    (copy / "truth" / "anatomy.yaml").unlink()                     # a folder of real data
    with pytest.raises(ValueError, match=r"anatomy\.yaml: missing"):
        record_experiment(copy)
