"""OpenSim's RigidTendonMuscle, Schutte1993Muscle_Deprecated and
Millard2012AccelerationMuscle in openfdk (docs/opensim-import.md, docs/muscles.md "OpenSim
curve muscles"), against OpenSim 4.6 as the oracle:

* the import maps every property (the curves as the file's functions);
* path lengths ≤ 1e-7 m and moment arms against ``computeMomentArm`` ≤ 1e-6 m;
* the force law: at given activation, fibre length and fibre velocity, openfdk's fibre
  force along the tendon equals OpenSim's tendon force ≤ 1e-6 relative;
* openfdk's a = 1 equilibrium (s + f_P, its fibre length) is OpenSim's equilibrium: set
  to that fibre length at zero speed, OpenSim's tendon force equals s + f_P and (Schutte)
  its fibre velocity is zero;
* OpenSim's static-optimisation strength (``calcInextensibleTendonActiveFiberForce``).

The arm is test_opensim_muscles's geometry. OpenSim's Python API has no
Schutte1993Muscle_Deprecated class, but its model reader has: the Schutte muscles are
written into the file by hand and read by OpenSim.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from lxml import etree

opensim = pytest.importorskip("opensim")

import opensim_models as om  # noqa: E402  (tests/opensim_models.py)

from openfdk.forces.curve_muscle import CurveMuscle  # noqa: E402
from openfdk.forces.millard import MillardMuscle, _fibre_force  # noqa: E402
from openfdk.forces.rigid_tendon import opensim_strengths  # noqa: E402
from openfdk.forces.hill import MuscleSet  # noqa: E402
from openfdk.io.modelfile import model_from_dict  # noqa: E402
from openfdk.io.opensim import OsimError, read_osim  # noqa: E402
from test_opensim_muscles import POINTS, _compare_paths, arm_skeleton  # noqa: E402

PASSIVE = ((0.9, 1.0, 1.2, 1.5, 1.8), (0.0, 0.0, 0.2, 1.0, 2.5))
AFL = dict(min_norm_active_fiber_length=0.5, transition_norm_fiber_length=0.75, max_norm_active_fiber_length=1.7,
           shallow_ascending_slope=0.7, minimum_value=0.05)
TFL = dict(strain_at_one_norm_force=0.04, stiffness_at_one_norm_force=40.0, norm_force_at_toe_end=0.6,
           curviness=0.4)
#: the muscles: (OpenSim class, path of POINTS, properties)
MUSCLES = {
    "biceps.long": ("RigidTendonMuscle", "biceps.long",
                    dict(max_isometric_force=812.5, optimal_fiber_length=0.121, tendon_slack_length=0.251,
                         pennation_angle_at_optimal=0.2, max_contraction_velocity=8.5)),
    "triceps": ("Millard2012AccelerationMuscle", "triceps",
                dict(max_isometric_force=1200.0, optimal_fiber_length=0.09, tendon_slack_length=0.22,
                     pennation_angle_at_optimal=0.3, max_contraction_velocity=12.0, fiber_damping=0.02)),
    "delt": ("Schutte1993Muscle_Deprecated", "delt",
             dict(max_isometric_force=500.0, optimal_fiber_length=0.1, tendon_slack_length=0.23,
                  pennation_angle_at_optimal=0.15, max_contraction_velocity=9.0, time_scale=0.08, damping=0.05)),
    "biceps.schutte": ("Schutte1993Muscle_Deprecated", "biceps.long",
                       dict(max_isometric_force=700.0, optimal_fiber_length=0.11, tendon_slack_length=0.26,
                            pennation_angle_at_optimal=0.0, max_contraction_velocity=10.0)),
}
SCHUTTE_WITH_PASSIVE = "biceps.schutte"  # given a passive curve (the other uses OpenSim's exponential)
OURS = {"optimal_fiber_length": "optimal_fibre_length"}


def _spline_xml(tag, x, y):
    """A function property as OpenSim 4 writes it (the function named after the property)."""
    return f"<SimmSpline name='{tag}'><x>{' '.join(map(repr, x))}</x><y>{' '.join(map(repr, y))}</y></SimmSpline>"


def curve_arm(path):
    """The arm with the muscles of MUSCLES, written by OpenSim (the Schutte muscles are
    Thelen muscles renamed in the XML, their properties replaced)."""
    m, bodies = arm_skeleton("curve_arm")
    for name, (cls, points, params) in MUSCLES.items():
        kind = "Thelen2003Muscle" if cls == "Schutte1993Muscle_Deprecated" else cls
        mu = getattr(opensim, kind)(name, params["max_isometric_force"], params["optimal_fiber_length"],
                                    params["tendon_slack_length"], params["pennation_angle_at_optimal"])
        if cls != "Schutte1993Muscle_Deprecated":
            for key, value in params.items():
                getattr(mu, f"set_{key}")(value)
        if cls == "RigidTendonMuscle":
            spline = opensim.SimmSpline()
            for x, y in zip(*PASSIVE):
                spline.addPoint(x, y)
            mu.set_passive_force_length_curve(spline)
        if cls == "Millard2012AccelerationMuscle":
            mu.setActiveForceLengthCurve(opensim.ActiveForceLengthCurve(*AFL.values()))
            mu.setTendonForceLengthCurve(opensim.TendonForceLengthCurve(*TFL.values()))
        for pname, body, loc in POINTS[points]:
            mu.addNewPathPoint(pname, bodies[body], om.vec3(loc))
        m.addForce(mu)
    m.finalizeConnections()
    assert m.printToXML(str(path))
    tree = etree.parse(str(path))
    for name, (cls, _, params) in MUSCLES.items():
        if cls != "Schutte1993Muscle_Deprecated":
            continue
        e = tree.xpath(f"//Thelen2003Muscle[@name='{name}']")[0]
        e.tag = cls
        for c in list(e):
            if c.tag not in ("appliesForce", "min_control", "max_control", "GeometryPath", "optimal_force"):
                e.remove(c)
        for key, value in params.items():
            e.append(etree.fromstring(f"<{key}>{value!r}</{key}>"))
        if name == SCHUTTE_WITH_PASSIVE:
            e.append(etree.fromstring(_spline_xml("passive_force_length_curve", *PASSIVE)))
    tree.write(str(path))
    return path


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    return curve_arm(tmp_path_factory.mktemp("curve_muscles") / "curve_arm.osim")


def _ours(arm):
    data, info = read_osim(arm)
    model = model_from_dict(data, source=str(arm))
    return data, {m.name: m.law for m in model.muscles}


def _theirs(arm):
    theirs = opensim.Model(str(arm))
    state = theirs.initSystem()
    coords = [theirs.getCoordinateSet().get(k) for k in range(theirs.getCoordinateSet().getSize())]
    muscles = {theirs.getMuscles().get(k).getName(): theirs.getMuscles().get(k)
               for k in range(theirs.getMuscles().getSize())}
    return theirs, state, coords, muscles


def _pose(rng, state, coords, theirs, speed=0.0):
    for c in coords:
        c.setValue(state, float(rng.uniform(-1.2, 1.2)), False)
        c.setSpeedValue(state, float(rng.uniform(-speed, speed)))
    theirs.realizeVelocity(state)


def test_import_maps_every_parameter(arm):
    """Every property reaches openfdk's muscle: the rigid-tendon and Schutte muscles as
    CurveMuscles (their functions equal OpenSim's at 200 points), the acceleration muscle
    as a MillardMuscle with its curves as given (OpenSim's acceleration muscle adjusts
    none, unlike the equilibrium one) and pennation up to π/2."""
    data, ours = _ours(arm)
    theirs, state, _, muscles = _theirs(arm)
    for name, (cls, _, params) in MUSCLES.items():
        law = ours[name.replace(".", "_")]
        for key, value in params.items():
            assert getattr(law, OURS.get(key, key)) == pytest.approx(value, rel=1e-15), (name, key)
        if cls == "Millard2012AccelerationMuscle":
            assert isinstance(law, MillardMuscle) and law.curve_rule == "as_given"
            assert law.maximum_pennation_angle == pytest.approx(math.pi / 2)
            assert law.minimum_activation == 0.0
            fal = law.curves_in_use()[0]
            assert fal.minimum_value == AFL["minimum_value"]  # kept, where the equilibrium muscle sets 0
            continue
        assert isinstance(law, CurveMuscle)
        assert law.kind == {"RigidTendonMuscle": "rigid_tendon"}.get(cls, "schutte1993")
        if cls == "RigidTendonMuscle":
            mu = opensim.RigidTendonMuscle.safeDownCast(muscles[name])
            funcs = law._functions()
            for key, theirs_f, xs in (("active_force_length", mu.get_active_force_length_curve(), (0.2, 2.0)),
                                      ("passive_force_length", mu.get_passive_force_length_curve(), (0.8, 2.0)),
                                      ("force_velocity", mu.get_force_velocity_curve(), (-1.1, 1.1))):
                x = np.linspace(*xs, 200)
                want = [theirs_f.calcValue(opensim.Vector(1, float(v))) for v in x]
                assert np.allclose(funcs[key].evaluate(x)[0], want, rtol=0, atol=1e-12), key
    schutte = ours["biceps_schutte"]
    assert schutte.passive_force_length["type"] == "simm_spline" and ours["delt"].passive_force_length is None


def test_paths_equal_opensims(arm):
    """Path lengths ≤ 1e-7 m, moment arms against OpenSim's computeMomentArm ≤ 1e-6 m
    (and openfdk's own against a central difference of its length) at 12 random poses."""
    worst = _compare_paths(arm, n=12, seed=7)
    print("|Δl|, |Δr|, |Δr_fd| =", worst)
    assert worst[0] <= 1e-7 and worst[1] <= 1e-6 and worst[2] <= 1e-6


def test_rigid_tendon_forces_equal_opensims(arm):
    """RigidTendonMuscle: at random poses, speeds and controls, a·s + f_P of openfdk's
    rule equals OpenSim's tendon force ≤ 1e-6 relative (the rule is OpenSim's law, the
    tendon being rigid), and CurveMuscle.fibre_force at OpenSim's fibre length and velocity
    too; OpenSim's static-optimisation strength equals ours."""
    _, ours = _ours(arm)
    theirs, state, coords, muscles = _theirs(arm)
    mu = opensim.RigidTendonMuscle.safeDownCast(muscles["biceps.long"])
    law = ours["biceps_long"]
    rng = np.random.default_rng(11)
    worst, loaded = 0.0, 0
    for _ in range(25):
        _pose(rng, state, coords, theirs, speed=3.0)
        a = float(rng.uniform(0.0, 1.0))
        controls = theirs.updControls(state)
        mu.setControls(opensim.Vector(1, a), controls)
        theirs.setControls(state, controls)
        theirs.realizeDynamics(state)
        tendon = mu.getTendonForce(state)
        s, f_p = law.evaluate(mu.getLength(state), mu.getLengtheningSpeed(state))
        f_law = law.fibre_force(a, mu.getFiberLength(state), mu.getFiberVelocity(state))
        f_opt = mu.calcInextensibleTendonActiveFiberForce(state, 1.0)
        so = opensim_strengths(MuscleSet([law]), np.array([mu.getLength(state)]),
                               np.array([mu.getLengtheningSpeed(state)]))[0]
        scale = max(abs(tendon), 1.0)
        worst = max(worst, abs(a * s + f_p - tendon) / scale, abs(f_law - tendon) / scale,
                    abs(so - f_opt) / max(abs(f_opt), 1.0))
        loaded += tendon > 10.0
    print(f"rigid tendon: relative difference ≤ {worst:.1e}")
    assert worst <= 1e-6 and loaded >= 5


def _schutte_state(theirs, state, mu, activation, fibre_length):
    names = mu.getStateVariableNames()
    mu.setStateVariableValue(state, names.get(0), activation)
    mu.setStateVariableValue(state, names.get(1), fibre_length)
    theirs.realizeAcceleration(state)
    return mu.getTendonForce(state), mu.getStateVariableDerivativeValue(state, names.get(1))


@pytest.mark.parametrize("name", ["delt", "biceps.schutte"])
def test_schutte_force_law_equals_opensims(arm, name):
    """Schutte1993Muscle_Deprecated: OpenSim states activation and fibre length, and
    derives the fibre velocity from its inverse force–velocity law; at random states
    openfdk's fibre force (the law solved for the force, damping included) at OpenSim's
    velocity equals OpenSim's tendon force ≤ 1e-6 relative, on both branches."""
    _, ours = _ours(arm)
    theirs, state, coords, muscles = _theirs(arm)
    mu = muscles[name]
    law = ours[name.replace(".", "_")]
    rng = np.random.default_rng(5)
    worst, branches = 0.0, set()
    for _ in range(40):
        _pose(rng, state, coords, theirs)
        a = float(rng.uniform(0.05, 1.0))
        # fibre lengths about the tendon's slack state: the tendon pulls more or less than
        # the fibre's isometric force (eccentric and concentric branches)
        slack = math.sqrt(max(mu.getLength(state) - law.tendon_slack_length, 0.0) ** 2
                          + (law.optimal_fibre_length * math.sin(law.pennation_angle_at_optimal)) ** 2)
        l_f = max(slack - law.tendon_slack_length * float(rng.uniform(0.0, 0.012)), 0.4 * law.optimal_fibre_length)
        tendon, v_f = _schutte_state(theirs, state, mu, a, l_f)
        passive = law.fibre_force(0.0, l_f, 0.0)
        if tendon <= passive + 1e-9 * law.max_isometric_force:  # OpenSim clamps that force at 0 first
            continue
        branches.add(v_f > 0)
        worst = max(worst, abs(law.fibre_force(a, l_f, v_f) - tendon) / max(tendon, 1.0))
    print(f"{name}: relative difference ≤ {worst:.1e}, branches {branches}")
    assert worst <= 1e-6 and branches == {True, False}


@pytest.mark.parametrize("name", ["delt", "biceps.schutte", "triceps"])
def test_equilibrium_is_opensims(arm, name):
    """openfdk's a = 1 state at zero speed: OpenSim's muscle at that fibre length (a = 1,
    zero fibre velocity for the acceleration muscle) carries the tendon force s + f_P,
    ≤ 1e-6 relative, and (Schutte) finds its fibre velocity zero; the passive state (a = 0)
    likewise gives f_P."""
    _, ours = _ours(arm)
    theirs, state, coords, muscles = _theirs(arm)
    mu = muscles[name]
    law = ours[name.replace(".", "_")]
    rng = np.random.default_rng(9)
    worst, loaded = 0.0, 0
    for _ in range(12):
        _pose(rng, state, coords, theirs)
        states = law.evaluate_states(np.array([mu.getLength(state)]), np.zeros(1))
        if states.status[0] != 0:
            continue
        for a, l_f, want in ((1.0, states.fibre_length_active[0], states.tendon_force_active[0]),
                             (0.0, states.fibre_length_passive[0], states.passive_force[0])):
            if isinstance(law, CurveMuscle):
                tendon, v_f = _schutte_state(theirs, state, mu, a, l_f)
                if a == 1.0:
                    assert abs(v_f) <= 1e-9 * law.optimal_fibre_length / law.time_scale
            else:
                acc = opensim.Millard2012AccelerationMuscle.safeDownCast(mu)
                acc.setActivation(state, a)
                acc.setFiberLength(state, l_f)
                acc.setFiberVelocity(state, 0.0)
                theirs.realizeDynamics(state)
                tendon = acc.getTendonForce(state)
                fibre = acc.getFiberForceAlongTendon(state)
                worst = max(worst, abs(fibre - want) / max(want, 1.0))
            worst = max(worst, abs(tendon - want) / max(want, 1.0))
            loaded += want > 10.0
    print(f"{name}: relative difference ≤ {worst:.1e}")
    assert worst <= 1e-6 and loaded >= 6


def test_acceleration_active_force_and_so_strength(arm):
    """Millard2012AccelerationMuscle: at random activations, fibre lengths and fibre
    velocities, openfdk's active fibre force along the tendon (its curves as given)
    equals OpenSim's getActiveFiberForceAlongTendon ≤ 1e-6 relative, and the
    static-optimisation strength its calcInextensibleTendonActiveFiberForce (pennation at
    the fibre length, not the equilibrium muscle's normalised one)."""
    _, ours = _ours(arm)
    theirs, state, coords, muscles = _theirs(arm)
    mu = opensim.Millard2012AccelerationMuscle.safeDownCast(muscles["triceps"])
    law = ours["triceps"]
    row = law._row()
    h = law.optimal_fibre_length * math.sin(law.pennation_angle_at_optimal)
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(25):
        _pose(rng, state, coords, theirs, speed=3.0)
        a = float(rng.uniform(0.05, 1.0))
        l_f = law.optimal_fibre_length * float(rng.uniform(0.6, 1.5))
        v_f = law.optimal_fibre_length * law.max_contraction_velocity * float(rng.uniform(-0.9, 0.9))
        mu.setActivation(state, a)
        mu.setFiberLength(state, l_f)
        mu.setFiberVelocity(state, v_f)
        theirs.realizeDynamics(state)
        x = math.sqrt(l_f * l_f - h * h)
        cos_a = x / l_f
        active = (_fibre_force(x, a, v_f / cos_a, row)[0] - _fibre_force(x, 0.0, v_f / cos_a, row)[0])
        want = mu.getActiveFiberForceAlongTendon(state)
        worst = max(worst, abs(active - want) / max(abs(want), 1.0))
        so = opensim_strengths(MuscleSet([law]), np.array([mu.getLength(state)]),
                               np.array([mu.getLengtheningSpeed(state)]))[0]
        f_opt = mu.calcInextensibleTendonActiveFiberForce(state, 1.0)
        worst = max(worst, abs(so - f_opt) / max(abs(f_opt), 1.0))
    print(f"acceleration muscle: relative difference ≤ {worst:.1e}")
    assert worst <= 1e-6


def test_schutte_so_strength_is_opensims_isometric_force(arm):
    """A Schutte muscle's static-optimisation strength: OpenSim's isometric force at a = 1
    (its own iteration, stopped at 0.01 N) times the generic f_V; ours the exact
    equilibrium times the same f_V: equal within OpenSim's 0.01 N (+ 1e-6 relative)."""
    _, ours = _ours(arm)
    theirs, state, coords, muscles = _theirs(arm)
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(10):
        _pose(rng, state, coords, theirs, speed=2.0)
        for name in ("delt", "biceps.schutte"):
            mu, law = muscles[name], ours[name.replace(".", "_")]
            length, speed = mu.getLength(state), mu.getLengtheningSpeed(state)
            f_opt = mu.calcInextensibleTendonActiveFiberForce(state, 1.0)
            so = opensim_strengths(MuscleSet([law]), np.array([length]), np.array([speed]))[0]
            assert abs(so - f_opt) <= 0.011 + 1e-6 * f_opt, (name, so, f_opt)
            checked += f_opt > 10.0
    assert checked >= 5


@pytest.mark.parametrize("edit,words", [
    (lambda m: m.append(etree.fromstring("<fiber_stiffness>1</fiber_stiffness>")), "<fiber_stiffness>"),
    (lambda m: m.find("time_scale").__setattr__("text", "-0.1"), "time_scale"),
    (lambda m: m.append(etree.fromstring("<tendon_force_length_curve/>")), "must hold one function"),
])
def test_bad_values_are_one_line_errors(arm, tmp_path, edit, words):
    """An unknown property, an invalid value, an empty curve: one line naming the file,
    the muscle and what is wrong."""
    tree = etree.parse(str(arm))
    edit(tree.xpath("//Schutte1993Muscle_Deprecated[@name='delt']")[0])
    path = tmp_path / "bad.osim"
    tree.write(str(path))
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and path.name in msg and "delt" in msg and words in msg, msg


def test_summary_lists_what_ignore_left_out(arm, tmp_path, monkeypatch, capsys):
    """``openfdk run model.osim --motion … --ignore TYPE``: the muscle of that type is left
    out, the run succeeds with the other muscles, and summary.json lists it (type, name,
    line) under ``input.opensim_import.dropped``; without ``--ignore`` an unsupported
    muscle class ends in one line naming it (test_opensim_muscles)."""
    import json

    from openfdk.cli import main

    monkeypatch.chdir(tmp_path)
    t = np.linspace(0.0, 0.5, 26)
    motion = om.write_motion(tmp_path / "arm.mot", t, {"q_shoulder": 0.3 + 0.2 * np.sin(2 * t),
                                                       "q_elbow": 0.8 + 0.3 * np.cos(3 * t)})
    code = main(["run", str(arm), "--motion", str(motion), "--ignore", "RigidTendonMuscle", "--out", "out",
                 "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    dropped = summary["input"]["opensim_import"]["dropped"]
    line = etree.parse(str(arm)).xpath("//RigidTendonMuscle")[0].sourceline
    assert {"type": "RigidTendonMuscle", "name": "biceps.long", "line": line} in dropped
