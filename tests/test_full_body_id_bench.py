"""The full-body inverse dynamics benchmark (openfdk.bench.full_body_id) and its inputs
(openfdk.fixtures.full_body_osim: the coordinate file and the two force plates' ground
reactions): ``openfdk bench --only full_body_id`` reports its figures, the coordinate
file holds the motion in OpenSim's IK output layout, and the ground reactions are a
plausible walk (body weight on average, double hump, shear, centre of pressure heel to
toe, free torque, nothing in swing). No timing is asserted here (targets live in the
benchmark)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from openfdk.fixtures.full_body_osim import (
    COORDINATES,
    GAIT_PERIOD_S,
    body_mass,
    full_body_coordinates,
    write_full_body_grf,
    write_full_body_motion,
    write_full_body_osim,
)
from openfdk.io.storage import read_storage

FIGURES = {"full_body_inverse_dynamics_ms", "full_body_id_vs_opensim", "full_body_id_max_diff_nm"}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("full_body_id")
    model = write_full_body_osim(folder / "full_body.osim")
    grf_times = np.arange(2200) / 1000.0  # two gait cycles at 1 kHz
    xml, mot = write_full_body_grf(model, folder, grf_times)
    motion = write_full_body_motion(folder, np.arange(220) / 100.0)
    return model, xml, mot, motion


def _foot(columns, prefix):
    f = np.column_stack([columns[f"{prefix}ground_force_v{c}"] for c in "xyz"])
    p = np.column_stack([columns[f"{prefix}ground_force_p{c}"] for c in "xyz"])
    t = np.column_stack([columns[f"{prefix}ground_torque_{c}"] for c in "xyz"])
    return f, p, t


def test_vertical_force_averages_body_weight_with_a_double_hump(inputs):
    _, _, mot, _ = inputs
    t, columns, in_degrees = read_storage(mot)
    assert not in_degrees
    weight = body_mass() * 9.80665
    assert 60 < body_mass() < 80
    right, left = _foot(columns, ""), _foot(columns, "1_")
    cycle = t < GAIT_PERIOD_S - 1e-9
    total = right[0][:, 1] + left[0][:, 1]
    # the two plates' mean vertical force over a gait cycle: the body weight
    mean = np.trapezoid(total[cycle], t[cycle]) / (t[cycle][-1] - t[cycle][0])
    assert abs(mean / weight - 1.0) < 0.2, mean / weight
    assert abs(total[cycle].mean() / weight - 1.0) < 0.02
    for force, point, torque in (right, left):
        loaded = force[:, 1] > 1e-9
        # stance: ≈ 60 % of the cycle; swing: every column zero
        assert 0.55 < loaded[cycle].mean() < 0.65
        assert np.all(force[~loaded] == 0) and np.all(point[~loaded] == 0) and np.all(torque[~loaded] == 0)
        assert np.all(force[:, 1] >= 0)
        # double hump: two peaks of 1.0-1.3 BW with a mid-stance valley of 0.6-0.9 BW
        first = np.flatnonzero(loaded & cycle)
        runs = np.split(first, np.flatnonzero(np.diff(first) > 1) + 1)
        stance = max(runs, key=len)
        fy = force[stance, 1] / weight
        n = len(fy)
        peak1, valley, peak2 = fy[: n // 3].max(), fy[n // 3: 2 * n // 3].min(), fy[2 * n // 3:].max()
        assert min(peak1, peak2) > 1.0 and max(peak1, peak2) < 1.3 and 0.6 < valley < 0.9, (peak1, valley, peak2)
        # fore-aft shear: braking (backward, −x) then propulsion, about 0.2 BW, no net impulse
        fx = force[stance, 0] / weight
        assert fx[: n // 2].mean() < -0.05 and fx[n // 2:].mean() > 0.05 and 0.1 < np.abs(fx).max() < 0.3
        # free torque about the vertical only, a few N m; the plate's surface is y = 0
        assert np.all(torque[:, [0, 2]] == 0) and 1.0 < np.abs(torque[:, 1]).max() < 10.0
        assert np.all(point[:, 1] == 0)
    # medio-lateral shear towards the midline: −z under the right foot, +z under the left
    assert right[0][:, 2].min() < 0 <= right[0][:, 2].max() + 1e-12 and right[0][:, 2].max() <= 1e-12
    assert left[0][:, 2].max() > 0 and left[0][:, 2].min() >= -1e-12


def test_centre_of_pressure_runs_heel_to_toe_under_the_foot(inputs):
    """In each stance the centre of pressure, seen along the calcaneus's heel-to-mtp line
    projected on the ground, goes from the heel to the metatarsal heads, monotonically."""
    from openfdk.io.opensim.document import read_document
    from openfdk.io.opensim.tree import Tree

    model, _, mot, _ = inputs
    t, columns, _ = read_storage(mot)
    tree = Tree(read_document(model))
    q = full_body_coordinates(t)
    for side, prefix in (("r", ""), ("l", "1_")):
        force, point, _ = _foot(columns, prefix)
        loaded = np.flatnonzero(force[:, 1] > 1e-9)
        stance = max(np.split(loaded, np.flatnonzero(np.diff(loaded) > 1) + 1), key=len)
        z = 1.0 if side == "r" else -1.0
        heel_B, toe_B = np.array([-0.02, 0.0, 0.0]), np.array([0.176, 0.0, 0.0012 * z])
        along = []
        for k in stance[::10]:
            p_WB, R_WB = tree.body_pose(f"calcn_{side}", tree.poses({n: float(q[n][k]) for n in q}))
            heel, toe = p_WB + R_WB @ heel_B, p_WB + R_WB @ toe_B
            axis = (toe - heel)[[0, 2]]
            along.append(float(np.dot(point[k, [0, 2]] - heel[[0, 2]], axis) / np.dot(axis, axis)))
        along = np.array(along)
        assert along[0] < 0.1 and along[-1] > 0.9 and np.all(np.diff(along) > 0), along.round(3)


def test_coordinate_file_is_the_motion_in_degrees_and_openfdk_reads_the_inputs(inputs, capsys):
    from openfdk.cli import main

    model, xml, _, motion = inputs
    t, columns, in_degrees = read_storage(motion)
    assert in_degrees and list(columns) == list(COORDINATES)
    assert motion.read_text().startswith("Coordinates\nversion=1\nnRows=220\nnColumns=24\ninDegrees=yes\n")
    q = full_body_coordinates(t)
    for name in COORDINATES:
        expected = q[name] if name in ("pelvis_tx", "pelvis_ty", "pelvis_tz") else np.degrees(q[name])
        np.testing.assert_allclose(columns[name], expected, rtol=0, atol=1e-12)
    code = main(["check", str(model), "--external-loads", str(xml), "--motion", str(motion)])
    assert code == 0, capsys.readouterr().err


def test_opensim_reads_the_external_loads_as_written(inputs):
    """OpenSim's ExternalLoads reader finds both forces, on the calcanei, in the ground,
    with the file's columns."""
    osim = pytest.importorskip("opensim")
    model_path, xml, _, _ = inputs
    osim.Logger.setLevelString("warn")
    loads = osim.ExternalLoads(str(xml), True)
    assert loads.getSize() == 2
    found = {}
    for i in range(loads.getSize()):
        f = loads.get(i)
        found[f.getName()] = (f.get_applied_to_body(), f.get_force_expressed_in_body(), f.get_point_expressed_in_body(),
                              f.get_force_identifier(), f.get_point_identifier(), f.get_torque_identifier())
    assert found == {"right": ("calcn_r", "ground", "ground", "ground_force_v", "ground_force_p", "ground_torque_"),
                     "left": ("calcn_l", "ground", "ground", "1_ground_force_v", "1_ground_force_p",
                              "1_ground_torque_")}
    model = osim.Model(str(model_path))
    tool = osim.InverseDynamicsTool()
    tool.createExternalLoads(str(xml), model)  # as InverseDynamicsTool.run() adds them
    model.initSystem()
    applied = sorted(c.getAbsolutePathString() for c in model.getComponentsList()
                     if c.getConcreteClassName() == "ExternalForce")
    assert applied == ["/componentset/externalloads/left", "/componentset/externalloads/right"]


def test_bench_quick_json_prints_the_figures(capsys):
    from openfdk.cli import main

    assert main(["bench", "--only", "full_body_id", "--quick", "--json"]) == 0
    records = {r["name"]: r for r in (json.loads(x) for x in capsys.readouterr().out.splitlines()
                                      if x.startswith("{"))}
    assert set(records) == FIGURES
    assert records["full_body_inverse_dynamics_ms"]["value"] > 0
    try:
        import opensim  # noqa: F401
    except ImportError:
        for name in FIGURES - {"full_body_inverse_dynamics_ms"}:
            assert "not installed" in records[name]["note"]
    else:
        ratio, diff = records["full_body_id_vs_opensim"], records["full_body_id_max_diff_nm"]
        assert ratio["value"] > 0 and ratio["target"] == 0.5
        assert ratio["loop_vs_tool_nm"] < 1e-6  # the timed loop computes what the tool writes
        # the two spline interpolations differ, most at the ends; not dynamics errors
        assert 0 < diff["interior_nm"] < 1.0 and np.isfinite(diff["value"])
        assert diff["openfdk_vs_exact_interior_nm"] < 1.0 and diff["opensim_vs_exact_interior_nm"] < 0.1


def test_bench_without_opensim_skips_the_comparison_with_a_note(tmp_path, monkeypatch):
    from openfdk.bench import full_body_id

    full_body_id.write_inputs(tmp_path, quick=True)
    monkeypatch.setattr(full_body_id, "opensim_available", lambda: False)
    records = {r["name"]: r for r in full_body_id.measure(tmp_path, quick=True)}
    assert set(records) == FIGURES
    assert records["full_body_inverse_dynamics_ms"]["value"] > 0
    for name in ("full_body_id_vs_opensim", "full_body_id_max_diff_nm"):
        assert np.isnan(records[name]["value"]) and "opensim" in records[name]["note"]
