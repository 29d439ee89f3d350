"""The bench's full-body model with 92 muscles (openfdk.fixtures.full_body_muscles,
``write_full_body_osim(muscles=True)``) against OpenSim 4.6, and the benchmark
openfdk.bench.full_body_muscles: OpenSim loads the file without a warning, openfdk
imports it, and the 92 path lengths and some moment arms are OpenSim's at two poses of
the walk. No timing is asserted here (targets live in the benchmark)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from openfdk.fixtures.full_body_muscles import muscle_table
from openfdk.fixtures.full_body_osim import full_body_coordinates, write_full_body_osim

FIGURES = {"full_body_paths_us", "full_body_recruitment_ms", "full_body_joint_loads_ms", "full_body_so_vs_opensim",
           "view_full_body_60s_build_s"}
POSE_TIMES = (0.25, 0.8)  # s of the walk; no conditional point is within 0.02 rad of its range's end there
#: (muscle, coordinate): a plain, a conditional, a wrapped and a trunk muscle
MOMENT_ARMS = [("glut_med1_r", "hip_adduction_r"), ("semimem_r", "knee_angle_r"), ("semimem_r", "hip_flexion_r"),
               ("psoas_r", "hip_flexion_r"), ("med_gas_l", "ankle_angle_l"), ("med_gas_l", "knee_angle_l"),
               ("ercspn_l", "lumbar_extension"), ("tib_ant_r", "subtalar_angle_r")]
#: muscles over the moving patella point: compared with OpenSim's −∂l/∂q (its computeMomentArm
#: of a MovingPathPoint leaves out the point's motion, tests/test_opensim_muscles.py)
MOVING_ARMS = [("rect_fem_r", "knee_angle_r"), ("vas_lat_l", "knee_angle_l")]


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    return write_full_body_osim(tmp_path_factory.mktemp("full_body_muscles") / "full_body.osim", muscles=True)


def test_model_has_the_issue_s_elements(model_path):
    """92 muscles (43 per leg, 6 of the trunk), conditional and moving points, 4 wrap
    cylinders and a CoordinateActuator on each of the 23 coordinates, read from the file."""
    from openfdk.io.opensim.document import read_document

    text = model_path.read_text()
    assert text.count("<Thelen2003Muscle ") == 92
    assert text.count("<ConditionalPathPoint ") == 20 and text.count("<MovingPathPoint ") == 8
    assert text.count("<WrapCylinder ") == 4 and text.count("<PathWrap ") == 8
    assert text.count("<CoordinateActuator ") == 23
    doc = read_document(model_path)
    assert len(doc.markers) == 40
    legs = [m for m in muscle_table() if m.endswith("_r") and not m.startswith(("ercspn", "intobl", "extobl"))]
    assert len(legs) == 43
    # positive tendon slack lengths, strengths and fibre lengths of adult muscles
    table = muscle_table()
    assert all(0.005 < float(v) for v in
               [line.split(">")[1].split("<")[0] for line in text.splitlines() if "<tendon_slack_length>" in line])
    assert all(0.02 <= lopt <= 0.6 and 100 <= f0 <= 3000 for f0, lopt, _, _, _ in table.values())


def test_openfdk_check_reads_the_model(model_path, capsys):
    from openfdk.cli import main

    assert main(["check", str(model_path)]) == 0, capsys.readouterr().err
    assert "muscles: 92" in capsys.readouterr().out


def test_paths_and_moment_arms_equal_opensim(model_path):
    """At two poses of the walk: every straight or conditional/moving path length equal to
    OpenSim's within 1e-7 m, the 8 wrapped ones within 1e-5 relative (OpenSim's cylinder
    path is the longer, docs/opensim-import.md "Wrapping"); moment arms −∂l/∂q (openfdk's
    analytic Jacobian) against ``computeMomentArm``, 1e-6 m (1e-4 m wrapped: OpenSim's
    tangent points are not quite tangent), and for the patella-point muscles against a
    central difference of OpenSim's length (1e-6 m). OpenSim loads the file with no
    warning."""
    osim = pytest.importorskip("opensim")
    from openfdk.io.opensim import read_osim
    from openfdk.io.modelfile import model_from_dict
    from openfdk.kinematics.coordinate_pose import pose_from_coordinates

    sink = osim.StringLogSink()
    osim.Logger.addSink(sink)
    level = osim.Logger.getLevelString()
    osim.Logger.setLevelString("warn")
    try:
        theirs = osim.Model(str(model_path))
        state = theirs.initSystem()
        logged = sink.getString()
    finally:
        osim.Logger.setLevelString(level)
        osim.Logger.removeSink(sink)
    assert logged == ""
    data, _ = read_osim(model_path)
    ours = model_from_dict(data, source=str(model_path))
    by_name = {m.name: m for m in ours.muscles}
    coords = {theirs.getCoordinateSet().get(i).getName(): theirs.getCoordinateSet().get(i)
              for i in range(theirs.getCoordinateSet().getSize())}
    muscles = {theirs.getMuscles().get(i).getName(): theirs.getMuscles().get(i)
               for i in range(theirs.getMuscles().getSize())}
    assert sorted(by_name) == sorted(muscles) and len(muscles) == 92
    table = muscle_table()
    walk = full_body_coordinates(np.array(POSE_TIMES))
    wrapped_engaged = 0
    for k in range(len(POSE_TIMES)):
        q = {n: float(v[k]) for n, v in walk.items()}
        for name, c in coords.items():
            c.setValue(state, q[name], False)
        theirs.realizePosition(state)
        st, _ = pose_from_coordinates(ours, q)
        for name, m in by_name.items():
            l_ours = float(np.ravel(m.path.evaluate(st, 0)[0])[0])
            l_theirs = muscles[name].getLength(state)
            if table[name][4] is None:
                assert abs(l_ours - l_theirs) <= 1e-7, (name, k, l_ours, l_theirs)
            else:
                assert abs(l_ours - l_theirs) <= 1e-5 * l_theirs, (name, k, l_ours, l_theirs)
                wrapped_engaged += muscles[name].getGeometryPath().getCurrentPath(state).getSize() > 2
        for name, coordinate in MOMENT_ARMS + MOVING_ARMS:
            st_v, _ = pose_from_coordinates(ours, q, qdot={coordinate: 1.0})
            _, L, _ = by_name[name].path.evaluate(st_v, 1)
            r_ours = -float(np.ravel(np.asarray(L) @ st_v.get_v())[0])
            if (name, coordinate) in MOVING_ARMS:
                h, c = 1e-6, coords[coordinate]
                c.setValue(state, q[coordinate] + h, False)
                theirs.realizePosition(state)
                plus = muscles[name].getLength(state)
                c.setValue(state, q[coordinate] - h, False)
                theirs.realizePosition(state)
                r_theirs = -(plus - muscles[name].getLength(state)) / (2 * h)
                c.setValue(state, q[coordinate], False)
                theirs.realizePosition(state)
            else:
                r_theirs = muscles[name].computeMomentArm(state, coords[coordinate])
            tol = 1e-4 if table[name][4] else 1e-6
            assert abs(r_ours - r_theirs) <= tol, (name, coordinate, k, r_ours, r_theirs)
            assert abs(r_theirs) > 1e-3  # the muscle crosses that joint
    assert wrapped_engaged >= 4  # the wraps are in contact at these poses, not only lifted off


def test_capsule_mesh_is_closed_with_the_capsule_s_volume(tmp_path):
    """The viewer bench's capsule STL: every edge shared by two triangles, the enclosed
    volume (divergence theorem) that of a cylinder plus a sphere, πr²L + 4πr³/3, within the
    polygon's deficit (< 2 %), outward normals (positive volume)."""
    from openfdk.bench.full_body_muscles import capsule, write_stl
    from openfdk.contact.stl import read_stl

    r, a, b = 0.03, np.array([0.0, 0.0, 0.0]), np.array([0.01, -0.38, 0.02])
    v, f = read_stl(write_stl(tmp_path / "c.stl", *capsule(a, b, r)))
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    tri = v[f]
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
    exact = np.pi * r ** 2 * np.linalg.norm(b - a) + 4.0 / 3.0 * np.pi * r ** 3
    assert 0.98 * exact < volume < exact


@pytest.mark.slow
def test_bench_quick_json_prints_the_figures(capsys):
    from openfdk.cli import main

    assert main(["bench", "--only", "full_body_muscles", "--quick", "--json"]) == 0
    records = {r["name"]: r for r in (json.loads(x) for x in capsys.readouterr().out.splitlines()
                                      if x.startswith("{"))}
    assert set(records) == FIGURES
    assert records["full_body_paths_us"]["value"] > 0 and records["full_body_recruitment_ms"]["value"] > 0
    assert records["full_body_joint_loads_ms"]["value"] > 0
    view = records["view_full_body_60s_build_s"]
    assert view["value"] > 0 and view["file_mb"] > 0.1 and view["frames"] == 500
    try:
        import opensim  # noqa: F401
    except ImportError:
        assert "not installed" in records["full_body_so_vs_opensim"]["note"]
    else:
        ratio = records["full_body_so_vs_opensim"]
        assert ratio["value"] > 0 and ratio["target"] == 0.1
        assert ratio["loop_vs_tool_n"] < 1e-6  # the timed loop computes what the tool writes
        # the two programs' splines differ at the ends; OpenSim's IPOPT stops at 1e-4
        assert 0 <= ratio["interior_muscle_diff_n"] <= ratio["max_muscle_diff_n"] < 100
