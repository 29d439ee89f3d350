"""``openfdk run MODEL.osim --motion ik.mot [--motion-cutoff HZ] --external-loads LOADS.xml``
against OpenSim 4.6's InverseDynamicsTool on the same files: the generalised forces of a
coordinate *file*, where the derivatives come from how each tool processes the samples
(OpenSim: padding, its third-order IIR filter and a natural quintic spline;
openfdk.io.opensim.coordinate_filter), not only from the dynamics
(tests/test_opensim_inverse_dynamics.py compares those on analytic trajectories).

The project's full-body model (23 coordinates, spline-coupled knees) moves along smooth
trajectories sampled at 100 Hz with 0.2° / 0.2 mm of noise, written in degrees, so the
filter and the spline matter: without the filter the noise differenced twice moves the
pelvis forces by hundreds of newtons, and a cubic spline instead of OpenSim's quintic
moves them by tens. Two ExternalForces load the feet. The two tools agree to 1e-6 of
each column's range (1e-6 N m at least) at every frame, the first and the last included.
"""

from __future__ import annotations

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.fixtures.full_body_osim import COORDINATES, write_full_body_osim  # noqa: E402
from openfdk.io.storage import read_storage, write_storage  # noqa: E402

RATE = 100.0
N = 61
TRANSLATIONS = ("pelvis_tx", "pelvis_ty", "pelvis_tz")


def _files(folder, rng):
    """The coordinate file (degrees) and the ExternalLoads file with its data."""
    times = np.round(np.arange(N) / RATE + 0.2, 10)
    columns = {}
    for name in COORDINATES:
        f, phi = rng.uniform(0.6, 1.4), rng.uniform(0, 2 * np.pi)
        if name in TRANSLATIONS:
            a = {"pelvis_tx": 0.1, "pelvis_ty": 0.95, "pelvis_tz": 0.02}[name]
            q = a + 0.03 * np.sin(2 * np.pi * f * times + phi) + rng.normal(0, 2e-4, N)
        else:
            a = -0.6 if name.startswith("knee_angle") else rng.uniform(-0.1, 0.1)
            q = np.degrees(a + rng.uniform(0.05, 0.25) * np.sin(2 * np.pi * f * times + phi)) + rng.normal(0, 0.2, N)
        columns[name] = q
    write_storage(folder / "ik.mot", times, columns, name="ik", in_degrees=True)
    t = np.round(np.arange(0, 0.85, 0.001), 10)  # 1 000 Hz, over the motion's times
    write_storage(folder / "loads.mot", t, {
        "g_vx": 80 * np.sin(3 * t), "g_vy": 700 + 50 * np.cos(2 * t), "g_vz": -30 + 10 * t,
        "g_px": 0.3 + 0.4 * t, "g_py": 0.0 * t, "g_pz": 0.1 - 0.05 * t,
        "g_tx": 0.0 * t, "g_ty": 5 * np.sin(4 * t), "g_tz": 0.0 * t,
        "b_vx": 20 + 5 * t, "b_vy": -40 * np.cos(t), "b_vz": 10 * np.sin(2 * t),
        "b_px": 0.05 + 0.0 * t, "b_py": -0.01 + 0.02 * t, "b_pz": 0.01 + 0.0 * t,
        "b_tx": 1.5 + 0.0 * t, "b_ty": -0.5 * t, "b_tz": 0.2 + 0.0 * t}, name="loads")
    forces = "".join(f"""
      <ExternalForce name="{name}">
        <applied_to_body>{body}</applied_to_body>
        <force_expressed_in_body>{frame}</force_expressed_in_body>
        <point_expressed_in_body>{frame}</point_expressed_in_body>
        <force_identifier>{p}_v</force_identifier>
        <point_identifier>{p}_p</point_identifier>
        <torque_identifier>{p}_t</torque_identifier>
      </ExternalForce>""" for name, body, frame, p in (("ground_reaction", "calcn_r", "ground", "g"),
                                                      ("pushing_hand", "talus_l", "talus_l", "b")))
    (folder / "loads.xml").write_text(f"""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <ExternalLoads name="loads">
    <objects>{forces}
    </objects>
    <datafile>loads.mot</datafile>
  </ExternalLoads>
</OpenSimDocument>
""")
    return folder / "ik.mot", folder / "loads.xml"


def _opensim_tool(model, motion, loads, cutoff, out):
    """OpenSim's InverseDynamicsTool over the motion's time range (wider, it would also
    report the samples its filter padded the file with): (times (n,), {column: (n,)}) of
    its generalised-force file."""
    tool = opensim.InverseDynamicsTool()
    osim_model = opensim.Model(str(model))  # referenced while the tool runs (the tool does not own it)
    tool.setModel(osim_model)
    tool.setCoordinatesFileName(str(motion))
    tool.setLowpassCutoffFrequency(cutoff)
    tool.setExternalLoadsFileName(str(loads))
    tool.setStartTime(0.2)
    tool.setEndTime(0.2 + (N - 1) / RATE)
    tool.setResultsDir(str(out))
    tool.setOutputGenForceFileName("id.sto")
    assert tool.run()
    times, columns, _ = read_storage(out / "id.sto")
    return times, columns


@pytest.mark.slow
@pytest.mark.parametrize("cutoff", [-1.0, 6.0])
def test_the_generalised_forces_of_a_coordinate_file_equal_opensims_tool(tmp_path, capsys, cutoff):
    rng = np.random.default_rng(11)
    model = write_full_body_osim(tmp_path / "full_body.osim")
    motion, loads = _files(tmp_path, rng)
    t_theirs, theirs = _opensim_tool(model, motion, loads, cutoff, tmp_path / "opensim")

    args = ["run", str(model), "--motion", str(motion), "--external-loads", str(loads), "--out",
            str(tmp_path / "ours"), "--no-plots", "-q"]
    if cutoff > 0:
        args += ["--motion-cutoff", str(cutoff)]
    code = main(args)
    assert code == 0, capsys.readouterr().err
    t_ours, ours, _ = read_storage(tmp_path / "ours" / "generalized_forces.sto")
    assert len(t_ours) == len(t_theirs) == N
    np.testing.assert_allclose(t_ours, t_theirs, atol=1e-9)
    for name in COORDINATES:
        key = f"{name}_force" if name in TRANSLATIONS else f"{name}_moment"
        scale = np.ptp(theirs[key])
        assert scale > 0.01, key  # a moving column (the toes' moments are the smallest)
        np.testing.assert_allclose(ours[key], theirs[key], atol=1e-6 * max(scale, 1.0), rtol=0, err_msg=key)
    # the filter matters: unfiltered, the noise moves the vertical residual by far more
    if cutoff > 0:
        assert np.ptp(theirs["pelvis_ty_force"]) < 2000.0
    else:
        assert np.ptp(theirs["pelvis_ty_force"]) > 2000.0


def test_check_with_a_coordinate_file_that_starts_late_and_a_model_without_markers(tmp_path, capsys):
    """Found on opensim-models' Gait2392 (its IK file starts at 0.5 s): ``openfdk check
    MODEL --motion FILE`` evaluated the drivers at t = 0 and failed, "spline driver
    evaluated at t = 0.0 s outside its data". It now checks at a time every driver
    covers. Without a motion or markers, an OpenSim model's check names --motion."""
    from lxml import etree

    model = write_full_body_osim(tmp_path / "full_body.osim")
    tree = etree.parse(str(model))
    for marker in tree.xpath("//MarkerSet/objects/Marker"):
        marker.getparent().remove(marker)
    bare = tmp_path / "no_markers.osim"
    tree.write(str(bare))
    code = main(["check", str(bare), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "no markers to track them: give a trial of the model's markers, or drive every " \
                         "coordinate from a coordinate file with --motion FILE" in err, err
    t = np.round(0.5 + np.arange(20) / RATE, 10)
    write_storage(tmp_path / "late.mot", t, {name: 0.01 * np.sin(t) + (0.95 if name == "pelvis_ty" else 0.0)
                                             for name in COORDINATES}, name="late", in_degrees=False)
    code = main(["check", str(bare), "--motion", str(tmp_path / "late.mot")])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "kinematics: determinate" in out.out


@pytest.mark.slow
def test_a_states_file_labelled_by_state_paths_drives_the_same_motion(tmp_path, capsys):
    """OpenSim 4 and Moco write coordinates as state variables, /jointset/<joint>/<coordinate>/value
    (Moco's example3DWalking coordinates.sto), next to their /speed columns. The same
    samples so labelled give the IK .mot's generalised forces exactly; the speeds are not
    used (the rates come from the spline, as OpenSim's tool takes them). OpenSim 4.6's
    InverseDynamicsTool does not read such labels: it logs that the file "does not contain
    coordinate 'pelvis_tilt'" and assumes every coordinate at its default value."""
    rng = np.random.default_rng(11)
    model = write_full_body_osim(tmp_path / "full_body.osim")
    motion, loads = _files(tmp_path, rng)
    times, columns, in_degrees = read_storage(motion)
    osim_model = opensim.Model(str(model))
    joint = {name: osim_model.getCoordinateSet().get(name).getJoint().getName() for name in columns}
    states = {}
    for name, values in columns.items():
        states[f"/jointset/{joint[name]}/{name}/value"] = values
        states[f"/jointset/{joint[name]}/{name}/speed"] = np.full_like(values, 1e6)
    write_storage(tmp_path / "states.sto", times, states, name="states", in_degrees=in_degrees)
    assert opensim.TimeSeriesTable(str(tmp_path / "states.sto")).getNumColumns() == 2 * len(columns)
    results = {}
    for label, path in (("mot", motion), ("states", tmp_path / "states.sto")):
        code = main(["run", str(model), "--motion", str(path), "--external-loads", str(loads), "--out",
                     str(tmp_path / label), "--no-plots", "-q"])
        assert code == 0, capsys.readouterr().err
        results[label] = read_storage(tmp_path / label / "generalized_forces.sto")[1]
    assert results["mot"].keys() == results["states"].keys()
    for key, values in results["mot"].items():
        np.testing.assert_array_equal(results["states"][key], values, err_msg=key)
    both = {**{f"/jointset/{joint['knee_angle_r']}/knee_angle_r/value": columns["knee_angle_r"]}, **columns}
    write_storage(tmp_path / "both.sto", times, both, name="both", in_degrees=in_degrees)
    code = main(["run", str(model), "--motion", str(tmp_path / "both.sto"), "--out", str(tmp_path / "b"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and (f"both.sto: coordinate 'knee_angle_r' is given twice, by columns "
                          f"'/jointset/{joint['knee_angle_r']}/knee_angle_r/value' and 'knee_angle_r'") in err, err
