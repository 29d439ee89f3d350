"""Hostile ExternalLoads files and ground-reaction data (the sweep of stop 72): every one
ends in exit code 2 with one line naming the file and the entry (column, time, element),
or is read with a warning; none reaches the solver, and no summary holds NaN/Infinity.

The inputs are the fuzzer's own pair (openfdk.bench.fuzz_kinds): the two-body ``leg.osim``
with an ExternalLoads file of two forces and its 21-sample GRF ``.mot`` (100 Hz)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cli_helpers import error_line, run_cli
from openfdk.bench.fuzz_inputs import write_leg
from openfdk.bench.fuzz_kinds import EXTERNAL_LOADS_TEXT, _write_grf, _write_motion

#: the row of the GRF file the cells below are written into (t = 0.05 s at 100 Hz)
ROW_TIME = 0.05


@pytest.fixture
def leg(tmp_path):
    """A folder with leg.osim (and its mesh), motion.sto, loads.xml and grf.mot."""
    write_leg(tmp_path)
    (tmp_path / "loads.xml").write_text(EXTERNAL_LOADS_TEXT)
    _write_grf(tmp_path / "grf.mot")
    _write_motion(tmp_path / "motion.sto")
    return tmp_path


def _run(capsys, folder, *extra):
    return run_cli(capsys, "run", folder / "leg.osim", "--motion", folder / "motion.sto", "--external-loads",
                   folder / "loads.xml", "--no-plots", "-q", "--out", folder / "out", *extra)


def _set_cells(path, column, value, time=ROW_TIME):
    """Write ``value`` (text) into ``column`` of the .mot at ``path``, at the row of
    ``time`` (s), or in every row when ``time`` is None."""
    lines = path.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("time"))
    j = lines[header].split("\t").index(column)
    hits = 0
    for i in range(header + 1, len(lines)):
        cells = lines[i].split("\t")
        if time is None or math.isclose(float(cells[0]), time):
            cells[j] = value
            lines[i] = "\t".join(cells)
            hits += 1
    assert hits == (1 if time is not None else len(lines) - header - 1)
    path.write_text("\n".join(lines) + "\n")


def _strict_json(path):
    """``path`` parsed by a strict JSON parser (NaN, Infinity and -Infinity refused)."""
    def refuse(constant):
        raise ValueError(f"{path.name}: {constant} is not JSON")

    return json.loads(path.read_text(), parse_constant=refuse)


# -- 1, 2, 4: impossible magnitudes in the GRF data -------------------------------------

@pytest.mark.parametrize("cutoff", [(), ("--external-loads-cutoff", "6")], ids=["as given", "6 Hz"])
@pytest.mark.parametrize("column, value, entry, words", [
    ("ground_force_vy", "1.7e308", "force", "ground_force_vy = 1.7e+308 N"),
    ("ground_force_vy", "1e300", "force", "ground_force_vy = 1e+300 N"),
    ("ground_force_vx", "-2e6", "force", "ground_force_vx = -2e+06 N"),
    ("ground_force_px", "1.7e308", "point", "ground_force_px = 1.7e+308 m"),
    ("ground_torque_y", "1.7e308", "torque", "ground_torque_y = 1.7e+308 N m"),
    ("push_vz", "-1e300", "force", "push_vz = -1e+300 N"),
])
def test_an_impossible_cell_is_refused_naming_file_column_and_time(leg, capsys, cutoff, column, value, entry, words):
    _set_cells(leg / "grf.mot", column, value)
    code, _, err = _run(capsys, leg, *cutoff)
    line = error_line(err)
    assert code == 2
    load = "push" if column.startswith("push") else "right"
    assert f"external_loads.{load}.{entry}: {words} in {leg / 'grf.mot'} at t = 0.05 s" in line
    assert "C and d must be finite" not in err and "look unfiltered" not in err
    assert not (leg / "out" / "summary.json").exists()


def test_a_whole_column_of_huge_forces_is_refused_and_not_called_unfiltered(leg, capsys):
    _set_cells(leg / "grf.mot", "ground_force_vy", "1.7e308", time=None)
    code, _, err = _run(capsys, leg)
    line = error_line(err)
    assert code == 2 and "ground_force_vy = 1.7e+308 N" in line and "at t = 0 s" in line
    assert "look unfiltered" not in err and "(inf)" not in err


def test_a_point_far_away_is_refused_only_under_load(leg, capsys):
    # at t = 0.05 s the force is (50, 700, 10) sin(pi t / 0.2) N = (35.36, 495.0, 7.07) N and
    # the point (3000, 0, 0.05) m: |p| |F| = 3000.0 m * 496.3 N = 1.49e6 N m, beyond 1e6 N m
    F = np.array([50.0, 700.0, 10.0]) * np.sin(np.pi * ROW_TIME / 0.2)
    moment = math.hypot(3000.0, 0.05) * float(np.linalg.norm(F))
    _set_cells(leg / "grf.mot", "ground_force_px", "3000")
    code, _, err = _run(capsys, leg)
    line = error_line(err)
    assert code == 2
    assert (f"external_loads.right.point: ground_force_px = 3000 m with ground_force_vy = {F[1]:.4g} N in "
            f"{leg / 'grf.mot'} at t = 0.05 s: a moment of {moment:.3g} N m about the origin") in line


def test_a_point_far_away_where_the_force_is_zero_is_read(leg, capsys):
    # as in OpenSim's Rajagopal (2016) walk: the unloaded point 500 m away, force 0 at t = 0
    _set_cells(leg / "grf.mot", "ground_force_px", "500", time=0.0)
    code, _, err = _run(capsys, leg)
    assert code == 0, err
    _strict_json(leg / "out" / "summary.json")


def test_a_non_finite_equation_names_its_row_and_column():
    from openfdk.recruitment.result import RecruitmentInputError, check_problem

    C, d = np.eye(2), np.array([1.0, np.inf])
    with pytest.raises(RecruitmentInputError) as exc:
        check_problem(C, d, 1, [10.0], row_names=["shank.Fx", "shank.Fy"], column_names=["m", "hip"])
    assert str(exc.value).startswith("C and d must be finite: d of row 'shank.Fy'") and " is inf" in str(exc.value)
    C[0, 1] = np.nan
    with pytest.raises(RecruitmentInputError) as exc:
        check_problem(C, np.ones(2), 1, [10.0], row_names=["shank.Fx", "shank.Fy"], column_names=["m", "hip"])
    assert "C of row 'shank.Fx', column 'hip' is nan" in str(exc.value)
    assert "\n" not in str(exc.value)


def test_a_force_plate_sample_beyond_the_bound_is_refused(tmp_path):
    import ezc3d

    from openfdk.bench.fuzz_kinds import _write_plates
    from openfdk.io.c3d import C3DError
    from openfdk.io.force_plates import read_force_plates

    path = tmp_path / "plates.c3d"
    _write_plates(path)                    # 40 frames at 100 Hz, analog 500 Hz; FP2 (type 2): channels 7–12
    c3d = ezc3d.c3d(str(path))
    analog = c3d["data"]["analogs"]
    analog[0, 8, 100] = 1e30               # FP2's Fz (N), analog sample 101: t = 100 / 500 Hz = 0.2 s
    c3d["data"]["analogs"] = analog
    c3d.write(str(path))
    with pytest.raises(C3DError) as exc:
        read_force_plates(path)
    message = str(exc.value)
    assert message.startswith(f"{path}: force plate FP2: a force of 1e+30 N at t = 0.2 s (analog sample 101): "
                              f"beyond 1e+06 N, not a measurement")
    assert "\n" not in message


# -- 3: summary.json is strict JSON -----------------------------------------------------

def test_write_json_writes_non_finite_numbers_as_null(tmp_path):
    from openfdk.io.results import write_json

    data = {"residuals": {"columns": {"hip_force": {"rms": float("inf"), "peak": np.float64(-np.inf)}},
                          "mean": np.nan, "ok": np.float32(2.5)},
            "values": np.array([1.0, np.nan, np.inf]), "pair": (np.int64(3), np.bool_(True)), "name": "leg"}
    write_json(tmp_path / "summary.json", data)
    back = _strict_json(tmp_path / "summary.json")
    assert back == {"residuals": {"columns": {"hip_force": {"rms": None, "peak": None}}, "mean": None, "ok": 2.5},
                    "values": [1.0, None, None], "pair": [3, True], "name": "leg"}


def test_the_summary_of_a_run_with_external_loads_is_strict_json(leg, capsys):
    _set_cells(leg / "grf.mot", "ground_force_vy", "9e5")    # within the bound: read, large residuals
    code, _, err = _run(capsys, leg)
    assert code == 0, err
    summary = _strict_json(leg / "out" / "summary.json")
    assert isinstance(summary, dict) and "inverse_dynamics" in summary


# -- 5: the ExternalLoads XML -----------------------------------------------------------

@pytest.mark.parametrize("old, new, words", [
    ("<isDisabled>false</isDisabled>", "<isDisabled>maybe</isDisabled>",
     "line 5: ExternalForce 'right': <isDisabled> must be true or false, got 'maybe'"),
    ("<isDisabled>false</isDisabled>", "<appliesForce>0</appliesForce>",
     "line 5: ExternalForce 'right': <appliesForce> must be true or false, got '0'"),
    ('<ExternalForce name="right">', '<ExternalForce name="">',
     "line 5: ExternalForce: no name (name=\"…\")"),
    ('<ExternalForce name="push">', "<ExternalForce>", "line 15: ExternalForce: no name"),
    ('<ExternalForce name="right">', '<ExternalForce name="right" file="other.xml">',
     "line 5: ExternalForce 'right': file='other.xml': openfdk does not read objects from other files"),
    ('<ExternalLoads name="grf_loads">', '<ExternalLoads name="grf_loads" file="loads.xml">',
     "line 3: ExternalLoads 'grf_loads': file='loads.xml'"),
])
def test_bad_external_loads_xml_is_refused_in_one_line(leg, capsys, old, new, words):
    xml = EXTERNAL_LOADS_TEXT.replace(old, new, 1)
    assert xml != EXTERNAL_LOADS_TEXT
    (leg / "loads.xml").write_text(xml)
    code, _, err = _run(capsys, leg)
    assert code == 2 and error_line(err).startswith(f"openfdk: error: loads.xml: {words}")


def test_a_two_file_loop_of_file_attributes_is_refused(leg, capsys):
    (leg / "loads.xml").write_text(EXTERNAL_LOADS_TEXT.replace("<objects>", '<objects file="other.xml">'))
    (leg / "other.xml").write_text(EXTERNAL_LOADS_TEXT.replace("<objects>", '<objects file="loads.xml">'))
    code, _, err = _run(capsys, leg)
    assert code == 2
    assert error_line(err).startswith("openfdk: error: loads.xml: line 4: objects: file='other.xml': ")


def test_an_unknown_element_is_read_with_one_warning(leg, capsys):
    xml = EXTERNAL_LOADS_TEXT.replace("<isDisabled>false</isDisabled>",
                                      "<isDisabled>false</isDisabled>\n    <units>furlongs</units>")
    (leg / "loads.xml").write_text(xml)
    code, _, err = _run(capsys, leg)
    assert code == 0, err
    warned = [line for line in err.splitlines() if "<units>" in line]
    assert warned == ["openfdk: warning: loads.xml: <units> of ExternalForce 'right' (line 7): not an OpenSim "
                      "ExternalLoads or ExternalForce property, ignored (as OpenSim ignores it)"]


def test_booleans_read_in_any_case_and_opensim_3_elements_without_warning(leg, capsys):
    # OpenSim 3.x files: <defaults> and the load-kinematics properties, isDisabled FALSE
    xml = (EXTERNAL_LOADS_TEXT.replace("<isDisabled>false</isDisabled>", "<isDisabled>FALSE</isDisabled>")
           .replace("<datafile>", "<defaults/>\n  <external_loads_model_kinematics_file>ik.mot"
                                  "</external_loads_model_kinematics_file>\n  <lowpass_cutoff_frequency_for_load_"
                                  "kinematics>6</lowpass_cutoff_frequency_for_load_kinematics>\n  <datafile>"))
    (leg / "loads.xml").write_text(xml)
    code, _, err = _run(capsys, leg)
    assert code == 0 and "loads.xml" not in err, err


def _set_times(path, times):
    """Replace the time column of the .mot at ``path`` by ``times`` (one per row, s)."""
    lines = path.read_text().splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("time"))
    rows = lines[header + 1:]
    assert len(rows) == len(times)
    lines[header + 1:] = ["\t".join([repr(float(t))] + row.split("\t")[1:]) for row, t in zip(rows, times)]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("times, words", [
    (lambda n: np.arange(n) * 1e-300, "times 1.2e-299 and 1.3e-299 s are 1e-300 s apart: a sampling rate above 1e+06 Hz"),
    (lambda n: 1e300 + np.arange(n) * 1e290, "(sample 21) is beyond 1e+10 s (317 years)")])
def test_load_samples_a_run_cannot_resolve_are_refused(leg, capsys, times, words):
    """Samples 1e-300 s apart reached the recruitment as NaN loads ("C and d must be
    finite", naming no file); times of 1e300 s were refused only as outside the window.
    Both are now refused naming the data file, as a motion file's are."""
    n = len([ln for ln in (leg / "grf.mot").read_text().splitlines()[7:] if ln.strip()])
    _set_times(leg / "grf.mot", times(n))
    code, _, err = _run(capsys, leg)
    line = error_line(err)
    assert code == 2 and f"external_loads.right.file: {leg / 'grf.mot'}: " in line and words in line, line


def test_load_samples_on_an_offset_clock_are_read(leg, capsys):
    """A plate's clock offset (Unix time, 1.7e9 s at 100 Hz) is interpolated at the
    trial's frames in float64 to 0.4 µs, and never printed: read, unlike a motion file's
    (whose times are the frames')."""
    from openfdk.io.storage import sample_times_problem

    offset = 1.7e9 + np.arange(21) * 0.01
    assert "less than 1e-09 of their magnitude" in sample_times_problem(offset, "m.mot")
    assert sample_times_problem(offset, "grf.mot", printed=False) == ""
