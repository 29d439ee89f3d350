"""Hostile marker (.trc) and coordinate (.mot/.sto, ``--motion``) files (the sweep of stop
72): each ends in exit code 2 with one line naming the file and the entry (line, marker,
column, time), or is read with a one-line warning naming them; none gives a traceback or
reaches the solver with numbers it cannot use.

The inputs are the fuzzer's own (openfdk.bench.fuzz_inputs): the two-body jaw model with
its 20-frame TRC (100 Hz, mm; markers S1–S4, J1–J4), and the ``leg.osim`` (hip_q with
range [-2, 2] rad, knee without a range, pat_q = 0.5·knee + 0.1 by a coupler) with a
21-sample coordinate file written here (100 Hz)."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest

from cli_helpers import error_line, run_cli
from openfdk.bench.fuzz_inputs import _dump, _trc_text, write_leg
from openfdk.fixtures.synthetic import two_body_model_dict

#: the TRC's first data line (1-based; 5 header lines and a blank one before it)
FIRST_ROW_LINE = 7
#: the TRC's data rate (Hz) and the motion file's sample interval (s)
TRC_RATE, MOTION_DT = 100.0, 0.01


# -- the files ----------------------------------------------------------------------------

@pytest.fixture
def jaw(tmp_path):
    """A folder with tb.yaml (the two-body model) and t.trc (its trial)."""
    (tmp_path / "tb.yaml").write_text(_dump(two_body_model_dict()))
    (tmp_path / "t.trc").write_text(_trc_text())
    return tmp_path


@pytest.fixture
def leg(tmp_path):
    """A folder with leg.osim and its mesh."""
    write_leg(tmp_path)
    return tmp_path


def _trc_lines(folder):
    return (folder / "t.trc").read_text().split("\n")


def _write_trc(folder, lines):
    (folder / "t.trc").write_text("\n".join(lines))


def _set_trc_cell(lines, row, column, value):
    """``lines`` with the cell ``column`` (0: frame, 1: time, 2: S1's x, …) of data row
    ``row`` (0-based) set to ``value`` (text)."""
    lines = list(lines)
    i = FIRST_ROW_LINE - 1 + row
    cells = lines[i].split("\t")
    cells[column] = value
    lines[i] = "\t".join(cells)
    return lines


#: the motion file's columns: hip_q = 10 sin(2t) and knee = −30 + 5t (deg at inDegrees=yes)
def _hip(t):
    return 10 * np.sin(2 * t)


def _knee(t):
    return -30 + 5 * t


def _motion_text(columns=None, times=None, in_degrees="yes", n_rows=None, n_columns=None):
    """The text of a coordinate file: ``columns`` {label: (21,) values or text cells}
    (default hip_q and knee above), at ``times`` (default 0, 0.01, …, 0.2 s), its header
    with ``inDegrees=in_degrees`` (None: no such line) and nRows/nColumns as given or as
    the data are."""
    times = np.arange(21) * MOTION_DT if times is None else np.asarray(times)
    if columns is None:
        columns = {"hip_q": _hip(times), "knee": _knee(times)}
    header = ["motion", "version=1", f"nRows={len(times) if n_rows is None else n_rows}",
              f"nColumns={len(columns) + 1 if n_columns is None else n_columns}"]
    if in_degrees is not None:
        header.append(f"inDegrees={in_degrees}")
    rows = ["\t".join([repr(float(t))] + [v if isinstance(v, str) else repr(float(v)) for v in values])
            for t, values in zip(times, zip(*columns.values()))]
    return "\n".join(header + ["endheader", "\t".join(["time", *columns])] + rows) + "\n"


def _run_motion(capsys, folder, text, command="run"):
    """(exit code, stderr) of ``openfdk run|kinematics|check leg.osim --motion m.mot`` with
    the coordinate file ``text``."""
    (folder / "m.mot").write_text(text)
    extra = {"run": ["--no-plots", "-q", "--out", folder / "out", "--force"],
             "kinematics": ["-q", "--out", folder / "out", "--force"], "check": ["-q"]}[command]
    code, _, err = run_cli(capsys, command, folder / "leg.osim", "--motion", folder / "m.mot", *extra)
    assert "Traceback" not in err
    return code, err


def _warning_lines(err):
    return [line for line in err.splitlines() if line.startswith("openfdk: warning:")]


def _one_warning(err, *needles):
    """The single warning line of ``err`` holding every one of ``needles``."""
    found = [line for line in _warning_lines(err) if all(n in line for n in needles)]
    assert len(found) == 1, err
    return found[0]


# -- 1. TRC: coordinates no capture volume holds ------------------------------------------

@pytest.mark.parametrize("command", ["kinematics", "run"])
@pytest.mark.parametrize("row, value", [(0, "1e200"), (4, "1e200"), (0, "1e10")])
def test_a_marker_coordinate_beyond_a_kilometre_is_refused_naming_the_line_and_marker(jaw, capsys, command, row,
                                                                                       value):
    """The first row's 1e200 mm raised OverflowError in check_trial_markers (a traceback);
    a later row's gave exit 3 with "RMS residual inf mm"; 1e10 mm (10 000 km) failed every
    frame. Each is now refused by the reader: the line, the time and the marker."""
    _write_trc(jaw, _set_trc_cell(_trc_lines(jaw), row, 2, value))
    extra = ["--no-plots"] if command == "run" else []
    code, _, err = run_cli(capsys, command, jaw / "tb.yaml", jaw / "t.trc", "-q", "--out", jaw / "out", *extra)
    assert code == 2
    line = error_line(err)
    assert (f"t.trc: line {FIRST_ROW_LINE + row}: marker 'S1' at time {row / TRC_RATE:g} s: x = {float(value):g} mm "
            "is beyond 1000 m from the origin") in line
    assert not (jaw / "out" / "summary.json").exists()


def test_a_row_of_the_largest_doubles_is_refused_at_its_first_marker(jaw, capsys):
    lines = _trc_lines(jaw)
    i = FIRST_ROW_LINE - 1
    cells = lines[i].split("\t")
    lines[i] = "\t".join(cells[:2] + ["1e308"] * (len(cells) - 2))
    _write_trc(jaw, lines)
    code, _, err = run_cli(capsys, "kinematics", jaw / "tb.yaml", jaw / "t.trc", "-q", "--out", jaw / "out")
    assert code == 2
    assert f"t.trc: line {FIRST_ROW_LINE}: marker 'S1' at time 0 s: x = 1e+308 mm" in error_line(err)


def test_the_kilometre_bound_applies_after_the_unit_conversion(jaw):
    """999 999 mm (just under 1 km) is read as 999.999 m; 1 000 001 mm is refused."""
    from openfdk.io.trc import TRCError, read_trc

    _write_trc(jaw, _set_trc_cell(_trc_lines(jaw), 3, 4, "999999"))   # S1's z at t = 0.03 s
    assert read_trc(jaw / "t.trc").positions[3, 0, 2] == pytest.approx(999.999, rel=1e-12)
    _write_trc(jaw, _set_trc_cell(_trc_lines(jaw), 3, 4, "-1000001"))
    with pytest.raises(TRCError, match=r"t\.trc: line 10: marker 'S1' at time 0\.03 s: z = -1e\+06 mm is beyond "
                                       r"1000 m"):
        read_trc(jaw / "t.trc")


def test_a_c3d_coordinate_beyond_a_kilometre_is_refused_naming_frame_time_and_marker(tmp_path, monkeypatch):
    """The same bound for a C3D trial (checked where trials are read, the frame named).
    openfdk's writer refuses such a file itself: its bound is lifted to write it."""
    from openfdk.io.c3d import C3DError, write_c3d
    from openfdk.io.trials import read_trial

    monkeypatch.setattr("openfdk.io.c3d.MAX_LAB_COORDINATE_M", 1e9)
    positions = np.full((10, 2, 3), 0.5)
    positions[6, 1, 1] = 2000.0                       # 2 km, as metres; written in mm
    write_c3d(tmp_path / "far.c3d", ["A", "B"], positions, 100.0, units="mm")
    with pytest.raises(C3DError, match=r"far\.c3d: frame 7 \(time 0\.06 s\): marker 'B': y = 2000 m is beyond 1000 m"):
        read_trial(tmp_path / "far.c3d")


def test_the_units_check_of_a_trial_takes_any_spread_without_overflow():
    """check_trial_markers computed 10**round(log10(ratio)) and overflowed on a ratio of
    inf (markers near the double's limit) or 1e200. Trials that bypass the readers
    (built in Python) still reach it: the warning names no factor then, and no
    exception or numpy overflow warning escapes."""
    from openfdk.io.c3d import MarkerTrial
    from openfdk.model.plausibility import PlausibilityWarning, check_trial_markers
    from openfdk.fixtures.synthetic import two_body_model

    model = two_body_model()
    M = model.markers.positions(model.initial_state())           # (8, 3) m
    labels = tuple(model.markers.labels)
    spread = float(np.sqrt(np.mean(np.sum((M - M.mean(0)) ** 2, axis=1))))
    cases = [(M * 1e3, f"{1e3:.3g}x", "a factor 1000"),
             (M * 1e200, f"{1e200:.3g}x", "a factor 1e+200"),
             (np.sign(M - M.mean(0)) * 1.5e308, "infx", "no unit factor")]
    for P, ratio_text, factor_text in cases:
        trial = MarkerTrial(labels=labels, rate=100.0, time=np.array([0.0, 0.01]),
                            positions=np.stack([P, P]), source="big.trc")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_trial_markers(model, trial, np.array([0.0, 0.01]))
        texts = [str(w.message) for w in caught]
        assert len(texts) == 1 and caught[0].category is PlausibilityWarning, texts
        assert ratio_text in texts[0] and f"({factor_text}; check Units on line 3)" in texts[0]
    assert spread > 0


# -- 2. TRC: rows cut short ---------------------------------------------------------------

def test_a_row_cut_inside_a_marker_is_refused_naming_the_line_and_the_marker(jaw, capsys):
    """A row of frame, time and 7 coordinates stops inside the third marker (S3: x
    only): refused. Before, the row was read with S1–J4 partly missing, silently."""
    lines = _trc_lines(jaw)
    i = FIRST_ROW_LINE - 1 + 2
    lines[i] = "\t".join(lines[i].split("\t")[:9])
    _write_trc(jaw, lines)
    code, _, err = run_cli(capsys, "kinematics", jaw / "tb.yaml", jaw / "t.trc", "-q", "--out", jaw / "out")
    assert code == 2
    assert (f"t.trc: line {FIRST_ROW_LINE + 2}: the row stops inside marker 'S3' (1 of its x y z): 9 values, "
            "expected 26") in error_line(err)


def test_a_last_row_cut_after_a_marker_is_read_with_a_warning_naming_it(jaw, capsys):
    """A file cut short: its last row stops mid-number after S1's z ("35."), every other
    row complete. It reads as S1 alone in that row (the markers after it missing), and
    one warning names the line. Short rows elsewhere too (a writer that drops trailing
    empty cells, OpenSim's layout with the last markers lost) are read without one."""
    from openfdk.io.trc import read_trc

    lines = _trc_lines(jaw)
    last = max(i for i, line in enumerate(lines) if line.strip())
    cells = lines[last].split("\t")
    lines[last] = "\t".join(cells[:4] + [cells[4][:3]])     # S1's z cut to its first 3 characters
    _write_trc(jaw, lines)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trial = read_trc(jaw / "t.trc")
    texts = [str(w.message) for w in caught]
    assert len(texts) == 1, texts
    assert texts[0].startswith(f"{jaw / 't.trc'}: line {last + 1}, the last row, stops before the last marker "
                               "(26 values expected")
    assert np.isnan(trial.positions[-1, 1:]).all() and np.isfinite(trial.positions[-1, 0]).all()
    assert np.isfinite(trial.positions[:-1]).all(axis=2).sum() == trial.positions[:-1].shape[0] * 8 - 4  # S3's gap
    code, _, err = run_cli(capsys, "kinematics", jaw / "tb.yaml", jaw / "t.trc", "-q", "--out", jaw / "out")
    assert f"line {last + 1}, the last row, stops before the last marker" in _one_warning(err, "the last row")
    for row in (0, 3):  # short rows elsewhere too: a writer's layout, no warning
        i = FIRST_ROW_LINE - 1 + row
        lines[i] = "\t".join(lines[i].split("\t")[:5])
    _write_trc(jaw, lines)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trial = read_trc(jaw / "t.trc")
    assert [str(w.message) for w in caught] == []
    assert np.isnan(trial.positions[[0, 3], 1:]).all() and np.isfinite(trial.positions[[0, 3], 0]).all()


@pytest.mark.parametrize("kept, tail, refused", [(5, "\t", None), (4, "", "(2 of its x y z): 4 values"),
                                                 (3, "\t", "(1 of its x y z): 4 values")])
def test_a_separator_after_the_last_value_does_not_decide_where_a_row_stops(jaw, kept, tail, refused):
    """Frame, time and S1's x y z and a tab (a writer that ends every cell with a tab) stop
    after a marker: read, S1 alone. S1's x y, or its x and a tab, stop inside it: refused."""
    from openfdk.io.trc import TRCError, read_trc

    lines = _trc_lines(jaw)
    lines[FIRST_ROW_LINE - 1] = "\t".join(lines[FIRST_ROW_LINE - 1].split("\t")[:kept]) + tail
    _write_trc(jaw, lines)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if refused:
            expected = rf"t\.trc: line 7: the row stops inside marker 'S1' {re.escape(refused)}"
            with pytest.raises(TRCError, match=expected):
                read_trc(jaw / "t.trc")
        else:
            trial = read_trc(jaw / "t.trc")
            assert np.isfinite(trial.positions[0, 0]).all() and np.isnan(trial.positions[0, 1:]).all()
    assert len(caught) == 0


def test_rows_with_empty_cells_for_missing_markers_are_read_silently(jaw):
    """The fuzzer's TRC writes its gap (S3, rows 5–8) as empty cells, every row full
    length: no warning, S3 missing there and nowhere else."""
    from openfdk.io.trc import read_trc

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trial = read_trc(jaw / "t.trc")
    assert [str(w.message) for w in caught] == []
    missing = np.isnan(trial.positions).any(axis=2)
    assert np.argwhere(missing).tolist() == [[5, 2], [6, 2], [7, 2], [8, 2]]


# -- 3. Motion: values no coordinate reaches ----------------------------------------------

@pytest.mark.parametrize("column, value, row", [("hip_q", "1e308", 6), ("knee", "1e150", 6), ("hip_q", "1e300", None)])
def test_a_coordinate_value_no_motion_reaches_is_refused_naming_column_and_time(leg, capsys, column, value, row):
    """1e308 or 1e150 deg at one time gave "SVD did not converge" (no file named); 1e300
    in every row a Newton failure of every frame (exit 3). Refused now: the file, the
    column, the time and the value in deg and rad."""
    t = np.arange(21) * MOTION_DT
    cols = {"hip_q": [repr(float(v)) for v in _hip(t)], "knee": [repr(float(v)) for v in _knee(t)]}
    for k in range(21) if row is None else [row]:
        cols[column][k] = value
    code, err = _run_motion(capsys, leg, _motion_text(cols))
    assert code == 2
    first = 0 if row is None else row
    rad = math.radians(float(value))
    assert (f"m.mot: column '{column}' at time {first * MOTION_DT:.10g} s: {float(value):g} deg, {rad:g} rad, beyond "
            "the 100000 rad a rotational coordinate can reach") in error_line(err)
    assert not (leg / "out" / "summary.json").exists()


def test_the_rotation_bound_is_one_hundred_thousand_radians(leg, capsys):
    """inDegrees=no: 1.0001e5 rad in hip_q is refused; 9.999e4 rad is read (with the
    range warning of the next test, 99 990 − 2 rad outside)."""
    t = np.arange(21) * MOTION_DT
    hip = np.radians(_hip(t))
    hip[3] = 1.0001e5
    code, err = _run_motion(capsys, leg, _motion_text({"hip_q": hip, "knee": np.radians(_knee(t))}, in_degrees="no"),
                            command="check")
    assert code == 2
    assert "m.mot: column 'hip_q' at time 0.03 s: 100010 rad, beyond the 100000 rad" in error_line(err)
    hip[3] = 9.999e4
    code, err = _run_motion(capsys, leg, _motion_text({"hip_q": hip, "knee": np.radians(_knee(t))}, in_degrees="no"),
                            command="check")
    assert code == 0, err
    assert "'hip_q' 9.999e+04 rad at 0.03 s (range [-2, 2])" in _one_warning(err, "outside the coordinate's range")


# -- 4. Motion: degrees read as radians ----------------------------------------------------

@pytest.mark.parametrize("in_degrees, said", [("no", "inDegrees=no on line 5"),
                                              (None, "no inDegrees line: read as radians")])
@pytest.mark.parametrize("command", ["run", "kinematics"])
def test_degrees_read_as_radians_are_a_warning_naming_column_extreme_and_range(leg, capsys, in_degrees, said, command):
    """The file's degrees under inDegrees=no (or no such line) drove the knee to −30 rad
    and hip_q to 3.9 rad (range [-2, 2]) silently. OpenSim follows an unclamped
    coordinate outside its range too, so the run goes on, with one warning: hip_q's
    largest value 10 sin(0.4) rad at 0.2 s, the knee's −30 rad at 0 s against OpenSim's
    default range [-10, 10] (the .osim gives it none)."""
    code, err = _run_motion(capsys, leg, _motion_text(in_degrees=in_degrees), command=command)
    assert code == 0, err
    line = _one_warning(err, "outside the coordinate's range")
    assert line == (f"openfdk: warning: m.mot: rotational column(s) more than 1 rad outside the coordinate's range: "
                    f"'hip_q' {10 * math.sin(0.4):.4g} rad at 0.2 s (range [-2, 2]), 'knee' -30 rad at 0 s "
                    f"(range [-10, 10], OpenSim's default); {said}: is that right? (the motion is followed as given, "
                    "as OpenSim follows an unclamped coordinate)")


def test_a_motion_file_in_its_coordinates_ranges_is_read_silently(leg, capsys):
    """The same file with inDegrees=yes: no warning at all (run and kinematics)."""
    for command in ("run", "kinematics"):
        code, err = _run_motion(capsys, leg, _motion_text(), command=command)
        assert code == 0 and _warning_lines(err) == [], err


# -- 5. Motion: header counts --------------------------------------------------------------

def test_header_row_and_column_counts_that_contradict_the_data_are_a_warning(leg, capsys):
    code, err = _run_motion(capsys, leg, _motion_text(n_rows=100, n_columns=7))
    assert code == 0, err
    assert _one_warning(err, "nRows") == ("openfdk: warning: m.mot: line 3: nRows=100, the file has 21 data rows; "
                                          "line 4: nColumns=7, the file has 3 columns (time included); the data are "
                                          "read as they are")


# -- 6. Motion: columns the model does not use --------------------------------------------

@pytest.mark.parametrize("extra, listed", [(["elbow"], "1 column(s) name no coordinate of the model and are not "
                                                      "used: 'elbow'"),
                                           ([f"c{i}" for i in range(5000)],
                                            "5000 column(s) name no coordinate of the model and are not used: 'c0', "
                                            "'c1', 'c2', 'c3', 'c4' and 4995 more")])
def test_columns_naming_no_coordinate_are_ignored_with_a_warning(leg, capsys, extra, listed):
    t = np.arange(21) * MOTION_DT
    cols = {"hip_q": _hip(t), "knee": _knee(t), **{name: np.ones(21) for name in extra}}
    code, err = _run_motion(capsys, leg, _motion_text(cols))
    assert code == 0, err
    assert _one_warning(err, "name no coordinate") == f"openfdk: warning: m.mot: {listed}"


def test_a_coupled_coordinates_column_its_coupler_contradicts_is_a_warning(leg, capsys):
    """pat_q = 99 deg where the coupler gives 0.5·knee + 0.1 rad: the column is not used,
    and the warning says by how much it is off (largest at t = 0, knee = −30 deg)."""
    t = np.arange(21) * MOTION_DT
    code, err = _run_motion(capsys, leg, _motion_text({"hip_q": _hip(t), "knee": _knee(t), "pat_q": np.full(21, 99.0)}))
    assert code == 0, err
    off = math.radians(99.0) - (0.5 * math.radians(-30.0) + 0.1)
    assert _one_warning(err, "pat_q") == (f"openfdk: warning: m.mot: column(s) of coupled coordinates that their "
                                          f"couplers contradict, not used (the coupler sets them): 'pat_q' (coupler "
                                          f"'pat_cc' from 'knee': {off:.3g} rad off at 0 s)")


def test_a_file_with_every_coordinate_as_ik_writes_it_is_read_silently(leg, capsys):
    """OpenSim's IK writes every coordinate, the coupled pat_q too (as its coupler gives
    it, 8 digits), and state files add /speed columns: nothing to warn about."""
    t = np.arange(21) * MOTION_DT
    pat = np.degrees(0.5 * np.radians(_knee(t)) + 0.1)
    code, err = _run_motion(capsys, leg, _motion_text({"hip_q": _hip(t), "knee": _knee(t),
                                                       "pat_q": [f"{v:.8g}" for v in pat]}))
    assert code == 0 and _warning_lines(err) == [], err
    code, err = _run_motion(capsys, leg, _motion_text({"/jointset/hip/hip_q/value": _hip(t),
                                                       "/jointset/knee_j/knee/value": _knee(t),
                                                       "/jointset/hip/hip_q/speed": np.zeros(21),
                                                       "/jointset/knee_j/knee/speed": np.zeros(21)}))
    assert code == 0 and _warning_lines(err) == [], err


def test_a_state_path_naming_another_joint_is_a_warning(leg, capsys):
    t = np.arange(21) * MOTION_DT
    code, err = _run_motion(capsys, leg, _motion_text({"/jointset/hip/hip_q/value": _hip(t),
                                                       "/jointset/WRONG/knee/value": _knee(t)}))
    assert code == 0, err
    assert _one_warning(err, "WRONG") == ("openfdk: warning: m.mot: column(s) naming another joint than the model's: "
                                          "'/jointset/WRONG/knee/value' (the model's 'knee' is in joint 'knee_j'); "
                                          "they are read by the coordinate's name: was the file written for another "
                                          "model?")


# -- 7. Motion: times that cannot be resolved ---------------------------------------------

@pytest.mark.parametrize("times, expected", [
    (1e300 + 1e290 * np.arange(21), "m.mot: time {t[20]!r} s (sample 21) is beyond 1e+10 s (317 years)"),
    (1e-300 * np.arange(21), "m.mot: times {a!r} and {b!r} s are {gap:.3g} s apart: a sampling rate above 1e+06 Hz, "
                             "the highest a run takes (analysis.rate_hz)"),
    (1.7e9 + 0.01 * np.arange(21), "s apart, less than 1e-09 of their magnitude: the results print times to 10 "
                                   "significant digits, too few to tell the samples apart"),
])
def test_times_whose_spacing_cannot_be_resolved_are_refused_naming_the_motion_file(leg, capsys, times, expected):
    """1e300 + 1e290·i was accepted and every output row printed 1e+300; samples 1e-300
    s apart were blamed on the model (leg.osim: analysis.rate_hz); Unix time with 10 ms
    samples (1.7e9 s: 5.9e-12 of it) prints alike at 10 significant digits."""
    code, err = _run_motion(capsys, leg, _motion_text(times=times))
    assert code == 2
    line = error_line(err)
    k = int(np.argmin(np.diff(times)))          # the closest samples, as written (repr)
    a, b = float(repr(float(times[k]))), float(repr(float(times[k + 1])))
    assert expected.format(t=[float(x) for x in times], a=a, b=b, gap=b - a) in line
    assert line.startswith("openfdk: error: m.mot: time")
    assert "leg.osim" not in line


def test_an_offset_clock_that_the_outputs_resolve_is_accepted(leg, capsys):
    """Seconds since midnight (86 000 s) at 100 Hz: 1e-2 / 8.6e4 = 1.2e-7 of the
    magnitude, printed to 10 digits as 86000.00000, 86000.01000, …: read, and the
    kinematics' times are the file's."""
    times = 86000.0 + MOTION_DT * np.arange(21)
    code, err = _run_motion(capsys, leg, _motion_text(times=times), command="kinematics")
    assert code == 0, err
    import csv

    with open(leg / "out" / "kinematics.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["time"]) for r in rows] == pytest.approx(times, abs=1e-6)


def test_a_motion_file_of_labels_and_no_rows_is_refused_as_too_few_samples(leg, capsys):
    """Found by the fuzzer while the value checks were written: no rows reached argmax of
    an empty column. The file is refused as before: 0 samples."""
    code, err = _run_motion(capsys, leg, _motion_text(times=[]), command="check")
    assert code == 2
    assert error_line(err) == ("openfdk: error: m.mot: 0 sample(s); a motion file needs at least 6 (OpenSim's quintic "
                               "spline)")
