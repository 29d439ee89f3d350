"""OpenSim's Millard2012EquilibriumMuscle in openfdk (docs/muscles.md, "Millard muscle";
docs/opensim-import.md), against OpenSim 4.6 as the oracle:

* the four curves (active and passive force–length, force–velocity, tendon) built from
  their properties, value and slope ≤ 1e-9 at many points, with default, explicit and
  "fitted" (optional properties absent) parameters;
* the import: every property of the file reaches :class:`MillardMuscle`, the curves as
  the muscle adjusts them (damped, classic and rigid-tendon models);
* the maximal tendon force s + f_P equal to OpenSim's tendon force after
  ``equilibrateMuscles`` at activation 1 (random poses, zero speed);
* OpenSim's static-optimisation strength (``calcInextensibleTendonActiveFiberForce``)
  at random poses and speeds.

The arm is test_opensim_muscles's geometry with three Millard muscles (non-default
parameters and curves): a damped one, a classic (fiber_damping 0) one and a rigid-tendon
one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

import opensim_models as om  # noqa: E402  (tests/opensim_models.py)

from openfdk.forces import millard_curves as mc  # noqa: E402
from openfdk.forces.millard import MillardMuscle, opensim_so_strength  # noqa: E402
from openfdk.io.modelfile import model_from_dict  # noqa: E402
from openfdk.io.opensim import OsimError, read_osim  # noqa: E402
from openfdk.kinematics.coordinate_pose import pose_from_coordinates  # noqa: E402
from test_opensim_muscles import POINTS, _edit  # noqa: E402

AFL = dict(min_norm_active_fiber_length=0.5, transition_norm_fiber_length=0.75, max_norm_active_fiber_length=1.7,
           shallow_ascending_slope=0.7, minimum_value=0.05)
FV = dict(concentric_slope_at_vmax=0.1, concentric_slope_near_vmax=0.3, isometric_slope=4.0,
          eccentric_slope_at_vmax=0.05, eccentric_slope_near_vmax=0.2, max_eccentric_velocity_force_multiplier=1.5,
          concentric_curviness=0.5, eccentric_curviness=0.8)
FPE = dict(strain_at_zero_force=0.02, strain_at_one_norm_force=0.65, stiffness_at_low_force=0.25,
           stiffness_at_one_norm_force=4.0, curviness=0.6)
TFL = dict(strain_at_one_norm_force=0.04, stiffness_at_one_norm_force=40.0, norm_force_at_toe_end=0.6,
           curviness=0.4)
#: (kind, ours, OpenSim's constructor arguments) of each curve checked
CURVES = [
    ("ActiveForceLengthCurve", {}, ()),
    ("ActiveForceLengthCurve", AFL, tuple(AFL.values())),
    ("ForceVelocityCurve", {}, ()),
    ("ForceVelocityCurve", FV, tuple(FV.values())),
    ("FiberForceLengthCurve", {}, ()),
    ("FiberForceLengthCurve", FPE, tuple(FPE.values())),
    ("FiberForceLengthCurve", dict(strain_at_zero_force=-0.05, strain_at_one_norm_force=0.5), "fitted"),
    ("TendonForceLengthCurve", {}, ()),
    ("TendonForceLengthCurve", TFL, tuple(TFL.values())),
    ("TendonForceLengthCurve", dict(strain_at_one_norm_force=0.033), "fitted"),
]
DOMAIN = {"ActiveForceLengthCurve": (0.0, 2.2), "ForceVelocityCurve": (-1.3, 1.3),
          "FiberForceLengthCurve": (0.8, 1.9), "TendonForceLengthCurve": (0.95, 1.1)}


def _their_curve(kind, ours, args):
    cls = getattr(opensim, kind)
    if args != "fitted":
        return cls(*args)
    curve = cls()
    for key, value in ours.items():
        getattr(curve, f"set_{key}")(value)
    curve.ensureCurveUpToDate()
    return curve


@pytest.mark.parametrize("kind,ours,args", CURVES)
def test_curves_equal_opensims(kind, ours, args):
    """Value and slope of each curve equal OpenSim's curve object (calcValue,
    calcDerivative(x, 1)) ≤ 1e-9 at 1500 points through the domain and its linear
    extrapolation (measured: ≤ 5e-13 in value, ≤ 8e-11 in the tendon's slope, OpenSim's
    Newton tolerance on the Bézier parameter)."""
    theirs = _their_curve(kind, ours, args)
    curve = getattr(mc, kind)(**ours)
    lo, hi = DOMAIN[kind]
    rng = np.random.default_rng(5)
    x = np.concatenate([np.linspace(lo, hi, 1000), rng.uniform(lo, hi, 500)])
    table = curve.table()
    w = mc.SEGMENT_WIDTH
    x = np.concatenate([x, table[7:7 + w * int(table[0])].reshape(-1, w)[:, [0, 5]].ravel()])  # segment ends
    y, dy = mc.evaluate_curve(curve, x)
    ty = np.array([theirs.calcValue(float(v)) for v in x])
    tdy = np.array([theirs.calcDerivative(float(v), 1) for v in x])
    print(f"{kind}: |Δy| ≤ {np.abs(y - ty).max():.1e}, |Δy'| ≤ {np.abs(dy - tdy).max():.1e}")
    assert np.abs(y - ty).max() <= 1e-9 and np.abs(dy - tdy).max() <= 1e-9


def test_partial_optional_properties_are_refused():
    """OpenSim's rule: the three optional properties are all given or all absent."""
    with pytest.raises(mc.CurveError, match="all be given or all be absent"):
        mc.TendonForceLengthCurve(0.04, stiffness_at_one_norm_force=40.0).table()
    with pytest.raises(mc.CurveError, match="stiffness_at_low_force"):
        mc.FiberForceLengthCurve(0.0, 0.7, 3.0, 4.0, 0.5).table()  # k_low ≥ 1/(ε1 − ε0)


#: the arm's Millard muscles: OpenSim setter -> value, and the curves
MUSCLES = {
    "biceps.long": dict(max_isometric_force=812.5, optimal_fiber_length=0.121, tendon_slack_length=0.251,
                        pennation_angle_at_optimal=0.11, max_contraction_velocity=8.5, fiber_damping=0.1,
                        curves=dict(ActiveForceLengthCurve=AFL, ForceVelocityCurve=FV)),
    "triceps": dict(max_isometric_force=1200.0, optimal_fiber_length=0.09, tendon_slack_length=0.22,
                    pennation_angle_at_optimal=0.3, max_contraction_velocity=12.0, fiber_damping=0.0,
                    maximum_pennation_angle=1.2,
                    curves=dict(FiberForceLengthCurve=FPE, TendonForceLengthCurve=TFL)),
    "delt": dict(max_isometric_force=500.0, optimal_fiber_length=0.1, tendon_slack_length=0.23,
                 pennation_angle_at_optimal=0.0, ignore_tendon_compliance=True, curves={}),
}
OURS = {"ActiveForceLengthCurve": "active_force_length", "ForceVelocityCurve": "force_velocity",
        "FiberForceLengthCurve": "fibre_force_length", "TendonForceLengthCurve": "tendon_force_length",
        "optimal_fiber_length": "optimal_fibre_length"}


def millard_arm(path):
    """test_opensim_muscles's two-pin arm with the Millard muscles of MUSCLES, written by
    OpenSim."""
    from test_opensim_muscles import arm_skeleton

    m, bodies = arm_skeleton("millard_arm")
    for name, params in MUSCLES.items():
        mu = opensim.Millard2012EquilibriumMuscle(name, params["max_isometric_force"], params["optimal_fiber_length"],
                                                  params["tendon_slack_length"], params["pennation_angle_at_optimal"])
        for key, value in params.items():
            if key != "curves":
                getattr(mu, f"set_{key}")(value)
        for kind, values in params["curves"].items():
            getattr(mu, f"set{kind}")(getattr(opensim, kind)(*values.values()))
        for pname, body, loc in POINTS[name]:
            mu.addNewPathPoint(pname, bodies[body], om.vec3(loc))
        m.addForce(mu)
    m.finalizeConnections()
    assert m.printToXML(str(path))
    return path


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    return millard_arm(tmp_path_factory.mktemp("millard") / "millard_arm.osim")


def _ours(arm):
    data, _ = read_osim(arm)
    model = model_from_dict(data, source=str(arm))
    return data, {m.name: m for m in model.muscles}


def test_import_maps_every_parameter(arm):
    """Every property of the file reaches the MillardMuscle (OpenSim's defaults for the
    rest), and the curves in use are the ones OpenSim's muscle uses after its own
    adjustment (damped/rigid: f_L minimum 0, f_V end slopes 0; classic: f_L minimum ≥ 0.1,
    f_V end slopes ≥ half the near slopes)."""
    from lxml import etree

    data, ours = _ours(arm)
    theirs = opensim.Model(str(arm))
    theirs.initSystem()
    tree = etree.parse(str(arm))
    for name, params in MUSCLES.items():
        law = ours[name.replace(".", "_")].law
        assert isinstance(law, MillardMuscle)
        assert data["muscles"][name.replace(".", "_")]["model"] == "millard"
        for key, value in params.items():
            if key != "curves":
                assert getattr(law, OURS.get(key, key)) == pytest.approx(value, rel=1e-15)
        # the curves as the file gives them (OpenSim writes the values its muscle adjusted)
        element = tree.xpath(f"//Millard2012EquilibriumMuscle[@name='{name}']")[0]
        for kind in ("ActiveForceLengthCurve", "ForceVelocityCurve", "FiberForceLengthCurve",
                     "TendonForceLengthCurve"):
            given = {c.tag: float(c.text) for c in element.find(kind) if isinstance(c.tag, str)}
            for key, value in {**params["curves"].get(kind, {}), **given}.items():
                if key != "minimum_value" and not key.endswith("slope_at_vmax"):  # adjusted, below
                    assert getattr(getattr(law, OURS[kind]), key) == pytest.approx(value, rel=1e-15)
        mu = opensim.Millard2012EquilibriumMuscle.safeDownCast(theirs.getMuscles().get(name))
        fal, fv, fpe, fse = law.curves_in_use()
        tfal, tfv = mu.getActiveForceLengthCurve(), mu.getForceVelocityCurve()
        assert fal.minimum_value == tfal.getMinValue()
        assert fv.concentric_slope_at_vmax == pytest.approx(tfv.getConcentricSlopeAtVmax(), abs=1e-15)
        assert fv.eccentric_slope_at_vmax == pytest.approx(tfv.getEccentricSlopeAtVmax(), abs=1e-15)
        lengths = np.linspace(0.3, 2.0, 50)
        for ours_curve, their_curve in ((fal, tfal), (fpe, mu.getFiberForceLengthCurve())):
            y, _ = mc.evaluate_curve(ours_curve, lengths)
            assert np.allclose(y, [their_curve.calcValue(float(x)) for x in lengths], atol=1e-12, rtol=0)
        v = np.linspace(-1.2, 1.2, 50)
        assert np.allclose(mc.evaluate_curve(fv, v)[0], [tfv.calcValue(float(x)) for x in v], atol=1e-12, rtol=0)
        tl = np.linspace(0.98, 1.08, 50)
        assert np.allclose(mc.evaluate_curve(fse, tl)[0],
                           [mu.getTendonForceLengthCurve().calcValue(float(x)) for x in tl], atol=1e-12, rtol=0)


def _theirs(arm):
    theirs = opensim.Model(str(arm))
    state = theirs.initSystem()
    coords = [theirs.getCoordinateSet().get(k) for k in range(theirs.getCoordinateSet().getSize())]
    muscles = [opensim.Millard2012EquilibriumMuscle.safeDownCast(theirs.getMuscles().get(k))
               for k in range(theirs.getMuscles().getSize())]
    return theirs, state, coords, muscles


def test_maximal_tendon_force_equals_opensims_equilibrium(arm):
    """At full activation and zero speed, s + f_P (openfdk's a = 1 equilibrium) equals
    the tendon force of OpenSim's muscle after ``equilibrateMuscles``, ≤ 1e-6 relative
    (OpenSim's own tolerance is 1e-8 F0; measured ≈ 1e-8), at 12 random poses, for the
    damped, the classic and the rigid-tendon muscle (with the fibre damping force zero at
    zero speed), at OpenSim's path length (test_path_lengths_equal_opensims checks
    openfdk's)."""
    _, ours = _ours(arm)
    theirs, state, coords, muscles = _theirs(arm)
    rng = np.random.default_rng(2)
    worst, loaded = 0.0, 0
    for _ in range(12):
        q = {c.getName(): float(rng.uniform(-1.2, 1.2)) for c in coords}
        for c in coords:
            c.setValue(state, q[c.getName()], False)
        for mu in muscles:
            mu.setActivation(state, 1.0)
        theirs.equilibrateMuscles(state)
        theirs.realizeDynamics(state)
        for mu in muscles:
            m = ours[mu.getName().replace(".", "_")]
            s, f_p = m.law.evaluate(mu.getLength(state), 0.0)
            tendon = mu.getTendonForce(state)
            worst = max(worst, abs(s + f_p - tendon) / max(tendon, 1.0))
            loaded += tendon > 1.0
    print(f"maximal tendon force: relative difference ≤ {worst:.1e}")
    assert worst <= 1e-6
    assert loaded >= 30  # and a few states where the fibre is at its lower bound: both 0


def test_path_lengths_equal_opensims(arm):
    """The Millard muscles' paths are read like the Thelen muscles': lengths ≤ 1e-7 m."""
    data, _ = read_osim(arm)
    model = model_from_dict(data, source=str(arm))
    theirs, state, coords, muscles = _theirs(arm)
    by_name = {m.name: m for m in model.muscles}
    rng = np.random.default_rng(4)
    for _ in range(10):
        q = {c.getName(): float(rng.uniform(-1.2, 1.2)) for c in coords}
        for c in coords:
            c.setValue(state, q[c.getName()], False)
        theirs.realizePosition(state)
        st, _ = pose_from_coordinates(model, q)
        for mu in muscles:
            m = by_name[mu.getName().replace(".", "_")]
            length = float(np.ravel(m.path.evaluate(st, 0)[0])[0])
            assert abs(length - mu.getLength(state)) <= 1e-7


def test_static_optimisation_strength_equals_opensims(arm):
    """F_opt of ``static_optimization: opensim`` equals OpenSim's
    ``calcInextensibleTendonActiveFiberForce(s, 1)`` (what its StaticOptimization uses) ≤
    1e-9 N at 40 random poses and speeds (measured ≈ 1e-11 N). This includes OpenSim 4.x's
    pennation angle at the normalised fibre length (millard.opensim_so_strength): with the
    angle at the fibre length itself the pennated muscle differs by percents, checked
    below."""
    _, ours = _ours(arm)
    theirs, state, coords, muscles = _theirs(arm)
    rng = np.random.default_rng(3)
    worst, quirk = 0.0, 0.0
    for _ in range(40):
        for c in coords:
            c.setValue(state, float(rng.uniform(-1.2, 1.2)), False)
            c.setSpeedValue(state, float(rng.uniform(-3, 3)))
        theirs.realizeVelocity(state)
        for mu in muscles:
            law = ours[mu.getName().replace(".", "_")].law
            length, speed = mu.getLength(state), mu.getLengtheningSpeed(state)
            f_opt = mu.calcInextensibleTendonActiveFiberForce(state, 1.0)
            worst = max(worst, abs(opensim_so_strength(law, length, speed)[0] - f_opt))
            if law.pennation_angle_at_optimal > 0.2 and f_opt > 10.0:
                h = law.optimal_fibre_length * math.sin(law.pennation_angle_at_optimal)
                x = length - law.tendon_slack_length
                l_f = math.hypot(x, h)
                # the same force with cos α at l_f: F_opt cos α(l_f)/cos α(l̃)
                cos_true = x / l_f
                cos_used = math.sqrt(1 - (h / (l_f / law.optimal_fibre_length)) ** 2)
                quirk = max(quirk, abs(f_opt * cos_true / cos_used - f_opt) / f_opt)
    print(f"F_opt: |Δ| ≤ {worst:.1e} N; the pennation quirk is worth {quirk:.1%}")
    assert worst <= 1e-9
    assert quirk > 0.01


@pytest.mark.parametrize("edit,words", [
    (lambda m: m.find("ActiveForceLengthCurve").append(_element("plateau_width", "0.1")), "<plateau_width>"),
    (lambda m: m.find("TendonForceLengthCurve").remove(m.find("TendonForceLengthCurve/curviness")),
     "all be given or all be absent"),
    (lambda m: m.find("fiber_damping").__setattr__("text", "-1"), "fiber_damping"),
    (lambda m: m.append(_element("use_fiber_damping", "true")), "<use_fiber_damping> is not read"),
])
def test_bad_millard_values_are_one_line_errors(arm, tmp_path, edit, words):
    """An unknown property of the muscle or of a curve, a partial set of a curve's
    optional properties, an invalid value: one line naming the file, the muscle and what
    is wrong."""
    def apply(tree):
        m = tree.xpath("//Millard2012EquilibriumMuscle[@name='triceps']")[0]
        edit(m)
        return m

    path = tmp_path / "bad.osim"
    _edit(arm, path, apply)
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and path.name in msg and "triceps" in msg and words in msg, msg


def _element(tag, text):
    from lxml import etree

    e = etree.Element(tag)
    e.text = text
    return e


@pytest.mark.slow
def test_muscle_forces_equal_opensims_static_optimization(tmp_path, monkeypatch, capsys):
    """openfdk with ``recruitment: {power: 2, static_optimization: opensim}`` against
    OpenSim 4.6's StaticOptimization on the Millard arm with a reserve actuator (optimal
    force 1 N m) on each coordinate, on a smooth motion: muscle forces within 1 N. OpenSim
    uses calcInextensibleTendonActiveFiberForce for Millard muscles too
    (test_static_optimisation_strength_equals_opensims); the remaining difference is the
    coordinates' accelerations (OpenSim's quintic GCV spline against openfdk's cubic
    spline) and IPOPT's tolerance, as for the Thelen arm
    (tests/test_opensim_static_optimization.py)."""
    from openfdk.cli import main
    from openfdk.io.results import read_table

    monkeypatch.chdir(tmp_path)
    model, motion, (t, theirs) = om.arm_static_optimization(millard_arm(tmp_path / "arm.osim"), tmp_path)
    (tmp_path / "so.yaml").write_text("recruitment: {power: 2, static_optimization: opensim}\n")
    code = main(["run", str(model), "--motion", str(motion), "--with",
                 str(tmp_path / "so.yaml"), "--out", str(tmp_path / "ours"), "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    ours = read_table(tmp_path / "ours" / "forces.csv")
    worst = {}
    for name in MUSCLES:
        mine = name.replace(".", "_")
        f = np.interp(t, ours["time"], ours[f"{mine}.force_N"])
        worst[name] = float(np.max(np.abs(f - theirs[name])))
        print(name, "largest force (N):", float(np.max(theirs[name])))
        assert np.max(theirs[name]) > 5.0  # every muscle works
    for name in ("reserve_q_shoulder", "reserve_q_elbow"):
        f = np.interp(t, ours["time"], ours[f"{name}.actuator"])
        worst[name] = float(np.max(np.abs(f - theirs[name])))
    print("largest differences from OpenSim's StaticOptimization (N, N m):", worst)
    assert max(worst.values()) < 1.0
