"""joint_loads.csv/.sto (the load each joint transmits to its child body) against
OpenSim 4.6's own joint reactions, and against Newton–Euler on each body.

The project's full-body model (12 bodies, 23 coordinates, spline-coupled knees, oblique
ankle axes) moves along the analytic trajectories of test_opensim_inverse_dynamics, with
its two external forces. OpenSim gets q, q̇ at each sample time, its
InverseDynamicsSolver's generalised forces τ applied by a CoordinateActuator on every
coordinate (so that its forward dynamics reproduce q̈: checked), and
``Joint::calcReactionOnChildExpressedInGround`` (what OpenSim's JointReaction analysis
reports with its defaults) gives each joint's force and moment on the child at the
child frame's origin, in the ground. openfdk runs the same motion two ways: the
coordinates driven (inverse dynamics, the drivers carry τ), and with an OpenSim actuator
file of one CoordinateActuator per coordinate (static optimisation: the actuators carry
τ, the drivers nothing). Then the loads OpenSim books as generalised forces on a
coordinate: a muscle's moving path point (the project's 92-muscle model) and a coordinate
coupler (a patella coupled to the knee), OpenSim given openfdk's forces.
"""

from __future__ import annotations

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.fixtures.full_body_osim import COORDINATES, write_full_body_osim  # noqa: E402
from openfdk.io.results import read_table  # noqa: E402
from test_opensim_inverse_dynamics import (N, RATE, _loads, _motion, _overlay, _q,  # noqa: E402
                                           coordinate_actuators, mobility_slots, opensim_model_with_loads,
                                           set_motion)

COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz", "px", "py", "pz")


def _opensim_reactions(model_path, loads_xml, motion, times, reports=()):
    """({joint: (n, 9) [F, M, p] on the child at its frame's origin, in the ground},
    {joint: child body name}, largest |q̈_forward − q̈| (rad/s², m/s²)); with ``reports``
    [(joint, "child" or "parent", frame: "ground", "child", "parent" or a body)], instead
    of the first {OpenSim's column label base: (n, 9)} of each, computed as OpenSim's
    JointReaction analysis does with those options."""
    model, _data = opensim_model_with_loads(model_path, loads_xml) if loads_xml else (opensim.Model(str(model_path)), 0)
    cs = model.getCoordinateSet()
    names = [cs.get(i).getName() for i in range(cs.getSize())]
    actuators = coordinate_actuators(model, names)
    state = model.initSystem()
    coords = [cs.get(n) for n in names]
    slot = mobility_slots(state, coords)
    solver = opensim.InverseDynamicsSolver(model)
    joints = model.getJointSet()
    out = {joints.get(i).getName(): [] for i in range(joints.getSize())}
    child = {joints.get(i).getName(): joints.get(i).getChildFrame().findBaseFrame().getName()
             for i in range(joints.getSize())}
    worst = 0.0
    for t in times:
        set_motion(model, state, coords, names, motion, t)
        for a in actuators.values():
            a.overrideActuation(state, False)
        model.realizeVelocity(state)
        udot = opensim.Vector(len(names), 0.0)
        for n in names:
            udot.set(slot[n], _q(motion[n], t, 2))
        tau = solver.solve(state, udot)  # the actuators' forces are not applied: control 0
        for n, a in actuators.items():
            a.overrideActuation(state, True)
            a.setOverrideActuation(state, tau.get(slot[n]))
        model.realizeAcceleration(state)
        worst = max(worst, max(abs(state.getUDot().get(slot[n]) - _q(motion[n], t, 2)) for n in names))
        for i in range(joints.getSize()):
            j = joints.get(i)
            load = j.calcReactionOnChildExpressedInGround(state)
            p = j.getChildFrame().getPositionInGround(state)
            out[j.getName()].append([load.get(1).get(k) for k in range(3)] + [load.get(0).get(k) for k in range(3)]
                                    + [p.get(k) for k in range(3)])
        for name, on, frame in reports:
            out.setdefault(_opensim_label(model, name, on, frame), []).append(
                _opensim_report(model, state, joints.get(name), on, frame))
    out = {k: np.array(v) for k, v in out.items()}
    if reports:
        out = {_opensim_label(model, *r): out[_opensim_label(model, *r)] for r in reports}
    return out, child, worst


def _opensim_frame(model, joint, frame):
    """The OpenSim Frame a report is expressed in (JointReaction's express_in_frame)."""
    if frame == "child":
        return joint.getChildFrame().findBaseFrame()
    if frame == "parent":
        return joint.getParentFrame().findBaseFrame()
    if "/" in frame:  # a joint's frame, by its path in the JointSet
        return opensim.Frame.safeDownCast(model.getComponent(f"/jointset/{frame}"))
    return model.getGround() if frame == "ground" else model.getBodySet().get(frame)


def _opensim_label(model, name, on, frame):
    joint = model.getJointSet().get(name)
    body = (joint.getChildFrame() if on == "child" else joint.getParentFrame()).findBaseFrame().getName()
    return f"{name}_on_{body}_in_{_opensim_frame(model, joint, frame).getName()}"


def _opensim_report(model, state, joint, on, frame):
    """[F, M, p] (9,) of one joint as JointReaction reports it: OpenSim's reaction on the
    body, about that side's joint frame origin, the three vectors in ``frame``."""
    ground, target = model.getGround(), _opensim_frame(model, joint, frame)
    if on == "child":
        load, origin = joint.calcReactionOnChildExpressedInGround(state), joint.getChildFrame()
    else:
        load, origin = joint.calcReactionOnParentExpressedInGround(state), joint.getParentFrame()
    F = ground.expressVectorInAnotherFrame(state, load.get(1), target)
    M = ground.expressVectorInAnotherFrame(state, load.get(0), target)
    p = ground.findStationLocationInAnotherFrame(state, origin.getPositionInGround(state), target)
    return [v.get(k) for v in (F, M, p) for k in range(3)]


def _actuator_file(path):
    """An OpenSim actuator file: one CoordinateActuator of optimal force 1 per coordinate."""
    body = "".join(f'<CoordinateActuator name="tau_{n}"><coordinate>{n}</coordinate><optimal_force>1</optimal_force>'
                   "<min_control>-Inf</min_control><max_control>Inf</max_control></CoordinateActuator>"
                   for n in COORDINATES)
    path.write_text('<?xml version="1.0"?>\n<OpenSimDocument Version="40000"><ForceSet name="tau"><objects>'
                    f"{body}</objects></ForceSet></OpenSimDocument>\n")
    return path


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """The model, the motion's sample times and OpenSim's reactions."""
    folder = tmp_path_factory.mktemp("joint_loads")
    model = write_full_body_osim(folder / "full_body.osim")
    times = np.arange(N) / RATE + 0.2
    motion = _motion(np.random.default_rng(7))
    loads = _loads(folder, times)
    overlay = _overlay(folder, motion, times)
    theirs, child, worst = _opensim_reactions(model, loads, motion, times)
    assert worst < 1e-8, worst  # OpenSim's forward dynamics with τ reproduce the motion
    return folder, model, overlay, loads, times, theirs, child


def _compare(ours, theirs, child):
    """Largest difference of the forces (N), moments (N m) and points (m), and the
    largest force and moment magnitudes of OpenSim's (that the case has real loads)."""
    worst = np.zeros(3)
    for joint, values in theirs.items():
        cols = np.column_stack([ours[f"{joint}_on_{child[joint]}_in_ground_{c}"] for c in COMPONENTS])
        for k in range(3):
            worst[k] = max(worst[k], float(np.max(np.abs(cols[:, 3 * k:3 * k + 3] - values[:, 3 * k:3 * k + 3]))))
    peak_F = max(float(np.max(np.abs(v[:, :3]))) for v in theirs.values())
    peak_M = max(float(np.max(np.abs(v[:, 3:6]))) for v in theirs.values())
    return worst, peak_F, peak_M


@pytest.mark.slow
@pytest.mark.parametrize("how", ["drivers", "actuators"])
def test_joint_loads_equal_opensims_joint_reactions(case, how, capsys):
    folder, model, overlay, loads, times, theirs, child = case
    out = folder / how
    args = ["run", str(model), "--with", str(overlay), "--external-loads", str(loads), "--out", str(out),
            "--no-plots", "-q"]
    if how == "actuators":
        args += ["--actuators", str(_actuator_file(folder / "tau.xml"))]
    assert main(args) == 0, capsys.readouterr().err
    ours = read_table(out / "joint_loads.csv")
    np.testing.assert_allclose(ours["time"], times, atol=1e-12)
    assert len(ours) == 1 + 9 * len(theirs)
    (dF, dM, dp), peak_F, peak_M = _compare(ours, theirs, child)
    print(how, "largest differences: force", dF, "N, moment", dM, "N m, point", dp, "m")
    assert peak_F > 500.0 and peak_M > 100.0  # real loads
    assert dF < 1e-6 * peak_F and dM < 1e-6 * peak_M and dp < 1e-9, (dF, dM, dp)

    # the .sto reads in OpenSim with the same labels and numbers
    table = opensim.TimeSeriesTable(str(out / "joint_loads.sto"))
    labels = list(table.getColumnLabels())
    assert labels == [k for k in ours if k != "time"]
    col = table.getDependentColumn("knee_r_on_tibia_r_in_ground_fy").to_numpy()
    np.testing.assert_allclose(col, ours["knee_r_on_tibia_r_in_ground_fy"], rtol=1e-8)  # both files print 10 digits or more

    import json

    from openfdk.plots.run import figure_plan
    from openfdk.results.run import read_results

    results = read_results(out)  # Python reads the folder's joint loads, and draws them
    np.testing.assert_array_equal(results.joint_loads["knee_r_on_tibia_r_in_ground_fx"].to_numpy(),
                                  ours["knee_r_on_tibia_r_in_ground_fx"])
    assert "joint_loads" in [name for name, _, _ in figure_plan(results)]
    summary = json.loads((out / "summary.json").read_text())["joint_loads"]
    F = np.column_stack([theirs["knee_r"][:, k] for k in range(3)])
    knee = np.linalg.norm(F, axis=1)
    assert summary["joints"]["knee_r"]["peak_N"] == pytest.approx(knee.max(), rel=1e-6)
    assert summary["joints"]["knee_r"]["peak_BW"] == pytest.approx(knee.max() / summary["body_weight_N"], rel=1e-12)
    assert summary["joints"]["knee_r"]["time_s"] == pytest.approx(times[int(np.argmax(knee))])


def test_python_api_gives_the_same_joint_loads(case):
    """openfdk.run (the Python API) computes the joint loads in memory: the same numbers
    as OpenSim's, and the same summary."""
    import openfdk
    from openfdk.io.opensim.overlay import register

    folder, model, overlay, loads, times, theirs, child = case
    register(str(model), overlay=overlay, external_loads=loads)
    result = openfdk.run(str(model))
    ours = {"time": result.joint_loads.index.to_numpy(), **{k: v.to_numpy() for k, v in result.joint_loads.items()}}
    (dF, dM, dp), peak_F, _ = _compare(ours, theirs, child)
    assert dF < 1e-6 * peak_F and dp < 1e-9, (dF, dM, dp)
    assert result.summary["joint_loads"]["joints"]["knee_r"]["peak_N"] > 100.0


@pytest.mark.slow
def test_joint_loads_balance_each_body(case, capsys):
    """Newton on every body, openfdk alone: the load from its parent joint, minus the
    loads it passes to its child joints, plus gravity and the external forces on it,
    equals m a of its centre of mass, at every frame."""
    folder, model, overlay, loads, times, _, _ = case
    out = folder / "balance"
    assert main(["run", str(model), "--with", str(overlay), "--external-loads", str(loads), "--out", str(out),
                 "--no-plots", "-q"]) == 0, capsys.readouterr().err
    from openfdk.io.modelfile import load_model
    from openfdk.numerics.spatial import rotation_matrix

    ours = read_table(out / "joint_loads.csv")
    kin = read_table(out / "kinematics.csv")
    fdk_model = load_model(model)
    t = np.asarray(times)
    external = {"calcn_r": np.column_stack([80 * np.sin(3 * t), 700 + 50 * np.cos(2 * t), -30 + 10 * t])}
    quat = np.column_stack([kin[f"talus_l.e{k}"] for k in range(4)])
    F_body = np.column_stack([20 + 5 * t, -40 * np.cos(t), 10 * np.sin(2 * t)])
    external["talus_l"] = np.array([rotation_matrix(q) @ f for q, f in zip(quat, F_body)])
    joints = {j.name: (fdk_model.frame(j.parent).body if j.parent else "ground", fdk_model.frame(j.child).body)
              for j in fdk_model.joints}
    worst, scale = 0.0, 0.0
    for b in fdk_model.moving_bodies:
        total = b.mass * fdk_model.gravity_W + external.get(b.name, 0.0)
        for name, (parent, child) in joints.items():
            F = np.column_stack([ours[f"{name}_on_{child}_in_ground_f{c}"] for c in "xyz"])
            if child == b.name:
                total = total + F
            elif parent == b.name:
                total = total - F
            else:
                continue
            scale = max(scale, float(np.max(np.abs(F))))
        ma = b.mass * np.column_stack([kin[f"{b.name}.a{c}_m_s2"] for c in "xyz"])
        worst = max(worst, float(np.max(np.abs(total - ma))))
    assert scale > 500.0  # the joints carry real loads
    assert worst <= 1e-8 * scale, worst

    # the viewer draws them: an arrow per joint at its centre, the force on the child
    from openfdk.viewer import view_data
    from openfdk.viewer.pack import unpack

    data, _ = view_data(out)
    drawn = {j["name"]: j for j in data["frames"]["joint_loads"]}
    assert set(drawn) == set(joints)
    F = unpack(drawn["knee_r"]["force"]).astype(float).reshape(-1, 3)
    P = unpack(drawn["knee_r"]["cop"]).astype(float).reshape(-1, 3)
    np.testing.assert_allclose(F[:, 1], ours["knee_r_on_tibia_r_in_ground_fy"], rtol=1e-6)
    np.testing.assert_allclose(P[:, 0], ours["knee_r_on_tibia_r_in_ground_px"], rtol=1e-6)
    peak = max(float(np.max(np.linalg.norm(np.column_stack([ours[f"{n}_on_{c}_in_ground_f{a}"] for a in "xyz"]),
                                           axis=1))) for n, (_, c) in joints.items())
    assert data["frames"]["arrow_scale"]["joint_load"]["fmax"] == pytest.approx(peak, rel=1e-6)


@pytest.mark.slow
def test_joint_loads_with_muscles_equal_opensims(tmp_path, capsys):
    """The full-body model with its 92 muscles (the quadriceps over a MovingPathPoint,
    conditional points, wrapping cylinders) and a CoordinateActuator on every coordinate,
    static optimisation over the same motion. OpenSim gets openfdk's tensions and
    actuator forces (overridden), reproduces the motion's accelerations from them (the
    recruited forces balance the motion: checked to 1e-3 rad/s², the CSV's rounding) and its joint reactions equal
    openfdk's joint loads, the knees' moments too: the part of the quadriceps' load that
    comes from the moving patella point is a generalised force on the knee angle in
    OpenSim, and openfdk counts it in the knee."""
    import re

    model = write_full_body_osim(tmp_path / "muscles.osim", muscles=True)
    # straight paths: OpenSim's wrapping and openfdk's differ in their moment arms by
    # ~1e-5 (docs/muscles.md), which OpenSim's forward dynamics would turn into
    # accelerations other than the motion's; the moving and conditional points stay
    text = model.read_text()
    model.write_text(re.sub(r"<PathWrapSet>.*?</PathWrapSet>", "<PathWrapSet><objects /></PathWrapSet>", text,
                            flags=re.S))
    times = np.arange(N) / RATE + 0.2
    motion = _motion(np.random.default_rng(7))
    loads = _loads(tmp_path, times)
    overlay = _overlay(tmp_path, motion, times)
    text = overlay.read_text() + "recruitment: {power: 2, static_optimization: opensim}\n"
    overlay.write_text(text)
    out = tmp_path / "so"
    assert main(["run", str(model), "--with", str(overlay), "--external-loads", str(loads), "--out", str(out),
                 "--no-plots", "-q"]) == 0, capsys.readouterr().err
    forces = read_table(out / "forces.csv")
    ours = read_table(out / "joint_loads.csv")
    assert np.all(forces["converged"] == 1)

    osim, _data = opensim_model_with_loads(model, loads)
    state = osim.initSystem()
    cs = osim.getCoordinateSet()
    names = [cs.get(i).getName() for i in range(cs.getSize())]
    coords = [cs.get(n) for n in names]
    slot = mobility_slots(state, coords)
    actuators = osim.getActuators()
    overridden = []
    for i in range(actuators.getSize()):
        a = opensim.ScalarActuator.safeDownCast(actuators.get(i))
        name = a.getName()
        value = forces[f"{name}.force_N"] + forces[f"{name}.passive_N"] if f"{name}.force_N" in forces \
            else forces[f"{name}.actuator"]
        a.overrideActuation(state, True)
        overridden.append((a, value))
    muscles = [a for a, _ in overridden if a.getConcreteClassName() == "Thelen2003Muscle"]
    assert len(muscles) == 92
    joints = osim.getJointSet()
    worst_udot, worst_F, worst_M, peak_M_knee = 0.0, 0.0, 0.0, 0.0
    for k, t in enumerate(times):
        set_motion(osim, state, coords, names, motion, t)
        for a, value in overridden:
            a.setOverrideActuation(state, float(value[k]))
        osim.realizeAcceleration(state)
        worst_udot = max(worst_udot, max(abs(state.getUDot().get(slot[n]) - _q(motion[n], t, 2)) for n in names))
        for i in range(joints.getSize()):
            j = joints.get(i)
            child = j.getChildFrame().findBaseFrame().getName()
            load = j.calcReactionOnChildExpressedInGround(state)
            base = f"{j.getName()}_on_{child}_in_ground"
            F = np.array([ours[f"{base}_f{c}"][k] for c in "xyz"])
            M = np.array([ours[f"{base}_m{c}"][k] for c in "xyz"])
            worst_F = max(worst_F, float(np.max(np.abs(F - [load.get(1).get(c) for c in range(3)]))))
            worst_M = max(worst_M, float(np.max(np.abs(M - [load.get(0).get(c) for c in range(3)]))))
            if j.getName().startswith("knee"):
                peak_M_knee = max(peak_M_knee, float(np.max(np.abs(M))))
    print("udot", worst_udot, "force", worst_F, "N, moment", worst_M, "N m; knee moments up to", peak_M_knee)
    # forces.csv's 10 digits: ~1e-7 N of a tension, a toe of 0.2 kg and 1e-4 kg m²
    assert worst_udot < 1e-3, worst_udot
    assert peak_M_knee > 5.0  # the knees carry moments
    quadriceps = max(float(np.max(forces[f"{m}_{s}.force_N"])) for m in ("vas_int", "rect_fem") for s in "rl")
    assert quadriceps > 100.0  # and the moving patella point's term acts
    assert worst_F < 1e-4 and worst_M < 1e-5, (worst_F, worst_M)


#: (joint, apply_on_bodies, express_in_frame): both sides, the keywords, other bodies, a
#: pin joint whose frames are turned, joints' own frames (by their paths in the JointSet)
REPORTS = [("hip_r", "parent", "child"), ("knee_r", "child", "parent"), ("ankle_l", "parent", "tibia_r"),
           ("back", "child", "ground"), ("subtalar_r", "child", "child"), ("mtp_l", "parent", "pelvis"),
           ("ankle_r", "child", "ankle_r/talus_r_offset"), ("mtp_r", "parent", "mtp_r/calcn_r_offset")]


def _setup_file(path, reports):
    """An OpenSim AnalyzeTool setup whose JointReaction asks for ``reports``."""
    names, on, frames = (" ".join(r[k] for r in reports) for k in range(3))
    path.write_text('<?xml version="1.0"?>\n<OpenSimDocument Version="40000"><AnalyzeTool name="jr">'
                    "<model_file>full_body.osim</model_file><AnalysisSet><objects><JointReaction name=\"JointReaction\">"
                    f"<on>true</on><forces_file>forces.sto</forces_file><joint_names>{names}</joint_names>"
                    f"<apply_on_bodies>{on}</apply_on_bodies><express_in_frame>{frames}</express_in_frame>"
                    "</JointReaction></objects></AnalysisSet></AnalyzeTool></OpenSimDocument>\n")
    return path


@pytest.mark.slow
@pytest.mark.parametrize("given", ["overlay", "setup_file", "flag"])
def test_joint_reaction_options_equal_opensims(case, given, capsys):
    """OpenSim's JointReaction options (apply_on_bodies, express_in_frame), given in the
    overlay's joint_reaction section, as OpenSim's own setup file named there, or with
    --joint-reaction: joint_loads.sto holds the same columns as OpenSim's, with the same
    numbers; joint_loads.csv keeps the ground columns besides."""
    import yaml

    from openfdk.io.storage import read_storage
    from test_opensim_inverse_dynamics import _motion

    folder, model, overlay, loads, times, theirs, child = case
    reports, _, _ = _opensim_reactions(model, loads, _motion(np.random.default_rng(7)), times, REPORTS)
    data = yaml.safe_load(overlay.read_text())
    if given == "overlay":
        data["joint_reaction"] = {"joint_names": [r[0] for r in REPORTS],
                                  "apply_on_bodies": [r[1] for r in REPORTS],
                                  "express_in_frame": [r[2] for r in REPORTS]}
    elif given == "setup_file":
        data["joint_reaction"] = _setup_file(folder / "setup_JointReaction.xml", REPORTS).name
    flag = ["--joint-reaction", str(_setup_file(folder / "setup_flag.xml", REPORTS))] if given == "flag" else []
    (folder / f"jr_{given}.yaml").write_text(yaml.safe_dump(data))
    out = folder / f"jr_{given}"
    assert main(["run", str(model), "--with", str(folder / f"jr_{given}.yaml"), "--external-loads", str(loads),
                 "--out", str(out), "--no-plots", "-q", *flag]) == 0, capsys.readouterr().err
    t, ours, _ = read_storage(out / "joint_loads.sto")
    np.testing.assert_allclose(t, times, atol=1e-12)
    assert list(ours) == [f"{base}_{c}" for base in reports for c in COMPONENTS]  # OpenSim's labels, its order
    assert "ankle_l_on_tibia_l_in_tibia_r_fx" in ours and "mtp_l_on_calcn_l_in_pelvis_fx" in ours
    for base, values in reports.items():
        mine = np.column_stack([ours[f"{base}_{c}"] for c in COMPONENTS])
        scale = [max(float(np.max(np.abs(values[:, k:k + 3]))), 1.0) for k in (0, 3)]
        print(base, [float(np.max(np.abs(mine[:, k:k + 3] - values[:, k:k + 3]))) for k in (0, 3, 6)], scale)
        assert np.max(np.abs(mine[:, :3] - values[:, :3])) < 1e-6 * scale[0], base
        assert np.max(np.abs(mine[:, 3:6] - values[:, 3:6])) < 1e-6 * scale[1], base
        assert np.max(np.abs(mine[:, 6:] - values[:, 6:])) < 1e-9, base
    assert max(float(np.max(np.abs(v[:, :3]))) for v in reports.values()) > 500.0  # real loads
    csv = read_table(out / "joint_loads.csv")
    (dF, dM, dp), peak_F, peak_M = _compare(csv, theirs, child)  # the ground columns stay
    assert dF < 1e-6 * peak_F and dM < 1e-6 * peak_M and dp < 1e-9
    assert all(f"{base}_fx" in csv for base in reports)
    import json

    peaks = json.loads((out / "summary.json").read_text())["joint_loads"]["joints"]  # every joint's, as without
    assert set(peaks) == set(theirs)
    assert peaks["knee_r"]["peak_N"] == pytest.approx(float(np.max(np.linalg.norm(theirs["knee_r"][:, :3], axis=1))),
                                                      rel=1e-6)
    from openfdk.io.joint_load_outputs import joint_load_bases
    from openfdk.plots.run import figure_plan
    from openfdk.results.run import read_results

    defaults, asked = joint_load_bases([k for k in csv if k != "time"])  # the figures' split of the columns
    assert sorted(defaults) == sorted(f"{j}_on_{child[j]}_in_ground" for j in theirs)
    assert asked == [b for b in reports if b not in defaults]  # back on torso in ground is a default report
    assert {"joint_loads", "joint_reaction"} <= {name for name, _, _ in figure_plan(read_results(out))}
    from openfdk.viewer import view_data
    from openfdk.viewer.pack import unpack

    drawn = view_data(out)[0]["frames"]["joint_loads"]  # the viewer's arrows: the ground reports, once per joint
    assert sorted(j["name"] for j in drawn) == sorted(theirs)
    knee = next(j for j in drawn if j["name"] == "knee_r")
    np.testing.assert_allclose(unpack(knee["force"]).astype(float).reshape(-1, 3)[:, 1],
                               csv["knee_r_on_tibia_r_in_ground_fy"], rtol=1e-6)
    if given == "setup_file":
        _imported_yaml_reports_the_same(folder, model, folder / f"jr_{given}.yaml", loads, ours, capsys)
    elif given == "flag":  # recorded with the run's options; the overlay may not name another
        options = json.loads((out / "summary.json").read_text())["input"]["opensim_import"]["options"]
        assert options["joint_reaction"] == str((folder / "setup_flag.xml").resolve())
        data["joint_reaction"] = "setup_flag.xml"
        (folder / "jr_both.yaml").write_text(yaml.safe_dump(data))
        assert main(["check", str(model), "--with", str(folder / "jr_both.yaml"), *flag]) == 2  # a bad input
        assert "jr_both.yaml: joint_reaction: given by --joint-reaction too" in capsys.readouterr().err
    else:  # the Python API adds the same columns
        import openfdk
        from openfdk.io.opensim.overlay import register

        register(str(model), overlay=folder / f"jr_{given}.yaml", external_loads=loads)
        api = openfdk.run(str(model)).joint_loads
        for base in reports:
            np.testing.assert_allclose(api[f"{base}_fy"].to_numpy(), ours[f"{base}_fy"], rtol=1e-8, atol=1e-8)


def _imported_yaml_reports_the_same(folder, model, overlay, loads, ours, capsys):
    """The model file import-opensim writes keeps the OpenSim bodies' frames of the
    section: the same .sto. With the keywords and body names instead, the frames are the
    YAML bodies' (the OpenSim axes, the origin at the centre of mass): the same forces and
    moments, the points moved by the OpenSim frame's position p_BF in the body."""
    import yaml

    from openfdk.io.storage import read_storage

    assert main(["import-opensim", str(model), "--with", str(overlay), "--external-loads", str(loads),
                 "--out", str(folder / "imported"), "-q"]) == 0, capsys.readouterr().err
    path = folder / "imported" / "full_body.yaml"
    assert main(["run", str(path), "--out", str(folder / "imported_run"), "--no-plots", "-q"]) == 0
    _, same, _ = read_storage(folder / "imported_run" / "joint_loads.sto")
    assert list(same) == list(ours)
    np.testing.assert_allclose(np.column_stack(list(same.values())), np.column_stack(list(ours.values())),
                               rtol=1e-9, atol=1e-9)
    data = yaml.safe_load(path.read_text())
    frames = data["joint_reaction"]["express_in_frame"]
    assert [f if isinstance(f, str) else f["name"] for f in frames] == ["femur_r", "femur_r", "tibia_r", "ground",
                                                                        "calcn_r", "pelvis", "talus_r_offset",
                                                                        "calcn_r_offset"]
    # the keywords and body names (child, parent, tibia_r, ground, …); the joints' frames stay as written
    data["joint_reaction"]["express_in_frame"] = [f if "/" in r[2] else r[2] for r, f in zip(REPORTS, frames)]
    path.write_text(yaml.safe_dump(data))
    assert main(["run", str(path), "--out", str(folder / "keywords_run"), "--no-plots", "-q"]) == 0
    _, mine, _ = read_storage(folder / "keywords_run" / "joint_loads.sto")
    assert list(mine) == list(ours)
    moved = 0.0
    for (joint, _, target), frame in zip(REPORTS, frames):
        if "/" in target:
            continue
        base = next(k[:-3] for k in ours if k.startswith(f"{joint}_on_") and k.endswith("_fx"))
        p_BF = np.zeros(3) if isinstance(frame, str) else np.asarray(frame["position"])
        assert np.allclose(frame["orientation"]["matrix"] if not isinstance(frame, str) else np.eye(3), np.eye(3))
        for k, c in enumerate("xyz"):
            for kind in "fm":
                np.testing.assert_allclose(mine[f"{base}_{kind}{c}"], ours[f"{base}_{kind}{c}"], rtol=1e-9, atol=1e-8)
            np.testing.assert_allclose(mine[f"{base}_p{c}"], ours[f"{base}_p{c}"] + p_BF[k], atol=1e-12)
        moved = max(moved, float(np.max(np.abs(p_BF))))
    assert moved > 0.05  # the OpenSim frames are not the centres of mass


def test_a_failed_frame_has_no_joint_loads(case, tmp_path):
    """A frame whose recruitment failed keeps its row, NaN, in joint_loads.csv, is left out
    of the .sto (which says so), and of the peaks in the summary."""
    from openfdk.analysis.jobs import model_and_settings, run_job
    from openfdk.io.joint_load_outputs import write_joint_loads
    from openfdk.io.opensim.overlay import register
    from openfdk.io.storage import read_storage

    folder, model, overlay, loads, times, theirs, child = case
    register(str(model), overlay=overlay, external_loads=loads)
    loaded = model_and_settings(str(model))
    kin, dyn, _ = run_job(str(model), None, progress=False, loaded=loaded, rim_check=False)
    import dataclasses

    converged = np.array(dyn.converged)
    converged[3] = False
    dyn = dataclasses.replace(dyn, converged=converged)
    summary = write_joint_loads(tmp_path, loaded[0], kin, dyn)
    ours = read_table(tmp_path / "joint_loads.csv")
    assert len(ours["time"]) == len(times)
    assert np.isnan(ours["knee_r_on_tibia_r_in_ground_fx"][3]) and np.isfinite(ours["knee_r_on_tibia_r_in_ground_fx"][2])
    t, cols, header = read_storage(tmp_path / "joint_loads.sto")
    assert len(t) == len(times) - 1 and times[3] not in t
    assert "1 failed frames left out" in (tmp_path / "joint_loads.sto").read_text()
    knee = np.linalg.norm(theirs["knee_r"][:, :3], axis=1)
    knee[3] = 0.0
    assert summary["joints"]["knee_r"]["peak_N"] == pytest.approx(knee.max(), rel=1e-6)


def _spline(f):
    """A SimmSpline through f at 41 points over [-3, 3] rad."""
    from opensim_models import spline_points

    x = np.linspace(-3.0, 3.0, 41)
    return spline_points(opensim.SimmSpline(), x, f(x))


def _coupled_knee(path, splines=False):
    """A leg written with OpenSim's API: ground -hip (pin)- thigh -knee (pin)- shank, and a
    patella on the thigh whose CustomJoint coordinate beta rotates and slides it,
    beta = 0.8 knee + 0.05 by a CoordinateCouplerConstraint (Rajagopal's patella).
    ``splines``: beta moves the patella through SimmSplines only, as Rajagopal's does
    (openfdk then places it by the knee angle: the coupler holds by construction)."""
    model = opensim.Model()
    model.setName("coupled_knee")
    model.setGravity(opensim.Vec3(0, -9.81, 0))
    thigh = opensim.Body("thigh", 7.0, opensim.Vec3(0, -0.2, 0), opensim.Inertia(0.1, 0.02, 0.1))
    shank = opensim.Body("shank", 3.5, opensim.Vec3(0, -0.2, 0), opensim.Inertia(0.05, 0.006, 0.05))
    patella = opensim.Body("patella", 0.3, opensim.Vec3(0.01, 0, 0), opensim.Inertia(1e-4, 1e-4, 1e-4))
    for b in (thigh, shank, patella):
        model.addBody(b)
    hip = opensim.PinJoint("hip", model.getGround(), opensim.Vec3(0, 1, 0), opensim.Vec3(0, 0, 0),
                           thigh, opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0))
    knee = opensim.PinJoint("knee", thigh, opensim.Vec3(0, -0.42, 0), opensim.Vec3(0, 0, 0),
                            shank, opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0))
    st = opensim.SpatialTransform()
    rotation = _spline(lambda x: x + 0.1 * x * x) if splines else opensim.LinearFunction(1.0, 0.0)
    slide = _spline(lambda x: 0.04 + 0.02 * np.sin(x)) if splines else opensim.LinearFunction(0.02, 0.04)
    axes = [((0, 0, 1), "beta", rotation), ((1, 0, 0), None, opensim.Constant(0.0)),
            ((0, 1, 0), None, opensim.Constant(0.0)), ((1, 0, 0), "beta", slide),
            ((0, 1, 0), None, opensim.Constant(0.0)), ((0, 0, 1), None, opensim.Constant(0.0))]
    for k, (axis, coordinate, function) in enumerate(axes):
        ta = st.updTransformAxis(k)
        ta.setAxis(opensim.Vec3(*axis))
        if coordinate is not None:
            ta.setCoordinateNames(opensim.ArrayStr(coordinate, 1))
        ta.set_function(function)
    pf = opensim.CustomJoint("pf", thigh, opensim.Vec3(0, -0.38, 0), opensim.Vec3(0, 0, 0),
                             patella, opensim.Vec3(0, 0, 0), opensim.Vec3(0, 0, 0), st)
    for j in (hip, knee, pf):
        model.addJoint(j)
    hip.updCoordinate().setName("hip_q")
    knee.updCoordinate().setName("knee_q")
    from opensim_models import coupler

    model.addConstraint(coupler("pf_coupler", "knee_q", "beta", opensim.LinearFunction(0.8, 0.05)))
    model.finalizeConnections()
    model.printToXML(str(path))
    return path


@pytest.mark.slow
@pytest.mark.parametrize("splines", [False, True], ids=["coupler_row", "placed_by_the_knee"])
def test_joint_loads_with_a_coordinate_coupler_equal_opensims(tmp_path, capsys, splines):
    """A patella placed by the knee angle through a CoordinateCouplerConstraint, pulled by
    an external force (its tendon). openfdk drives the hip and the knee; OpenSim gets
    openfdk's two generalised forces on CoordinateActuators and none on the patella's
    coordinate, so that its coupler carries the patella, reproduces the motion's
    accelerations, and its joint reactions equal openfdk's joint loads: the knee's
    includes the coupler's generalised force on the knee angle (OpenSim's booking). With
    splines the patella's rows are written through the knee angle and carry the coupler."""
    model = _coupled_knee(tmp_path / "knee.osim", splines)
    times = np.arange(N) / RATE + 0.2
    motion = {"hip_q": (0.3, 0.4, 0.9, 0.2), "knee_q": (-0.7, 0.5, 1.1, 1.0)}
    drivers = {}
    for name, (a, b, f, phi) in motion.items():
        drivers[f"{name}_motion"] = {"measure": name, "reaction": True, "function": {
            "type": "fourier", "frequency": float(f), "a": [float(a), float(b * np.sin(phi))],
            "b": [float(b * np.cos(phi))]}}
    import yaml

    (tmp_path / "overlay.yaml").write_text(yaml.safe_dump(
        {"drivers": drivers, "analysis": {"start": float(times[0]), "end": float(times[-1]), "frames": len(times)}}))
    write_storage = __import__("openfdk.io.storage", fromlist=["write_storage"]).write_storage
    t = times
    write_storage(tmp_path / "tendon.mot", t, {"p_vx": 300 + 50 * np.sin(3 * t), "p_vy": 500 + 0 * t,
                                               "p_vz": 0 * t, "p_px": 0.02 + 0 * t, "p_py": 0.01 + 0 * t,
                                               "p_pz": 0 * t}, name="tendon")
    (tmp_path / "tendon.xml").write_text("""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000"><ExternalLoads name="tendon"><objects>
<ExternalForce name="tendon"><applied_to_body>patella</applied_to_body>
<force_expressed_in_body>ground</force_expressed_in_body><point_expressed_in_body>patella</point_expressed_in_body>
<force_identifier>p_v</force_identifier><point_identifier>p_p</point_identifier></ExternalForce>
</objects><datafile>tendon.mot</datafile></ExternalLoads></OpenSimDocument>
""")
    out = tmp_path / "id"
    assert main(["run", str(model), "--with", str(tmp_path / "overlay.yaml"), "--external-loads",
                 str(tmp_path / "tendon.xml"), "--out", str(out), "--no-plots", "-q"]) == 0, capsys.readouterr().err
    tau = read_table(out / "generalized_forces.csv")
    ours = read_table(out / "joint_loads.csv")

    osim = opensim.Model(str(model))
    ext = opensim.ExternalLoads(str(tmp_path / "tendon.xml"), True)
    data = opensim.Storage(str(tmp_path / "tendon.mot"))
    force = ext.get(0).clone()
    force.setDataSource(data)
    osim.addForce(force)
    actuators = coordinate_actuators(osim, motion)
    state = osim.initSystem()
    cs = osim.getCoordinateSet()
    worst_udot, worst_F, worst_M, knee_M = 0.0, 0.0, 0.0, 0.0
    for k, tk in enumerate(times):
        state.setTime(float(tk))
        for n in motion:
            cs.get(n).setValue(state, _q(motion[n], tk), False)
        cs.get("beta").setValue(state, 0.8 * _q(motion["knee_q"], tk) + 0.05, False)
        osim.assemble(state)
        for n in motion:
            cs.get(n).setSpeedValue(state, _q(motion[n], tk, 1))
        cs.get("beta").setSpeedValue(state, 0.8 * _q(motion["knee_q"], tk, 1))
        for n, a in actuators.items():
            a.overrideActuation(state, True)
            a.setOverrideActuation(state, float(tau[f"{n}_moment"][k]))
        osim.realizeAcceleration(state)
        worst_udot = max(worst_udot, max(abs(cs.get(n).getAccelerationValue(state) - _q(motion[n], tk, 2))
                                         for n in motion))
        for joint, child in (("hip", "thigh"), ("knee", "shank"), ("pf", "patella")):
            load = osim.getJointSet().get(joint).calcReactionOnChildExpressedInGround(state)
            base = f"{joint}_on_{child}_in_ground"
            worst_F = max(worst_F, max(abs(ours[f"{base}_f{c}"][k] - load.get(1).get(i)) for i, c in enumerate("xyz")))
            worst_M = max(worst_M, max(abs(ours[f"{base}_m{c}"][k] - load.get(0).get(i)) for i, c in enumerate("xyz")))
            if joint == "knee":
                knee_M = max(knee_M, abs(load.get(0).get(2)))
    print("udot", worst_udot, "force", worst_F, "moment", worst_M, "knee moment up to", knee_M)
    assert worst_udot < 1e-5, worst_udot
    assert knee_M > 5.0
    assert worst_F < 1e-5 and worst_M < 1e-5, (worst_F, worst_M)


@pytest.mark.parametrize("section, message", [
    ({"joint_names": ["knee_q"]}, "joint_reaction.joint_names[0]: no joint 'knee_q' with a child body in the model; "
                                  "did you mean 'knee_r'?"),
    ({"express_in_frame": "femur_q"}, "joint_reaction.express_in_frame: 'femur_q': expected ground, child, parent, "
                                      "a body of the OpenSim model or a joint's frame (joint/frame); did you mean "
                                      "'femur_r'?"),
    ({"joint_names": ["knee_r", "hip_r"], "apply_on_bodies": ["child", "parent", "child"]},
     "joint_reaction.apply_on_bodies: give one entry or one per joint (2), got 3"),
    ({"apply_on_bodies": "middle"}, "joint_reaction.apply_on_bodies: unknown body side 'middle'; expected one of "
                                    "['child', 'parent']"),
    ({"joints": "all"}, "joint_reaction.joints: unknown key; did you mean 'joint_names'?"),
    # a mapping where a name belongs (hypothesis' fuzzing, stop 71: a TypeError before)
    ({"joint_names": ["knee_r", {"side": "parent", "name": "femur_r"}]},
     "joint_reaction.joint_names[1]: expected a non-empty name, got {'name': 'femur_r', 'side': 'parent'}"),
    ("missing.xml", "joint_reaction: "),
    ("<JointReaction><on>false</on></JointReaction>", "<on> is false: this JointReaction is switched off"),
    ("<AnalyzeTool/>", "no <JointReaction>"),
])
def test_joint_reaction_section_errors_name_the_entry(case, tmp_path, capsys, section, message):
    """Every mistake in the section or the setup file ends in one line naming the file
    and the entry."""
    import yaml

    folder, model, overlay, loads, *_ = case
    data = yaml.safe_load(overlay.read_text())
    if isinstance(section, str) and section.startswith("<"):
        (tmp_path / "setup.xml").write_text(f'<?xml version="1.0"?>\n<OpenSimDocument>{section}</OpenSimDocument>\n')
        section = "setup.xml"
    data["joint_reaction"] = section
    (tmp_path / "overlay.yaml").write_text(yaml.safe_dump(data))
    code = main(["check", str(model), "--with", str(tmp_path / "overlay.yaml"), "--external-loads", str(loads)])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("openfdk: error")]
    assert code != 0 and len(lines) == 1 and "Traceback" not in err, err
    assert message in lines[0] and ("overlay.yaml" in lines[0] or "setup.xml" in lines[0]), lines[0]


def test_the_setup_reader_skips_the_tools_defaults(tmp_path):
    """An AnalyzeTool's <defaults> holds template objects, not analyses: the JointReaction
    read is the one in its AnalysisSet (as in opensim-models' Gait2392 setups, whose
    JointReaction names a joint twice, once on each side)."""
    from openfdk.io.opensim.joint_reaction import read_setup

    template = ("<JointReaction name='default'><joint_names>all</joint_names><apply_on_bodies>child"
                "</apply_on_bodies></JointReaction>")
    (tmp_path / "setup.xml").write_text(
        f"<OpenSimDocument><AnalyzeTool><defaults>{template}</defaults><AnalysisSet><objects>"
        "<JointReaction name='JointReaction'><on> true </on><joint_names> hip_r knee_r knee_r </joint_names>"
        "<apply_on_bodies> child child parent </apply_on_bodies><express_in_frame> ground child child "
        "</express_in_frame></JointReaction></objects></AnalysisSet></AnalyzeTool></OpenSimDocument>")
    assert read_setup(tmp_path / "setup.xml") == {
        "joint_names": ["hip_r", "knee_r", "knee_r"], "apply_on_bodies": ["child", "child", "parent"],
        "express_in_frame": ["ground", "child", "child"], "from_file": "setup.xml"}


def _welded_model(path):
    """ground -Pin- a -Weld(jc)- c -Gimbal- e, a -Weld(jb)- b -Pin- f, and a -Pin- d;
    every joint's frames offset and turned (tests/opensim_models.py)."""
    from opensim_models import BALL_RANGES, add_markers, fixed_joint, random_body, write

    rng = np.random.default_rng(11)
    m = opensim.Model()
    m.setName("welded")
    B = {n: random_body(n, rng) for n in ("a", "b", "c", "d", "e", "f")}
    for b in B.values():
        m.addBody(b)
    m.addJoint(fixed_joint(opensim.PinJoint, "ja", m.getGround(), B["a"], rng, [(-2.0, 2.0)]))
    m.addJoint(fixed_joint(opensim.WeldJoint, "jc", B["a"], B["c"], rng))
    m.addJoint(fixed_joint(opensim.GimbalJoint, "je", B["c"], B["e"], rng, BALL_RANGES))  # u = q̇, as the oracle sets
    m.addJoint(fixed_joint(opensim.WeldJoint, "jb", B["a"], B["b"], rng))
    m.addJoint(fixed_joint(opensim.PinJoint, "jf", B["b"], B["f"], rng, [(-2.0, 2.0)]))
    m.addJoint(fixed_joint(opensim.PinJoint, "jd", B["a"], B["d"], rng, [(-2.0, 2.0)]))
    for b in B.values():
        add_markers(m, b, rng)
    m.finalizeFromProperties()
    return write(m, path)


def _welded_run(tmp_path, model, motion, times, reports, name, capsys):
    """openfdk's joint_loads.sto of the welded model driven along ``motion`` with the
    ``reports`` [(joint, side, frame)] asked for."""
    import yaml

    from openfdk.io.storage import read_storage
    from test_opensim_inverse_dynamics import _overlay

    data = yaml.safe_load(_overlay(tmp_path, motion, times).read_text())
    data["joint_reaction"] = {"joint_names": [r[0] for r in reports], "apply_on_bodies": [r[1] for r in reports],
                              "express_in_frame": [r[2] for r in reports]} if reports != "all" else {}
    (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(data))
    assert main(["run", str(model), "--with", str(tmp_path / f"{name}.yaml"), "--out", str(tmp_path / name),
                 "--no-plots", "-q"]) == 0, capsys.readouterr().err
    return read_storage(tmp_path / name / "joint_loads.sto")[1]


def _assert_equal_reports(ours, theirs):
    assert list(ours) == [f"{base}_{c}" for base in theirs for c in COMPONENTS]  # OpenSim's labels, its order
    for base, values in theirs.items():
        mine = np.column_stack([ours[f"{base}_{c}"] for c in COMPONENTS])
        scale = max(float(np.max(np.abs(values[:, :6]))), 1.0)
        assert np.max(np.abs(mine[:, :6] - values[:, :6])) < 1e-7 * scale, base
        assert np.max(np.abs(mine[:, 6:] - values[:, 6:])) < 1e-9, base
    assert max(float(np.max(np.abs(v[:, :3]))) for v in theirs.values()) > 5.0  # real loads


@pytest.mark.slow
def test_joint_reaction_with_welded_bodies_equals_opensims(tmp_path, capsys):
    """openfdk merges a body welded to another into it, its frame turned and offset there;
    a weld the JointReaction names is kept apart instead, joined by its six rows, so that
    its load is known. Loads on welded bodies and in their frames, with their OpenSim
    names (``jf_on_b_in_b``: b merged into a), and the named weld's, equal OpenSim's
    JointReaction; ``all`` keeps every weld and reports it, as OpenSim does."""
    names = ["ja_coord_0", "je_coord_0", "je_coord_1", "je_coord_2", "jf_coord_0", "jd_coord_0"]
    model = _welded_model(tmp_path / "welded.osim")
    rng = np.random.default_rng(3)
    motion = {n: (rng.uniform(-0.3, 0.3), rng.uniform(0.2, 0.5), rng.uniform(0.6, 1.4), rng.uniform(0, 6.3))
              for n in names}
    times = np.arange(N) / RATE + 0.2
    reports = [("je", "parent", "parent"), ("je", "child", "c"), ("jd", "parent", "child"), ("ja", "child", "b"),
               ("je", "parent", "ground"), ("jf", "parent", "parent"), ("jf", "child", "b"), ("jc", "child", "c"),
               ("jc", "parent", "parent")]
    theirs, _, worst = _opensim_reactions(model, None, motion, times, reports)
    assert worst < 1e-8, worst
    ours = _welded_run(tmp_path, model, motion, times, reports, "named", capsys)
    assert "jf_on_b_in_b_fx" in ours and "jc_on_c_in_c_fx" in ours  # b merged into a keeps its name
    _assert_equal_reports(ours, theirs)
    import json

    imported = json.loads((tmp_path / "named" / "summary.json").read_text())["input"]["opensim_import"]
    assert imported["merged_bodies"] == {"b": "a"} and imported["welds"] == {"jb": ["b", "a"]}

    # joint_names: all (the section's defaults), every joint in the JointSet's order, the welds too
    everything = [(j, "child", "ground") for j in ("ja", "jc", "je", "jb", "jf", "jd")]
    theirs, _, _ = _opensim_reactions(model, None, motion, times, everything)
    _assert_equal_reports(_welded_run(tmp_path, model, motion, times, "all", "all", capsys), theirs)
