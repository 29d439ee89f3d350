"""The low-pass filter of measured external loads (forces/load_filter.py) and its
model-file key, overlay key and command-line option.

Independent references: the noise bandwidth of the zero-lag order-2 Butterworth in
closed form, scipy.signal's own sosfiltfilt of the same wrench, the statics of a wrench
(p × F + T about the origin), and the sampled sine's difference ratio 2 sin(π f / f_s)."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.cli import main
from openfdk.fixtures.full_body_osim import write_full_body_osim
from openfdk.forces.load_filter import filter_load, noise_ratio, uniform_samples
from openfdk.io.storage import write_storage

RATE = 1200.0
FC = 6.0


def _wrench(F, P, T):
    return np.cross(P, F) + T


def test_white_noise_on_a_standing_load_falls_by_the_filters_noise_bandwidth():
    # a foot standing on a plate for 60 s: constant force, centre of pressure and free
    # moment, with white noise on the force (5 N) and on the point (1 mm, in the plane)
    rng = np.random.default_rng(1)
    n = int(60 * RATE)
    t = np.arange(n) / RATE
    F = np.array([30.0, 700.0, -20.0]) + 5.0 * rng.standard_normal((n, 3))
    P = np.array([0.4, 0.0, 0.25]) + 1e-3 * rng.standard_normal((n, 3)) * [1, 0, 1]
    T = np.zeros((n, 3))
    T[:, 1] = 2.0
    t_f, F_f, P_f, T_f = filter_load(t, F, P, T, True, FC)
    np.testing.assert_array_equal(t_f, t)
    mid = slice(n // 10, -n // 10)  # away from the filter's ends
    # filtfilt's gain is G(f) = 1 / (1 + (f/fc)^4); white noise keeps the share
    # (fc / (fs/2)) ∫0^∞ dx / (1 + x^4)^2 = (fc / (fs/2)) · 3π / (8√2) of its variance
    expected = np.sqrt(FC / (RATE / 2) * 3 * np.pi / (8 * np.sqrt(2)))
    ratio = np.std(F_f[mid], axis=0) / 5.0
    assert expected == pytest.approx(0.0913, abs=1e-3)
    np.testing.assert_allclose(ratio, expected, rtol=0.15)
    # the centre of pressure stays on the plate (y = 0), near where it was, much quieter
    np.testing.assert_allclose(P_f[:, 1], 0.0, atol=1e-15)
    np.testing.assert_allclose(P_f[mid].mean(axis=0)[[0, 2]], [0.4, 0.25], atol=1e-4)
    assert np.all(np.std(P_f[mid], axis=0)[[0, 2]] < 0.2e-3)
    # the free moment is about the plate's normal only
    np.testing.assert_allclose(T_f[:, [0, 2]], 0.0, atol=1e-9)
    np.testing.assert_allclose(T_f[mid, 1].mean(), 2.0, atol=0.05)


def test_the_filtered_wrench_is_scipys_low_pass_of_the_measured_wrench():
    signal = pytest.importorskip("scipy.signal")
    rng = np.random.default_rng(2)
    n = 2400
    t = np.arange(n) / RATE
    F = np.column_stack((50 * np.sin(3 * t), 650 + 80 * np.cos(5 * t), -30 + 10 * t)) + 3 * rng.standard_normal((n, 3))
    P = np.column_stack((0.3 + 0.4 * t, 0.01 * np.ones(n), 0.2 - 0.02 * t)) + 1e-3 * rng.standard_normal((n, 3))
    T = np.column_stack((np.zeros(n), 3 * np.sin(7 * t), np.zeros(n)))
    _, F_f, P_f, T_f = filter_load(t, F, P, T, True, FC)
    sos = signal.butter(2, FC, fs=RATE, output="sos")
    W = signal.sosfiltfilt(sos, np.column_stack((F, _wrench(F, P, T))), axis=0)
    np.testing.assert_allclose(F_f, W[:, :3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(_wrench(F_f, P_f, T_f), W[:, 3:], rtol=0, atol=1e-9)
    # the plate's plane: through the measured points' median height
    np.testing.assert_allclose(P_f[:, 1], np.median(P[:, 1]), atol=1e-15)


def test_a_noiseless_load_is_kept_and_its_centre_of_pressure_found_again():
    n = 600
    t = np.arange(n) / RATE
    F = np.tile([10.0, 600.0, -5.0], (n, 1))
    P = np.tile([0.35, 0.0, 0.21], (n, 1))
    T = np.tile([0.0, 1.5, 0.0], (n, 1))
    _, F_f, P_f, T_f = filter_load(t, F, P, T, True, FC)
    np.testing.assert_allclose(F_f, F, atol=1e-9)
    np.testing.assert_allclose(P_f, P, atol=1e-12)
    np.testing.assert_allclose(T_f, T, atol=1e-9)


def test_the_foot_is_not_loaded_before_it_lands():
    # zero before 0.5 s, then a rise to 700 N with noise: the samples before the landing
    # stay exactly zero (a filter across it would load the swinging foot)
    rng = np.random.default_rng(3)
    n = 1800
    t = np.arange(n) / RATE
    on = t >= 0.5
    F = np.zeros((n, 3))
    F[on, 1] = 700 * (1 - np.exp(-(t[on] - 0.5) / 0.03)) + 5 * rng.standard_normal(on.sum())
    F[on, 1] = np.maximum(F[on, 1], 0.0)
    P = np.where(on[:, None], [0.4, 0.0, 0.25], [0.3, 0.0, 0.2]).astype(float)
    _, F_f, P_f, T_f = filter_load(t, F, P, None, True, FC)
    first = int(np.argmax(np.linalg.norm(F, axis=1) >= 20.0))
    np.testing.assert_array_equal(F_f[:first], F[:first])  # below the threshold: as measured
    np.testing.assert_array_equal(F_f[~on], 0.0)
    np.testing.assert_array_equal(P_f[:first], P[:first])
    assert np.std(np.diff(F_f[first + 200:, 1], 2)) < 0.05 * np.std(np.diff(F[first + 200:, 1], 2))


def test_a_run_shorter_than_the_filters_padding_is_left_as_measured():
    n = 400
    t = np.arange(n) / RATE
    F = np.zeros((n, 3))
    F[100:105, 1] = [30, 60, 90, 60, 30]
    P = np.tile([0.4, 0.0, 0.25], (n, 1))
    _, F_f, P_f, _ = filter_load(t, F, P, None, True, FC)
    np.testing.assert_array_equal(F_f, F)
    np.testing.assert_array_equal(P_f, P)


def test_uneven_sample_times_are_resampled_and_a_ramp_kept():
    # times at 120 Hz rounded to 1 ms plus an offset (DM's treadmill files)
    k = np.arange(720)
    t = np.round(k / 120.0, 3) + 0.439997
    F = np.column_stack((2 + 3 * t, 700 + 40 * t, -1 + 0.5 * t))
    t_u, X = uniform_samples(t, F)
    h = np.median(np.diff(t))
    np.testing.assert_allclose(np.diff(t_u), h, rtol=1e-12)
    np.testing.assert_allclose(X, np.column_stack((2 + 3 * t_u, 700 + 40 * t_u, -1 + 0.5 * t_u)), atol=1e-9)
    # a zero-lag, unit-gain filter keeps a line away from the record's ends (a symmetric
    # impulse response of unit sum: its first moment is zero)
    t_f, F_f, _, T_f = filter_load(t, F, None, None, False, FC)
    mid = slice(120, -120)
    np.testing.assert_allclose(F_f[mid], np.column_stack((2 + 3 * t_f, 700 + 40 * t_f, -1 + 0.5 * t_f))[mid],
                               atol=1e-6)
    np.testing.assert_allclose(T_f, 0.0, atol=1e-12)


def test_a_load_in_the_body_is_filtered_column_by_column():
    signal = pytest.importorskip("scipy.signal")
    rng = np.random.default_rng(4)
    n = 1200
    t = np.arange(n) / RATE
    F = np.column_stack((20 + 5 * t, -40 * np.cos(t), 10 * np.sin(2 * t))) + rng.standard_normal((n, 3))
    P = np.tile([0.05, -0.01, 0.01], (n, 1)) + 1e-3 * rng.standard_normal((n, 3))
    T = rng.standard_normal((n, 3))
    _, F_f, P_f, T_f = filter_load(t, F, P, T, False, FC)
    sos = signal.butter(2, FC, fs=RATE, output="sos")
    for got, raw in ((F_f, F), (P_f, P), (T_f, T)):
        np.testing.assert_allclose(got, signal.sosfiltfilt(sos, raw, axis=0), atol=1e-9)


def test_a_cutoff_at_half_the_rate_is_refused():
    t = np.arange(100) / 100.0
    with pytest.raises(ValueError, match="below half the samples' rate"):
        filter_load(t, np.ones((100, 3)) * 100, None, None, False, 50.0)


def test_the_noise_ratio_of_white_noise_and_of_a_sine():
    rng = np.random.default_rng(5)
    noise = 700 + rng.standard_normal((20000, 3))
    # white noise: Var(Δ²x) / Var(Δx) = 6σ² / 2σ² → √3
    assert noise_ratio(noise) == pytest.approx(np.sqrt(3), rel=0.02)
    t = np.arange(6000) / RATE
    f = 2.0
    sine = np.column_stack((100 * np.sin(2 * np.pi * f * t), 700 + 0 * t, 0 * t))
    # a sampled sine: |Δ²x| / |Δx| = 2 sin(π f / f_s)
    assert noise_ratio(sine) == pytest.approx(2 * np.sin(np.pi * f / RATE), rel=1e-3)
    assert noise_ratio(np.zeros((50, 3))) == 0.0


# -- the model-file key, the overlay key, the command line ------------------------------

LOADS_XML = """<OpenSimDocument Version="40000"><ExternalLoads><objects>
<ExternalForce name="grf_r"><applied_to_body>calcn_r</applied_to_body>
<force_expressed_in_body>ground</force_expressed_in_body><point_expressed_in_body>ground</point_expressed_in_body>
<force_identifier>g_v</force_identifier><point_identifier>g_p</point_identifier>
<torque_identifier>g_t</torque_identifier></ExternalForce>
</objects><datafile>grf.mot</datafile></ExternalLoads></OpenSimDocument>"""


@pytest.fixture(scope="module")
def osim(tmp_path_factory):
    return write_full_body_osim(tmp_path_factory.mktemp("m") / "full_body.osim")


def _grf(folder, noisy, seconds=2.0):
    rng = np.random.default_rng(6)
    t = np.arange(int(seconds * RATE)) / RATE
    n = len(t)
    cols = {"g_vx": 20 * np.sin(2 * t), "g_vy": 700 + 50 * np.cos(3 * t), "g_vz": -10 + 0 * t,
            "g_px": 0.3 + 0.1 * t, "g_py": 0 * t, "g_pz": 0.2 + 0 * t, "g_tx": 0 * t, "g_ty": 0 * t, "g_tz": 0 * t}
    if noisy:
        for c in ("g_vx", "g_vy", "g_vz"):
            cols[c] = cols[c] + 5 * rng.standard_normal(n)
    write_storage(folder / "grf.mot", t, cols, name="grf")
    (folder / "loads.xml").write_text(LOADS_XML)
    return folder / "loads.xml"


def _check(osim, xml, *extra):
    return main(["check", str(osim), "--ignore", "Mesh", "--external-loads", str(xml), "-q", *extra])


def test_unfiltered_ground_reactions_are_named_in_a_warning(osim, tmp_path, capsys):
    xml = _grf(tmp_path, noisy=True)
    assert _check(osim, xml) == 0
    err = capsys.readouterr().err
    assert "grf.mot" in err and "'grf_r' (" in err and "look unfiltered" in err and "cutoff" in err
    # the ratio given is the file's: white noise of 5 N on a slow load, near √3
    ratio = float(err.split("'grf_r' (")[1].split(")")[0])
    assert ratio == pytest.approx(np.sqrt(3), abs=0.15)
    # filtered, or smooth: no warning
    assert _check(osim, xml, "--external-loads-cutoff", "6") == 0
    assert "look unfiltered" not in capsys.readouterr().err
    xml = _grf(tmp_path, noisy=False)
    assert _check(osim, xml) == 0
    assert "look unfiltered" not in capsys.readouterr().err


def test_a_kinematics_pass_does_not_warn_about_loads_it_does_not_apply(osim, tmp_path, capsys):
    """``openfdk kinematics`` applies no loads: the raw ground reactions of the model (an
    overlay naming another trial's, DM's first pass) are not warned about there, where
    ``check`` (above) and ``run`` warn."""
    import openfdk
    from openfdk.io.storage import write_storage

    xml = _grf(tmp_path, noisy=True)
    model = openfdk.load_model(osim, ignore=["Mesh"])
    t = np.arange(0.0, 1.0, 0.05)
    free = [c.name for c in model.coordinates if not (c.locked or c.prescribed)]
    write_storage(tmp_path / "still.mot", t, {name: np.zeros(t.size) for name in free}, name="still")
    code = main(["kinematics", str(osim), "--ignore", "Mesh", "--motion", str(tmp_path / "still.mot"),
                 "--external-loads", str(xml), "--out", str(tmp_path / "kin"), "-q"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "look unfiltered" not in err
    assert _check(osim, xml) == 0  # the same model and loads, checked: warned
    assert "look unfiltered" in capsys.readouterr().err


def test_the_overlay_key_and_the_option_filter_the_loads_alike(osim, tmp_path):
    from openfdk.io.modelfile import load_model_and_settings
    from openfdk.io.opensim.overlay import register

    xml = _grf(tmp_path, noisy=True)
    overlay = tmp_path / "o.yaml"
    overlay.write_text(f"opensim: {osim}\nignore: [Mesh]\nexternal_loads: {xml}\nexternal_loads_cutoff_hz: 6\n")
    by_overlay, _ = load_model_and_settings(overlay)
    register(osim, ignore=["Mesh"], external_loads=xml, external_loads_cutoff_hz=6.0)
    by_option, _ = load_model_and_settings(osim)
    register(osim, ignore=["Mesh"], external_loads=xml)
    raw, _ = load_model_and_settings(osim)
    times = np.linspace(0.5, 1.5, 11)
    values = {}
    for label, m in (("overlay", by_overlay), ("option", by_option), ("raw", raw)):
        (load,) = m.external_loads
        fns = (load.force, load.point, load.torque)
        values[label] = [np.array([fn.derivatives(t)[0] for t in times]) for fn in fns]
    for a, b in zip(values["overlay"], values["option"]):
        np.testing.assert_array_equal(a, b)
    # the filtered force is the low-pass of the raw one: within the noise of it, not equal
    F_f, F_r = values["overlay"][0], values["raw"][0]
    assert 0 < np.max(np.abs(F_f - F_r)) < 25.0
    smooth = np.column_stack((20 * np.sin(2 * times), 700 + 50 * np.cos(3 * times), -10 + 0 * times))
    assert np.max(np.abs(F_f - smooth)) < 3.0 < np.max(np.abs(F_r - smooth))


@pytest.mark.parametrize("text, words", [
    ("external_loads_cutoff_hz: -1\n", "external_loads_cutoff_hz: expected a number >= 0"),
    ("external_loads_cutoff_hz: 700\n", "external_loads.grf_r.cutoff_hz"),
    ("external_loads_cutoff_hz: yes\n", "external_loads_cutoff_hz"),
])
def test_a_bad_cutoff_ends_in_one_line_naming_it(osim, tmp_path, capsys, text, words):
    xml = _grf(tmp_path, noisy=True)
    overlay = tmp_path / "o.yaml"
    overlay.write_text(f"opensim: {osim}\nignore: [Mesh]\nexternal_loads: {xml}\n{text}")
    code = main(["check", str(overlay), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0] and "Traceback" not in err[0], err


def test_the_option_without_loads_is_refused(osim, capsys):
    code = main(["check", str(osim), "--ignore", "Mesh", "--external-loads-cutoff", "6", "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--external-loads-cutoff" in err[0], err


def test_samples_that_overflow_the_filter_are_refused():
    # found by fuzzing the GRF file through the filter: finite samples whose moment
    # p × F overflows gave a NaN spline
    n = 200
    t = np.arange(n) / RATE
    F = np.tile([10.0, 700.0, 0.0], (n, 1))
    F[50, 1] = 1e308
    P = np.tile([0.4, 0.0, 0.25], (n, 1))
    P[50, 0] = 1e308
    with pytest.raises(ValueError, match="overflows the filter"):
        filter_load(t, F, P, None, True, FC)


# -- one overlay for every trial: the command line's loads replace the overlay's ----------

def _other_trial(folder, seconds=2.0):
    """Another trial's loads (loads_b.xml, grf_b.mot): a different force, point and torque."""
    t = np.arange(int(seconds * RATE)) / RATE
    cols = {"g_vx": -30 + 5 * t, "g_vy": 900 + 40 * np.sin(5 * t), "g_vz": 15 * t, "g_px": 0.5 - 0.2 * t,
            "g_py": 0.01 + 0 * t, "g_pz": 0.1 * np.cos(t), "g_tx": 0 * t, "g_ty": 2 * t, "g_tz": 0 * t}
    write_storage(folder / "grf_b.mot", t, cols, name="grf")
    (folder / "loads_b.xml").write_text(LOADS_XML.replace("grf.mot", "grf_b.mot"))
    return folder / "loads_b.xml", t, cols


def test_one_overlay_for_every_trial_the_command_lines_loads_replace_its_own(osim, tmp_path, capsys):
    import openfdk
    from openfdk.io.opensim.overlay import options_record, register, register_record

    own = _grf(tmp_path, noisy=True)
    other, t, cols = _other_trial(tmp_path)
    overlay = tmp_path / "o.yaml"
    overlay.write_text(f"opensim: {osim}\nignore: [Mesh]\nexternal_loads: {own.name}\n")
    # the command line: the overlay's loads replaced, with a warning naming both files
    code = main(["check", str(overlay), "--external-loads", str(other), "-q"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "o.yaml: external_loads: loads.xml replaced by --external-loads loads_b.xml" in err
    assert options_record(overlay) == {"external_loads": str(other.resolve())}
    # in Python: the model's load is the other trial's, sample for sample (the spline
    # passes through the samples), and not the overlay's own
    with pytest.warns(UserWarning, match="replaced by --external-loads loads_b.xml"):
        model = openfdk.load_model(overlay, external_loads=other)
    (load,) = model.external_loads
    k = np.arange(200, 2200, 250)
    F = np.array([load.force.derivatives(t[i])[0] for i in k])
    P = np.array([load.point.derivatives(t[i])[0] for i in k])
    T = np.array([load.torque.derivatives(t[i])[0] for i in k])
    np.testing.assert_allclose(F, np.column_stack([cols[f"g_v{a}"][k] for a in "xyz"]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(P, np.column_stack([cols[f"g_p{a}"][k] for a in "xyz"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(T, np.column_stack([cols[f"g_t{a}"][k] for a in "xyz"]), rtol=0, atol=1e-9)
    assert np.all(F[:, 1] > 850)  # the overlay's own trial pushes at 700 ± 55 N
    # a finished run's record reads the model again with the other trial's loads
    register(overlay)
    register_record(overlay, {"external_loads": str(other.resolve())})
    (again,) = _reloaded(overlay).external_loads
    assert again.force.derivatives(t[k[3]])[0][1] == pytest.approx(cols["g_vy"][k[3]], abs=1e-9)
    # --external-loads-cutoff alone filters the overlay's own loads: within 3 N of the
    # smooth load its noise was added to (5 N white noise at 1 200 Hz, 6 Hz low-pass)
    register(overlay, external_loads_cutoff_hz=6.0)
    (filtered,) = _reloaded(overlay).external_loads
    times = np.linspace(0.5, 1.5, 11)
    smooth = np.column_stack((20 * np.sin(2 * times), 700 + 50 * np.cos(3 * times), -10 + 0 * times))
    F_f = np.array([filtered.force.derivatives(x)[0] for x in times])
    assert np.max(np.abs(F_f - smooth)) < 3.0
    # and a cutoff without loads anywhere: one line naming the option
    bare = tmp_path / "bare.yaml"
    bare.write_text(f"opensim: {osim}\nignore: [Mesh]\n")
    code = main(["check", str(bare), "--external-loads-cutoff", "6", "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "bare.yaml: --external-loads-cutoff: filters the loads of external loads" in err[0]


def _reloaded(path):
    """The model of ``path`` read with the options registered for it (no new ones)."""
    from openfdk.io.modelfile import load_model

    return load_model(path)
