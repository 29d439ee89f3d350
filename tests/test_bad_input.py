"""Issue 16's inputs, one test each: the exact exit code and a message naming the item
(file and entry). Exit codes: 0 success, 2 bad input, 3 too many failed frames, 130
interrupted."""

import argparse
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import trimesh
import yaml

from cli_helpers import error_line, run_cli
from openfdk.cli.commands import build_parser, main
from openfdk.contact.shapes import flat_patch
from openfdk.io.c3d import write_c3d
from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict
from test_passive_elements import HELD, MODEL


def _write(tmp_path, data, name="model.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False) if not isinstance(data, str) else data)
    return path


@pytest.fixture
def files(tmp_path):
    model = _write(tmp_path, two_body_model_dict())
    t, labels, x, truth = synthetic_markers(40, rate=100.0, noise=0.0)
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0, units="mm")
    return model, tmp_path / "trial.c3d", (labels, x)


_run, _error_line = run_cli, error_line


# -- crashes that were tracebacks ----------------------------------------------------

def test_fdk_dof_component_out_of_range(tmp_path, capsys):
    data = two_body_model_dict()
    data["measures"] = {"knee_trans": {"type": "vector", "from": "skull.plane", "to": "jaw.condyle"}}
    data["fdk_dofs"] = {"ap": {"measure": "knee_trans", "component": 5}}
    code, _, err = _run(capsys, "check", _write(tmp_path, data))
    assert code == 2
    assert "model.yaml: fdk_dofs.ap.component: must be an integer in [0, 2], got 5" in _error_line(err)


def test_huge_mass_is_refused_by_check(tmp_path, capsys):
    data = two_body_model_dict()
    data["bodies"]["jaw"]["mass"] = 1.0e300
    code, _, err = _run(capsys, "check", _write(tmp_path, data))
    assert code == 2
    assert "model.yaml: bodies.jaw.mass: 1e+300 kg is not a plausible body mass" in _error_line(err)


# -- accepted silently ---------------------------------------------------------------

DUPLICATE_LIGAMENT = """\
openfdk: 1
bodies:
  femur: {mass: 1, inertia: [0.1, 0.1, 0.1], points: {a: [0, 0, 0.1], b: [0, 0.01, 0.1]}}
  tibia: {mass: 1, inertia: [0.1, 0.1, 0.1], points: {a: [0, 0, -0.1], b: [0, 0.01, -0.1]}}
ligaments:
  ACL: {path: [femur.a, tibia.a], stiffness: 1000}
  ACL: {path: [femur.b, tibia.b], stiffness: 1000}
"""


def test_duplicate_ligament_key_names_both_lines(tmp_path, capsys):
    code, _, err = _run(capsys, "check", _write(tmp_path, DUPLICATE_LIGAMENT))
    assert code == 2
    assert "model.yaml: ligaments.ACL: duplicate key, given at lines 6 and 7" in _error_line(err)


def test_duplicate_body_names_both_lines(tmp_path, capsys):
    text = DUPLICATE_LIGAMENT.replace("  tibia:", "  femur:").split("ligaments:")[0]
    code, _, err = _run(capsys, "check", _write(tmp_path, text))
    assert code == 2
    assert "model.yaml: bodies.femur: duplicate key, given at lines 3 and 4" in _error_line(err)


def test_duplicate_keys_in_subject_and_study_files(tmp_path):
    from openfdk.mandible.subject import SubjectError, load_subject
    from openfdk.study.spec import StudyError, load_study

    (tmp_path / "subj").mkdir()
    (tmp_path / "subj" / "subject.yaml").write_text("format: openfdk-subject\nversion: 1\nmuscles:\n  a: 1\n  a: 2\n")
    with pytest.raises(SubjectError, match=r"subject\.yaml: muscles\.a: duplicate key, given at lines 4 and 5"):
        load_subject(tmp_path / "subj")
    (tmp_path / "s.yaml").write_text("openfdk_study: 1\nrun:\n  chunks: 2\n  chunks: 3\n")
    with pytest.raises(StudyError, match=r"s\.yaml: run\.chunks: duplicate key, given at lines 3 and 4"):
        load_study(tmp_path / "s.yaml")


def test_all_nan_markers_exit_3_with_reason_and_no_numpy_noise(files, tmp_path, capsys):
    model, _, (labels, x) = files
    write_c3d(tmp_path / "nan.c3d", labels, np.full_like(x, np.nan), 100.0, units="mm")
    code, _, err = _run(capsys, "run", model, tmp_path / "nan.c3d", "--out", tmp_path / "o", "--no-progress")
    assert code == 3
    summary = [ln for ln in err.splitlines() if "most common reason" in ln]
    assert len(summary) == 1 and summary[0].startswith("openfdk: 40 of 40 frames failed")
    assert "(40 frames): kinematics_failed" in summary[0]
    assert "never visible" in err and "'S1'" in err              # the marker warning names them
    assert "RuntimeWarning" not in err and "All-NaN" not in err and "Traceback" not in err
    # the same run tolerating every failed frame exits 0
    code, _, _ = _run(capsys, "run", model, tmp_path / "nan.c3d", "--out", tmp_path / "o2", "--no-progress",
                      "--max-failed", "1")
    assert code == 0


def test_markers_in_mm_declared_as_m_exit_3_with_unit_hint(files, tmp_path, capsys):
    model, _, (labels, x) = files
    # a file in mm whose POINT:UNITS says m (write_c3d itself refuses to write such a file)
    write_c3d(tmp_path / "mm_as_m.c3d", labels, x, 100.0, units="mm")
    data = bytearray((tmp_path / "mm_as_m.c3d").read_bytes())
    i = data.index(b"mm", data.index(b"UNITS"))
    data[i:i + 2] = b"m "
    (tmp_path / "mm_as_m.c3d").write_bytes(bytes(data))
    code, _, err = _run(capsys, "kinematics", model, tmp_path / "mm_as_m.c3d", "--out", tmp_path / "o", "--no-progress")
    warning = [ln for ln in err.splitlines() if ln.startswith("openfdk: warning:") and "mm_as_m.c3d" in ln]
    assert len(warning) == 1 and "likely the wrong units (a factor 1000" in warning[0]
    # 1000x the spread: the markers cannot be fitted by a rigid model (the least-squares
    # fit exists, with residuals of metres, and is refused as such)
    assert code == 3 and "most common reason" in err and "the markers do not fit the model" in err


def test_marker_never_visible_is_warned(files, tmp_path, capsys):
    model, _, (labels, x) = files
    x = x.copy()
    x[:, labels.index("S2")] = np.nan
    write_c3d(tmp_path / "s2.c3d", labels, x, 100.0, units="mm")
    code, _, err = _run(capsys, "kinematics", model, tmp_path / "s2.c3d", "--out", tmp_path / "o", "--no-progress",
                        "--start", "0.1", "--end", "0.3")
    assert code == 0  # three skull markers still determine the skull
    assert "s2.c3d: marker(s) 'S2' never visible in the analysis window [0.1, 0.3] s" in err


def test_inertia_triangle_inequality_in_model_file(tmp_path, capsys):
    data = two_body_model_dict()
    data["bodies"]["jaw"]["inertia"] = [1e-4, 1e-4, 3e-4]    # 1 + 1 < 3
    code, _, err = _run(capsys, "check", _write(tmp_path, data))
    assert code == 2
    assert "model.yaml: bodies.jaw.inertia: principal moments" in _error_line(err)
    assert "triangle inequality" in err
    # declared as given (an OpenSim import writes it for OpenSim's own such bodies): a warning
    data["bodies"]["jaw"]["inertia_as_given"] = True
    code, _, err = _run(capsys, "check", _write(tmp_path, data))
    assert "model.yaml: bodies.jaw.inertia: principal moments" in err and "used as given" in err
    assert "error" not in err


def test_opensim_inertia_without_a_rigid_body_is_used_as_given(tmp_path, capsys):
    """OpenSim's release builds take an inertia that breaks the triangle inequality (its
    Gait2392 toes in the joint-reaction tutorial); the import takes it as given, with a
    warning naming the body, and the model's inertia is the file's."""
    from openfdk.fixtures.full_body_osim import write_full_body_osim
    from openfdk.io.modelfile import load_model

    path = write_full_body_osim(tmp_path / "body.osim")
    text = path.read_text()
    body = text.index('<Body name="toes_r">')
    start = text.index("<inertia>", body)
    end = text.index("</inertia>", start)
    path.write_text(text[:start] + "<inertia>1e-4 2e-4 9e-4 0 0 0" + text[end:])
    with pytest.warns(UserWarning, match=r"body\.osim: bodies\.toes_r\.inertia: principal moments .* used as given"):
        model = load_model(path)
    toes = model.body("toes_r")
    assert toes.inertia_as_given and not model.body("toes_l").inertia_as_given
    np.testing.assert_allclose(np.sort(np.linalg.eigvalsh(toes.inertia_B)), [1e-4, 2e-4, 9e-4], rtol=1e-12)


def test_start_after_end_is_an_error_not_a_swap(files, tmp_path, capsys):
    model, trial, _ = files
    data = two_body_model_dict()
    data["analysis"].update({"start": 1, "end": 0})
    code, _, err = _run(capsys, "check", _write(tmp_path, data, "swapped.yaml"))
    assert code == 2 and "swapped.yaml: analysis: start (1 s) is after end (0 s)" in _error_line(err)
    code, _, err = _run(capsys, "run", model, trial, "--out", tmp_path / "o", "--start", "1", "--end", "0")
    assert code == 2 and "--start (1 s) is after --end (0 s)" in _error_line(err)


def test_length_magnitude_warns_with_likely_unit(tmp_path, capsys):
    data = two_body_model_dict()
    data["units"]["length"] = "m"          # the numbers are mm
    code, _, err = _run(capsys, "check", _write(tmp_path, data))
    assert code == 0
    assert "model.yaml: units.length: the model's points span" in err and "the numbers look like mm" in err


def _patch(path, size, edge, flip=False, extra=None):
    p = flat_patch(size, size, edge)
    V, F = p.vertices_B, p.faces[:, ::-1] if flip else p.faces
    if extra is not None:
        V, F = extra(V, F)
    trimesh.Trimesh(V, F, process=False).export(path)


# the block of test_passive_elements held 0.1 mm above the floor (no contact with correct normals)
BLOCK = (textwrap.dedent(MODEL) + textwrap.dedent(HELD)).replace("[0, 0, 4.9]", "[0, 0, 5.1]")


def test_inverted_contact_normals_are_refused_by_check_and_run(tmp_path, capsys):
    """The floor's normals point down, away from the block 0.1 mm above it: the contact
    would pull the block into the floor. ``check`` and ``run`` refuse the model in one
    line naming the contact, the mesh and the fix (contact/mesh_check.py); with the
    normals the right way round the run has no normals or pulling warning."""
    _patch(tmp_path / "bottom.stl", 10.0, 0.5)
    _patch(tmp_path / "floor.stl", 40.0, 1.0, flip=True)
    model = _write(tmp_path, BLOCK, "block.yaml")
    for command in (["check", model], ["run", model, "--out", tmp_path / "o", "--no-progress"]):
        code, _, err = _run(capsys, *command)
        errors = [ln for ln in err.splitlines() if ln.startswith("openfdk: error:")]
        assert code == 2 and len(errors) == 1, err
        assert "contacts.floor" in errors[0] and "floor.stl" in errors[0] and "flip_normals" in errors[0]
    assert not (tmp_path / "o" / "forces.csv").exists()
    _patch(tmp_path / "floor.stl", 40.0, 1.0)
    code, _, err = _run(capsys, "run", model, "--out", tmp_path / "o2", "--no-progress")
    assert code == 0 and "pulls" not in err and "point away" not in err and "normals" not in err


def test_mesh_duplicate_faces_and_non_manifold_edge_counted(tmp_path, capsys):
    from openfdk.contact.mesh import undirected_edge_keys

    def fin(V, F):
        E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        keys = undirected_edge_keys(E)
        u, c = np.unique(keys, return_counts=True)
        e = E[np.flatnonzero(np.isin(keys, u[c == 2]))[0]]   # an interior edge
        V = np.vstack([V, V[e[0]] + [0.0, 0.0, 5.0]])
        return V, np.vstack([F, F[:3], [[e[0], e[1], len(V) - 1]]])    # 3 duplicates and a fin

    _patch(tmp_path / "bottom.stl", 10.0, 0.5)
    _patch(tmp_path / "floor.stl", 40.0, 1.0, extra=fin)
    code, _, err = _run(capsys, "check", _write(tmp_path, BLOCK, "block.yaml"))
    assert code == 0
    assert "mesh 'floor.stl': 3 duplicate triangle(s)" in err
    assert "mesh 'floor.stl': 1 non-manifold edge(s)" in err


def test_results_are_not_overwritten_without_force(files, tmp_path, capsys):
    model, trial, _ = files
    out = tmp_path / "o"
    assert _run(capsys, "kinematics", model, trial, "--out", out, "--no-progress")[0] == 0
    before = (out / "kinematics.csv").read_text()
    code, _, err = _run(capsys, "kinematics", model, trial, "--out", out, "--no-progress", "--end", "0.05")
    assert code == 2 and f"output folder '{out}' already holds results" in _error_line(err) and "--force" in err
    assert (out / "kinematics.csv").read_text() == before
    assert _run(capsys, "kinematics", model, trial, "--out", out, "--no-progress", "--end", "0.05", "--force")[0] == 0
    assert len((out / "kinematics.csv").read_text().splitlines()) == 1 + 6   # header + frames 0..0.05 s


def test_unwritable_out_is_found_before_computation(files, tmp_path, capsys, monkeypatch):
    import openfdk.analysis.jobs

    def must_not_run(*a, **k):
        raise AssertionError("the computation started")

    monkeypatch.setattr(openfdk.analysis.jobs, "run_job", must_not_run)
    model, trial, _ = files
    (tmp_path / "afile").write_text("x")
    code, _, err = _run(capsys, "run", model, trial, "--out", tmp_path / "afile" / "out")
    assert code == 2 and "is not writable" in _error_line(err)
    from openfdk.io.outdir import OutputDirError, check_output_dir

    with pytest.raises(OutputDirError, match="is a file"):
        check_output_dir(tmp_path / "afile", force=True)
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "summary.json").write_text("{}")
    with pytest.raises(OutputDirError, match="no checkpoint to resume"):  # finished results: nothing to resume
        check_output_dir(tmp_path / "r", resume=True)
    (tmp_path / "r" / ".checkpoint").mkdir()
    assert check_output_dir(tmp_path / "r", resume=True) == tmp_path / "r"


HILL = """
muscles:
  m1:
    path: [skull.o, jaw.i]
    max_isometric_force: 500
    optimal_fibre_length: {L0}
    tendon_slack_length: 20
"""


def test_muscle_passive_force_above_ten_percent_warned(tmp_path, capsys):
    """Path length 60 mm; tendon slack 20 mm. With an optimal fibre length of 10 mm the
    fibres are ≈ 4 L0 long: passive force far above 10 % F0 → warned. With 40 mm the
    fibres are at L0 (tendon slack, no passive force) → no warning."""
    data = two_body_model_dict()
    data["bodies"]["skull"]["points"] = {"o": [60.0, 0.0, 0.0]}
    data["bodies"]["jaw"]["points"] = {"i": [0.0, 0.0, -30.0]}     # jaw COM at (60, 0, -30) mm
    for L0, warned in ((10, True), (40, False)):
        text = yaml.safe_dump(data, sort_keys=False) + HILL.format(L0=L0)
        code, _, err = _run(capsys, "check", _write(tmp_path, text, f"hill{L0}.yaml"))
        assert code == 0
        assert (f"hill{L0}.yaml: muscles.m1: passive force" in err) is warned, err
    from openfdk.forces.hill import Hill3ElementMuscle

    m = Hill3ElementMuscle(max_isometric_force=500, optimal_fibre_length=0.01, tendon_slack_length=0.02)
    assert m.evaluate(0.06, 0.0)[1] > 50.0


# -- noise -----------------------------------------------------------------------------

def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    import openfdk

    assert capsys.readouterr().out.strip() == f"openfdk {openfdk.__version__}"


def test_every_argument_has_help():
    def walk(parser, where):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from walk(sub, f"{where} {name}")
            elif not isinstance(action, argparse._HelpAction):
                yield where, action

    missing = [(w, a.dest) for w, a in walk(build_parser(), "openfdk") if not (a.help and a.help.strip())]
    assert missing == []
    assert sum(1 for _ in walk(build_parser(), "openfdk")) > 40


def test_quiet_prints_nothing_on_success(files, tmp_path, capsys):
    model, trial, _ = files
    code, out, err = _run(capsys, "--quiet", "kinematics", model, trial, "--out", tmp_path / "o")
    assert code == 0 and out == "" and err == ""
    code, out, err = _run(capsys, "kinematics", model, trial, "--out", tmp_path / "o2", "-q")
    assert code == 0 and out == "" and err == ""


def test_interrupted_exits_130(files, tmp_path, capsys, monkeypatch):
    import openfdk.analysis.jobs

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(openfdk.analysis.jobs, "kinematics_job", interrupted)
    model, trial, _ = files
    code, _, err = _run(capsys, "kinematics", model, trial, "--out", tmp_path / "o")
    assert code == 130 and err.strip() == "openfdk: interrupted"


def test_non_terminal_stderr_has_lines_per_ten_percent_and_no_carriage_returns(files, tmp_path):
    model, trial, _ = files
    log = tmp_path / "log.txt"
    with open(log, "w") as fh:
        proc = subprocess.run([sys.executable, "-m", "openfdk.cli", "kinematics", str(model), str(trial), "--out",
                               str(tmp_path / "o")], stderr=fh, stdout=subprocess.DEVNULL, timeout=600,
                              env={**os.environ, "PYTHONWARNINGS": ""})
    assert proc.returncode == 0
    text = log.read_bytes()
    assert b"\r" not in text
    lines = text.decode().splitlines()
    kin = [ln for ln in lines if ln.startswith("kinematics: ")]
    assert [ln.split()[1] for ln in kin] == [f"{p}%" for p in range(10, 101, 10)]
    assert kin[-1].startswith("kinematics: 100% (40/40 frame")  # the trial driver: one pass, one count per frame


def test_progress_lines_module():
    import io

    from openfdk.trial.progress import progress, set_quiet

    buf = io.StringIO()
    with progress(7, "x", "case", stream=buf) as bar:
        for _ in range(7):
            bar.update(1)
    # one line each time a tenth is crossed: after 1..7 of 7 cases the tenths are 1, 2, 4, 5, 7, 8, 10
    assert [ln.split(":")[1].split("%")[0].strip() for ln in buf.getvalue().splitlines()] == \
        ["10", "20", "40", "50", "70", "80", "100"]
    assert "\r" not in buf.getvalue()
    set_quiet(True)
    try:
        buf2 = io.StringIO()
        bar = progress(5, "x", stream=buf2)
        bar.update(5)
        assert buf2.getvalue() == ""
    finally:
        set_quiet(False)


def _fake_study(calls, failed):
    """A stand-in for the mandible study (run_study / run_demo): records its call and
    returns a result whose ``failed`` tasks are given."""
    def run(*args, **kwargs):
        calls.append(args)
        return {"failed": failed, "table1": [], "completed": ["open_close"]}
    return run


def test_subject_study_and_demo_with_a_failed_task_exit_3(tmp_path, capsys, monkeypatch):
    """A task failed while the others completed: exit 3 (completed with failures), not 2
    (bad input); the failed task is named on stderr. No failure: exit 0."""
    import openfdk.mandible.demo
    import openfdk.mandible.study

    calls = []
    failed = {"chewing": "no periodic movement in the record"}
    monkeypatch.setattr(openfdk.mandible.study, "run_study", _fake_study(calls, failed))
    monkeypatch.setattr(openfdk.mandible.demo, "run_demo", _fake_study(calls, failed))
    code, _, err = _run(capsys, "subject", "study", tmp_path / "subject", "--out", tmp_path / "s", "--no-progress")
    assert code == 3 and len(calls) == 1
    assert "task 'chewing' failed: no periodic movement in the record" in err
    assert "1 task(s) failed" in err
    code, _, err = _run(capsys, "demo", "--out", tmp_path / "d", "--no-progress")
    assert code == 3 and len(calls) == 2 and "task 'chewing' failed" in err
    failed.clear()
    assert _run(capsys, "demo", "--out", tmp_path / "d2", "--no-progress")[0] == 0


def test_subject_study_and_demo_check_their_output_folder_first(tmp_path, capsys, monkeypatch):
    """`openfdk subject study` and `openfdk demo` refuse a folder holding study results
    (exit 2, the folder named, nothing computed) unless --force, and an unwritable one."""
    import openfdk.mandible.demo
    import openfdk.mandible.study

    calls = []
    monkeypatch.setattr(openfdk.mandible.study, "run_study", _fake_study(calls, {}))
    monkeypatch.setattr(openfdk.mandible.demo, "run_demo", _fake_study(calls, {}))
    study, demo = tmp_path / "s", tmp_path / "d"
    (demo / "study").mkdir(parents=True)
    for folder in (study, demo / "study"):
        folder.mkdir(exist_ok=True)
        (folder / "summary.json").write_text("{}")
    code, _, err = _run(capsys, "subject", "study", tmp_path / "subject", "--out", study, "--no-progress")
    assert code == 2 and f"output folder '{study}' already holds results (summary.json)" in _error_line(err)
    code, _, err = _run(capsys, "demo", "--out", demo, "--no-progress")
    assert code == 2 and f"output folder '{demo / 'study'}' already holds results" in _error_line(err)
    assert "--force" in err and calls == []
    (tmp_path / "afile").write_text("x")
    code, _, err = _run(capsys, "subject", "study", tmp_path / "subject", "--out", tmp_path / "afile" / "o")
    assert code == 2 and "is not writable" in _error_line(err) and calls == []
    code, _, err = _run(capsys, "demo", "--out", tmp_path / "afile")
    assert code == 2 and "is a file, not a folder" in _error_line(err) and calls == []
    assert _run(capsys, "subject", "study", tmp_path / "subject", "--out", study, "--force", "--no-progress")[0] == 0
    assert _run(capsys, "demo", "--out", demo, "--force", "--no-progress")[0] == 0
    assert len(calls) == 2


def test_chunked_runs_warn_about_trial_markers_and_pulling_contacts_once(files, tmp_path, capsys, monkeypatch):
    """`openfdk run --chunks K`: the trial-marker warning and the pulling-contact warning
    of the whole trial appear once, as in the serial run (the segments skip them); the
    inverted floor is refused before any segment, as the serial run refuses it."""
    from openfdk.study.case import segment_task
    from openfdk.study.cli import job_case

    model, _, (labels, x) = files
    x = x.copy()
    x[:, labels.index("S2")] = np.nan
    write_c3d(tmp_path / "s2.c3d", labels, x, 100.0, units="mm")
    code, _, err = _run(capsys, "run", model, tmp_path / "s2.c3d", "--out", tmp_path / "o", "--no-progress",
                        "--no-plots", "--start", "0.1", "--end", "0.3", "--chunks", "2", "--workers", "0",
                        "--max-failed", "1")  # no muscles: every inverse-dynamics frame fails
    assert code == 0
    never = [ln for ln in err.splitlines() if "never visible" in ln]
    assert len(never) == 1 and never[0].startswith("openfdk: warning: ")
    assert never[0].endswith("s2.c3d: marker(s) 'S2' never visible in the analysis window [0.1, 0.3] s")
    # a segment told to skip the checks warns about nothing
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        segment_task(job_case(model, tmp_path / "s2.c3d", 2, 1, None, 0.1, 0.3), 1, checks=False)
    assert not [w for w in caught if "never visible" in str(w.message)]

    _patch(tmp_path / "bottom.stl", 10.0, 0.5)
    _patch(tmp_path / "floor.stl", 40.0, 1.0, flip=True)
    block = _write(tmp_path, BLOCK, "block.yaml")
    chunked = ("run", block, "--out", tmp_path / "b", "--no-progress", "--no-plots", "--chunks", "2", "--workers", "0")
    code, _, err = _run(capsys, *chunked)
    errors = [ln for ln in err.splitlines() if ln.startswith("openfdk: error:")]
    assert code == 2 and len(errors) == 1 and "contacts.floor" in errors[0] and "flip_normals" in errors[0], err
    # with the contact-mesh check bypassed, the run goes on and its contact pulls
    import openfdk.analysis.jobs as jobs

    monkeypatch.setattr(jobs, "contact_mesh_checks", lambda model, label: [])
    code, _, err = _run(capsys, *chunked)
    assert code == 0
    pulls = [ln for ln in err.splitlines() if "pulls" in ln]
    assert len(pulls) == 1
    assert "contacts.floor: the contact force pulls the surfaces together in 3 of 3 frames" in pulls[0]
