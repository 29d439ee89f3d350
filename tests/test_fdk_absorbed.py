"""Muscles FDK can never recruit (openfdk.fdk.absorbed).

A thigh on a hinge to the ground and a patella on a six-coordinate CustomJoint to the
thigh, all six coordinates FDK DOFs; a patellar "tendon" ligament holds the patella to
the ground. Three muscles, built with OpenSim's API:

* ``vastus`` thigh → patella: an internal force of the pair thigh–patella, whose relative
  motion is the six FDK coordinates, so its column of C f = d is a combination of the six
  FDK residual columns (closed form: the residual generalized forces of a six-DOF
  relative joint span every internal load between the two bodies). Never recruited.
* ``rectus`` ground → patella: it pulls the pair as a whole, so it has a moment about the
  hinge; recruitable.
* ``hamstring`` ground → thigh: recruitable.

The hinge's coordinate is tracked by a driver with its reaction omitted (a pure driver),
so its moment must come from the muscles: the frame's recruitment gives the vastus 0 N
(to the square root of round-off) while the others carry the hinge moment.
"""

from __future__ import annotations

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from opensim_models import six_dof_transform  # noqa: E402

from cli_helpers import run_cli  # noqa: E402
from openfdk.dynamics.inverse import InverseDynamics  # noqa: E402
from openfdk.fdk.absorbed import fdk_absorbed_muscles  # noqa: E402
from openfdk.io.modelfile import load_model_and_settings  # noqa: E402
from openfdk.kinematics.system import ConstraintSystem  # noqa: E402

PF = ["pf_flex", "pf_rot", "pf_tilt", "pf_tx", "pf_ty", "pf_tz"]
HIP = 0.3  # rad, the driven hinge angle


def _v3(x):
    return opensim.Vec3(*[float(v) for v in x])


def _model(folder):
    m = opensim.Model()
    m.setName("absorbed")
    thigh = opensim.Body("thigh", 7.0, _v3([0, -0.2, 0]), opensim.Inertia(0.1, 0.02, 0.1))
    patella = opensim.Body("patella", 0.02, _v3([0, 0, 0]), opensim.Inertia(1e-5, 1e-5, 1e-5))
    m.addBody(thigh)
    m.addBody(patella)
    m.addJoint(opensim.PinJoint("hip", m.getGround(), _v3([0, 1.0, 0]), _v3([0, 0, 0]), thigh, _v3([0, 0, 0]),
                                _v3([0, 0, 0])))
    transform = six_dof_transform(PF)
    m.addJoint(opensim.CustomJoint("pf", thigh, _v3([0.05, -0.4, 0]), _v3([0, 0, 0]), patella, _v3([0, 0, 0]),
                                   _v3([0, 0, 0]), transform))
    for name, (b1, p1), (b2, p2) in (("vastus", (thigh, [0.03, -0.15, 0]), (patella, [0, 0.01, 0])),
                                     ("rectus", (m.getGround(), [0.04, 1.05, 0]), (patella, [0.0, 0.012, 0.003])),
                                     ("hamstring", (m.getGround(), [-0.06, 0.95, 0]), (thigh, [-0.03, -0.3, 0]))):
        mus = opensim.Thelen2003Muscle(name, 1500.0, 0.1, 0.2, 0.0)
        mus.addNewPathPoint(f"{name}_a", b1, _v3(p1))
        mus.addNewPathPoint(f"{name}_b", b2, _v3(p2))
        m.addForce(mus)
    tendon = opensim.Blankevoort1991Ligament("tendon", patella, _v3([0, -0.02, 0]), m.getGround(),
                                             _v3([0.05, 0.55, 0]), 2000.0, 0.05)
    m.addForce(tendon)
    m.finalizeConnections()
    state = m.initSystem()
    m.getCoordinateSet().get("hip_coord_0").setValue(state, HIP)
    m.realizePosition(state)
    for name in ("vastus", "rectus", "hamstring"):  # fibres at their optimal length at the pose
        mus = opensim.Thelen2003Muscle.safeDownCast(m.getForceSet().get(name))
        mus.setTendonSlackLength(mus.getLength(state) - mus.getOptimalFiberLength())
    lig = opensim.Blankevoort1991Ligament.safeDownCast(m.getForceSet().get("tendon"))
    lig.set_slack_length(lig.getLength(state) / 1.02)  # 2 % strain at the pose
    path = folder / "absorbed.osim"
    m.printToXML(str(path))
    return path


@pytest.fixture(scope="module")
def overlay(tmp_path_factory):
    folder = tmp_path_factory.mktemp("absorbed")
    _model(folder)
    (folder / "fdk.yaml").write_text("opensim: absorbed.osim\nfdk: [" + ", ".join(PF) + "]\n"
                                     "drivers:\n  hip_drive: {measure: hip_coord_0, function: {type: constant, value: " + str(HIP) + "}}\n")
    return folder / "fdk.yaml"


def test_the_muscle_inside_the_fdk_pair_is_absorbed_and_the_others_are_not(overlay):
    model, settings = load_model_and_settings(str(overlay))
    solver = InverseDynamics(model, ConstraintSystem(model), settings)
    assert fdk_absorbed_muscles(solver, model.initial_state()) == ["vastus"]
    # the closed form behind it: the vastus column is a combination of the six FDK
    # residual columns (least squares leaves nothing), the rectus column is not
    C, _, _, _, _ = solver.equilibrium(model.initial_state(), np.zeros(model.n_coords), 0.0,
                                       np.zeros(len(model.fdk_dofs)), forces=False)
    names = solver.layout.column_names
    F = C[:, [names.index(f"fdk.{n}") for n in PF]]
    for muscle, outside in (("vastus", False), ("rectus", True), ("hamstring", True)):
        c = C[:, names.index(muscle)]
        r = c - F @ np.linalg.lstsq(F, c, rcond=None)[0]
        assert np.linalg.norm(c) > 1e-3
        assert (np.linalg.norm(r) / np.linalg.norm(c) > 1e-3) == outside, muscle
    # the frame's recruitment: the hinge moment (the thigh's weight at 0.3 rad) is carried by
    # the rectus or the hamstring; the vastus gets exactly nothing
    state = model.initial_state()
    from openfdk.kinematics.determinate import solve_positions

    assert solve_positions(solver.system, state, 0.0, np.zeros(6)).converged
    fr = solver.frame(state, np.zeros(model.n_coords), 0.0, np.zeros(6))
    assert fr.converged, fr.message
    f = dict(zip(names, fr.f))
    s = dict(zip(names, fr.s))
    # 0 up to the square root of round-off in its dual (p = 3), against ≈ 40 N for the others
    assert abs(f["vastus"]) < 1e-6 * s["vastus"] and f["rectus"] + f["hamstring"] > 20.0, f


def test_check_names_them(overlay, capsys):
    code, out, err = run_cli(capsys, "check", overlay)
    line = next(x for x in out.splitlines() if "never recruit" in x)
    assert "vastus" in line and "rectus" not in line and "hamstring" not in line
