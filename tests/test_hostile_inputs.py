"""Issue 30's hostile inputs, one test each: the exact exit code and the one-line message
naming the file and the entry; no traceback, no hang, nothing written outside --out, no
code run from a data file. Exit codes: 0 success, 2 bad input, 3 too many failed frames."""

import hashlib
import json
import os
import pickle
import shutil
import time

import pytest
import yaml

from cli_helpers import error_line, run_cli
from openfdk.cli import main
from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict
from openfdk.io.c3d import write_c3d

ARM = """\
units: {length: mm, angle: deg}
bodies:
  arm: {mass: 1.0, inertia: [0.01, 0.01, 0.01], position: [0, -200, 0], frames: {pivot: [0, 200, 0], insertion: [10, 150, 0]}}
  ground: {frames: {origin_point: [5, 5, 0]}}
joints:
  pin: {type: revolute, parent: ground.origin, child: arm.pivot}
drivers:
  swing: {measure: pin.angle, function: {type: constant, value: 0}}
analysis: {start: 0, end: 0.02}
"""


_run, _error_line = run_cli, error_line


def _write(path, text):
    path.write_text(text)
    return path


def _snapshot(folder):
    """{relative path: (mtime_ns, bytes)} of every file under ``folder``."""
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.read_bytes())
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def watched(tmp_path):
    """A sibling folder that no command may change; compare with _snapshot afterwards."""
    d = tmp_path / "watched"
    d.mkdir()
    (d / "target.txt").write_text("precious\n")
    (d / "sub").mkdir()
    (d / "sub" / "other.txt").write_text("also precious\n")
    return d


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """(model path, trial path, result folder) of one finished two-body run."""
    d = tmp_path_factory.mktemp("finished")
    model = _write(d / "model.yaml", yaml.safe_dump(two_body_model_dict(), sort_keys=False))
    _t, labels, x, _truth = synthetic_markers(20, rate=100.0, noise=0.0)
    write_c3d(d / "trial.c3d", labels, x, 100.0, units="mm")
    out = d / "res"
    assert main(["run", str(model), str(d / "trial.c3d"), "--out", str(out), "--no-progress", "--no-plots",
                 "--max-failed", "1"]) == 0
    return model, d / "trial.c3d", out


@pytest.fixture
def result(finished, tmp_path):
    """A private copy of the finished result folder."""
    res = tmp_path / "res"
    shutil.copytree(finished[2], res)
    return res


# -- hangs ----------------------------------------------------------------------------

def test_run_on_a_yaml_alias_bomb_is_refused_at_once(tmp_path, capsys):
    lines = ["openfdk: 1", "a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, 12)]
    bomb = _write(tmp_path / "bomb.yaml", "\n".join(lines) + "\n")   # 10^12 leaves when expanded
    t0 = time.perf_counter()
    code, _, err = _run(capsys, "run", bomb, "--out", tmp_path / "out")
    assert time.perf_counter() - t0 < 20
    assert code == 2
    assert ("bomb.yaml: 1 234 567 901 247 YAML nodes with the aliases expanded (most under a11), above the limit "
            "of 2 000 000 (openfdk.io.limits.YAML_NODES)") in _error_line(err)


@pytest.mark.parametrize("value", ["0", "-5", "2"])
def test_view_max_vertices_below_the_minimum_is_refused(result, capsys, value):
    with pytest.raises(SystemExit) as exc:
        main(["view", str(result), "--max-vertices", value])
    assert exc.value.code == 2
    assert f"--max-vertices: expected a whole number >= 3, got '{value}'" in capsys.readouterr().err


def test_view_data_refuses_a_max_vertices_below_the_minimum(result):
    from openfdk.viewer import view_data

    with pytest.raises(ValueError, match="max_vertices must be a whole number >= 3, got 0"):
        view_data(result, max_vertices=0)


# -- tracebacks -----------------------------------------------------------------------

def test_a_path_point_inside_a_wrapping_cylinder_gives_failed_frames_not_a_traceback(tmp_path, capsys):
    model = _write(tmp_path / "wrap.yaml", ARM + """\
wrapping:
  drum: {type: cylinder, frame: ground.origin, radius: 30}
muscles:
  m: {path: [ground.origin_point, drum, arm.insertion], strength: 100}
""")
    code, _, err = _run(capsys, "run", model, "--out", tmp_path / "out", "--no-progress", "--no-plots")
    assert code == 3
    assert "Traceback" not in err
    assert "path 'm': a path point lies inside the wrapping surface" in err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["inverse_dynamics"]["converged_frames"] == 0


def test_jcs_joint_given_as_a_list_is_refused(tmp_path, capsys):
    model = _write(tmp_path / "model.yaml", ARM + """\
measures:
  ang: {type: jcs, frame: ground.origin, of: arm.pivot, joint: [knee]}
""")
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert "model.yaml: measures.ang.joint: unknown joint convention ['knee']" in _error_line(err)


@pytest.mark.parametrize("content", ["[]", '{"host": 5, "pid": "x"}', "not json"])
def test_a_study_lock_that_is_not_an_object_is_reported(tmp_path, content):
    from openfdk.study import StudyError
    from openfdk.study.runner import _acquire_lock

    (tmp_path / ".study.lock").write_text(content)
    with pytest.raises(StudyError, match=r"is in use by a study running on .*delete '.*\.study\.lock'"):
        _acquire_lock(tmp_path)


@pytest.mark.parametrize("command", ["plot", "export-opensim"])
@pytest.mark.parametrize("tamper, expected", [
    (lambda s: [], "summary.json: must be a JSON object, got list"),
    (lambda s: {**s, "input": []}, "summary.json: input: must be a JSON object, got list"),
    (lambda s: {**s, "input": {**s["input"], "model_file": 5}},
     "summary.json: input.model_file: must be a file name (text), got 5"),
])
def test_tampered_summary_json_is_refused(result, tmp_path, capsys, command, tamper, expected):
    path = result / "summary.json"
    path.write_text(json.dumps(tamper(json.loads(path.read_text()))))
    code, _, err = _run(capsys, command, result, "--out", tmp_path / "out")
    assert code == 2
    assert expected in _error_line(err)


def test_a_null_input_in_summary_json_is_no_input(result, tmp_path, capsys):
    """Found by the fuzz (seed 70): ``"input": null`` raised an AttributeError. It is read
    as no input: ``plot`` draws without the model, ``export-opensim`` needs it and says so."""
    path = result / "summary.json"
    path.write_text(json.dumps({**json.loads(path.read_text()), "input": None}))
    code, _, err = _run(capsys, "plot", result, "--out", tmp_path / "plots")
    assert code == 0 and "Traceback" not in err, err
    assert sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    code, _, err = _run(capsys, "export-opensim", result, "--out", tmp_path / "out")
    assert code == 2
    assert "the model file of this run cannot be found" in _error_line(err)


@pytest.mark.parametrize("command", ["plot", "export-opensim"])
def test_a_foreign_kinematics_csv_is_refused(result, tmp_path, capsys, command):
    (result / "kinematics.csv").write_text("time,x,y\n0,1,2\n0.01,1,2\n")
    code, _, err = _run(capsys, command, result, "--out", tmp_path / "out")
    assert code == 2
    assert "kinematics.csv: column 'converged' missing; not a table written by openfdk" in _error_line(err)


def test_a_half_written_checkpoint_part_is_refused_on_resume(finished, tmp_path, capsys):
    model, trial, _ = finished
    out = tmp_path / "out"
    args = [model, trial, "--out", out, "--no-progress", "--no-plots", "--max-failed", "1"]
    part = _checkpoint_part(args)
    part.write_bytes(part.read_bytes()[:40])   # cut short
    code, _, err = _run(capsys, "run", *args, "--resume")
    assert code == 2
    assert "part-000000.npz: the checkpoint part does not match its sidecar (cut short or changed)" in _error_line(err)


def _checkpoint_part(argv):
    """Write one genuine checkpoint part for ``openfdk run argv`` and return its path."""
    from openfdk.cli.commands import _run_checkpoints, build_parser

    args = build_parser().parse_args(["run", *map(str, argv)])
    ck = _run_checkpoints(args)
    ck.save([], None, 0)
    return ck.folder / "part-000000.npz"


class _Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _crafted(kind, marker):
    """Bytes of a crafted checkpoint part that would create ``marker`` if anything in it
    were run (a pickle, an .npz holding a pickled object array or a structure naming a
    callable), or junk."""
    import io

    import numpy as np

    evil = _Evil(marker)
    if kind == "pickle":
        return pickle.dumps({"fingerprint": "x", "next_frame": 1, "records": [], "carry": evil})
    if kind == "junk":
        return b"\x00\xffnot a checkpoint" * 10
    structure = {"format": "openfdk-checkpoint-1",
                 "root": {"t": "dict", "v": [["carry", {"t": "nd", "a": "a0", "ro": False}]]}}
    arrays = {"a0": np.array([evil, 1], dtype=object)}
    if kind == "npy_pickle":  # a single .npy whose data is a pickle
        buf = io.BytesIO()
        np.save(buf, np.array([evil, 1], dtype=object), allow_pickle=True)
        return buf.getvalue()
    if kind == "unknown_tag":
        structure["root"] = {"t": "call", "f": "os.system", "v": [f"touch {marker}"]}
    if kind == "unknown_class":
        structure["root"] = {"t": "obj", "c": "Popen", "f": {"args": f"touch {marker}"}}
    buf = io.BytesIO()
    np.savez(buf, structure=np.frombuffer(json.dumps(structure).encode(), dtype=np.uint8), **arrays)
    return buf.getvalue()


@pytest.mark.parametrize("kind", ["pickle", "junk", "npy_pickle", "npz_object_array", "unknown_tag",
                                  "unknown_class"])
@pytest.mark.parametrize("genuine_fingerprint", [True, False])
def test_a_crafted_checkpoint_part_runs_no_code_on_resume(finished, tmp_path, capsys, genuine_fingerprint, kind):
    """A crafted part (any bytes: a pickle, pickled object arrays, unknown type tags) with
    a matching sidecar: `--resume` refuses it in one line naming the part and nothing in
    it runs (the file it would create never exists), whether or not the attacker wrote
    the right fingerprint."""
    model, trial, _ = finished
    out = tmp_path / "out"
    args = [model, trial, "--out", out, "--no-progress", "--no-plots", "--max-failed", "1"]
    part = _checkpoint_part(args)
    side = json.loads(part.with_suffix(".json").read_text())
    marker = tmp_path / "pwned"
    fingerprint = side["fingerprint"] if genuine_fingerprint else "0" * 64
    data = _crafted(kind, marker)
    part.write_bytes(data)
    part.with_suffix(".json").write_text(json.dumps({"fingerprint": fingerprint,
                                                     "sha256": hashlib.sha256(data).hexdigest()}))
    code, _, err = _run(capsys, "run", *args, "--resume")
    assert code == 2
    line = _error_line(err)
    if genuine_fingerprint:
        assert "part-000000.npz: unreadable checkpoint part (" in line
    else:
        assert "part-000000.npz: the checkpoint belongs to another run" in line
    assert not marker.exists()


def test_a_checkpoint_part_without_its_sidecar_is_refused(finished, tmp_path, capsys):
    model, trial, _ = finished
    args = [model, trial, "--out", tmp_path / "out", "--no-progress", "--no-plots", "--max-failed", "1"]
    part = _checkpoint_part(args)
    part.with_suffix(".json").unlink()
    code, _, err = _run(capsys, "run", *args, "--resume")
    assert code == 2
    assert "part-000000.npz: the checkpoint part has no sidecar part-000000.json" in _error_line(err)


# -- silently accepted ----------------------------------------------------------------

@pytest.mark.parametrize("section, extra, entry", [
    ("drivers", "", "drivers.swing.reaction"),
    ("constraints", "constraints:\n  c: {measure: pin.angle, components: [0], reaction: \"false\"}\n",
     "constraints.c.reaction"),
])
def test_reaction_given_as_text_is_refused(tmp_path, capsys, section, extra, entry):
    text = ARM + extra
    if section == "drivers":
        text = text.replace("value: 0}}", "value: 0}, reaction: \"false\"}")
    model = _write(tmp_path / "model.yaml", text)
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert f"model.yaml: {entry}: expected true or false, got 'false'" in _error_line(err)


def test_body_fixed_given_as_text_is_refused(tmp_path, capsys):
    model = _write(tmp_path / "model.yaml", ARM.replace("arm: {mass: 1.0,", "arm: {fixed: \"no\", mass: 1.0,"))
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert "model.yaml: bodies.arm.fixed: expected true or false, got 'no'" in _error_line(err)


def test_an_unknown_spring_key_under_an_fdk_dof_is_refused(tmp_path, capsys):
    model = _write(tmp_path / "model.yaml", ARM + "fdk_dofs:\n  a: {measure: pin.angle, spring: {stiffness: 1}}\n")
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert "model.yaml: fdk_dofs.a.spring: unknown key" in _error_line(err)


def test_an_unknown_spring_key_under_a_joint_fdk_row_is_refused(tmp_path, capsys):
    data = two_body_model_dict()
    data["joints"]["tmj"]["fdk"] = {"x": {"spring": 1.0}}
    model = _write(tmp_path / "model.yaml", yaml.safe_dump(data))
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert "model.yaml: joints.tmj.fdk.x.spring: unknown key" in _error_line(err)


def test_a_misspelt_ground_reactions_key_gets_a_suggestion(tmp_path, capsys):
    model = _write(tmp_path / "model.yaml", ARM + "ground_reactions: {plate: {}}\n")
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert "model.yaml: ground_reactions.plate: unknown key; did you mean 'plates'?" in _error_line(err)


def test_a_misspelt_subject_unit_key_gets_a_suggestion(tmp_path):
    from openfdk.mandible.subject import SubjectError, load_subject

    (tmp_path / "subject.yaml").write_text("units: {lenght: mm}\n")
    with pytest.raises(SubjectError, match=r"subject\.yaml: units\.lenght: unknown key; did you mean 'length'\?"):
        load_subject(tmp_path)


def test_duplicate_fdk_rows_are_refused(tmp_path, capsys):
    data = two_body_model_dict()
    data["joints"]["tmj"]["fdk"] = ["x", "x"]
    model = _write(tmp_path / "model.yaml", yaml.safe_dump(data))
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert "model.yaml: joints.tmj.fdk: row 'x' is given twice" in _error_line(err)


def test_format_version_true_is_not_version_1(tmp_path, capsys):
    model = _write(tmp_path / "model.yaml", "openfdk: true\n" + ARM)
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert "model.yaml: openfdk: unsupported format version True" in _error_line(err)


def test_study_format_version_true_is_not_version_1(finished, tmp_path, capsys):
    study = _write(tmp_path / "s.yaml", f"openfdk_study: true\nmodels: {{m: {finished[0]}}}\n")
    code, _, err = _run(capsys, "study", study, "--out", tmp_path / "out", "--list")
    assert code == 2
    assert "s.yaml: openfdk_study: unsupported version True; this openfdk reads 1" in _error_line(err)


def test_subject_version_true_is_not_version_1(tmp_path):
    from openfdk.mandible.subject import _TOP_REQUIRED, FORMAT_NAME, SubjectError, load_subject

    data = {key: {} for key in _TOP_REQUIRED}
    data.update(format=FORMAT_NAME, version=True)
    (tmp_path / "subject.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(SubjectError, match=r"subject\.yaml: version: unsupported version True; this openfdk reads 1"):
        load_subject(tmp_path)


@pytest.mark.parametrize("name, shown", [("ar\x01m", "'ar\\x01m'"), ("a/b", "'/'"), ("a<b", "'<'"), ("a..b", "'..'")])
def test_a_bad_character_in_a_body_name_is_refused_at_load(tmp_path, capsys, name, shown):
    data = two_body_model_dict()
    data["bodies"] = {(name if k == "jaw" else k): v for k, v in data["bodies"].items()}
    model = _write(tmp_path / "model.yaml", json.dumps(data))
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    line = _error_line(err)
    assert "model.yaml: bodies." in line and shown in line


def test_a_contact_name_with_a_slash_is_refused_at_load(tmp_path, capsys, watched):
    data = two_body_model_dict()
    data["contacts"] = {str(watched / "evil"): {"vertices": {"body": "jaw"}, "surface": {"body": "skull"},
                                                "pressure_modulus": 1}}
    model = _write(tmp_path / "model.yaml", yaml.safe_dump(data))
    before = _snapshot(watched)
    code, _, err = _run(capsys, "check", model)
    assert code == 2
    assert f"model.yaml: contacts.{watched}/evil: name" in _error_line(err)
    assert _snapshot(watched) == before


@pytest.mark.parametrize("fname", ["../x.obj", "/etc/x.obj", "a/b_vertices.obj", "a\x01_surface.obj"])
def test_an_export_mesh_name_leaving_geometry_is_refused(tmp_path, fname):
    from openfdk.io.osim import _geometry_path

    with pytest.raises(ValueError, match="cannot export mesh file"):
        _geometry_path(tmp_path, fname)
    assert _geometry_path(tmp_path, "jaw_visual_0.obj") == tmp_path / "Geometry" / "jaw_visual_0.obj"


def test_an_export_mesh_file_link_is_refused(tmp_path, watched):
    import numpy as np

    from openfdk.io.osim import _write_obj

    (tmp_path / "g.obj").symlink_to(watched / "target.txt")
    before = _snapshot(watched)
    with pytest.raises(ValueError, match="g.obj' is a symbolic link"):
        _write_obj(tmp_path / "g.obj", np.zeros((3, 3)), [[0, 1, 2]], "x")
    assert _snapshot(watched) == before


def test_a_kinematics_csv_cut_mid_row_is_refused(result, tmp_path, capsys):
    path = result / "kinematics.csv"
    text = path.read_text()
    path.write_text(text[: len(text) - 200])   # the last row cut short
    n_lines = len(path.read_text().splitlines())
    code, _, err = _run(capsys, "export-opensim", result, "--out", tmp_path / "out")
    assert code == 2
    assert f"kinematics.csv: line {n_lines}: " in _error_line(err)
    assert "where the header has" in _error_line(err)


def _set_cell(path, column, row, value):
    """Write ``value`` into ``column`` of data row ``row`` (0-based) of a result table."""
    lines = path.read_text().splitlines()
    k = lines[0].split(",").index(column)
    cells = lines[row + 1].split(",")
    cells[k] = value
    lines[row + 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("command", ["plot", "export-opensim", "view"])
@pytest.mark.parametrize("column, value, expected", [
    ("converged", "7", "line 3: column 'converged': 7 is neither 0 nor 1"),
    ("converged", "0.5", "line 3: column 'converged': 0.5 is neither 0 nor 1"),
    ("time", "nan", "line 3: column 'time': nan is not a finite number of seconds"),
    ("time", "-1", "line 3: column 'time': -1 s does not follow"),
])
def test_a_result_table_with_a_bad_time_or_status_is_refused(result, tmp_path, capsys, command, column, value,
                                                             expected):
    _set_cell(result / "kinematics.csv", column, 1, value)
    extra = ["--out", tmp_path / "out"] if command == "export-opensim" else []
    code, _, err = _run(capsys, command, result, *extra)
    assert code == 2
    assert f"kinematics.csv: {expected}" in _error_line(err)


@pytest.mark.parametrize("command", ["plot", "export-opensim", "view"])
def test_an_empty_out_is_refused(result, tmp_path, capsys, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    code, _, err = _run(capsys, command, result, "--out", "")
    assert code == 2
    assert "the output is empty (--out '')" in _error_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["res"]


def test_run_with_an_empty_out_is_refused(finished, capsys):
    code, _, err = _run(capsys, "run", finished[0], finished[1], "--out", "")
    assert code == 2
    assert "the output folder is empty (--out '')" in _error_line(err)


# -- lost results ---------------------------------------------------------------------

def test_resume_without_a_checkpoint_keeps_finished_results(finished, result, tmp_path, capsys):
    other = _write(tmp_path / "other.yaml", finished[0].read_text().replace("two-body jaw", "other"))
    before = _snapshot(result)
    code, _, err = _run(capsys, "run", other, finished[1], "--resume", "--out", result, "--no-progress")
    assert code == 2
    assert "already holds results (summary.json, kinematics.csv, forces.csv) and no checkpoint to resume" \
        in _error_line(err)
    assert _snapshot(result) == before


# -- nothing written outside --out ----------------------------------------------------

def test_a_planted_view_tmp_link_is_refused(result, watched, capsys):
    (result / ".view.html.tmp").symlink_to(watched / "target.txt")
    before = _snapshot(watched)
    code, _, err = _run(capsys, "view", result)
    assert code == 2
    assert ".view.html.tmp' is a symbolic link" in _error_line(err)
    assert _snapshot(watched) == before


@pytest.mark.parametrize("entry, target", [(".checkpoint", "sub"), ("plots", "sub"), ("forces.csv", "target.txt")])
def test_a_planted_link_in_the_run_output_folder_is_refused(finished, tmp_path, watched, capsys, entry, target):
    out = tmp_path / "out"
    out.mkdir()
    (out / entry).symlink_to(watched / target)
    before = _snapshot(watched)
    code, _, err = _run(capsys, "run", finished[0], finished[1], "--out", out, "--no-progress", "--force")
    assert code == 2
    assert f"{entry}' is a symbolic link" in _error_line(err)
    assert _snapshot(watched) == before


def test_a_planted_link_at_a_figure_file_is_refused(result, watched, capsys):
    (result / "plots").mkdir()
    (result / "plots" / "kinematics.png").symlink_to(watched / "target.txt")
    before = _snapshot(watched)
    code, _, err = _run(capsys, "plot", result)
    assert code == 2
    assert "kinematics.png' is a symbolic link" in _error_line(err)
    assert _snapshot(watched) == before


def test_a_planted_figure_folder_link_is_refused_by_plot(result, watched, capsys):
    (result / "plots").symlink_to(watched / "sub")
    before = _snapshot(watched)
    code, _, err = _run(capsys, "plot", result)
    assert code == 2
    assert "plots' is a symbolic link" in _error_line(err)
    assert _snapshot(watched) == before


def test_a_planted_checkpoint_link_is_refused_when_saving(tmp_path, watched):
    from openfdk.trial.checkpoint import CheckpointError, Checkpoints

    (tmp_path / ".checkpoint").symlink_to(watched / "sub")
    before = _snapshot(watched)
    with pytest.raises(CheckpointError, match=r"\.checkpoint: is a symbolic link"):
        Checkpoints(tmp_path / ".checkpoint", "run").save([], None, 0)
    with pytest.raises(CheckpointError, match=r"\.checkpoint: is a symbolic link"):
        Checkpoints(tmp_path / ".checkpoint", "run").load()
    assert _snapshot(watched) == before


# -- documentation agrees with the CLI ------------------------------------------------

def test_studies_doc_gives_the_cli_exit_code_for_failed_cases():
    from pathlib import Path

    from openfdk.cli.commands import EXIT_FAILED_FRAMES

    text = (Path(__file__).parents[1] / "docs" / "studies.md").read_text()
    assert f"* {EXIT_FAILED_FRAMES}: some case failed" in text
    assert "* 1: some case failed" not in text


def test_study_with_an_empty_out_is_refused(finished, tmp_path, capsys, monkeypatch):
    model, trial, _ = finished
    study = _write(tmp_path / "s.yaml", f"openfdk_study: 1\nmodels: {{m: {model}}}\ntrials: {{t: {trial}}}\n")
    monkeypatch.chdir(tmp_path)
    code, _, err = _run(capsys, "study", study, "--out", "")
    assert code == 2
    assert "the output folder is empty (--out '')" in _error_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]


@pytest.mark.parametrize("node, message", [
    ({"t": "call", "f": "os.system"}, "unknown type tag 'call'"),
    ({"t": "obj", "c": "Popen", "f": {}}, "unknown class 'Popen'"),
    ({"t": "enum", "c": "system", "v": 1}, "unknown class 'system'"),
    ({"t": "obj", "c": "FrameReport", "f": {"status": None}}, "the fields of FrameReport do not match"),
    ({"t": "nd", "a": "structure"}, "no array 'structure'"),
    ([1, 2], "not a node"),
])
def test_the_checkpoint_decoder_accepts_only_known_type_tags(node, message):
    import io

    import numpy as np

    from openfdk.trial.checkpoint_format import FormatError, decode

    buf = io.BytesIO()
    doc = {"format": "openfdk-checkpoint-1", "root": node}
    np.savez(buf, structure=np.frombuffer(json.dumps(doc).encode(), dtype=np.uint8))
    with pytest.raises(FormatError, match=message):
        decode(buf.getvalue())


def test_the_checkpoint_format_round_trips_what_a_checkpoint_holds():
    import numpy as np

    from openfdk.fdk.contact_step import ContactSplit
    from openfdk.model.state import BodyStates
    from openfdk.recruitment.result import RecruitmentResult
    from openfdk.trial.checkpoint_format import decode, encode
    from openfdk.trial.status import NOT_RUN, FrameReport, Reason

    state = BodyStates(np.zeros((2, 3)), [[1, 0, 0, 0]] * 2, [-1, 0])
    q = np.arange(3.0)
    rr = RecruitmentResult(np.ones(2), True, "optimal", "", 3, 0.5, np.zeros(1), np.zeros(2, bool), np.zeros(2, bool))
    # the FDK step's carried Jacobian with the contacts split off (fdk/contact_step.py)
    split = ContactSplit(np.ones((6, 2)), np.zeros((2, 6)), np.arange(6), np.array([[0, -1]]), np.eye(2), None)
    payload = {"records": [(0, {"a": np.float64(1.5), "b": 2, "c": float("nan"), "r": NOT_RUN, "s": "x",
                                "f": FrameReport.failed(Reason.SINGULAR, "m", 2, 0.1)})],
               "carry": (state, q, {3: {"q": q}}, None, True, [rr]), "split": split}
    back = decode(encode(payload))
    rec = back["records"][0]
    assert isinstance(rec, tuple) and type(rec[1]["a"]) is np.float64 and rec[1]["a"] == 1.5
    assert repr(rec[1]["r"]) == repr(NOT_RUN) and rec[1]["f"] == FrameReport.failed(Reason.SINGULAR, "m", 2, 0.1)
    st, q2, pending, none, flag, (rr2,) = back["carry"]
    assert isinstance(st, BodyStates) and np.array_equal(st.R_WB, state.R_WB) and list(st.moving) == [1]
    assert pending[3]["q"] is q2 and np.array_equal(q2, q) and none is None and flag is True
    assert isinstance(rr2, RecruitmentResult) and np.array_equal(rr2.f, rr.f) and rr2.criterion == "polynomial"
    split2 = back["split"]
    assert isinstance(split2, ContactSplit) and split2.J_whole is None
    for name in ("U", "R", "cols", "blocks", "J_s"):
        assert np.array_equal(getattr(split2, name), getattr(split, name))


# -- the command line's own options (stop 72's sweep) -------------------------------------

@pytest.mark.parametrize("address", ["not a url", "", "localhost", "inproc://x", "tcp://127.0.0.1:0",
                                     "tcp://host:99999", "tcp://:8786", "tcp://a b:8786"])
def test_a_malformed_scheduler_address_is_a_usage_error(finished, tmp_path, capsys, address):
    """distributed's parse error came after its client had started: a traceback from the
    client's clean-up after a two-minute wait (exit 2 only then). Now argparse refuses it
    at once, naming the option, and nothing is written."""
    t0 = time.perf_counter()
    with pytest.raises(SystemExit) as exc:
        main(["run", str(finished[0]), str(finished[1]), "--chunks", "2", "--scheduler", address,
              "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and time.perf_counter() - t0 < 10.0
    assert "argument --scheduler: expected a scheduler address" in err and repr(address) in err
    assert "Traceback" not in err and not (tmp_path / "o").exists()


def test_a_well_formed_scheduler_address_is_taken_as_given():
    from openfdk.cli.argtypes import scheduler_address

    for address in ("tcp://10.0.0.5:8786", "10.0.0.5:8786", "tls://[::1]:8786", " ucx://node7:1 "):
        assert scheduler_address(address) == address.strip()


@pytest.mark.parametrize("options", [["--scheduler", "tcp://127.0.0.1:8786"], ["--workers", "2"]])
def test_cluster_options_of_a_serial_run_are_refused(finished, tmp_path, capsys, options):
    """--scheduler and --workers were accepted and ignored by a run without --chunks."""
    code, _, err = _run(capsys, "run", finished[0], finished[1], *options, "--out", tmp_path / "o")
    assert code == 2
    assert f"{options[0]} is used only with --chunks K >= 2" in _error_line(err)
    assert not (tmp_path / "o").exists()


def test_an_out_through_dot_dot_creates_only_that_folder(finished, tmp_path, monkeypatch, capsys):
    """``--out sub/../../res`` made an empty ``sub/`` in the working folder on its way."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    code, _, err = _run(capsys, "kinematics", finished[0], finished[1], "--out", "sub/../../res", "--no-progress")
    assert code == 0, err
    assert sorted(p.name for p in work.iterdir()) == []
    assert (tmp_path / "a" / "res" / "kinematics.csv").is_file()


def test_force_clears_the_earlier_runs_other_tables(finished, result, capsys):
    """A table the new run does not write (``joint_loads.csv`` of an earlier run, or one
    left by hand) stayed beside the new results and was read and plotted as theirs.
    A folder holding only such a table is a result folder too."""
    from openfdk.results.run import read_results

    (result / "joint_loads.csv").write_text((result / "forces.csv").read_text())
    (result / "plots").mkdir(exist_ok=True)
    (result / "plots" / "joint_loads.png").write_bytes(b"\x89PNG stale")
    assert read_results(result).joint_loads is not None  # read as the run's, before
    code, _, err = _run(capsys, "kinematics", finished[0], finished[1], "--out", result, "--force", "--no-progress")
    assert code == 0, err
    assert not (result / "joint_loads.csv").exists() and not (result / "plots" / "joint_loads.png").exists()
    assert not (result / "forces.csv").exists()  # the earlier run's forces: kinematics writes none
    assert read_results(result).joint_loads is None
    lone = result.parent / "lone"
    lone.mkdir()
    (lone / "moment_arms.csv").write_text("time,m.q\n0,0.01\n")
    code, _, err = _run(capsys, "kinematics", finished[0], finished[1], "--out", lone, "--no-progress")
    assert code == 2 and "already holds results (moment_arms.csv)" in _error_line(err)
    assert (lone / "moment_arms.csv").read_text() == "time,m.q\n0,0.01\n"
