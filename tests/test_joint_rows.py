"""Force-dependent joint rows (``fdk: [x, y]``), per-row reactions, joint measures by
name, and ``expressed_in`` with a frame's orientation."""

import numpy as np
import pytest

from openfdk.fdk.analysis import run_fdk
from openfdk.forces.elements import add_external_load, add_spring
from openfdk.model.builder import ModelBuilder
from openfdk.model.model import ModelError
from openfdk.model.timefunctions import Constant
from openfdk.numerics.numdiff import manifold_jacobian
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix

K_SPRING = 2000.0  # N/m
F_LOAD = np.array([30.0, -12.0, 0.0])  # N, in the world
PARENT_ROT = np.array([0.0, 0.0, 0.4])  # the knee's parent frame is turned 0.4 rad about z


def _knee(formulation):
    """A shank hinged to the ground about z, flexion driven to 0.3 rad, the two in-plane
    translations of the hinge force-dependent with linear springs k, a known force F at
    the hinge. ``formulation``: "joint" (revolute with fdk: [x, y]) or "generic" (the
    same rows built by hand from measures)."""
    b = ModelBuilder("knee", gravity=(0, 0, 0))
    b.add_body("shank", 1.0, [0.01, 0.01, 0.002], position=[0, -0.2, 0])
    b.add_frame("ground", "knee", [0, 0, 0], orientation=quat_from_rotvec(PARENT_ROT))
    b.add_frame("shank", "knee", [0, 0.2, 0], orientation=quat_from_rotvec(PARENT_ROT))
    if formulation == "joint":
        b.add_joint("knee", "revolute", "ground.knee", "shank.knee", fdk={"x": {"max_step": 0.01}, "y": {"max_step": 0.01}})
        b.add_driver("flexion", "knee.angle", Constant([0.3]))
        pos = b.measure("knee.position")
        dofs = ["knee_x", "knee_y"]
    else:
        pos = b.add_measure("pos", b.vector("ground.knee", "shank.knee", expressed_in="ground.knee"))
        b.add_constraint("knee_z", pos, components=[2])
        b.add_constraint("knee_axis", b.axis_dot("ground.knee", [0, 0, 1], "shank.knee", [1, 0, 0]))
        b.add_constraint("knee_axis2", b.axis_dot("ground.knee", [0, 0, 1], "shank.knee", [0, 1, 0]))
        b.add_driver("flexion", b.angles("ground.knee", "shank.knee"), Constant([0.3]), components=[2])
        for j, axis in enumerate("xy"):
            b.add_fdk_dof(f"knee_{axis}", pos, component=j, max_step=0.01)
        dofs = ["knee_x", "knee_y"]
    for j, axis in enumerate("xy"):
        add_spring(b, f"spring_{axis}", b._select(pos, [j]), K_SPRING)
    add_external_load(b, "push", "shank.knee", force=F_LOAD)
    return b.build(), dofs


@pytest.mark.parametrize("formulation", ["joint", "generic"])
def test_revolute_with_fdk_rows_under_load_gives_F_over_k(formulation):
    model, dofs = _knee(formulation)
    assert [d.name for d in model.fdk_dofs] == dofs
    res = run_fdk(model, None, np.array([0.0, 0.1]), jacobian="analytic")
    assert res.converged.all(), res.messages
    # the springs act along the parent frame's x, y: α = R_Wpᵀ F / k
    expected = (rotation_matrix(quat_from_rotvec(PARENT_ROT)).T @ F_LOAD)[:2] / K_SPRING
    np.testing.assert_allclose(res.alpha, np.tile(expected, (2, 1)), atol=1e-3 / K_SPRING)
    assert np.abs(expected).min() > 1e-3


def test_joint_fdk_rows_leave_no_redundant_rows():
    model, _ = _knee("joint")
    names = model.constraint_row_names() if callable(model.constraint_row_names) else model.constraint_row_names
    assert "knee.x" not in names and "knee.y" not in names
    assert {"knee.z", "knee.zx", "knee.zy"} <= set(names)
    # rank of Φ_q̂ with the FDK rows: full (6 rows, 6 coordinates)
    from openfdk.kinematics.system import ConstraintSystem

    system = ConstraintSystem(model)
    state = model.initial_state()
    _, A, _, _ = system.evaluate(state, 0.0, np.zeros(2), order=1)
    assert A.shape == (6, 6) and np.linalg.matrix_rank(A) == 6


def test_row_reactions_can_be_switched_off():
    b = ModelBuilder("r")
    b.add_body("a", 1.0, [1, 1, 1])
    c = b.add_joint("hinge", "revolute", "ground.origin", "a.origin", reaction={"zx": False, "zy": False})
    model = b.build()
    by_name = {c.name: c for c in model.constraints}
    assert by_name["hinge"].reaction and by_name["hinge"].row_names == ("hinge.x", "hinge.y", "hinge.z")
    assert not by_name["hinge.passive"].reaction
    assert by_name["hinge.passive"].row_names == ("hinge.zx", "hinge.zy")
    assert c is by_name["hinge"]
    # the equilibrium has reaction columns for x, y, z only
    from openfdk.dynamics.equilibrium import equilibrium_layout
    from openfdk.kinematics.system import ConstraintSystem

    columns = equilibrium_layout(model, ConstraintSystem(model)).column_names
    assert {"hinge.x", "hinge.y", "hinge.z"} <= set(columns)
    assert "hinge.zx" not in columns and "hinge.zy" not in columns
    b2 = ModelBuilder("r2")
    b2.add_body("a", 1.0, [1, 1, 1])
    with pytest.raises(ModelError, match="unknown rows \\['w'\\]"):
        b2.add_joint("j", "revolute", "ground.origin", "a.origin", fdk=["w"])
    with pytest.raises(ModelError, match="FDK DOF and cannot carry a reaction"):
        b2.add_joint("j", "revolute", "ground.origin", "a.origin", fdk=["x"], reaction={"x": True})


def test_joint_measures_by_name_match_hand_built_values():
    b = ModelBuilder("m")
    R_p = quat_from_rotvec([0.1, 0.2, 0.3])
    b.add_body("a", 1.0, [1, 1, 1], position=[0.1, 0.02, 0.03], orientation=quat_from_rotvec([0.1, 0.2, 0.3 + 0.5]))
    b.add_frame("ground", "p", [0.05, 0, 0], orientation=R_p)
    b.add_frame("a", "c", [-0.05, 0.02, 0.03])
    b.add_joint("hinge", "revolute", "ground.p", "a.c")
    model = b.build()
    state = model.initial_state()
    # the body is turned by a further 0.5 rad about... its own axis composition; compute by hand
    R_Wp = rotation_matrix(R_p)
    R_Wa = state.R_WB[1]
    p_c = state.p_WB[1] + R_Wa @ np.array([-0.05, 0.02, 0.03])
    pos = model.measures["hinge.position"].evaluate(state, 0)[0]
    np.testing.assert_allclose(pos, R_Wp.T @ (p_c - [0.05, 0, 0]), atol=1e-15)
    R_pc = R_Wp.T @ R_Wa
    angle = model.measures["hinge.angle"].evaluate(state, 0)[0][0]
    angles = model.measures["hinge.angles"].evaluate(state, 0)[0]
    assert angles[2] == pytest.approx(angle)
    # x-y-z Cardan: R = Rx Ry Rz, so R[0, 1] / R[0, 0] = −tan θz
    assert angle == pytest.approx(np.arctan2(-R_pc[0, 1], R_pc[0, 0]), abs=1e-14)
    assert abs(angle) > 0.1


def test_expressed_in_frame_uses_the_frame_orientation():
    b = ModelBuilder("e")
    b.add_body("a", 1.0, [1, 1, 1], position=[0.1, 0.2, 0.3], orientation=quat_from_rotvec([0.3, -0.2, 0.1]))
    b.add_body("c", 1.0, [1, 1, 1], position=[0.3, -0.1, 0.2], orientation=quat_from_rotvec([-0.1, 0.4, 0.2]))
    R_aF = rotation_matrix(quat_from_rotvec([0.0, 0.0, np.pi / 2]))
    b.add_frame("a", "F", [0.01, 0.02, 0.0], orientation=R_aF)
    b.add_frame("c", "q", [0.0, 0.05, 0.01])
    in_body = b.vector("a.F", "c.q", expressed_in="a")
    in_frame = b.vector("a.F", "c.q", expressed_in="a.F")
    model = b.build()
    state = model.initial_state()
    w_B = in_body.evaluate(state, 0)[0]
    w_F = in_frame.evaluate(state, 0)[0]
    np.testing.assert_allclose(w_F, R_aF.T @ w_B, atol=1e-15)
    # a quarter turn about z: (x, y) -> (y, −x)
    np.testing.assert_allclose(w_F, [w_B[1], -w_B[0], w_B[2]], atol=1e-15)
    _, M, _ = in_frame.evaluate(state, 1)
    fd = manifold_jacobian(lambda s: in_frame.evaluate(s, 0)[0], state)
    np.testing.assert_allclose(M, fd, atol=1e-9)
    assert np.abs(M).max() > 0.5


def test_model_file_joint_keys(tmp_path):
    from openfdk.io.modelfile import load_model

    text = """
units: {length: mm, angle: deg}
gravity: [0, 0, 0]
bodies:
  shank: {mass: 1.0, inertia: [0.01, 0.01, 0.002], position: [0, -200, 0], frames: {knee: [0, 200, 0]}}
joints:
  knee: {type: revolute, parent: ground.origin, child: shank.knee, fdk: {x: {max_step: 10}, y: {initial: 0}}}
drivers:
  flexion: {measure: knee.angle, function: {type: constant, value: 20}}
springs:
  kx: {measure: knee.position, component: 0, stiffness: 2000}
  ky: {measure: knee.position, component: 1, stiffness: 2000}
loads:
  push: {point: shank.knee, force: [30, -12, 0]}
"""
    f = tmp_path / "knee.yaml"
    f.write_text(text)
    model = load_model(str(f))
    assert [d.name for d in model.fdk_dofs] == ["knee_x", "knee_y"]
    assert model.fdk_dofs[0].settings["max_step"] == pytest.approx(0.01)
    res = run_fdk(model, None, np.array([0.0]), jacobian="analytic")
    assert res.converged.all(), res.messages
    np.testing.assert_allclose(res.alpha[0], F_LOAD[:2] / K_SPRING, atol=1e-3 / K_SPRING)
    bad = text.replace("fdk: {x: {max_step: 10}, y: {initial: 0}}", "fdk: [x, w]")
    f.write_text(bad)
    with pytest.raises(ModelError, match=r"knee.yaml: joints.knee: .*unknown rows \['w'\]"):
        load_model(str(f))


def test_joint_measures_are_written_to_measures_csv(tmp_path):
    import csv

    from openfdk.cli import main

    model = tmp_path / "pendulum.yaml"
    model.write_text("""
units: {length: m, angle: deg}
bodies:
  arm: {mass: 1.0, inertia: [0.01, 0.01, 0.01], position: [0, -0.5, 0], frames: {pivot: [0, 0.5, 0]}}
joints:
  pin: {type: revolute, parent: ground.origin, child: arm.pivot}
drivers:
  swing: {measure: pin.angle, function: {type: polynomial, coefficients: [0, 30]}}
analysis: {start: 0, end: 1, frames: 5}
""")
    assert main(["kinematics", str(model), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "out" / "measures.csv")))
    assert len(rows) == 5
    np.testing.assert_allclose([float(r["pin.angle_rad"]) for r in rows], np.radians(30 * np.linspace(0, 1, 5)), atol=1e-9)
    # the pivot stays at the ground origin: position ≈ 0
    assert max(abs(float(r["pin.position[0]_m"])) for r in rows) < 1e-9
