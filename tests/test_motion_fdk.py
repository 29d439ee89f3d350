"""FDK on a coordinate file (``motion: ik.mot`` with ``fdk_dofs``): the two-stage pipeline of
the commercial FDK tool's MoCap models and of COMAK, the primary coordinates from a first
tracking or IK pass, the secondary ones solved by FDK (issue 27).

The knee of :mod:`test_knee_jam_fdk` (OpenSim-JAM format, two condyle caps on a plateau,
four Blankevoort strands, a known load on the tibia):

* with the motion file driving flexion, the five FDK DOFs reach the independent force
  balance of that test (closed-form elastic foundation) whatever the file's columns for
  them say: the FDK DOFs are solved, not driven;
* a constraint of the overlay that fixes a combination of coordinates (a distance between
  a femur point and a tibia point) leaves the last coordinate of the combination to it,
  with a warning that names it: the determinate kinematics then hold the distance, to the
  root of that one equation found here by bisection, and follow the file elsewhere.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("opensim")

from test_knee_jam_fdk import (COORDINATES, FLEXION, LOAD_FORCE, LOAD_MOMENT, SECONDARY,  # noqa: E402
                               _closed_form_contact, _knee_model, _overlay, _solve, tibia_pose)

from openfdk.io.storage import write_storage  # noqa: E402

TIMES = np.linspace(0.0, 0.5, 11)  # s: the motion file's samples


def _write_motion(folder, columns, name="knee.mot"):
    write_storage(folder / name, TIMES, {c: np.asarray(columns[c], float) for c in COORDINATES if c in columns},
                  name="knee motion")
    return folder / name


#: the loop of the tests below: a femur point a_F (m) and a tibia point b_T (m) held at a
#: distance (m), the only row that sets knee_tz (the femur is welded to the ground)
REACH_A_F, REACH_B_T, REACH_LENGTH = np.array([0.03, 0.02, 0.01]), np.array([0.02, -0.04, 0.0]), 0.09


def _reach_overlay(folder, name, extra="", a_F=REACH_A_F, b_T=REACH_B_T, length=REACH_LENGTH):
    """An overlay of the knee driven by knee.mot with the distance |a_F − b_T| held at
    ``length`` (constraint ``reach_held``), and the lines ``extra``."""
    return _overlay(folder, f"""\
motion: knee.mot
frames:
  femur: {{hub: {np.asarray(a_F).tolist()}}}
  tibia: {{hub: {np.asarray(b_T).tolist()}}}
measures:
  reach: {{type: distance, from: ground.hub, to: tibia.hub}}
constraints:
  reach_held: {{measure: reach, value: {length}}}
{extra}""", name)


@pytest.fixture(scope="module")
def knee(tmp_path_factory):
    folder = tmp_path_factory.mktemp("motion_knee")
    _knee_model(folder)
    return folder


@pytest.mark.slow
def test_fdk_dofs_of_a_motion_file_are_solved_not_driven(knee):
    from openfdk.fdk.analysis import run_fdk
    from openfdk.io.modelfile import load_model_and_settings
    from openfdk.io.opensim.overlay import import_info

    # flexion held by the file; the secondary columns a first pass would give (far off)
    columns = {name: np.full(TIMES.size, 0.02) for name in SECONDARY}
    columns["knee_flex"] = np.full(TIMES.size, FLEXION)
    _write_motion(knee, columns)
    overlay = _overlay(knee, f"""\
motion: knee.mot
fdk_dofs: [knee_add, knee_rot, knee_tx, {{knee_ty: 0.0005}}, knee_tz]
fdk: {{tolerance: 1.0e-9, max_iterations: 60}}
loads:
  tibia_load: {{point: tibia.knee_child, force: {LOAD_FORCE.tolist()}, moment: {LOAD_MOMENT.tolist()}, frame: world}}
""", "motion_fdk.yaml")
    model, settings = load_model_and_settings(overlay)
    assert import_info(knee / "knee.osim")["motion_not_driven"] == {name: f"fdk_dofs.{name}" for name in SECONDARY}
    assert [c.name for c in model.constraints if c.kind == "driver"] == ["knee_flex_motion"]
    res = run_fdk(model, None, np.array([0.2]), settings)
    assert res.converged.all(), res.messages
    ours = dict(zip(res.dof_names, res.alpha[0]))
    ours = np.array([ours[name] for name in SECONDARY])
    closed = _solve(_closed_form_contact, np.r_[0, 0, 0, 5e-4, 0])
    assert np.all(np.abs(closed - 0.02) > 1e-3)  # the file's columns are far from the equilibrium
    # the same equilibrium as the locked flexion of test_knee_jam_fdk: 1e-6 m and rad
    # against the closed form (its caps' discretisation, measured there 1e-8 m, 3e-7 rad)
    np.testing.assert_allclose(ours, closed, rtol=0, atol=1e-6)
    # a file with flexion alone (the FDK DOFs' columns may be absent): the same run
    _write_motion(knee, {"knee_flex": columns["knee_flex"]}, "flexion.mot")
    alone = knee / "flexion_fdk.yaml"
    alone.write_text(overlay.read_text().replace("motion: knee.mot", "motion: flexion.mot"))
    model, settings = load_model_and_settings(alone)
    again = run_fdk(model, None, np.array([0.2]), settings)
    assert again.converged.all(), again.messages
    np.testing.assert_array_equal(again.alpha, res.alpha)


def _hub_distance(q, a_F, b_T):
    """|a_F − p_T(q) b_T| (m): the distance of a femur point ``a_F`` from a tibia point
    ``b_T`` (the tibia's frame) at the six coordinates ``q``."""
    R, p = tibia_pose(q)
    return float(np.linalg.norm(a_F - (p + R @ b_T)))


def test_a_constraint_leaves_its_coordinate_undriven(knee, tmp_path, monkeypatch, capsys):
    from scipy.optimize import brentq

    from openfdk.cli import main

    monkeypatch.chdir(tmp_path)
    columns = {"knee_flex": 0.2 + 0.4 * TIMES, "knee_add": 0.02 * np.sin(4 * TIMES), "knee_rot": -0.03 * TIMES,
               "knee_tx": 0.001 * TIMES, "knee_ty": np.full(TIMES.size, 0.004), "knee_tz": 0.0005 - 0.002 * TIMES}
    _write_motion(knee, columns)
    a_F, b_T, length = REACH_A_F, REACH_B_T, REACH_LENGTH
    overlay = _reach_overlay(knee, "motion_reach.yaml")
    code = main(["kinematics", str(overlay), "--out", str(tmp_path / "kin")])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "the motion file's knee_tz is not driven" in err
    summary = json.loads((tmp_path / "kin" / "summary.json").read_text())
    assert summary["input"]["opensim_import"]["motion_not_driven"] == {"knee_tz": "constraints"}
    # the same overlay without its motion: key, the motion given on the command line
    bare = knee / "reach.yaml"
    bare.write_text(overlay.read_text().replace("motion: knee.mot\n", ""))
    code = main(["kinematics", str(bare), "--motion", str(knee / "knee.mot"), "--out", str(tmp_path / "cli")])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "cli" / "summary.json").read_text())
    assert summary["input"]["opensim_import"]["options"] == {"motion": str((knee / "knee.mot").resolve())}
    assert (tmp_path / "cli" / "coordinates.csv").read_text() == (tmp_path / "kin" / "coordinates.csv").read_text()
    # plot, view and export read the model as the run did: the summary's --motion
    from openfdk.io.modelfile import load_model_for_results
    from openfdk.io.opensim.overlay import register

    register(bare)  # as in a new process: nothing registered
    replay = load_model_for_results(bare, summary)
    assert [c.name for c in replay.constraints if c.kind == "driver"] == [f"{n}_motion" for n in COORDINATES[:5]]
    # and in Python: an overlay takes motion= (and the .osim's other options but overlay=)
    import openfdk

    driven = [c.name for c in openfdk.load_model(bare, motion=knee / "knee.mot").constraints if c.kind == "driver"]
    assert driven == [f"{name}_motion" for name in COORDINATES[:5]]
    with pytest.raises(TypeError, match=r"reach\.yaml is not one .*an overlay takes all but 'overlay'"):
        openfdk.load_model(bare, overlay=overlay)
    table = np.genfromtxt(tmp_path / "kin" / "coordinates.csv", delimiter=",", names=True)
    assert table.size == TIMES.size
    for i, t in enumerate(table["time"]):
        k = int(np.argmin(np.abs(TIMES - t)))
        assert abs(TIMES[k] - t) < 1e-9
        given = np.array([columns[name][k] for name in COORDINATES])
        ours = np.array([table[f"{name}_{'rad' if name in COORDINATES[:3] else 'm'}"][i] for name in COORDINATES])
        # the five driven coordinates are the file's samples (the spline passes through them)
        np.testing.assert_allclose(ours[:5], given[:5], rtol=0, atol=1e-10)

        def reach(tz):
            return _hub_distance(np.r_[given[:5], tz], a_F, b_T) - length

        root = brentq(reach, -0.05, 0.05, xtol=1e-14)
        assert abs(root - given[5]) > 1e-3  # the file's knee_tz does not hold the distance
        assert ours[5] == pytest.approx(root, abs=1e-9)


def test_a_chunked_run_leaves_the_determined_coordinate_undriven(knee, tmp_path, monkeypatch, capsys):
    """``openfdk run --chunks``: each segment's model is built from the case's mapping
    (openfdk.study.case.build_case_model) as the file is on its own, so the motion's
    column of the coordinate the constraint determines is left out there too. Until stop
    71 the segments drove it as well (one row too many: every frame singular, DM's two
    stages with --chunks). The chunks equal the serial run, whose knee_tz holds the
    distance (test_a_constraint_leaves_its_coordinate_undriven)."""
    from openfdk.cli import main

    monkeypatch.chdir(tmp_path)
    columns = {"knee_flex": 0.2 + 0.4 * TIMES, "knee_add": 0.02 * np.sin(4 * TIMES), "knee_rot": -0.03 * TIMES,
               "knee_tx": 0.001 * TIMES, "knee_ty": np.full(TIMES.size, 0.004), "knee_tz": 0.0005 - 0.002 * TIMES}
    _write_motion(knee, columns)
    overlay = _reach_overlay(knee, "chunked_reach.yaml")
    tables = {}
    for name, extra in (("serial", []), ("chunked", ["--chunks", "2", "--workers", "0", "--overlap", "1"])):
        code = main(["run", str(overlay), "--out", str(tmp_path / name), "--no-plots", *extra])
        assert code == 0, capsys.readouterr().err
        tables[name] = np.genfromtxt(tmp_path / name / "coordinates.csv", delimiter=",", names=True)
    serial, chunked = tables["serial"], tables["chunked"]
    assert chunked.size == serial.size == TIMES.size
    for field in serial.dtype.names:
        np.testing.assert_allclose(chunked[field], serial[field], rtol=0, atol=1e-9)
    assert np.max(np.abs(serial["knee_tz_m"] - columns["knee_tz"])) > 1e-3  # the file's column is not used


def test_a_kinematics_pass_names_a_loop_through_held_fdk_dofs(knee, tmp_path, monkeypatch, capsys):
    """A kinematics pass holds the FDK DOFs at their initial values; a held distance that
    closes a loop through their bodies (the reach to the tibia, whose knee_add is an FDK
    DOF) is named in a warning, the first pass's pitfall of docs/gait.md. Without FDK
    DOFs, or for the locks (a coordinate's own row), nothing is said."""
    from openfdk.cli import main

    monkeypatch.chdir(tmp_path)
    columns = {name: np.zeros(TIMES.size) for name in COORDINATES}
    columns["knee_flex"] = 0.2 + 0.4 * TIMES
    _write_motion(knee, columns)
    for fdk, warned in (("fdk_dofs: [knee_add]\n", True), ("", False)):
        overlay = _reach_overlay(knee, "held_loop.yaml", "lock: [knee_rot]\n" + fdk)
        code = main(["kinematics", str(overlay), "--out", str(tmp_path / f"kin{int(warned)}")])
        err = capsys.readouterr().err
        assert code == 0, err
        said = [line for line in err.splitlines() if "closes a loop" in line]
        if warned:
            assert len(said) == 1 and said[0].startswith(
                f"openfdk: warning: {overlay}: constraints.reach_held: a kinematics pass holds the FDK DOFs at their "
                "initial values (knee_add)"), err
        else:
            assert said == [], err


def test_a_constraint_without_a_reach_is_not_named(tmp_path):
    """The mandible model's hyoid follows the mandible by a position and an orientation
    constraint (three rows each) that share the mandible with the TMJ's FDK DOFs. They
    set the hyoid's whole pose and have no reach, so a kinematics pass is not warned
    about them (held_fdk_loops names held distances only)."""
    from openfdk.io.modelfile import load_model_and_settings
    from openfdk.mandible.generator import create_subject
    from openfdk.mandible.models import write_models
    from openfdk.mandible.registration import register_from_braces
    from openfdk.mandible.subject import load_subject
    from openfdk.model.plausibility import held_fdk_loops

    subject = load_subject(create_subject(tmp_path / "subject", resolution="coarse"))
    paths = write_models(subject, register_from_braces(subject), tmp_path / "models")
    model, _ = load_model_and_settings(paths["fdk"])
    fdk_bodies = {b for d in model.fdk_dofs for b in d.measure.bodies()}
    sharing = [c.name for c in model.constraints if c.joint_type == "generic"
               and fdk_bodies & set(c.measure.bodies())]
    assert {"hyoid_follows_mandible", "hyoid_orientation"} <= set(sharing)  # they do share the mandible
    assert held_fdk_loops(model) == []


def test_a_trial_whose_markers_move_nothing_is_named(tmp_path, monkeypatch, capsys):
    """A trial given with a motion file that drives every coordinate: the markers have
    nothing to fit, and the run says so (the model alone leaves coordinates to them)."""
    from openfdk.analysis.model_check import markers_move_nothing
    from openfdk.cli import main
    from openfdk.fixtures.full_body_osim import write_full_body_motion, write_full_body_osim, write_full_body_trial
    from openfdk.io.modelfile import load_model

    monkeypatch.chdir(tmp_path)
    model = write_full_body_osim(tmp_path / "body.osim")
    trc, times, _, _ = write_full_body_trial(model, tmp_path / "walk.trc", n_frames=12)
    motion = write_full_body_motion(tmp_path, times)
    assert not markers_move_nothing(load_model(model))  # tracked: the markers set the coordinates
    code = main(["kinematics", str(model), str(trc), "--motion", str(motion), "--cutoff", "0", "--out",
                 str(tmp_path / "kin")])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "walk.trc: the markers move nothing: the model's rows" in err
    # openfdk check says the same of the model and its motion, and tracking of the model alone
    assert main(["check", str(model), "--motion", str(motion)]) == 0
    assert "kinematics: determinate (drivers and FDK DOFs fix every coordinate; a trial's markers would move " \
           "nothing)" in capsys.readouterr().out
    main(["check", str(model)])
    assert "kinematics: marker tracking" in capsys.readouterr().out


def test_a_motion_given_twice(knee, tmp_path, monkeypatch, capsys):
    """``--motion`` and the ``motion:`` of a ``--with`` overlay at once: one line naming
    both. An overlay run as the model: ``--motion`` replaces its ``motion:``, with a
    warning naming both, and the coordinates follow the command line's file."""
    from openfdk.cli import main

    monkeypatch.chdir(tmp_path)
    motion = _write_motion(knee, {name: np.zeros(TIMES.size) for name in COORDINATES})
    (knee / "with_motion.yaml").write_text("motion: knee.mot\n")
    code = main(["kinematics", str(knee / "knee.osim"), "--with", str(knee / "with_motion.yaml"), "--motion",
                 str(motion), "--out", str(tmp_path / "kin")])
    err = capsys.readouterr().err
    assert code == 2
    assert "knee.osim: --motion: the overlay with_motion.yaml gives motion: knee.mot too; give one of them" in err
    assert "Traceback" not in err
    # an overlay run as the model, with a motion: key and --motion: the command line's file
    flexed = {name: np.zeros(TIMES.size) for name in COORDINATES}
    flexed["knee_flex"] = 0.3 + 0.5 * TIMES
    other = _write_motion(knee, flexed, "flexed.mot")
    (knee / "run_motion.yaml").write_text("opensim: knee.osim\nmotion: knee.mot\n")
    code = main(["kinematics", str(knee / "run_motion.yaml"), "--motion", str(other), "--out", str(tmp_path / "k2")])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "run_motion.yaml: motion: knee.mot replaced by --motion flexed.mot" in err
    table = np.genfromtxt(tmp_path / "k2" / "coordinates.csv", delimiter=",", names=True)
    np.testing.assert_allclose(table["knee_flex_rad"], 0.3 + 0.5 * table["time"], rtol=0, atol=1e-10)
    # a cutoff for a motion that nobody gives: one line naming the option
    code = main(["kinematics", str(knee / "knee.osim"), "--motion-cutoff", "6",
                 "--out", str(tmp_path / "k3")])
    err = capsys.readouterr().err
    assert code == 2 and "--motion-cutoff: filters the coordinates of --motion, which is not given" in err, err
    (knee / "no_motion.yaml").write_text("opensim: knee.osim\n")
    code = main(["kinematics", str(knee / "no_motion.yaml"), "--motion-cutoff", "6", "--out", str(tmp_path / "k4")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no_motion.yaml: --motion-cutoff: filters the coordinates of motion" in err[0]


def test_a_run_never_writes_over_its_own_motion(knee, tmp_path, capsys):
    """The two stages of docs/gait.md read a first pass's ``coordinates.mot``, the name
    every run writes. With ``--out`` at that folder the run replaced its own input (exit 0,
    no warning); now it is refused before anything is written, whether the motion comes
    from ``--motion`` or from an overlay's ``motion:``, and the file keeps its bytes."""
    from openfdk.cli import main

    first = tmp_path / "first"
    first.mkdir()
    flexed = {name: np.zeros(TIMES.size) for name in COORDINATES}
    flexed["knee_flex"] = 0.3 + 0.5 * TIMES
    motion = _write_motion(first, flexed, "coordinates.mot")
    before = motion.read_bytes()
    code = main(["kinematics", str(knee / "knee.osim"), "--motion", str(motion), "--out", str(first)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert (f"{str(motion)!r} (--motion) is inside the output folder {str(first)!r}, where the run writes its "
            "results; choose another --out") in err
    (tmp_path / "over.yaml").write_text(f"opensim: {knee / 'knee.osim'}\nmotion: first/coordinates.mot\n")
    code = main(["kinematics", str(tmp_path / "over.yaml"), "--out", str(tmp_path / "first" / ".")])
    err = capsys.readouterr().err
    assert code == 2 and "(over.yaml: first/coordinates.mot) is inside the output folder" in err, err
    assert motion.read_bytes() == before and sorted(p.name for p in first.iterdir()) == ["coordinates.mot"]
    # the same motion read from beside the output folder runs, and its flexion is the file's
    code = main(["kinematics", str(knee / "knee.osim"), "--motion", str(motion), "--out", str(tmp_path / "k")])
    assert code == 0, capsys.readouterr().err
    table = np.genfromtxt(tmp_path / "k" / "coordinates.csv", delimiter=",", names=True)
    np.testing.assert_allclose(table["knee_flex_rad"], 0.3 + 0.5 * table["time"], rtol=0, atol=1e-10)


def test_an_overlays_file_keys_name_the_overlay_in_their_errors(knee, tmp_path, capsys):
    """A bad file named by an overlay's ``motion:`` or ``external_loads:`` was reported as
    if from the command line (``--motion: passwd: …``, ``passwd: not well-formed XML``),
    without the overlay; ``motion: null`` was read as no motion, and the run failed later
    for want of drivers. Each now names the overlay and the key."""
    from openfdk.cli import main

    (tmp_path / "not_a_motion.txt").write_text("root:x:0:0:root:/root:/bin/bash\n")
    cases = {"motion: not_a_motion.txt": "over.yaml: motion: not_a_motion.txt: no 'endheader' line",
             "motion: null": "over.yaml: motion: expected an existing .mot/.sto file, got None",
             "motion: knee.mot\nexternal_loads: not_a_motion.txt":
                 "over.yaml: external_loads: not_a_motion.txt: not well-formed XML"}
    _write_motion(tmp_path, {name: np.zeros(TIMES.size) for name in COORDINATES})
    for text, expected in cases.items():
        (tmp_path / "over.yaml").write_text(f"opensim: {knee / 'knee.osim'}\n{text}\n")
        code = main(["check", str(tmp_path / "over.yaml")])
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.startswith("openfdk: error:")]
        assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
        assert lines[0].startswith(f"openfdk: error: {expected}"), lines
