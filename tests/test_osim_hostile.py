"""Hostile inputs to the OpenSim readers (``.osim``, ``--ik-tasks``, ``--with`` overlays,
``import-opensim --out``), each through the command line: exit code 2 and exactly one
``openfdk: error:`` line naming the file (and, for XML, the line) — never a traceback, a
hang or a file written outside ``--out``. Each case is a bug that was found by attacking
the readers (before the fix: a traceback, a hang, a silently wrong model, an error that
did not name the file, or an earlier import overwritten). The mutated files start from
the fuzz suite's valid model (:data:`openfdk.bench.fuzz_inputs.OSIM_TEXT`)."""

from __future__ import annotations

import json
import os
import signal

import pytest

from openfdk.bench.fuzz_inputs import IK_SETUP_TEXT, OSIM_TEXT
from openfdk.cli import main

MOT = ("coords\nversion=1\nnRows=3\nnColumns=3\ninDegrees=yes\nendheader\n"
       "time\thip_q\tknee\n0\t1\t-30\n0.05\t2\t-29\n0.1\t3\t-28\n")
MARKERS = ("T1", "T2", "T3", "R.S1", "S2", "S3")
DOCTYPE = '<?xml version="1.0"?>\n<!DOCTYPE OpenSimDocument [<!ENTITY z "0">]>\n'


def _trc(rows=3):
    head = ["PathFileType\t4\t(X/Y/Z)\ttrial.trc",
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
            f"100\t100\t{rows}\t{len(MARKERS)}\tm\t100\t1\t{rows}",
            "Frame#\tTime\t" + "\t".join(f"{m}\t\t" for m in MARKERS),
            "\t\t" + "\t".join(f"X{k + 1}\tY{k + 1}\tZ{k + 1}" for k in range(len(MARKERS))), ""]
    return "\n".join(head + [f"{k + 1}\t{k / 100:.4f}\t" + "\t".join(["0.1"] * 18) for k in range(rows)]) + "\n"


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A model folder (the current directory): leg.osim, Geometry/thigh.obj, an IK setup
    with its coordinate file, a TRC trial and an overlay."""
    (tmp_path / "leg.osim").write_text(OSIM_TEXT)
    (tmp_path / "Geometry").mkdir()
    (tmp_path / "Geometry" / "thigh.obj").write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\n"
                                                     "f 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    (tmp_path / "Setup_IK.xml").write_text(IK_SETUP_TEXT)
    (tmp_path / "coords.mot").write_text(MOT)
    (tmp_path / "trial.trc").write_text(_trc())
    (tmp_path / "with.yaml").write_text("analysis: {marker_cutoff_hz: 0}\n")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _files(root, skip):
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        rel = os.path.relpath(dirpath, root)
        if rel.split(os.sep)[0] in skip:
            continue
        for f in filenames + dirnames:
            st = os.lstat(os.path.join(dirpath, f))
            out[os.path.normpath(os.path.join(rel, f))] = (st.st_size, st.st_mtime_ns)
    return out


def _timeout(signum, frame):
    raise TimeoutError("the command did not finish within 30 s")


def run(capsys, folder, argv, seconds=30):
    """(exit code, stderr) of ``openfdk *argv`` within ``seconds``; checks that nothing
    but the --out folder changed and that stderr holds no traceback."""
    out = argv[argv.index("--out") + 1] if "--out" in argv else None
    skip = {out.split("/")[0]} if out else set()
    before = _files(folder, skip)
    capsys.readouterr()
    old = signal.signal(signal.SIGALRM, _timeout)
    signal.alarm(seconds)
    try:
        code = main(list(argv))
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    after = _files(folder, skip)
    changed = sorted(k for k in after if before.get(k) != after[k] and not os.path.isdir(k))
    assert not changed, f"written outside --out: {changed}"
    return code, err


def error_line(err):
    lines = [ln for ln in err.splitlines() if ln.startswith("openfdk: error:")]
    assert len(lines) == 1, err
    assert len(lines[0]) < 1000, lines[0][:300]
    return lines[0]


# -- mutations --------------------------------------------------------------------------

def sub(old, new, file="leg.osim"):
    def edit(d):
        text = (d / file).read_text(encoding="utf-8")
        assert old in text, old
        (d / file).write_text(text.replace(old, new, 1), encoding="utf-8")
    return edit


def write(file, text):
    def edit(d):
        (d / file).write_text(text) if isinstance(text, str) else (d / file).write_bytes(text)
    return edit


def link(file, target):
    def edit(d):
        if os.path.lexists(d / file):
            (d / file).unlink()
        os.symlink(target, d / file)
    return edit


def fifo(file):
    def edit(d):
        if os.path.lexists(d / file):
            (d / file).unlink()
        os.mkfifo(d / file)
    return edit


def both(*edits):
    def edit(d):
        for e in edits:
            e(d)
    return edit


def doctype(file, old, new):
    def edit(d):
        text = (d / file).read_text().split("\n", 1)[1]
        assert old in text
        (d / file).write_text(DOCTYPE + text.replace(old, new, 1))
    return edit


EXTRA_JOINT = """<WeldJoint name="extra"><socket_parent_frame>/bodyset/thigh</socket_parent_frame>
<socket_child_frame>/ground</socket_child_frame></WeldJoint></objects></JointSet>"""
SECOND_COUPLER = """</CoordinateCouplerConstraint><CoordinateCouplerConstraint name="pat_cc">
<coupled_coordinates_function><Constant><value>0</value></Constant></coupled_coordinates_function>
<independent_coordinate_names>hip_q</independent_coordinate_names>
<dependent_coordinate_name>pat_q</dependent_coordinate_name></CoordinateCouplerConstraint>"""
WELD_AS_JOINT = """</CoordinateCouplerConstraint><WeldConstraint name="knee_j">
<socket_frame1>/bodyset/thigh</socket_frame1><socket_frame2>/bodyset/shank</socket_frame2></WeldConstraint>"""

CHECK = ("check", "leg.osim")
IK = ("check", "leg.osim", "--ik-tasks", "Setup_IK.xml")
IMPORT = ("import-opensim", "leg.osim", "--out", "out")

# (id, mutation, argv, fragments the error line must hold)
CASES = [
    # the file itself: a hang, a traceback or memory exhaustion before
    ("osim symlink loop", link("leg.osim", "leg.osim"), CHECK, ["leg.osim: cannot read the file"]),
    ("osim is a FIFO", fifo("leg.osim"), CHECK, ["leg.osim: cannot read the file (not a regular file)"]),
    ("osim is /dev/zero", link("leg.osim", "/dev/zero"), CHECK, ["leg.osim: cannot read the file"]),
    # entities: unexpanded, they silently dropped or changed values (mass 5&z; read as 5)
    ("DOCTYPE entity in mass", doctype("leg.osim", "<mass>5</mass>", "<mass>5&z;</mass>"), CHECK,
     ["leg.osim: has a DOCTYPE declaration"]),
    ("DOCTYPE entity in mesh_file", doctype("leg.osim", "thigh.obj<", "&z;<"), CHECK, ["leg.osim: has a DOCTYPE"]),
    ("DOCTYPE in the IK setup", doctype("Setup_IK.xml", "<weight>2</weight>", "<weight>2&z;</weight>"), IK,
     ["Setup_IK.xml: has a DOCTYPE declaration"]),
    # numbers Python reads and OpenSim does not
    ("mass 1_0", sub("<mass>5</mass>", "<mass>1_0</mass>"), CHECK, ["leg.osim: line 8: Body 'thigh' <mass>",
                                                                   "expected numbers"]),
    ("non-ASCII digit", sub("<translation>0 1 0<", "<translation>0 \u0661 0<"), CHECK,
     ["leg.osim: line", "PhysicalOffsetFrame 'ground_offset' <translation>: expected numbers"]),
    ("coupler scale_factor 1_0", sub("<dependent_coordinate_name>", "<scale_factor>1_0</scale_factor>"
                                     "<dependent_coordinate_name>"), CHECK, ["leg.osim: line", "<scale_factor>"]),
    ("IK weight 1_0", sub("<weight>2</weight>", "<weight>1_0</weight>", "Setup_IK.xml"), IK,
     ["Setup_IK.xml: line 7: IKMarkerTask 'T2': <weight> is not a finite number"]),
    ("IK manual value nan", sub("<value>0.1</value>", "<value>nan</value>", "Setup_IK.xml"), IK,
     ["Setup_IK.xml: line", "IKCoordinateTask 'hip_q': <value> is not a finite number"]),
    ("GCVSpline half_order of 5000 digits", both(sub("</SimmSpline>", "</GCVSpline>"),
                                                 sub('<SimmSpline name="function">', '<GCVSpline name="function">'
                                                     "<half_order>" + "9" * 5000 + "</half_order>")),
     CHECK, ["leg.osim: line", "<half_order> must be an integer from 1 to 3"]),
    # overflow: 'Eigenvalues did not converge' or 'piecewise polynomial: ... finite', no file
    ("mass_center 1e308", sub("<mass_center>0.01 -0.2 0<", "<mass_center>1e308 1e308 1e308<"), CHECK,
     ["leg.osim: line 6: Body 'thigh'", "too large"]),
    ("inertia near the float limit", sub("<inertia>0.1 0.02 0.1 0.001 0.002 0.003<",
                                         "<inertia>1.7e308 1.7e308 1.7e308 1e308 1e308 1e308<"), CHECK,
     ["leg.osim: bodies.thigh.inertia: principal moment"]),
    ("multiplier scale overflow", sub("<LinearFunction name=\"function\"><coefficients>1 0</coefficients>"
                                      "</LinearFunction>",
                                      "<MultiplierFunction name=\"function\"><scale>1e300</scale><function>"
                                      "<LinearFunction><coefficients>1e300 0</coefficients></LinearFunction>"
                                      "</function></MultiplierFunction>"),
     CHECK, ["leg.osim: line", "TransformAxis 'rotation1'", "overflows"]),
    # topology accepted silently, or a traceback
    ("joint whose child is the ground", sub("</objects></JointSet>", EXTRA_JOINT), CHECK,
     ["leg.osim: line", "WeldJoint 'extra'", "a joint's child must be a body"]),
    ("frame attached to itself", sub("<socket_parent>/ground</socket_parent>", "<socket_parent>ground_offset"
                                     "</socket_parent>"), CHECK, ["leg.osim: line", "is attached to itself"]),
    ("body named ground", sub('<Body name="patella">', '<Body name="ground">'), CHECK,
     ["leg.osim: line 11: Body 'ground'"]),
    ("two joints with one name", sub('<PinJoint name="pat_j">', '<PinJoint name="hip">'), CHECK,
     ["leg.osim: line", "a second joint named 'hip'"]),
    ("two markers with one name", sub('<Marker name="T2">', '<Marker name="T1">'), CHECK,
     ["leg.osim: line", "a second marker named 'T1'"]),
    ("two constraints with one name", sub("</CoordinateCouplerConstraint>", SECOND_COUPLER), CHECK,
     ["leg.osim: line", "a second constraint named 'pat_cc'"]),
    ("weld constraint named as a joint", sub("</CoordinateCouplerConstraint>", WELD_AS_JOINT), CHECK,
     ["leg.osim: two joints named 'knee_j'"]),
    ("coupler of a coordinate on itself", sub(">pat_q</dependent", ">knee</dependent"), CHECK,
     ["leg.osim: line", "CoordinateCouplerConstraint 'pat_cc': the dependent coordinate 'knee' is also"]),
    ("marker on an unknown frame", sub("/bodyset/thigh</socket_parent_frame><location>0.05",
                                       "/bodyset/nope</socket_parent_frame><location>0.05"), CHECK,
     ["leg.osim: line", "Marker 'T1': frame 'nope'"]),
    ("weld constraint on an unknown frame", sub("</CoordinateCouplerConstraint>", WELD_AS_JOINT.replace(
        "knee_j", "wc").replace("/bodyset/shank", "/bodyset/nope")), CHECK, ["leg.osim: line", "WeldConstraint 'wc'"]),
    # meshes: absolute paths without a mesh suffix were copied into --out; long names and
    # symlink loops raised OSError / RuntimeError without the model's name
    ("mesh /etc/passwd", sub(">thigh.obj<", ">/etc/passwd<"), IMPORT,
     ["leg.osim: line", "Mesh '/etc/passwd': unknown mesh format"]),
    # IK tasks and their coordinate file
    ("two IK tasks with one name", sub('<IKMarkerTask name="T2">', '<IKMarkerTask name="T1">', "Setup_IK.xml"), IK,
     ["Setup_IK.xml: line 7: IKMarkerTask 'T1': a second IKMarkerTask named 'T1'"]),
    ("coordinate file is /dev/zero", link("coords.mot", "/dev/zero"), IK,
     ["Setup_IK.xml: coordinate_file: coords.mot: cannot read the file (not a regular file)"]),
    ("coordinate file is a FIFO", fifo("coords.mot"), IK, ["coords.mot: cannot read the file (not a regular file)"]),
    ("coordinate file NaN value", sub("\t-29\n", "\tnan\n", "coords.mot"), IK,
     ["Setup_IK.xml: line", "column 'knee' of coords.mot: the value at t = 0.05 s is nan"]),
    ("coordinate file of one row", write("coords.mot", MOT.split("0.05")[0]), IK,
     ["column 'knee' of coords.mot: 1 rows"]),
    ("coordinate file column twice", sub("time\thip_q\tknee", "time\tknee\tknee", "coords.mot"), IK,
     ["IKCoordinateTask 'knee': column 'knee' is given twice with different values in coords.mot"]),
    ("coordinate file value 1_0", sub("\t-29\n", "\t1_0\n", "coords.mot"), IK,
     ["coords.mot: line 9: column 'knee' is '1_0', expected a number"]),
    ("coordinate file inDegrees=maybe", sub("inDegrees=yes", "inDegrees=maybe", "coords.mot"), IK,
     ["coords.mot: line 5: inDegrees must be yes or no"]),
    # overlays: a TypeError traceback, or errors naming the .osim for the overlay's entries
    ("overlay naming itself", write("over.yaml", "opensim: over.yaml\n"), ("check", "over.yaml"),
     ["over.yaml: opensim: expected the path of an .osim file"]),
    ("overlay naming a YAML model", write("over.yaml", "opensim: with.yaml\n"), ("check", "over.yaml"),
     ["over.yaml: opensim: expected the path of an .osim file"]),
    ("overlay geometry folder missing", write("over.yaml", "opensim: leg.osim\ngeometry: [nope]\n"),
     ("check", "over.yaml"), ["over.yaml: geometry: folder 'nope' does not exist"]),
    ("--geometry folder missing", lambda d: None, CHECK + ("--geometry", "nope"), ["--geometry: folder 'nope'"]),
    ("--with unknown section", write("with.yaml", "foo: 1\n"), CHECK + ("--with", "with.yaml"),
     ["with.yaml: foo: not a model-file section"]),
    ("--with section not a mapping", write("with.yaml", "tasks: [1, 2]\n"), CHECK + ("--with", "with.yaml"),
     ["with.yaml: tasks: expected a mapping"]),
    ("--with misspelt section", write("with.yaml", "analisys: {start: 0}\n"), CHECK + ("--with", "with.yaml"),
     ["with.yaml: analisys: not a model-file section an overlay can add; did you mean 'analysis'?"]),
    ("--with entry names the overlay", write("with.yaml", "drivers: {d: {measur: x}}\n"),
     CHECK + ("--with", "with.yaml"), ["leg.osim with with.yaml: drivers.d.measur: unknown key; did you mean 'measure'?"]),
    ("import-opensim of an overlay", write("over.yaml", "opensim: leg.osim\n"),
     ("import-opensim", "over.yaml", "--out", "out"), ["over.yaml: not an OpenSim model"]),
    # import-opensim --out
    ("--out ''", lambda d: None, ("import-opensim", "leg.osim", "--out", ""), ["--out ''"]),
    ("earlier import", both(lambda d: (d / "out").mkdir(), write("out/leg.yaml", "# mine\n")), IMPORT,
     ["output folder 'out' already holds leg.yaml", "--force"]),
    ("a mesh of an earlier import", both(lambda d: (d / "out" / "Geometry").mkdir(parents=True),
                                          write("out/Geometry/thigh.obj", "mine\n")), IMPORT,
     ["already holds Geometry/thigh.obj"]),
    ("model file target is a symlink", both(lambda d: (d / "out").mkdir(), link("out/leg.yaml", "../elsewhere.yaml")),
     IMPORT, ["already holds leg.yaml"]),
    ("Geometry is a symlink out of --out", both(lambda d: (d / "out").mkdir(), link("out/Geometry", "..")), IMPORT,
     ["Geometry is not a folder of its own"]),
    ("model error before writing", sub("<mass>5</mass>", "<mass>1e300</mass>"), IMPORT,
     ["leg.osim: bodies.thigh.mass"]),
    # YAML model files: coordinates, custom joints, couplers
    ("YAML coordinate not a name", write("m.yaml", "__custom_coordinate_list__"), ("check", "m.yaml"),
     ["m.yaml: joints.j.rotations[0].coordinate: unknown coordinate [1]"]),
    ("YAML coupler on itself", write("m.yaml", "__coupler_on_itself__"), ("check", "m.yaml"),
     ["m.yaml: couplers.c.dependent: 'q' is also the independent coordinate"]),
    ("YAML multipliers nested 300 deep", write("m.yaml", "__deep_multiplier__"), ("check", "m.yaml"),
     ["m.yaml: joints.j.rotations[0].function", "nested more than 200 deep"]),
    ("YAML polynomial overflowing in degrees", write("m.yaml", "__overflow_deg__"), ("check", "m.yaml"),
     ["m.yaml: joints.j.rotations[0].function", "too large"]),
    ("YAML two parallel moving rotation axes", write("m.yaml", "__parallel_axes__"), ("check", "m.yaml"),
     ["m.yaml: joints.j", "do not span space"]),
    ("YAML three moving rotation axes in a plane", write("m.yaml", "__planar_axes__"), ("check", "m.yaml"),
     ["m.yaml: joints.j", "do not span space"]),
    # TRC trials
    ("TRC time NaN", sub("\t0.0100\t", "\tnan\t", "trial.trc"), ("kinematics", "leg.osim", "trial.trc", "--out", "k"),
     ["trial.trc: line 8: the time is 'nan'"]),
    ("TRC is a FIFO", fifo("trial.trc"), ("kinematics", "leg.osim", "trial.trc", "--out", "k"),
     ["trial.trc: cannot read the file: not a regular file"]),
]


def _yaml_model(kind):
    """A small YAML model with a custom joint (and a coupler) for the YAML cases."""
    function = {"type": "linear", "slope": 1.0, "intercept": 0.0}
    rot = {"axis": [0, 0, 1], "coordinate": "q", "function": function}
    data = {"openfdk": 1, "units": {"length": "m", "angle": "rad"},
            "bodies": {"ground": {}, "b": {"mass": 1.0, "inertia": [0.1, 0.1, 0.1], "position": [0, 0, 0],
                                           "markers": {"m1": {"position": [0.1, 0, 0]}, "m2": {"position": [0, 0.1, 0]},
                                                       "m3": {"position": [0, 0, 0.1]}}}},
            "coordinates": {"q": {}},
            "joints": {"j": {"type": "custom", "parent": "ground.origin", "child": "b.origin", "rotations": [rot]}}}
    if kind == "__custom_coordinate_list__":
        rot["coordinate"] = [1]
    elif kind == "__coupler_on_itself__":
        data["couplers"] = {"c": {"independent": "q", "dependent": "q", "function": function}}
    elif kind == "__deep_multiplier__":
        for _ in range(300):
            function = {"type": "multiplier", "scale": 1.0, "function": function}
        rot["function"] = function
    elif kind in ("__parallel_axes__", "__planar_axes__"):  # not orthogonal, and no angles about them
        axes = [[0, 0, 1], [0, 0, -2]] if kind == "__parallel_axes__" else [[1, 0, 0], [1, 1, 0], [0, 1, 0]]
        data["coordinates"] = {f"q{k}": {} for k in range(len(axes))}
        data["joints"]["j"]["rotations"] = [{"axis": a, "coordinate": f"q{k}", "function": function}
                                            for k, a in enumerate(axes)]
    elif kind == "__overflow_deg__":
        data["units"]["angle"] = "deg"
        rot["function"] = {"type": "polynomial", "coefficients": [1e306, 0, 0, 0, 0, 0]}
    return json.dumps(data)  # (JSON is YAML; yaml.safe_dump recurses once per nesting level)


@pytest.mark.parametrize("name, edit, argv, fragments", CASES, ids=[c[0] for c in CASES])
def test_hostile_input_is_one_line_naming_the_file(folder, capsys, name, edit, argv, fragments):
    edit(folder)
    if (folder / "m.yaml").exists():
        (folder / "m.yaml").write_text(_yaml_model((folder / "m.yaml").read_text()))
    fresh = not os.path.lexists(folder / "out")
    code, err = run(capsys, folder, argv)
    line = error_line(err)
    assert code == 2, err
    for fragment in fragments:
        assert fragment in line, line
    if fresh:
        assert not os.path.lexists(folder / "out") or not os.listdir(folder / "out"), "files written to --out"


def test_import_refuses_an_earlier_import_and_overwrites_it_with_force(folder, capsys):
    assert run(capsys, folder, IMPORT)[0] == 0
    first = (folder / "out" / "leg.yaml").read_text()
    (folder / "out" / "leg.yaml").write_text("# edited by hand\n")
    code, err = run(capsys, folder, IMPORT)
    assert code == 2 and "already holds leg.yaml" in error_line(err)
    assert (folder / "out" / "leg.yaml").read_text() == "# edited by hand\n"
    assert run(capsys, folder, IMPORT + ("--force",))[0] == 0
    assert (folder / "out" / "leg.yaml").read_text() == first


def test_import_with_force_replaces_a_symlink_instead_of_writing_through_it(folder, capsys, tmp_path_factory):
    outside = tmp_path_factory.mktemp("outside") / "victim.obj"
    outside.write_text("do not touch\n")
    (folder / "out" / "Geometry").mkdir(parents=True)
    os.symlink(outside, folder / "out" / "Geometry" / "thigh.obj")
    assert run(capsys, folder, IMPORT + ("--force",))[0] == 0
    assert outside.read_text() == "do not touch\n"
    assert not (folder / "out" / "Geometry" / "thigh.obj").is_symlink()


def test_import_into_the_models_own_folder_with_force_keeps_its_meshes(folder, capsys):
    code, err = run(capsys, folder, ("import-opensim", "leg.osim", "--out", "."))
    assert code == 2 and "'.' already holds Geometry/thigh.obj" in error_line(err)
    code, err = run(capsys, folder, ("import-opensim", "leg.osim", "--out", ".", "--force"))
    assert code == 0, err
    assert (folder / "leg.yaml").is_file() and (folder / "Geometry" / "thigh.obj").stat().st_size > 0


def test_import_of_a_model_named_too_long_for_a_file_name(folder, capsys):
    (folder / "leg.osim").write_text(OSIM_TEXT.replace('<Model name="leg">', f'<Model name="{"L" * 100000}">'))
    code, err = run(capsys, folder, IMPORT)
    assert code == 0, err[:300]
    assert [p.name for p in (folder / "out").glob("*.yaml")] == ["leg.yaml"]


@pytest.mark.parametrize("name, edit, fragment", [
    ("mesh name of 5000 characters", sub(">thigh.obj<", ">" + "x" * 5000 + ".obj<"), "'" + "x" * 60 + "'"),
    ("mesh in a symlink-loop folder", both(link("loop", "loop"), sub(">thigh.obj<", ">loop/x.obj<")), "'loop/x.obj'"),
])
def test_a_display_mesh_not_found_is_one_warning_and_the_model_is_read(folder, capsys, name, edit, fragment):
    """A display mesh that cannot be found (a name too long for the file system, a folder
    that links to itself): as OpenSim, the model is read without it, with one warning
    line naming the model file and the mesh (these were errors until stop 64)."""
    edit(folder)
    code, err = run(capsys, folder, CHECK)
    assert code == 0, err
    lines = [x for x in err.splitlines() if "display mesh" in x]
    assert len(lines) == 1 and "leg.osim: 1 display mesh file(s) not found (" in lines[0] and fragment in lines[0], err
