"""Coordinate actuators (reserve and residual actuators) as recruitment columns weighted by
their optimal force, against closed forms and OpenSim 4.6's static optimisation.

Closed form: actuators j acting on one coordinate with total generalised force T share it
by min Σ |τ_j/F_j|^p s.t. Σ τ_j = T, whose stationarity p |τ_j|^(p−1)/F_j^p = λ gives
τ_j = T F_j^(p/(p−1)) / Σ_k F_k^(p/(p−1)).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from cli_helpers import error_line
from openfdk.cli import main
from openfdk.io.results import read_table
from openfdk.recruitment.polynomial import solve_polynomial


def _share(T, F, p):
    w = np.asarray(F, float) ** (p / (p - 1.0))
    return T * w / w.sum()


@pytest.mark.parametrize("p", [2.0, 3.0, 4.5])
def test_actuators_share_a_load_by_their_optimal_forces(p):
    """Two actuators on one row, each split in τ⁺/τ⁻ columns without bounds (upper = +inf),
    plus a muscle: closed form of the split, cold and warm started, both signs."""
    F = np.array([2.0, 5.0])
    for T in (-7.3, 4.1):
        C = np.array([[1.0, 1.0, -1.0, -1.0]])
        res = solve_polynomial(C, np.array([T]), 4, np.r_[F, F], p, upper=np.full(4, np.inf))
        assert res.converged
        tau = res.f[:2] - res.f[2:]
        np.testing.assert_allclose(tau, _share(T, F, p), rtol=1e-9, atol=1e-12)
        assert np.all(res.f[:2] * res.f[2:] == 0.0)  # never both signs at once
        warm = solve_polynomial(C, np.array([T * 1.01]), 4, np.r_[F, F], p, upper=np.full(4, np.inf), x0=res)
        np.testing.assert_allclose(warm.f[:2] - warm.f[2:], _share(1.01 * T, F, p), rtol=1e-9)


def test_control_bounds_saturate_and_infeasible_is_diagnosed():
    """max/min control bound the actuator (|τ| ≤ u F); the rest goes to the other one;
    beyond both bounds the frame is infeasible, with the row named."""
    F = np.array([2.0, 5.0])
    C = np.array([[1.0, 1.0, -1.0, -1.0]])
    # τ⁻ of the first limited to 0.5 F = 1 N m: it saturates, the second takes the rest
    res = solve_polynomial(C, np.array([-7.3]), 4, np.r_[F, F], 2.0, upper=np.array([1.0, 1.0, 0.5, 2.0]))
    assert res.converged
    np.testing.assert_allclose(res.f[:2] - res.f[2:], [-1.0, -6.3], atol=1e-9)
    assert res.active_upper[2] and not res.active_upper[3]
    bad = solve_polynomial(C, np.array([-7.3]), 4, np.r_[F, F], 2.0, upper=np.ones(4), row_names=["knee"])
    assert not bad.converged and "knee" in bad.message
    with pytest.raises(ValueError, match="upper"):
        solve_polynomial(C, np.array([1.0]), 4, np.r_[F, F], 2.0, upper=np.array([1.0, 0.0, 1.0, 1.0]))


def _arm(folder):
    """A two-link arm built with OpenSim's API: two CoordinateActuators per pin joint
    (optimal forces 10 and 4 N m, 3 and 7 N m), two PointActuators and two
    TorqueActuators in every combination of frames, a smooth motion in a .mot."""
    opensim = pytest.importorskip("opensim")
    import opensim_models as om

    m, b1, b2 = om.two_link_arm("arm2")
    for name, coordinate, force in (("a1", "q1", 10.0), ("a1b", "q1", 4.0), ("a2", "q2", 3.0), ("a2b", "q2", 7.0)):
        a = opensim.CoordinateActuator(coordinate)
        a.setName(name)
        a.setOptimalForce(force)
        a.setMinControl(-1e3)
        a.setMaxControl(1e3)
        m.addForce(a)
    # a force at a body point (global direction, non-unit as OpenSim allows), one at a
    # ground point acting on the body there (direction in the body), and two torques
    pa = opensim.PointActuator("lower")
    pa.setName("px")
    pa.set_point(opensim.Vec3(0.02, -0.2, 0.01))
    pa.set_point_is_global(False)
    pa.set_direction(opensim.Vec3(0.6, 0.8, 0))
    pa.set_force_is_global(True)
    pa.setOptimalForce(20)
    m.addForce(pa)
    pb = opensim.PointActuator("upper")
    pb.setName("pb")
    pb.set_point(opensim.Vec3(0.1, 0.7, 0.0))
    pb.set_point_is_global(True)
    pb.set_direction(opensim.Vec3(0, 0.3, 1))
    pb.set_force_is_global(False)
    pb.setOptimalForce(15)
    m.addForce(pb)
    ta = opensim.TorqueActuator(b2, b1, opensim.Vec3(0.2, 0.1, 1), True)
    ta.setName("tq")
    ta.setOptimalForce(6)
    m.addForce(ta)
    tb = opensim.TorqueActuator(b1, m.getGround(), opensim.Vec3(0, 0.3, 1), False)
    tb.setName("tq2")
    tb.setOptimalForce(5)
    m.addForce(tb)
    m.finalizeConnections()
    m.initSystem()
    m.printToXML(str(folder / "arm2.osim"))
    t = np.linspace(0, 1, 201)
    motion = om.write_motion(folder / "motion.mot", t, {"q1": 0.3 + 0.5 * np.sin(2 * np.pi * 0.8 * t),
                                                        "q2": 0.8 + 0.4 * np.sin(2 * np.pi * 1.1 * t + 0.5)})
    return opensim, folder / "arm2.osim", motion


@pytest.mark.slow
def test_static_optimisation_equals_opensims(tmp_path, monkeypatch, capsys):
    """openfdk with OpenSim's setting (p = 2) against OpenSim's StaticOptimization on the
    same .osim and .mot, with coordinate, point and torque actuators. The remaining
    difference (≤ 1e-3 relative; 4.9e-4 N of 4 N measured, 6e-4 N until stop 64's
    quintic spline) is the coordinates' second derivatives: both fit OpenSim's quintic
    spline to the samples, but OpenSim's static optimisation takes q̈ from a second
    quintic spline through the first one's q̇; on one coordinate the ratio of the two
    actuators is the closed form's to round-off."""
    monkeypatch.chdir(tmp_path)
    opensim, model, motion = _arm(tmp_path)
    import opensim_models as om

    t, theirs = om.static_optimization(model, motion, tmp_path)

    (tmp_path / "p2.yaml").write_text("recruitment: {power: 2}\n")
    code = main(["run", str(model), "--motion", str(motion), "--with", str(tmp_path / "p2.yaml"),
                 "--out", str(tmp_path / "ours"), "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    ours = read_table(tmp_path / "ours" / "forces.csv")
    assert not any(k.endswith(".reaction") and k.split(".")[0] in ("a1", "a1b") for k in ours)
    for name in ("a1", "a1b", "a2", "a2b", "px", "pb", "tq", "tq2"):
        mine = np.interp(t, ours["time"], ours[f"{name}.actuator"])
        assert np.max(np.abs(mine - theirs[name])) < 1e-3 * max(1.0, np.max(np.abs(theirs[name]))), name
        assert np.max(np.abs(theirs[name])) > 0.1  # every actuator works
    # the closed-form split on each coordinate, at every frame
    np.testing.assert_allclose(ours["a1.actuator"], ours["a1b.actuator"] * (10.0 / 4.0) ** 2, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(ours["a2b.actuator"], ours["a2.actuator"] * (7.0 / 3.0) ** 2, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(ours["a2.control"], ours["a2.actuator"] / 3.0, rtol=1e-8)  # (CSV: 10 digits)


def _full_body_id(tmp_path, capsys):
    """The full-body model driven by a smooth motion (12 frames), and its plain inverse
    dynamics in ``id/`` (the drivers' reactions; checked against OpenSim's ID in
    test_opensim_inverse_dynamics)."""
    from openfdk.fixtures.full_body_osim import COORDINATES, write_full_body_osim
    from openfdk.io.storage import write_storage

    model = write_full_body_osim(tmp_path / "full_body.osim")
    t = np.arange(12) / 100.0
    rng = np.random.default_rng(3)
    cols = {}
    for name in COORDINATES:
        base = {"pelvis_ty": 0.95, "knee_angle_r": -0.6, "knee_angle_l": -0.6}.get(name, 0.0)
        cols[name] = base + rng.uniform(0.02, 0.2) * np.sin(2 * np.pi * rng.uniform(0.5, 1.5) * t + rng.uniform(0, 6))
    write_storage(tmp_path / "motion.mot", t, cols, name="motion")
    code = main(["run", str(model), "--motion", "motion.mot", "--out", "id", "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    return model, COORDINATES, read_table(tmp_path / "id" / "generalized_forces.csv")


def test_reserves_are_the_generalised_forces_when_determinate(tmp_path, monkeypatch, capsys):
    """The full-body model driven by a motion: with one reserve or residual actuator per
    coordinate and no muscle, the recruitment is determinate and every actuator equals the
    coordinate's generalised force of plain inverse dynamics (a cost-free driver
    reaction, checked against OpenSim's ID elsewhere) — whatever the weights. The
    residual summary reads the residual actuators."""
    monkeypatch.chdir(tmp_path)
    model, coordinates, ref = _full_body_id(tmp_path, capsys)
    (tmp_path / "reserves.yaml").write_text(yaml.safe_dump(
        {"reserves": {"optimal_force": 2.0, "residual_force": 50.0, "residual_moment": 0.5}}))
    code = main(["run", str(model), "--motion", "motion.mot", "--with", "reserves.yaml", "--out", "so", "--no-plots",
                 "-q"])
    assert code == 0, capsys.readouterr().err
    so = read_table(tmp_path / "so" / "forces.csv")
    assert not (tmp_path / "so" / "generalized_forces.csv").exists()  # no driver carries a reaction
    for name in coordinates:
        root = name.startswith("pelvis")
        actuator = f"{'residual' if root else 'reserve'}_{name}.actuator"
        key = f"{name}_{'force' if name in ('pelvis_tx', 'pelvis_ty', 'pelvis_tz') else 'moment'}"
        scale = max(1.0, float(np.max(np.abs(ref[key]))))
        assert np.max(np.abs(so[actuator] - ref[key])) < 1e-7 * scale, name
    assert np.max(np.abs(ref["pelvis_ty_force"])) > 100.0
    res_id = json.loads((tmp_path / "id" / "summary.json").read_text())["residuals"]
    res_so = json.loads((tmp_path / "so" / "summary.json").read_text())["residuals"]
    assert set(res_so["columns"]) == set(res_id["columns"])
    for key, stats in res_id["columns"].items():
        assert abs(res_so["columns"][key]["peak"] - stats["peak"]) < 1e-6 * max(1.0, stats["peak"])


def test_residual_point_and_torque_actuators(tmp_path, monkeypatch, capsys):
    """OpenSim's residual actuators as Gait2392's SO setup gives them (PointActuators FX,
    FY, FZ at a pelvis point, global directions; TorqueActuators MX, MY, MZ pelvis–ground;
    3.x isDisabled and a <defaults> block), with reserves on every other coordinate: the
    frame is determinate, and the three forces equal the generalised forces of the
    pelvis translations (along the ground's axes) of plain inverse dynamics; the summary
    reports them as residuals."""
    monkeypatch.chdir(tmp_path)
    model, coordinates, ref = _full_body_id(tmp_path, capsys)
    parts = []
    for k, axis in enumerate("XYZ"):
        d = " ".join("1" if i == k else "0" for i in range(3))
        parts.append(f'<PointActuator name="F{axis}"><isDisabled>false</isDisabled><body>pelvis</body>'
                     f"<point>-0.07 0.01 0</point><point_is_global>false</point_is_global><direction>{d}</direction>"
                     f"<force_is_global>true</force_is_global><optimal_force>{100 + 50 * k}</optimal_force>"
                     "<min_control>-1e4</min_control><max_control>1e4</max_control></PointActuator>")
        parts.append(f'<TorqueActuator name="M{axis}"><bodyA>pelvis</bodyA><bodyB>ground</bodyB>'
                     f"<torque_is_global>true</torque_is_global><axis>{d}</axis><optimal_force>80</optimal_force>"
                     "</TorqueActuator>")
    (tmp_path / "residuals.xml").write_text(
        '<?xml version="1.0"?>\n<OpenSimDocument Version="20302"><ForceSet name="res"><defaults>'
        '<PointActuator name="default"><optimal_force>1000</optimal_force></PointActuator></defaults><objects>'
        + "".join(parts) + "</objects></ForceSet></OpenSimDocument>\n")
    (tmp_path / "reserves.yaml").write_text("reserves: {optimal_force: 3.0, residuals: false}\n")
    code = main(["run", str(model), "--motion", "motion.mot", "--with", "reserves.yaml", "--actuators",
                 "residuals.xml", "--out", "so", "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    so = read_table(tmp_path / "so" / "forces.csv")
    for axis, coordinate in zip("XYZ", ("pelvis_tx", "pelvis_ty", "pelvis_tz")):
        expected = ref[f"{coordinate}_force"]
        assert np.max(np.abs(so[f"F{axis}.actuator"] - expected)) < 1e-7 * max(1.0, np.max(np.abs(expected)))
    assert np.max(np.abs(so["FY.actuator"])) > 100.0
    assert not any(k.startswith("reserve_pelvis") or k.startswith("residual_") for k in so)
    summary = json.loads((tmp_path / "so" / "summary.json").read_text())["residuals"]
    res = summary["columns"]
    assert set(res) == {"FX_force", "FY_force", "FZ_force", "MX_moment", "MY_moment", "MZ_moment"}
    # the actuators' figure: every actuator's force and control, the residual threshold
    from openfdk.plots.run import make_figures
    from openfdk.results.run import RunResults

    results = RunResults.read(tmp_path / "so")
    fig = make_figures(results, measures=[])["actuators"]
    force_axis, control_axis = fig.axes[:2]
    n = len(results.actuators())
    assert n == 6 + 17 and len(control_axis.lines) == n and len(force_axis.lines) == n + 2
    threshold = force_axis.lines[0].get_ydata()[0]
    assert threshold == pytest.approx(summary["force_threshold_N"]) and threshold > 0
    assert abs(res["FY_force"]["peak"] - np.max(np.abs(ref["pelvis_ty_force"]))) < 1e-6 * res["FY_force"]["peak"]


def _yaml_model(folder, actuators, extra=None):
    """A one-body pendulum on a hinge (custom joint with one coordinate), driven."""
    data = {
        "openfdk": 1, "units": {"length": "m", "angle": "rad"},
        "bodies": {"link": {"mass": 1.0, "inertia": [0.01, 0.01, 0.01], "position": [0, -0.2, 0]}},
        "coordinates": {"q": {"default": 0.0}},
        "joints": {"hinge": {"type": "custom", "parent": "ground", "child": "link",
                             "rotations": [{"axis": [0, 0, 1], "coordinate": "q"}]}},
        "drivers": {"q_motion": {"measure": "q", "function": {"type": "fourier", "frequency": 1.0, "a": [0.0, 0.3],
                                                               "b": [0.0]}}},
        "analysis": {"start": 0.0, "end": 0.1, "frames": 3},
        "actuators": actuators,
    }
    data.update(extra or {})
    (folder / "m.yaml").write_text(yaml.safe_dump(data))
    return folder / "m.yaml"


def test_bad_actuators_end_in_one_line(tmp_path, capsys):
    cases = [
        ({"a": {"coordinate": "nope", "optimal_force": 1.0}}, None, "actuators.a.coordinate: unknown coordinate"),
        ({"a": {"coordinate": "q", "optimal_force": 0.0}}, None, "actuators.a.optimal_force: must be > 0"),
        ({"a": {"coordinate": "q", "optimal_force": 1.0, "min_control": 0.5}}, None, "must contain 0"),
        ({"a": {"coordinate": "q", "optimal_force": 1.0, "gain": 2}}, None, "actuators.a.gain: unknown key"),
        ({"a": {"coordinate": "q", "optimal_force": 1.0}}, {"recruitment": {"criterion": "minmax"}},
         "polynomial criterion"),
        ({}, {"recruitment": {"static_optimization": "anybody"}}, "recruitment.static_optimization"),
        ({}, {"recruitment": {"static_optimization": "opensim", "criterion": "minmax"}}, "polynomial criterion"),
    ]
    for actuators, extra, expected in cases:
        path = _yaml_model(tmp_path, actuators, extra)
        code = main(["run", str(path), "--out", str(tmp_path / "out"), "--force", "--no-plots", "-q"])
        line = error_line(capsys.readouterr().err)
        assert code == 2, (actuators, line)
        assert expected in line and "m.yaml" in line, line


def test_actuator_files_of_opensim(tmp_path, monkeypatch, capsys):
    """--actuators reads an OpenSim actuator file: CoordinateActuators are recruited, a
    disabled one is dropped and listed, another force type is refused by name and line."""
    from openfdk.fixtures.full_body_osim import write_full_body_osim

    monkeypatch.chdir(tmp_path)
    model = write_full_body_osim(tmp_path / "full_body.osim")

    def file(body):
        (tmp_path / "act.xml").write_text(
            f'<?xml version="1.0"?>\n<OpenSimDocument Version="40000"><ForceSet name="reserves"><objects>{body}'
            "</objects></ForceSet></OpenSimDocument>\n")
        return "act.xml"

    good = ('<CoordinateActuator name="hip_r"><coordinate>hip_flexion_r</coordinate><optimal_force>5</optimal_force>'
            "<min_control>-Inf</min_control><max_control>Inf</max_control></CoordinateActuator>"
            '<CoordinateActuator name="off"><appliesForce>false</appliesForce><coordinate>hip_flexion_l</coordinate>'
            "</CoordinateActuator>")
    from openfdk.io.opensim.overlay import imported_model_data, register

    register(model, actuators=file(good))
    data = imported_model_data(model)
    assert data["actuators"] == {"hip_r": {"coordinate": "hip_flexion_r", "optimal_force": 5.0}}
    for body, expected in (
            ('<PointActuator name="fx"><body>pelvis</body></PointActuator>', "line 2: PointActuator 'fx'"),
            ('<CoordinateActuator name="x"><coordinate>elbow</coordinate></CoordinateActuator>',
             "unknown coordinate 'elbow'"),
            ('<CoordinateActuator name="x"><coordinate>hip_flexion_r</coordinate><optimal_force>-1</optimal_force>'
             "</CoordinateActuator>", "line 2: CoordinateActuator 'x': optimal_force must be a positive number")):
        code = main(["check", str(model), "--actuators", file(body)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "act.xml" in err[0] and expected in err[0], err
        assert err[0].count("Actuator '") == 1, err  # the actuator named once (stop 72's sweep: twice)


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_lower_activity_bounds_closed_form(p):
    """A minimum activation l (OpenSim's min_control of a muscle): three muscles of
    strengths s on one row d; with Σ x_i s_i = d and x_i ≥ l the optimum is the
    closed form x_i ∝ s_i^(1/(p−1)) on the muscles above l, and l on the others (the
    weak muscles held at their floor) — cold and warm started."""
    s = np.array([100.0, 400.0, 5.0])
    C = np.array([[1.0, 1.0, 1.0]])
    lower = np.full(3, 0.05)
    d = 30.0
    res = solve_polynomial(C, np.array([d]), 3, s, p, lower=lower)
    assert res.converged
    x = res.f / s
    # closed form (KKT): x_i = ρ s_i^(1/(p−1)) on the free set, l on the held set; move
    # any free x_i below l to the held set until none is
    held = np.zeros(3, bool)
    while True:
        rest = d - np.sum(lower[held] * s[held])
        rho = rest / np.sum(s[~held] ** (p / (p - 1.0)))
        expected = np.where(held, lower, rho * s ** (1.0 / (p - 1.0)))
        if not np.any(expected[~held] < lower[~held]):
            break
        held |= expected < lower
    np.testing.assert_allclose(x, expected, rtol=1e-9)
    np.testing.assert_array_equal(res.active_lower, held)
    assert held[2] and not held.all()
    # without the floor the weakest muscle would be below it: the bound is active for real
    free = solve_polynomial(C, np.array([d]), 3, s, p)
    assert free.f[2] / s[2] < 0.05
    warm = solve_polynomial(C, np.array([d]), 3, s, p, lower=lower, x0=res)
    np.testing.assert_allclose(warm.f, res.f, rtol=1e-9)
    with pytest.raises(ValueError, match="lower"):
        solve_polynomial(C, np.array([d]), 3, s, p, lower=np.full(3, 1.5))
