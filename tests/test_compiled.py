"""Compiled measures (openfdk.model.compiled): every op-code against the Python
evaluation (the reference) and against finite differences on the manifold (q ⊕ ε e_k):
value, Jacobian and acceleration bias, each non-zero."""

import numpy as np
import pytest

from openfdk.model.builder import ModelBuilder
from openfdk.model.compiled import CompiledMeasures, MeasureCompileError
from openfdk.model.coordinate_functions import polynomial, simm_spline
from openfdk.model.function_measure import FunctionOf
from openfdk.model.measures import Linear, Measure
from openfdk.numerics.numdiff import manifold_jacobian, second_derivative_along
from openfdk.numerics.spatial import quat_from_rotvec

from test_measures import ALL, _add_two_bodies_with_frame_j, _model_and_state

JOINTS = ["weld", "spherical", "revolute", "prismatic", "point_on_plane"]


def _joint_measures(seed=7):
    rng = np.random.default_rng(seed)
    b = ModelBuilder("joints")
    _add_two_bodies_with_frame_j(b, rng)
    for k, jt in enumerate(JOINTS):
        b.add_joint(f"j_{jt}", jt, parent="a.j", child="b.j")
    # a driver on one Cardan angle, a muscle-like via-point path, an FDK-DOF-like row
    from openfdk.forces.elements import path_measure
    from openfdk.model.timefunctions import Polynomial

    b.add_frame("a", "via", rng.normal(size=3) * 0.05)
    b.add_driver("drive", b.angles("a.j", "b.j"), Polynomial([[0.1], [0.2]]), components=[1])
    path = path_measure(b, ["ground.origin", "a.via", "b.j"], "path")
    model = b.build()
    state = model.initial_state()
    state.set_v(rng.normal(size=model.n_coords))
    measures = {c.name: c.measure for c in model.constraints}
    measures["via_point_path"] = path
    measures["angles_zxz"] = b.angles("a.j", "b.j", sequence="zxz")
    measures["jcs_knee_left"] = b.jcs_angles("a.j", "b.j", joint="knee", side="left")
    measures["fdk_row"] = Linear([(np.array([[0.0, 0.0, 1.0]]), b.vector("a.j", "b.j", expressed_in="a"))])
    # OP_FUNCTION: a spline of a Cardan angle (an OpenSim knee translation) and a coupler
    # row q_dep − f(q_indep) (a distance coupled to an angle by a polynomial)
    x = np.linspace(-4.0, 4.0, 9)
    angle = Linear([(np.array([[0.0, 1.0, 0.0]]), measures["angles_zxz"])])
    measures["function_of"] = FunctionOf(simm_spline(x, 0.05 * np.sin(1.3 * x) + 0.01 * x**2), angle, "length")
    coupled = FunctionOf(polynomial([0.3, -0.2, 0.05]), Linear([(np.array([[1.0, 0.0, 0.0]]), measures["angles_zxz"])]))
    measures["coupler_row"] = Linear([(np.ones((1, 1)), b.distance("a.j", "b.origin")), (-np.ones((1, 1)), coupled)])
    return model, state, measures


def _cases():
    out = [("basic", name) for name in ALL]
    out += [("joints", f"j_{jt}") for jt in JOINTS]
    out += [("joints", "drive"), ("joints", "via_point_path"), ("joints", "fdk_row")]
    out += [("joints", "angles_zxz"), ("joints", "jcs_knee_left")]
    out += [("joints", "function_of"), ("joints", "coupler_row")]
    return out


def _get(kind, name, seed):
    model, state, measures = _model_and_state(seed=seed) if kind == "basic" else _joint_measures(seed=seed + 4)
    return state, measures[name]


@pytest.mark.parametrize("kind,name", _cases())
def test_compiled_equals_python_and_finite_differences(kind, name):
    state, m = _get(kind, name, seed=3)
    prog = CompiledMeasures([m])
    val, M, b = prog.evaluate(state, 2)
    ref_val, ref_M, ref_b = m.evaluate(state, 2)
    # the Python evaluation is the reference
    np.testing.assert_allclose(val, ref_val, rtol=0, atol=1e-14)
    np.testing.assert_allclose(M, ref_M, rtol=0, atol=1e-13)
    np.testing.assert_allclose(b, ref_b, rtol=1e-12, atol=1e-12)
    # and independently: finite differences on the manifold, non-zero derivatives
    assert np.max(np.abs(M)) > 1e-3, "Jacobian must not vanish"
    M_fd = manifold_jacobian(lambda s: prog.evaluate(s, 0)[0], state, eps=1e-6)
    np.testing.assert_allclose(M, M_fd, atol=1e-8, rtol=1e-6)
    assert np.max(np.abs(b)) > 1e-4, "bias must not vanish for a non-zero velocity"
    b_fd = second_derivative_along(lambda s: prog.evaluate(s, 0)[0], state, state.get_v(), h=1e-4)
    np.testing.assert_allclose(b, b_fd, atol=2e-6, rtol=1e-5)
    # the value itself against an independent formula for the simple leaves
    if name == "distance":
        pa = state.p_WB[m.vector.point_a.body] + state.R_WB[m.vector.point_a.body] @ m.vector.point_a.p_BP
        pb = state.p_WB[m.vector.point_b.body] + state.R_WB[m.vector.point_b.body] @ m.vector.point_b.p_BP
        np.testing.assert_allclose(val[0], np.linalg.norm(pb - pa), rtol=1e-14)


def test_program_of_many_measures_shares_nodes_and_selects_rows():
    """All measures in one program (shared sub-measures compiled once), with row
    selection, equal the stacked Python evaluations; orders 0 and 1 agree."""
    _, state, basic = _model_and_state(seed=9)
    measures = [basic[n] for n in ALL]
    rows = [list(range(m.size))[::-1] for m in measures]  # reversed rows of each
    prog = CompiledMeasures(measures, rows)
    assert prog.op.size < sum(_count_nodes(m) for m in measures), "shared measures compiled once"
    val, M, b = prog.evaluate(state, 2)
    ref = [m.evaluate(state, 2) for m in measures]
    np.testing.assert_allclose(val, np.concatenate([r[0][::-1] for r in ref]), atol=1e-14)
    np.testing.assert_allclose(M, np.vstack([r[1][::-1] for r in ref]), atol=1e-13)
    np.testing.assert_allclose(b, np.concatenate([r[2][::-1] for r in ref]), atol=1e-11)
    v0, M0, b0 = prog.evaluate(state, 0)
    v1, M1, b1 = prog.evaluate(state, 1)
    assert M0 is None and b0 is None and b1 is None
    np.testing.assert_array_equal(v0, val)
    np.testing.assert_array_equal(M1, M)


def _count_nodes(m):
    kids = []
    if hasattr(m, "terms"):
        kids = [s for _, s in m.terms]
    elif hasattr(m, "vector"):
        kids = [m.vector]
    elif hasattr(m, "point_a"):
        kids = [m.point_a, m.point_b]
    return 1 + sum(_count_nodes(k) for k in kids)


def test_compiled_errors_match_python():
    """Coincident points of a distance and gimbal lock raise the reference's error."""
    b = ModelBuilder("err")
    b.add_body("a", 1.0, [1, 1, 1])
    b.add_frame("a", "f", [0, 0, 0], orientation=quat_from_rotvec([0, np.pi / 2, 0]))
    d = b.distance("ground.origin", "a.origin", name="d0")
    ang = b.angles("ground.origin", "a.f", name="lock")
    euler = b.angles("ground.origin", "a.origin", name="euler", sequence="zxz")  # θ2 = 0 at rest
    model = b.build()
    state = model.initial_state()
    for m, what in ((d, "coincide"), (ang, r"gimbal lock, the middle angle \(about y'\) is 90.0 deg"), (euler, "gimbal lock, the middle angle is 0.0 deg")):
        with pytest.raises(FloatingPointError, match=what):
            m.evaluate(state, 1)
        with pytest.raises(FloatingPointError, match=what):
            CompiledMeasures([m]).evaluate(state, 1)


def test_unknown_measure_type_is_named():
    class Custom(Measure):
        size = 1
        name = "mine"

    with pytest.raises(MeasureCompileError, match="mine.*Custom"):
        CompiledMeasures([Custom()])


def test_nested_linears_with_offsets():
    """Nested one-term linear measures with offsets at both levels (FDK-DOF and joint
    rows are built this way) against the Python reference and finite differences."""
    _, state, basic = _model_and_state(seed=11)
    inner = Linear([(np.array([[1.0, 0.5, 0.0], [0.0, -1.0, 3.0]]), basic["vector_world"])], offset=[0.1, -0.2])
    outer = Linear([(np.array([[2.0, -1.0]]), inner)], offset=[0.05])
    picked = [outer, Linear([(np.array([[0.3, -0.4, 0.866]]), basic["vector_in_a"])], offset=[0.01]), inner]
    prog = CompiledMeasures(picked)
    val, M, b = prog.evaluate(state, 2)
    ref = [m.evaluate(state, 2) for m in picked]
    np.testing.assert_allclose(val, np.concatenate([r[0] for r in ref]), atol=1e-15)
    np.testing.assert_allclose(M, np.vstack([r[1] for r in ref]), atol=1e-14)
    np.testing.assert_allclose(b, np.concatenate([r[2] for r in ref]), atol=1e-12)
    M_fd = manifold_jacobian(lambda s: prog.evaluate(s, 0)[0], state, eps=1e-6)
    assert np.min(np.max(np.abs(M), axis=1)) > 1e-3
    np.testing.assert_allclose(M, M_fd, atol=1e-8, rtol=1e-6)


def test_constraint_system_compiled_equals_reference_with_driver_and_fdk():
    """Revolute and prismatic joints, a driver on a Cardan angle and an FDK DOF: the
    system's compiled evaluation equals the measure-by-measure one (Φ, Φ_q̂, ν, γ)."""
    from openfdk.kinematics.system import ConstraintSystem
    from openfdk.model.timefunctions import Polynomial

    rng = np.random.default_rng(2)
    b = ModelBuilder("system")
    _add_two_bodies_with_frame_j(b, rng)
    b.add_joint("hinge", "revolute", parent="ground", child="a.j")
    b.add_driver("turn", b.angles("ground.origin", "a.j"), Polynomial([[0.1], [2.0], [0.5]]), components=[2])
    b.add_joint("slide", "prismatic", parent="a.j", child="b.j")
    b.add_fdk_dof("gap", b.vector("a.j", "b.j", expressed_in="a"), component=2)
    model = b.build()
    state = model.initial_state()
    state.set_v(rng.normal(size=model.n_coords))
    system = ConstraintSystem(model)
    out = system.evaluate(state, 0.3, [0.01], order=2)
    ref = system.evaluate_reference(state, 0.3, [0.01], order=2)
    for x, y in zip(out, ref):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-13)
    # driver rows: ν = ḟ, and γ = f̈ − b with f = 0.1 + 2 t + 0.5 t²
    r = system.row_names.index("turn")
    assert out[2][r] == pytest.approx(2.0 + 1.0 * 0.3)
    assert out[3][r] == pytest.approx(1.0 - system.program.evaluate(state, 2)[2][r])
