"""OpenSim's SpringGeneralizedForce (stiffness, rest length, viscosity) imported as a
linear spring with a parallel damper on its coordinate, its CoordinateLimitForce
(limits, stiffnesses and damping per degree, a smooth transition) as openfdk's limit
law and its ExpressionBasedCoordinateForce as a safely parsed expression, against OpenSim 4.6's InverseDynamicsSolver on the same analytic motion (q, q̇, q̈
exact on both sides): the generalised forces agree to 1e-6 N m, and the springs and
limits change them."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

opensim = pytest.importorskip("opensim")

import opensim_models as om  # noqa: E402  (tests/opensim_models.py)

from openfdk.cli import main  # noqa: E402
from openfdk.io.results import read_table  # noqa: E402

MOTION = {"q1": (0.3, 0.5, 0.8, 0.0), "q2": (0.8, 0.4, 1.1, 0.5)}  # a + b sin(2π f t + φ)


def _q(name, t, order=0):
    a, b, f, phi = MOTION[name]
    w = 2 * np.pi * f
    return [a + b * np.sin(w * t + phi), b * w * np.cos(w * t + phi), -b * w * w * np.sin(w * t + phi)][order]


def _model(path, springs=True, limits=True):
    m, _, _ = om.two_link_arm("arm")
    if springs:
        s1 = opensim.SpringGeneralizedForce("q1")
        s1.setName("spring_q1")
        s1.setStiffness(3.0)
        s1.setRestLength(0.2)
        s1.setViscosity(0.5)
        m.addForce(s1)
        s2 = opensim.SpringGeneralizedForce("q2")
        s2.setName("damper_q2")
        s2.setViscosity(0.8)
        m.addForce(s2)
    if limits:  # q2 swings 0.4–1.2 rad: past both limits (35°, 60°) and through the 5° transitions
        m.addForce(opensim.CoordinateLimitForce("q2", 60.0, 2.0, 35.0, 3.0, 0.05, 5.0))
        expr = opensim.ExpressionBasedCoordinateForce("q1", "-2.5*(q-0.3)^3 - 0.4*qdot*abs(qdot) + 0.2*sin(q)")
        expr.setName("expr_q1")
        m.addForce(expr)
    m.finalizeConnections()
    m.initSystem()
    m.printToXML(str(path))
    return path


def _opensim_id(path, times):
    model = opensim.Model(str(path))
    state = model.initSystem()
    cs = model.getCoordinateSet()
    solver = opensim.InverseDynamicsSolver(model)
    out = {"q1": [], "q2": []}
    for t in times:
        state.setTime(float(t))
        for name in out:
            cs.get(name).setValue(state, _q(name, t), False)
        model.assemble(state)
        for name in out:
            cs.get(name).setSpeedValue(state, _q(name, t, 1))
        model.realizeVelocity(state)
        udot = opensim.Vector([_q("q1", t, 2), _q("q2", t, 2)])
        tau = solver.solve(state, udot)
        out["q1"].append(tau.get(0))
        out["q2"].append(tau.get(1))
    return {k: np.array(v) for k, v in out.items()}


def test_spring_generalized_forces_equal_opensims_inverse_dynamics(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    model = _model(tmp_path / "arm.osim")
    times = np.linspace(0.1, 0.9, 81)
    drivers = {f"{n}_motion": {"measure": n, "reaction": True, "function": {
        "type": "fourier", "frequency": f, "a": [a, float(b * np.sin(phi))], "b": [float(b * np.cos(phi))]}}
        for n, (a, b, f, phi) in MOTION.items()}
    (tmp_path / "motion.yaml").write_text(yaml.safe_dump(
        {"drivers": drivers, "analysis": {"start": 0.1, "end": 0.9, "frames": 81}}))
    code = main(["run", str(model), "--with", "motion.yaml", "--out", "ours", "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    ours = read_table(tmp_path / "ours" / "generalized_forces.csv")
    import json

    assert json.loads((tmp_path / "ours" / "summary.json").read_text())["kinematics"]["model"] == "arm"
    theirs = _opensim_id(model, times)
    bare = _opensim_id(_model(tmp_path / "bare.osim", springs=False, limits=False), times)
    no_limits = _opensim_id(_model(tmp_path / "no_limits.osim", limits=False), times)
    for name in ("q1", "q2"):
        assert np.max(np.abs(ours[f"{name}_moment"] - theirs[name])) < 1e-6, name
    # the spring and the damper are in the generalised forces: τ = τ_bare − f_spring
    spring = -3.0 * (_q("q1", times) - 0.2) - 0.5 * _q("q1", times, 1)
    np.testing.assert_allclose(no_limits["q1"], bare["q1"] - spring, atol=1e-9)
    np.testing.assert_allclose(no_limits["q2"], bare["q2"] + 0.8 * _q("q2", times, 1), atol=1e-9)
    assert np.max(np.abs(spring)) > 0.1
    # the motion crosses both transition bands (30–35° and 60–65°)
    q2 = np.degrees(_q("q2", times))
    assert np.any((q2 > 30) & (q2 < 35)) and np.any((q2 > 60) & (q2 < 65))
    # the limit force acts (past the limits), and only on q2
    assert np.max(np.abs(theirs["q2"] - no_limits["q2"])) > 0.5
    # the expression on q1: τ = τ_no_limits − f(q, q̇), its closed form
    q1, q1d = _q("q1", times), _q("q1", times, 1)
    expr = -2.5 * (q1 - 0.3) ** 3 - 0.4 * q1d * np.abs(q1d) + 0.2 * np.sin(q1)
    np.testing.assert_allclose(theirs["q1"], no_limits["q1"] - expr, atol=1e-9)
    assert np.max(np.abs(expr)) > 0.1


def test_bad_springs_are_one_line_errors(tmp_path, capsys):
    model = _model(tmp_path / "arm.osim")
    text = model.read_text()
    for old, new, words in (("<viscosity>0.8", "<viscosity>-1", "viscosity must be"),
                            ("<coordinate>q2", "<coordinate>q9", "unknown coordinate 'q9'"),
                            ("<expression>", "<expression>__import__('os').getcwd() + ",
                             "only the functions"),
                            ("<expression>", "<expression>q.real + ", "Attribute is not allowed"),
                            ("<expression>", "<expression>x + ", "unknown name 'x'")):
        bad = tmp_path / "bad.osim"
        bad.write_text(text.replace(old, new, 1))
        code = main(["check", str(bad)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "bad.osim" in err[0] and words in err[0], err
