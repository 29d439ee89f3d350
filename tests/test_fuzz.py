"""Fuzz suite, quick version (issues 16 and 30): mutated model, subject and study files, C3D and
TRC trials, OpenSim models and IK setup files, ExternalLoads with their GRF files, motion
files, force-plate parameters, result folders, checkpoint parts and study locks either
load or raise the loader's documented error naming the file — never anything else. The
long run (>= 10 000 inputs per kind) is ``python -m openfdk.bench.fuzz_inputs 10000``;
its counts are in the closing note."""

import warnings

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from openfdk.bench.fuzz_inputs import (KINDS, Bases, _load, _paths, documented_error, fuzz, mutate_bytes, mutate_xml,
                                       mutate_yaml)


@pytest.fixture(scope="module")
def bases():
    b = Bases(KINDS)
    yield b
    b.close()


def _outcome(kind, bases):
    """'loaded' or 'refused'; any other exception propagates and fails the test."""
    error = documented_error(kind)
    path = bases.paths[kind]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with np.errstate(all="ignore"):
                _load(kind, path)
        return "loaded"
    except error as exc:
        assert path.name in str(exc) or path.parent.name in str(exc), str(exc)
        return "refused"


@pytest.mark.parametrize("kind", KINDS)
def test_seeded_fuzz_quick(kind, bases):
    c = fuzz(kind, 40 if kind != "subject" else 25, seed=2024, bases=bases)
    assert c["unexpected"] == []
    # both outcomes occur: the mutations are neither all harmless nor all fatal
    assert c["loaded"] > 0 and c["refused"] > 0
    assert c["loaded"] + c["refused"] == c["inputs"]


_SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.mark.parametrize("kind", ["model", "study", "subject"])
@_SETTINGS
@given(seed=st.integers(0, 2**63 - 1))
def test_hypothesis_mutated_yaml(kind, bases, seed):
    path = bases.paths[kind]
    original = path.read_bytes() if path.exists() else None
    try:
        path.write_text(mutate_yaml(bases.texts[kind], np.random.default_rng(seed)))
        _outcome(kind, bases)
    finally:
        if original is not None:
            path.write_bytes(original)


@_SETTINGS
@given(seed=st.integers(0, 2**63 - 1))
def test_hypothesis_mutated_c3d(bases, seed):
    path = bases.paths["c3d"]
    try:
        path.write_bytes(mutate_bytes(bases.c3d_bytes, np.random.default_rng(seed)))
        _outcome("c3d", bases)
    finally:
        path.write_bytes(bases.c3d_bytes)


@pytest.mark.parametrize("kind", ["osim", "ik"])
@_SETTINGS
@given(seed=st.integers(0, 2**63 - 1))
def test_hypothesis_mutated_opensim_xml(kind, bases, seed):
    """Mutated OpenSim models and IK setup files (numbers, elements, names, text)."""
    path = bases.paths[kind]
    try:
        path.write_text(mutate_xml(bases.texts[kind], np.random.default_rng(seed)))
        _outcome(kind, bases)
    finally:
        path.write_text(bases.texts[kind])


_ANY = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=6),
                 st.lists(st.floats(), max_size=4), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


@_SETTINGS
@given(data=st.data())
def test_hypothesis_any_value_at_any_entry_of_a_model(bases, data):
    """Any YAML value (of any type and magnitude, NaN and infinities included) at any
    entry of a valid model file."""
    tree = yaml.safe_load(bases.texts["model"])
    paths = [p for p, _ in _paths(tree) if p]
    path = data.draw(st.sampled_from(paths))
    node = tree
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = data.draw(_ANY)
    target = bases.paths["model"]
    try:
        target.write_text(yaml.safe_dump(tree, sort_keys=False))
        _outcome("model", bases)
    finally:
        target.write_text(bases.texts["model"])


def test_c3d_numeric_parameter_stored_as_text_is_refused_not_a_crash(tmp_path):
    """Found by the fuzz suite: FORCE_PLATFORM:CHANNEL turned into a character parameter
    made ezc3d dereference a null pointer (segmentation fault). It is now a C3DError.
    Run in a child process so that a regression fails this test instead of the session."""
    import subprocess
    import sys

    from openfdk.io.c3d import write_c3d
    from openfdk.fixtures.synthetic import synthetic_markers

    _, labels, x, _ = synthetic_markers(10)
    write_c3d(tmp_path / "ok.c3d", labels, x, 100.0)
    data = bytearray((tmp_path / "ok.c3d").read_bytes())
    i = data.index(b"CHANNEL")
    assert data[i + 9] == 2                      # type byte after the name and the 2-byte offset: int16
    data[i + 9], data[i + 10] = 255, 0           # -1: characters, 0 dimensions
    (tmp_path / "bad.c3d").write_bytes(bytes(data))
    code = ("from openfdk.io.c3d import read_c3d, C3DError\n"
            "try:\n    read_c3d(r'%s')\nexcept C3DError as e:\n    print(e)\n" % (tmp_path / "bad.c3d"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "bad.c3d: parameter FORCE_PLATFORM:CHANNEL must hold numbers" in proc.stdout


def test_trc_header_counts_nan_or_infinite_are_refused(bases, tmp_path):
    """Found by the fuzz suite: NumMarkers / NumFrames of NaN or inf raised ValueError /
    OverflowError from int(); now TRCError naming the file, the line and the field."""
    from openfdk.io.trc import TRCError, read_trc

    lines = bases.texts["trc"].split("\n")
    for field, value in ((3, "NaN"), (2, "inf"), (3, "2.5")):   # NumMarkers, NumFrames, NumMarkers
        cells = lines[2].split("\t")
        cells[field] = value
        path = tmp_path / "h.trc"
        path.write_text("\n".join(lines[:2] + ["\t".join(cells)] + lines[3:]))
        name = ("NumFrames", "NumMarkers")[field == 3]
        with pytest.raises(TRCError, match=rf"h\.trc: line 3: {name} is '{value}', expected a whole number"):
            read_trc(path)


# -- issue 30: the kinds of openfdk.bench.fuzz_kinds and what their fuzzing found -------

def test_plate_parameter_mutations_reach_the_plate_reader(bases):
    """The parameter mutator changes FORCE_PLATFORM and ANALOG records in place, so the
    refusals come from the plate reader's own checks, not only from the C3D header."""
    from openfdk.bench.fuzz_kinds import mutate_plate_parameters
    from openfdk.io.c3d import C3DError
    from openfdk.io.force_plates import read_force_plates

    base = bases.originals["force_plates"][bases.paths["force_plates"]]
    assert len(read_force_plates(bases.paths["force_plates"])) == 4
    rng, messages, loaded = np.random.default_rng(7), [], 0
    path = bases.paths["force_plates"]
    try:
        for _ in range(60):
            path.write_bytes(mutate_plate_parameters(base, rng, n_mutations=1))
            try:
                with warnings.catch_warnings(), np.errstate(all="ignore"):
                    warnings.simplefilter("ignore")
                    read_force_plates(path)
                loaded += 1
            except C3DError as exc:
                messages.append(str(exc))
    finally:
        path.write_bytes(base)
    assert loaded > 0
    reached = {m.split(": ")[1].split(":")[1] for m in messages if ": FORCE_PLATFORM:" in m}
    assert len(reached) >= 3, messages   # e.g. TYPE, CHANNEL, CORNERS, ORIGIN, CAL_MATRIX


def test_a_study_lock_with_a_pid_out_of_range_is_reported(tmp_path):
    """Found by the fuzz suite: a lock whose pid does not fit a C long raised OverflowError
    from os.kill; an id that is no process id now means an unknown owner."""
    import json
    import socket

    from openfdk.study import StudyError
    from openfdk.study.runner import _acquire_lock

    (tmp_path / ".study.lock").write_text(json.dumps({"host": socket.gethostname(), "pid": 10 ** 30}))
    with pytest.raises(StudyError, match=r"is in use by a study running on .* \(pid None, .*delete '.*\.study\.lock'"):
        _acquire_lock(tmp_path)


@pytest.fixture
def result(bases, tmp_path):
    """A private copy of the fuzz run's result folder (two-body model, 6 frames)."""
    import shutil

    res = tmp_path / "res"
    shutil.copytree(bases.paths["results"].parent, res)
    return res


def _edit_csv(path, edit):
    import csv

    rows = list(csv.reader(path.read_text().splitlines()))
    path.write_text("\n".join(",".join(r) for r in edit(rows)) + "\n")


def _drop_column(name):
    def edit(rows):
        j = rows[0].index(name)
        return [r[:j] + r[j + 1:] for r in rows]
    return edit


@pytest.mark.parametrize("command", ["plot", "export-opensim", "view"])
@pytest.mark.parametrize("table, edit, expected", [
    ("forces.csv", lambda rows: rows[:-2],
     "forces.csv: 4 frames whose times differ from the 6 frames of kinematics.csv"),
    ("kinematics.csv", _drop_column("jaw.e1"), "kinematics.csv: column 'jaw.e1' missing"),
    ("kinematics.csv", lambda rows: [rows[0]] + [r[:4] + ["m"] + r[5:] for r in rows[1:]],
     "kinematics.csv: column 'skull.x_m': values must be numbers"),
])
def test_result_tables_that_do_not_fit_are_refused(result, tmp_path, capsys, command, table, edit, expected):
    """Found by the fuzz suite: forces.csv of other frames than kinematics.csv, a body
    pose without one of its columns and text in a numeric column raised numpy's broadcast
    ValueError, KeyError or UFuncTypeError in plot, export-opensim or view."""
    from cli_helpers import error_line, run_cli

    _edit_csv(result / table, edit)
    args = [command, result] + (["--out", tmp_path / "out"] if command != "view" else [])
    code, _, err = run_cli(capsys, *args)
    line = error_line(err)
    assert code == 2
    if command == "view" and table == "forces.csv":
        expected = "forces.csv: 4 rows, kinematics.csv has 6"
    assert expected in line and str(result) in line


@pytest.mark.parametrize("edit, expected", [
    (lambda rows: rows[:-2], "coordinates.csv: 4 frames whose times differ from the 6 frames of kinematics.csv"),
    (lambda rows: [rows[0]] + [r[:1] + ["deg"] + r[2:] for r in rows[1:]],
     "coordinates.csv: column 'hinge_rad': values must be numbers"),
])
def test_a_coordinates_table_that_does_not_fit_is_refused_by_the_commands_that_read_it(result, tmp_path, capsys,
                                                                                         edit, expected):
    """coordinates.csv (an OpenSim model's run; plot draws the kinematics figure from it)
    is checked as the other tables are by plot and export-opensim; view does not read it."""
    from cli_helpers import error_line, run_cli

    assert (result / "coordinates.csv").is_file()  # the fuzz base has one (bench/fuzz_kinds.py)
    _edit_csv(result / "coordinates.csv", edit)
    for command in ("plot", "export-opensim"):
        code, _, err = run_cli(capsys, command, result, "--out", tmp_path / command)
        line = error_line(err)
        assert code == 2 and expected in line and str(result) in line, (command, line)
    code, out, _ = run_cli(capsys, "view", result, "--out", tmp_path / "view.html")
    assert code == 0 and (tmp_path / "view.html").is_file()


def test_view_refuses_a_marker_residual_without_all_its_columns(result, capsys):
    """Found by the fuzz suite (KeyError in the viewer's measured markers)."""
    from cli_helpers import error_line, run_cli

    _edit_csv(result / "kinematics.csv", _drop_column("S1.residual_y_m"))
    code, _, err = run_cli(capsys, "view", result)
    assert code == 2
    assert "kinematics.csv: column 'S1.residual_y_m' missing; the residual of marker 'S1' is incomplete" \
        in error_line(err)


def test_view_checks_summary_json_like_plot(result, capsys):
    """Found by the fuzz suite: ``"input": "x"`` gave AttributeError in view."""
    import json

    from cli_helpers import error_line, run_cli

    summary = json.loads((result / "summary.json").read_text())
    (result / "summary.json").write_text(json.dumps({**summary, "input": "x"}))
    code, _, err = run_cli(capsys, "view", result)
    assert code == 2
    assert "summary.json: input: must be a JSON object, got str" in error_line(err)


@pytest.fixture
def resumable(bases, tmp_path):
    """(model, trial, --out folder, run arguments) for ``openfdk run`` of the fuzz run's
    model and trial, and the Checkpoints object that run uses."""
    from openfdk.cli.commands import _run_checkpoints, build_parser

    run = bases.paths["results"].parent.parent
    argv = [run / "model.yaml", run / "trial.c3d", "--out", tmp_path / "out", "--no-progress", "--no-plots",
            "--max-failed", "1", "--end", "0.05"]
    ck = _run_checkpoints(build_parser().parse_args(["run", *map(str, argv)]))
    return argv, ck


def _report_with_text_reason():
    """A frame report whose reason is text, not a Reason (the fuzz, seed 70, input 5 of
    checkpoint_fdk: an AttributeError in the FDK result's columns after the resume)."""
    from openfdk.trial.status import FrameReport, FrameStatus

    report = FrameReport(FrameStatus.CONVERGED)
    object.__setattr__(report, "reason", "converged")
    return report


@pytest.mark.parametrize("records, carry, next_frame, expected", [
    ([(0, {"kin.q": np.zeros(3)})], None, 1, "frame 0: 'kin.q' is not an array (14,)"),
    ([(0, {"kin.report": _report_with_text_reason()})], None, 1,
     "frame 0: 'kin.report' is a frame report with fields of other types"),
    ([(0, {"kin.q": np.r_[0, 0, 0, 1e300, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0]})], None, 1,
     "frame 0: 'kin.q': the quaternion of moving body 0 cannot be normalised"),
    ([(0, {"kin.q": np.r_[np.nan, 0, 0, 1, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0]})], None, 1,
     "frame 0: 'kin.q': entries that are not finite in a pose"),
    ([(99, {})], None, 1, "frame 99 of 6"),
    ([(0, {"kin.report": 5.0})], None, 1, "frame 0: 'kin.report' is a float"),
    ([(0, {1.5: 1.0})], None, 1, "frame 0: a value named 1.5"),
    ([], None, 7, "next frame 7 of 6"),
    ([], ("x",), 0, "the solver state has another structure"),
])
def test_a_checkpoint_that_does_not_fit_the_run_is_refused_on_resume(resumable, capsys, records, carry, next_frame,
                                                                      expected):
    """Found by the fuzz suite: parts with this run's fingerprint and a matching hash but
    frames, values or a solver state that do not fit the run raised ValueError,
    AttributeError, ZeroDivisionError or numba's TypingError on --resume (a finished
    frame's pose whose quaternion cannot be normalised: ValueError in the contacts'
    plausibility check after the run, found by stop 59's edge-value mutations)."""
    from cli_helpers import error_line, run_cli

    argv, ck = resumable
    ck.save(records, carry, next_frame)
    code, _, err = run_cli(capsys, "run", *argv, "--resume")
    assert code == 2
    line = error_line(err)
    assert ".checkpoint: the checkpoint does not fit this run (" + expected in line, line


def test_a_genuine_checkpoint_still_resumes(bases):
    """The checks above accept what openfdk itself saved: the fuzz run's parts resume."""
    from openfdk.bench.fuzz_kinds import load

    kin, dyn, _ = load("checkpoint", bases.paths["checkpoint"])
    assert len(kin.time) == 6 and kin.converged.all()


def test_a_genuine_fdk_checkpoint_still_resumes(bases):
    """So do the FDK run's parts (their solver state carries the last solved frame's poses
    and KKT factors): the resumed run's frames all converge, FDK's included."""
    from openfdk.bench.fuzz_kinds import load, restore

    restore("checkpoint_fdk", bases)  # (the base parts, whatever a fuzz test left)
    kin, dyn, info = load("checkpoint_fdk", bases.paths["checkpoint_fdk"])
    assert len(kin.time) == 6 and kin.converged.all() and dyn.converged.all()
    assert info["fdk"]["converged_frames"] == 6


def _osim_folder(bases, tmp_path):
    import shutil

    for name in ("leg.osim", "loads.xml", "grf.mot", "motion.sto"):
        shutil.copy(bases.dir / name, tmp_path / name)
    shutil.copytree(bases.dir / "Geometry", tmp_path / "Geometry")
    return tmp_path


@pytest.mark.parametrize("old, new, expected", [
    ("<datafile>grf.mot</datafile>", "<datafile>true</datafile>",
     "loads.xml: line 15: ExternalForce 'push': data file 'true': true: cannot read the file"),
    ("<force_identifier>push_v</force_identifier>", "<force_identifier>push_w</force_identifier>",
     "loads.xml: line 15: ExternalForce 'push': force_identifier 'push_w': no column 'push_wx' in grf.mot"),
    ('<ExternalForce name="push">', '<ExternalForce name="..">',
     "loads.xml: line 15: ExternalForce '..': name '..' contains '..'"),
])
def test_external_loads_errors_name_the_xml_file(bases, tmp_path, capsys, old, new, expected):
    """Found by the fuzz suite: a data file that cannot be read and an unsafe force name
    were reported as errors of ``leg.osim: external_loads.…``; they name the ExternalLoads
    file, its line and the force now."""
    from cli_helpers import error_line, run_cli

    d = _osim_folder(bases, tmp_path)
    (d / "loads.xml").write_text((d / "loads.xml").read_text().replace(old, new))
    code, _, err = run_cli(capsys, "check", d / "leg.osim", "--external-loads", d / "loads.xml", "-q")
    assert code == 2
    assert expected in error_line(err)


@pytest.mark.parametrize("rows", [1, 5])
def test_a_motion_file_of_too_few_samples_is_refused(bases, tmp_path, capsys, rows):
    """Found by the fuzz suite: one sample gave a spline error naming the .osim's driver.
    OpenSim's quintic spline needs 6 samples."""
    from cli_helpers import error_line, run_cli

    d = _osim_folder(bases, tmp_path)
    lines = (d / "motion.sto").read_text().splitlines()
    (d / "motion.sto").write_text("\n".join(lines[:lines.index("endheader") + 2 + rows]) + "\n")
    code, _, err = run_cli(capsys, "check", d / "leg.osim", "--motion", d / "motion.sto", "-q")
    assert code == 2
    assert f"motion.sto: {rows} sample(s); a motion file needs at least 6" in error_line(err)


def test_a_hill_muscle_length_too_small_to_compute_with_is_refused(bases, tmp_path, capsys):
    """Found by the long fuzz run (model, input 3410): ``optimal_fibre_length: 1.0e-300``
    (mm) made the plausibility check's fibre equilibrium raise ZeroDivisionError."""
    from cli_helpers import error_line, run_cli

    tree = yaml.safe_load(bases.texts["model"])
    tree["muscles"]["m1"]["optimal_fibre_length"] = 1e-300
    (tmp_path / "model.yaml").write_text(yaml.safe_dump(tree, sort_keys=False))
    code, _, err = run_cli(capsys, "check", tmp_path / "model.yaml")
    assert code == 2
    assert "model.yaml: muscles.m1: Hill3ElementMuscle 'm1': optimal_fibre_length must be finite and >= 1e-09 m" \
        in error_line(err)


def test_a_point_rate_too_low_for_the_plate_filter_is_a_c3d_error(bases, tmp_path):
    """Found by the long fuzz run (force_plates, input 5160 and four more): POINT:RATE
    set to 3 or 5 Hz made the default 6 Hz low-pass impossible, reported as a plain ValueError
    about ``cutoff_hz``; it is the documented C3DError naming the file and the rate."""
    from openfdk.bench.fuzz_kinds import _parameter_records
    from openfdk.io.c3d import C3DError
    from openfdk.io.force_plates import read_force_plates

    data = bytearray(bases.originals["force_plates"][bases.paths["force_plates"]])
    records = _parameter_records(data)
    for key, rate in (("POINT:RATE", 5.0), ("ANALOG:RATE", 25.0)):   # 5 analog samples per frame, as before
        _, _, _, at, _, kind = records[key]
        assert kind == 4
        data[at:at + 4] = np.float32(rate).tobytes()
    (tmp_path / "slow.c3d").write_bytes(bytes(data))
    with pytest.raises(C3DError, match=r"slow\.c3d: cutoff_hz = 6 Hz must be 0 \(no filter\) or positive and "
                                       r"below 2\.5 Hz, half the point rate \(POINT:RATE\)"):
        read_force_plates(tmp_path / "slow.c3d")


def test_a_trc_header_with_empty_cells_between_its_values_reads_as_opensim_reads_it(bases, tmp_path):
    """Found on opensim-models' Rajagopal walk (``motion_capture_walk.trc``): its line 3
    puts two tabs between values ("100.0\\t\\t  100.0\\t\\t    238\\t\\t     41\\t\\t mm…"),
    which OpenSim's tokenizer reads as one separator. The file reads to the same trial as
    the single-tab one, and a header whose two lines still disagree is refused."""
    from openfdk.io.trc import TRCError, header_fields, read_trc

    lines = bases.texts["trc"].split("\n")
    plain = tmp_path / "plain.trc"
    plain.write_text("\n".join(lines))
    doubled = tmp_path / "doubled.trc"
    doubled.write_text("\n".join(lines[:2] + ["\t\t".join(lines[2].split("\t"))] + lines[3:]))
    a, b = read_trc(plain), read_trc(doubled)
    assert b.rate == a.rate and b.labels == a.labels
    np.testing.assert_array_equal(b.positions, a.positions)
    assert header_fields(doubled) == header_fields(plain)
    short = tmp_path / "short.trc"
    short.write_text("\n".join(lines[:2] + ["\t".join(lines[2].split("\t")[:2])] + lines[3:]))
    with pytest.raises(TRCError, match=r"short\.trc: line 2/3: header field 'NumMarkers' is missing"):
        read_trc(short)


def _tampered_resume(bases, kind, edit):
    """Resume the fuzz run of ``kind`` with its last checkpoint part's carry changed by
    ``edit(carry)``, the part re-encoded and its sidecar's hash made to match (what an
    attacker who knows the format would do). Returns the CheckpointError's text, or None
    when the run resumed."""
    from openfdk.bench.fuzz_kinds import _write_part, load, restore
    from openfdk.trial.checkpoint import CheckpointError
    from openfdk.trial.checkpoint_format import decode, encode

    restore(kind, bases)
    last = sorted(bases.paths[kind].parent.glob("part-*.npz"))[-1]
    payload = decode(last.read_bytes())
    payload["carry"] = edit(payload["carry"])
    _write_part(last, encode(payload), rehash=True)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            load(kind, bases.paths[kind])
        return None
    except CheckpointError as exc:
        return str(exc)
    finally:
        restore(kind, bases)


def _pending_with_data(carry):
    """The first pending frame of a kinematics-and-dynamics carry that holds its data."""
    pending = carry[0][4]
    return next(f for f in pending.values() if f.get("data") is not None)


def _kkt_2_by_0(carry):
    _pending_with_data(carry)["data"].kkt = np.zeros((2, 0))
    return carry


def _residuals_of_one_marker(carry):
    _pending_with_data(carry)["delta"] = np.zeros(1)
    return carry


def _columns_shifted(carry):
    carry[0][0].column = carry[0][0].column + 1
    return carry


def _split_columns_shifted(carry):
    carry[3].cols = carry[3].cols + 6
    return carry


def _alpha_too_short(carry):
    carry[1][-1] = (carry[1][-1][0], carry[1][-1][1][:-1])
    return carry


@pytest.mark.parametrize("kind, edit, expected", [
    ("checkpoint", _kkt_2_by_0, "data: KKT matrix: expected an array of shape ("),
    ("checkpoint", _residuals_of_one_marker, "marker residuals: expected an array of shape (8, 3), got (1,)"),
    ("checkpoint", _columns_shifted, "the solver state has another structure"),  # the driver's template check
    ("checkpoint_fdk", _split_columns_shifted, "the contacts' split names other coordinates than the model's"),
    ("checkpoint_fdk", _alpha_too_short, "FDK history: α of frame"),
])
def test_a_checkpoint_carry_of_other_shapes_is_refused_not_a_crash(bases, kind, edit, expected):
    """Found by the fuzz (seed 70, input 1033 of the checkpoint kind): a pending frame's
    KKT matrix of shape (2, 0) went into the compiled velocity solve, which does not check
    bounds, and the process died of a segmentation fault. Every array of a restored carry
    that the kernels index is now checked against the model (trial/restored.py)."""
    error = _tampered_resume(bases, kind, edit)
    assert error is not None and expected in error, error
    assert "resuming from the checkpoint failed" not in error  # refused before any frame
