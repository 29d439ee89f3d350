"""``openfdk validate-kinematics`` (openfdk.analysis.kinematics_validation): a run's
coordinates against a measured reference over one gait cycle.

The expected numbers are derived here in closed form, not taken from the code:

* reference r(p) = A sin(2πp/100) at p = 0, 1, …, 99 % (one full period) and model
  m = a r + b + c cos(2πp/100). Over a full period sampled uniformly, sin and cos sum to
  zero and are orthogonal (Σ sin² = Σ cos² = N/2, Σ sin cos = 0), so with d = m − r:
  mean d = b; mean d² = (a − 1)² A²/2 + b² + c²/2; the offset-removed mean square drops b²;
  r² = a² A² / (a² A² + c²).
* a model linear in time against a reference sampled in seconds, shifted by s seconds:
  the difference is the constant k s (no interpolation error on a straight line), so the
  offset and RMSD are k s, the offset-removed RMSD 0, r² 1, and the number of compared
  samples is the count of reference times inside the cycle and the run's frames.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import error_line, run_cli
from openfdk.analysis.kinematics_validation import (ValidationError, agreement, cycle_percent, interpolate_usable,
                                                     validate_kinematics)
from openfdk.io.results import write_table
from openfdk.io.storage import write_storage

ROOT = Path(__file__).resolve().parents[1]
T0, T1 = 2.406, 3.554


def write_run(folder, time, coordinates, converged=None, forces=True):
    """A result folder in the format ``openfdk run`` writes: kinematics.csv (time,
    converged, message), forces.csv (time, converged, status, message) and
    coordinates.csv (time, ``<name>_m`` / ``<name>_rad`` in SI; NaN where kinematics
    failed). ``coordinates``: {column name with unit suffix: (nf,) values}."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    time = np.asarray(time, dtype=float)
    ok = np.ones(time.size, bool) if converged is None else np.asarray(converged, bool)
    msg = ["" if c else "failed" for c in ok]
    write_table(folder / "kinematics.csv", {"time": time, "converged": ok, "message": msg})
    if forces:
        write_table(folder / "forces.csv", {"time": time, "converged": ok,
                                            "status": ["optimal" if c else "fdk_singular" for c in ok],
                                            "message": msg})
    write_table(folder / "coordinates.csv", {"time": time, **coordinates})
    return folder


def write_map(path, text):
    Path(path).write_text(text)
    return path


def read_csv_rows(path):
    with open(path, newline="") as fh:
        return {row["reference_column"]: row for row in csv.DictReader(fh)}


# -- the statistics -------------------------------------------------------------------

@pytest.mark.parametrize("a, b, c", [(0.8, 1.5, 1.0), (1.0, -0.3, 0.0), (1.3, 0.0, 2.5)])
def test_agreement_closed_form(a, b, c):
    A, N = 4.0, 100
    p = np.arange(N)
    r = A * np.sin(2 * np.pi * p / N)
    m = a * r + b + c * np.cos(2 * np.pi * p / N)
    s = agreement(m, r)
    assert s["n"] == N
    assert s["mean_offset"] == pytest.approx(b, abs=1e-12)
    assert s["rmsd"] == pytest.approx(math.sqrt((a - 1) ** 2 * A ** 2 / 2 + b ** 2 + c ** 2 / 2), rel=1e-12, abs=1e-12)
    assert s["rmsd_offset_removed"] == pytest.approx(math.sqrt((a - 1) ** 2 * A ** 2 / 2 + c ** 2 / 2), abs=1e-12)
    assert s["r2"] == pytest.approx(a ** 2 * A ** 2 / (a ** 2 * A ** 2 + c ** 2), rel=1e-12)


def test_agreement_of_a_constant_has_no_r2():
    s = agreement(np.full(5, 2.0), np.arange(5.0))
    assert math.isnan(s["r2"]) and s["mean_offset"] == pytest.approx(2.0 - 2.0)
    assert agreement([], [])["n"] == 0


def test_interpolation_skips_failed_frames():
    """Frames at 0, 1, …, 10 (value 2x + 1, frame 5 failed), samples at 0.5, 1.5, …: the
    two samples beside frame 5 are left out, the others are exact; a sample on a usable
    frame needs only that frame."""
    x = np.arange(11.0)
    usable = np.ones(11, bool)
    usable[5] = False
    at = np.concatenate([np.arange(10) + 0.5, [6.0, 5.0, -0.1, 10.1]])
    v, ok = interpolate_usable(x, 2 * x + 1, usable, at)
    expected_ok = np.array([True] * 4 + [False, False] + [True] * 4 + [True, False, False, False])
    assert np.array_equal(ok, expected_ok)
    assert np.allclose(v[ok], 2 * at[ok] + 1, rtol=0, atol=1e-14)
    assert np.isnan(v[~ok]).all()


def test_cycle_percent_on_known_events():
    assert cycle_percent([T0, T1], (T0, T1)) == pytest.approx([0.0, 100.0], abs=1e-12)
    assert cycle_percent(3.125, (T0, T1)) == pytest.approx(100 * (3.125 - 2.406) / (3.554 - 2.406), rel=1e-14)
    assert cycle_percent(T0 + 0.25 * (T1 - T0), (T0, T1)) == pytest.approx(25.0, rel=1e-12)


# -- the command on written files -----------------------------------------------------

A, a, b, c = 0.004, 0.8, 0.0015, 0.001        # m: reference amplitude, gain, offset, orthogonal term
DELTA = 0.01                                    # rad: the angle's constant offset


@pytest.fixture
def sine_case(tmp_path):
    """Run frames every 0.5 % of the cycle; reference at 0, 1, …, 99 % (time column in %)."""
    k = np.arange(201)
    t = T0 + (T1 - T0) * k / 200
    p = cycle_percent(t, (T0, T1))
    w = 2 * np.pi * p / 100
    ty = a * A * np.sin(w) + b + c * np.cos(w)
    flex = 0.5 + 0.3 * np.sin(w)
    run = write_run(tmp_path / "run", t, {"knee_ty_r_m": ty, "knee_flex_r_rad": flex + DELTA})
    pr = np.arange(100.0)
    wr = 2 * np.pi * pr / 100
    ref = write_storage(tmp_path / "fluoro.sto", pr, {"knee_sup_r": A * np.sin(wr),
                                                      "knee_rot_r": -(0.5 + 0.3 * np.sin(wr))})
    mp = write_map(tmp_path / "map.yaml", "knee_sup_r: {coordinate: knee_ty_r, unit: m, label: superior}\n"
                                          "knee_rot_r: {coordinate: knee_flex_r, unit: rad, scale: -1}\n")
    return run, ref, mp


def test_cli_closed_form_table_and_files(sine_case, capsys, tmp_path):
    run, ref, mp = sine_case
    code, out, err = run_cli(capsys, "validate-kinematics", run, ref, "--map", mp, "--cycle", T0, T1,
                             "--toe-off", 3.125, "--out", tmp_path / "val")
    assert code == 0, err
    rows = read_csv_rows(tmp_path / "val" / "validation.csv")
    sup, rot = rows["knee_sup_r"], rows["knee_rot_r"]
    assert sup["dof"] == "superior" and sup["coordinate"] == "knee_ty_r" and sup["unit"] == "mm"
    assert int(sup["n"]) == 100 and float(sup["cycle_from_pct"]) == 0 and float(sup["cycle_to_pct"]) == 99
    mm = 1e3
    assert float(sup["mean_offset"]) == pytest.approx(b * mm, rel=1e-8)
    assert float(sup["rmsd"]) == pytest.approx(mm * math.sqrt((a - 1) ** 2 * A ** 2 / 2 + b ** 2 + c ** 2 / 2),
                                               rel=1e-8)
    assert float(sup["rmsd_offset_removed"]) == pytest.approx(mm * math.sqrt((a - 1) ** 2 * A ** 2 / 2 + c ** 2 / 2),
                                                              rel=1e-8)
    assert float(sup["r2"]) == pytest.approx(a ** 2 * A ** 2 / (a ** 2 * A ** 2 + c ** 2), rel=1e-8)
    assert float(sup["reference_range"]) == pytest.approx(mm * (A * np.sin(2 * np.pi * 25 / 100) -
                                                                A * np.sin(2 * np.pi * 75 / 100)), rel=1e-9)
    # the relabelled, sign-flipped column: the model is the reference plus DELTA rad
    assert rot["unit"] == "deg" and float(rot["scale"]) == -1
    assert float(rot["mean_offset"]) == pytest.approx(math.degrees(DELTA), rel=1e-8)
    assert float(rot["rmsd"]) == pytest.approx(math.degrees(DELTA), rel=1e-8)
    assert float(rot["rmsd_offset_removed"]) == pytest.approx(0.0, abs=1e-7)
    assert float(rot["r2"]) == pytest.approx(1.0, abs=1e-12)
    md = (tmp_path / "val" / "validation.md").read_text()
    assert md.count("| superior | knee_sup_r | knee_ty_r |") == 1 and "toe-off 3.125 s = 62.6 %" in md
    assert (tmp_path / "val" / "validation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "superior" in out and "r²" in out and "reference time as percent" in out


def test_default_output_folder_and_no_plot(sine_case, capsys):
    run, ref, mp = sine_case
    code, _, err = run_cli(capsys, "validate-kinematics", run, ref, "--map", mp, "--cycle", T0, T1, "--no-plot", "-q")
    assert code == 0, err
    assert sorted(p.name for p in (run / "validation").iterdir()) == ["validation.csv", "validation.md"]


def test_time_normalisation_reference_in_seconds(tmp_path):
    """Model q = k (t − T0) on frames covering 25 %–110 % of the cycle; reference in s,
    sampled every 7 ms from 2.0 to 4.0 s, = k (t − T0 − s). Compared: reference times
    inside [T0 + 0.25 (T1 − T0), T1]; offset and RMSD k s; r² 1."""
    k_slope, shift = 0.02, 0.003                      # m/s, s
    t = np.linspace(T0 + 0.25 * (T1 - T0), T1 + 0.1 * (T1 - T0), 120)
    run = write_run(tmp_path / "run", t, {"q_m": k_slope * (t - T0)})
    tr = np.round(2.0 + 0.007 * np.arange(286), 12)
    ref = write_storage(tmp_path / "ref.sto", tr, {"col": k_slope * (tr - T0 - shift)})
    mp = write_map(tmp_path / "map.yaml", "col: {coordinate: q, unit: m}\n")
    res = validate_kinematics(run, ref, mp, (T0, T1))
    assert res.time_mode == "seconds"
    assert res.covered == pytest.approx((25.0, 100.0), abs=1e-9)
    (dof,) = res.dofs
    inside = (tr >= t[0]) & (tr <= T1)
    assert dof.stats["n"] == int(inside.sum())
    assert dof.percent == pytest.approx(100 * (tr[inside] - T0) / (T1 - T0), rel=1e-12)
    assert dof.stats["mean_offset"] == pytest.approx(1e3 * k_slope * shift, rel=1e-8)
    assert dof.stats["rmsd"] == pytest.approx(1e3 * k_slope * shift, rel=1e-8)
    assert dof.stats["rmsd_offset_removed"] == pytest.approx(0.0, abs=1e-9)
    assert dof.stats["r2"] == pytest.approx(1.0, abs=1e-12)


def test_reference_time_detection_and_override(tmp_path):
    """A 1..100 time column is read as % (auto); forced to seconds, the same file has
    one sample inside the cycle, and none inside a cycle at 200 s (an error)."""
    t = np.linspace(T0, T1, 50)
    run = write_run(tmp_path / "run", t, {"q_m": 0.01 * cycle_percent(t, (T0, T1)) / 100})
    p = np.arange(1.0, 101.0)
    ref = write_storage(tmp_path / "pct.sto", p, {"col": 0.01 * p / 100})
    mp = write_map(tmp_path / "map.yaml", "col: {coordinate: q, unit: m}\n")
    res = validate_kinematics(run, ref, mp, (T0, T1))
    assert res.time_mode == "percent" and res.dofs[0].stats["n"] == 100
    assert res.dofs[0].stats["rmsd"] == pytest.approx(0.0, abs=1e-6)  # mm; the CSV holds 10 digits
    assert validate_kinematics(run, ref, mp, (T0, T1), reference_time="percent").time_mode == "percent"
    # read as seconds, only the sample at t = 3 s lies inside the cycle 2.406–3.554 s
    res = validate_kinematics(run, ref, mp, (T0, T1), reference_time="seconds")
    assert res.time_mode == "seconds" and res.dofs[0].stats["n"] == 1
    assert res.dofs[0].percent == pytest.approx([100 * (3.0 - T0) / (T1 - T0)], rel=1e-12)
    with pytest.raises(ValidationError, match=r"pct\.sto: no sample within the gait cycle: times 1\.\.100 s"):
        validate_kinematics(run, ref, mp, (200.0, 201.0), reference_time="seconds")


def test_failed_frames_and_measures_and_fdk_columns(tmp_path):
    """Frames at integer % with frame 50 failed (kinematics.csv converged 0): the reference
    samples at 49.5 and 50.5 % are left out. A quantity found in measures.csv or as an FDK
    DOF of forces.csv (``fdk.<dof>.alpha``) is compared as a coordinate."""
    t = T0 + (T1 - T0) * np.arange(101) / 100
    ok = np.ones(101, bool)
    ok[50] = False
    p = cycle_percent(t, (T0, T1))
    run = write_run(tmp_path / "run", t, {"q_m": 1e-3 * p}, converged=ok, forces=False)
    write_table(run / "measures.csv", {"time": t, "angles[1]_rad": 0.001 * p})
    write_table(run / "forces.csv", {"time": t, "converged": ok, "status": ["optimal"] * 101, "message": [""] * 101,
                                     "fdk.anterior.alpha": 2e-3 * p, "fdk.anterior.residual": 0 * p})
    pr = np.arange(100) + 0.5
    ref = write_storage(tmp_path / "ref.sto", pr, {"x": 1e-3 * pr, "ang": 0.001 * pr, "ant": 2e-3 * pr})
    mp = write_map(tmp_path / "map.yaml", "x: {coordinate: q, unit: m}\nang: {coordinate: 'angles[1]', unit: rad}\n"
                                          "ant: {coordinate: anterior, unit: mm}\n")
    res = validate_kinematics(run, ref, mp, (T0, T1))
    for dof in res.dofs:
        assert dof.stats["n"] == 98
        assert not np.isin([49.5, 50.5], dof.percent).any()
    # 'ant' is declared in mm: the file's values (2e-3 p "mm") are 1e-3 of the model's
    # metres, so the model (2 p mm) minus the reference (2e-3 p mm) is 1.998 p mm on average
    ant = res.dofs[2]
    assert ant.stats["mean_offset"] == pytest.approx(1.998 * np.mean(pr[~np.isin(pr, [49.5, 50.5])]), rel=1e-9)
    assert res.dofs[0].stats["rmsd"] == pytest.approx(0.0, abs=1e-6)  # mm; the CSV holds 10 digits
    assert res.dofs[1].stats["rmsd"] == pytest.approx(0.0, abs=1e-9) and res.dofs[1].unit == "deg"


def test_end_to_end_on_a_real_run(tmp_path, capsys):
    """A real ``openfdk run`` of examples/knee/tibiofemoral_3dof.yaml (FDK DOFs in
    forces.csv, the JCS angles in measures.csv); the reference, in seconds at the run's
    own frame times, is the run's anterior translation + 2 mm and its adduction sign-
    flipped and shifted by 0.01 rad. Expected: offsets −2 mm and −0.01 rad (−0.573°),
    RMSD the same, offset removed 0, r² 1, n = the frames inside the cycle."""
    import shutil
    import subprocess
    import sys

    knee = ROOT / "examples" / "knee"
    shutil.copy(knee / "tibiofemoral_3dof.yaml", tmp_path / "tf.yaml")  # its meshes are generated, not in git
    subprocess.run([sys.executable, str(knee / "make_meshes.py"), str(tmp_path / "meshes")], check=True,
                   capture_output=True)
    out = tmp_path / "run"
    code, _, err = run_cli(capsys, "run", tmp_path / "tf.yaml", "--out", out, "--end", "0.5", "--no-plots", "-q")
    assert code == 0, err
    with open(out / "forces.csv", newline="") as fh:
        forces = list(csv.DictReader(fh))
    with open(out / "measures.csv", newline="") as fh:
        measures = list(csv.DictReader(fh))
    t = np.array([float(r["time"]) for r in forces])
    anterior = np.array([float(r["fdk.anterior.alpha"]) for r in forces])
    adduction = np.array([float(r["angles[1]_rad"]) for r in measures])
    assert np.ptp(anterior) > 1e-5 and np.ptp(adduction) > 1e-5  # not constant: r² is defined
    ref = write_storage(tmp_path / "ref.sto", t, {"ant": anterior + 0.002, "add": -(adduction + 0.01)})
    mp = write_map(tmp_path / "map.yaml", "ant: {coordinate: anterior, unit: m}\n"
                                          "add: {coordinate: 'angles[1]', unit: rad, scale: -1, label: adduction}\n")
    cycle = (t[3], t[12])
    code, out_text, err = run_cli(capsys, "validate-kinematics", out, ref, "--map", mp, "--cycle", *map(float, cycle),
                                  "--toe-off", float(0.5 * (cycle[0] + cycle[1])), "--reference-time", "seconds")
    assert code == 0, err
    rows = read_csv_rows(out / "validation" / "validation.csv")
    for col, offset in (("ant", -2.0), ("add", -math.degrees(0.01))):
        row = rows[col]
        assert int(row["n"]) == 10
        assert float(row["mean_offset"]) == pytest.approx(offset, rel=1e-6)
        assert float(row["rmsd"]) == pytest.approx(abs(offset), rel=1e-6)
        assert float(row["rmsd_offset_removed"]) == pytest.approx(0.0, abs=1e-6)
        assert float(row["r2"]) == pytest.approx(1.0, abs=1e-9)
    assert (out / "validation" / "validation.png").is_file()


# -- bad input: one line naming the file and the entry, exit code 2 -------------------

@pytest.fixture
def bad_case(sine_case):
    return sine_case


def _error(capsys, *argv):
    code, _, err = run_cli(capsys, "validate-kinematics", *argv, "--no-plot")
    assert code == 2, err
    return error_line(err)


def test_errors_of_files_and_cycle(bad_case, capsys, tmp_path):
    run, ref, mp = bad_case
    base = ["--cycle", T0, T1]
    assert "run folder" in _error(capsys, tmp_path / "nope", ref, "--map", mp, *base)
    assert "no kinematics.csv" in _error(capsys, tmp_path, ref, "--map", mp, *base)
    line = _error(capsys, run, tmp_path / "missing.sto", "--map", mp, *base)
    assert "reference file" in line and "missing.sto" in line
    assert "map file" in _error(capsys, run, ref, "--map", tmp_path / "missing.yaml", *base)
    assert "must come after the first" in _error(capsys, run, ref, "--map", mp, "--cycle", T1, T0)
    assert "must come after the first" in _error(capsys, run, ref, "--map", mp, "--cycle", T0, T0)
    assert "--toe-off: 4 s is not inside the cycle" in _error(capsys, run, ref, "--map", mp, *base, "--toe-off", 4)
    with pytest.raises(SystemExit) as exc:  # argparse's usage error, as every command's option types
        run_cli(capsys, "validate-kinematics", run, ref, "--map", mp, "--cycle", T0, "nan")
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "argument --cycle: expected a finite number, got 'nan'" in err
    line = _error(capsys, run, ref, "--map", mp, "--cycle", 10.0, 11.0, "--reference-time", "percent")
    assert "lie outside the cycle 10–11 s" in line
    line = _error(capsys, run, ref, "--map", mp, "--cycle", T0 - 100, T0 - 99)
    assert str(run) in line and "outside the cycle" in line


@pytest.mark.parametrize("text, expected", [
    ("knee_sup_r: {coordinate: knee_ty_r, unit: m\n", "map.yaml: malformed YAML at line"),
    ("knee_sup_r: {coordinat: knee_ty_r, unit: m}\n", "map.yaml: knee_sup_r.coordinat: unknown key; did you mean "
                                                      "'coordinate'?"),
    ("knee_sup_r: {coordinate: knee_ty_r}\n", "map.yaml: knee_sup_r: missing required key 'unit'"),
    ("knee_sup_r: {coordinate: knee_ty_r, unit: cm}\n", "map.yaml: knee_sup_r.unit: unknown unit 'cm'"),
    ("knee_sup_r: {coordinate: knee_ty_r, unit: m, scale: 0}\n", "map.yaml: knee_sup_r.scale: |scale| must be in"),
    ("knee_sup_r: {coordinate: knee_ty_r, unit: m, scale: -1e300}\n", "map.yaml: knee_sup_r.scale: |scale| must be "
                                                                       "in [1e-06, 1e+06]"),
    ("knee_sup_r: {coordinate: knee_ty_r, unit: m, scale: .nan}\n", "map.yaml: knee_sup_r.scale: expected a finite"),
    ("knee_sup: {coordinate: knee_ty_r, unit: m}\n", "fluoro.sto: no column 'knee_sup' (entry 'knee_sup' of map.yaml); "
                                                     "did you mean 'knee_sup_r'?"),
    ("knee_sup_r: {coordinate: knee_ty, unit: m}\n", "map.yaml: knee_sup_r.coordinate: 'knee_ty' is not in the run"),
    ("knee_sup_r: {coordinate: knee_flex_r, unit: m}\n", "map.yaml: knee_sup_r: unit m (a length) but 'knee_flex_r' "
                                                         "in coordinates.csv is an angle"),
    ("", "map.yaml: the file is empty"),
    ("{}\n", "map.yaml: no entries"),
    ("- knee_sup_r\n", "map.yaml: (top level): expected a mapping"),
    ("knee_sup_r: knee_ty_r\n", "map.yaml: knee_sup_r: expected a mapping"),
])
def test_errors_of_the_map(bad_case, capsys, text, expected):
    run, ref, mp = bad_case
    mp.write_text(text)
    line = _error(capsys, run, ref, "--map", mp, "--cycle", T0, T1)
    assert expected in line, line


def test_did_you_mean_names_the_close_coordinate(bad_case, capsys):
    run, ref, mp = bad_case
    mp.write_text("knee_sup_r: {coordinate: knee_ty, unit: m}\n")
    assert "did you mean 'knee_ty_r'?" in _error(capsys, run, ref, "--map", mp, "--cycle", T0, T1)


def test_errors_of_the_reference(bad_case, capsys, tmp_path):
    run, _, mp = bad_case
    p = np.arange(100.0)
    values = np.sin(p)
    values[7] = np.nan
    ref = write_storage(tmp_path / "nan.sto", p, {"knee_sup_r": values, "knee_rot_r": p})
    line = _error(capsys, run, ref, "--map", mp, "--cycle", T0, T1)
    assert "nan.sto: column 'knee_sup_r': nan at time 7 is not a finite number" in line
    ref = write_storage(tmp_path / "deg.sto", p, {"knee_sup_r": p, "knee_rot_r": p}, in_degrees=True)
    assert "deg.sto: column 'knee_rot_r': the map says rad" in _error(capsys, run, ref, "--map", mp, "--cycle", T0, T1)
    (tmp_path / "broken.sto").write_text("header\nendheader\ntime\tknee_sup_r\n0\t1\n1\tx\n")
    line = _error(capsys, run, tmp_path / "broken.sto", "--map", mp, "--cycle", T0, T1)
    assert "broken.sto: line 5: column 'knee_sup_r' is 'x', expected a number" in line
    ref = write_storage(tmp_path / "late.sto", np.linspace(10.0, 12.0, 30),
                        {"knee_sup_r": np.zeros(30), "knee_rot_r": np.zeros(30)})
    line = _error(capsys, run, ref, "--map", mp, "--cycle", T0, T1)
    assert "late.sto: no sample within the gait cycle: times 10..12 s are outside the cycle" in line


def test_error_when_the_run_has_no_converged_frame_or_misses_the_reference(tmp_path, capsys):
    t = np.linspace(T0, T1, 20)
    mp = write_map(tmp_path / "map.yaml", "col: {coordinate: q, unit: m}\n")
    ref = write_storage(tmp_path / "ref.sto", np.arange(101.0), {"col": np.zeros(101)})
    run = write_run(tmp_path / "failed", t, {"q_m": np.zeros(20)}, converged=np.zeros(20, bool))
    assert "no frame of the run converged" in _error(capsys, run, ref, "--map", mp, "--cycle", T0, T1)
    # the run covers 10.2–10.9 % of the cycle, the reference is sampled at whole percents
    t = T0 + (T1 - T0) * np.linspace(0.102, 0.109, 5)
    run = write_run(tmp_path / "short", t, {"q_m": np.zeros(5)})
    line = _error(capsys, run, ref, "--map", mp, "--cycle", T0, T1)
    assert "ref.sto: no sample within the part of the cycle the run covers (10.2–10.9 %" in line


def test_align_by_recovers_a_known_phase_shift(tmp_path, capsys):
    """The reference's flexion is the model's delayed by 7.3 % of the cycle (its 0 % is
    another event): --align-by finds the shift to the search step (0.1 %), after which
    the flexion and a second DOF shifted the same way agree to the interpolation error,
    and r² of the flexion goes from cos²-loss to ≈ 1."""
    shift = 7.3
    k = np.arange(401)
    t = T0 + (T1 - T0) * k / 400
    p = cycle_percent(t, (T0, T1))
    w = 2 * np.pi * p / 100
    run = write_run(tmp_path / "run", t, {"knee_flex_r_rad": 0.5 + 0.3 * np.sin(w),
                                          "knee_ty_r_m": 0.01 + 0.002 * np.cos(2 * w)})
    pr = np.arange(1.0, 101.0)
    wr = 2 * np.pi * (pr - shift) / 100  # measured at p % is the model's (p − shift) %
    ref = write_storage(tmp_path / "fluoro.sto", pr, {"knee_rot_r": -(0.5 + 0.3 * np.sin(wr)),
                                                      "knee_sup_r": 0.01 + 0.002 * np.cos(2 * wr)})
    mp = write_map(tmp_path / "map.yaml", "knee_rot_r: {coordinate: knee_flex_r, unit: rad, scale: -1}\n"
                                          "knee_sup_r: {coordinate: knee_ty_r, unit: m}\n")
    code, out, err = run_cli(capsys, "validate-kinematics", run, ref, "--map", mp, "--cycle", T0, T1,
                             "--out", tmp_path / "plain", "--no-plot")
    assert code == 0, err
    plain = read_csv_rows(tmp_path / "plain" / "validation.csv")
    # unaligned: r² of two sines 2π·7.3 % apart is cos²(2π·0.073)
    assert float(plain["knee_rot_r"]["r2"]) == pytest.approx(math.cos(2 * math.pi * shift / 100) ** 2, abs=2e-3)
    code, out, err = run_cli(capsys, "validate-kinematics", run, ref, "--map", mp, "--cycle", T0, T1,
                             "--out", tmp_path / "aligned", "--no-plot", "--align-by", "knee_rot_r")
    assert code == 0, err
    assert "shifted by +7.3 %" in out
    rows = read_csv_rows(tmp_path / "aligned" / "validation.csv")
    assert float(rows["knee_rot_r"]["r2"]) > 0.99999
    assert float(rows["knee_sup_r"]["r2"]) > 0.99999
    assert float(rows["knee_rot_r"]["rmsd"]) < 0.05  # deg: interpolation between frames 0.25 % apart
    assert "shifted by +7.3 %" in (tmp_path / "aligned" / "validation.md").read_text()
    code, out, err = run_cli(capsys, "validate-kinematics", run, ref, "--map", mp, "--cycle", T0, T1,
                             "--no-plot", "--align-by", "knee_flex")
    assert code != 0 and "--align-by: 'knee_flex' is not a column of map.yaml" in err and err.count("\n") == 1
