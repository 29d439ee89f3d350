"""The force-set interface (openfdk.forces.forceset) for the kinds other tests do not
cover: external loads and the muscles' passive (parallel-elastic) tension. Q against
independent closed forms, K = ∂Q/∂q̂ against finite differences on the manifold (and
non-zero), and the stiffness from the forces stage's outputs equal to the one computed
with Q."""

import numpy as np
import pytest
from scipy.optimize import brentq

from openfdk.forces.elements import add_external_load, add_muscle
from openfdk.forces.forceset import FORCE_KINDS, ForceElements
from openfdk.forces.hill import Hill3ElementMuscle, passive_force_length, tendon_force_strain
from openfdk.model.builder import ModelBuilder
from openfdk.model.timefunctions import Constant
from openfdk.numerics.numdiff import manifold_jacobian
from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix

P_BP = np.array([0.03, -0.02, 0.05])
ROTVEC = np.array([0.3, -0.2, 0.5])


def _body(b):
    b.add_body("a", 1.0, [1e-3] * 3, position=[0.01, 0.02, -0.3], orientation=quat_from_rotvec(ROTVEC))
    b.add_frame("a", "p", P_BP)


@pytest.mark.parametrize("frame", ["world", "body"])
def test_load_forces_closed_form_and_stiffness(frame):
    """Q of a force F and moment M at a point P: the force rows are F_W and the moment
    rows the virtual work of F through δp_P (independent: the manifold Jacobian of
    F_W·p_WP) plus the moment in the body frame; K (non-zero: the rotation turns the
    lever or the force) against manifold finite differences of Q."""
    F, M = np.array([3.0, -4.0, 12.0]), np.array([0.5, 0.2, -0.7])
    b = ModelBuilder("load", gravity=(0, 0, 0))
    _body(b)
    add_external_load(b, "push", "a.p", force=Constant(F), moment=Constant(M), frame=frame)
    model = b.build()
    state = model.initial_state()
    forces = ForceElements(model)
    Q, out, K = forces.generalized_forces(state, 0.0, want_stiffness=True)
    R = rotation_matrix(quat_from_rotvec(ROTVEC))
    F_W, M_B = (F, R.T @ M) if frame == "world" else (R @ F, M)
    # δW = F_W · δp_P: differentiate p_WP = r + R p_BP on the manifold at fixed F_W
    work = manifold_jacobian(lambda s: F_W @ (s.p_WB[1] + s.R_WB[1] @ P_BP), state, 1e-7)[0]
    np.testing.assert_allclose(Q, work + np.r_[0, 0, 0, M_B], rtol=1e-8, atol=1e-8)
    K_fd = manifold_jacobian(lambda s: forces.generalized_forces(s, 0.0)[0], state, 1e-7)
    assert np.abs(K).max() > 0.1
    np.testing.assert_allclose(K, K_fd, atol=1e-6 * np.abs(K).max())
    np.testing.assert_allclose(forces.stiffness(state, out), K, rtol=0, atol=1e-14)


def _hill_passive(muscle, l_MT):
    """Passive tension of a Hill unit without pennation, independently: the root of
    F0 f_T((l_MT − l_f − Lt0)/Lt0) = F0 f_PE(l_f/Lf0) in l_f (brentq on the curves)."""
    lf0, lt0, f0 = muscle.optimal_fibre_length, muscle.tendon_slack_length, muscle.max_isometric_force
    eps0_t = muscle.tendon_strain_at_max_force

    def residual(l_f):
        return (tendon_force_strain((l_MT - l_f - lt0) / lt0, eps0_t)[0]
                - passive_force_length(l_f / lf0, muscle.passive_shape_factor, muscle.passive_strain_at_max_force)[0])

    l_f = brentq(residual, lf0, l_MT - lt0, xtol=1e-15, rtol=1e-15)
    return f0 * float(passive_force_length(l_f / lf0, muscle.passive_shape_factor, muscle.passive_strain_at_max_force)[0])


def test_muscle_passive_tension_closed_form_and_stiffness():
    """A stretched Hill muscle from a ground point O to P on a rotated body: the passive
    tension f_P is the root of the tendon–fibre equilibrium (solved here with brentq),
    Q = −f_P [e; p̃_BP R_WBᵀ e] with e the unit vector O→P, and K (material and
    geometric parts both non-zero) against manifold finite differences of Q."""
    b = ModelBuilder("muscle", gravity=(0, 0, 0))
    _body(b)
    b.add_frame("ground", "o", [0.0, 0.0, 0.0])
    R = rotation_matrix(quat_from_rotvec(ROTVEC))
    p_WP = np.array([0.01, 0.02, -0.3]) + R @ P_BP
    length = float(np.linalg.norm(p_WP))
    # optimal fibre 0.1 m, tendon 0.12 m: the unit is ≈ 0.06 m longer, the fibre stretched
    muscle = Hill3ElementMuscle(200.0, 0.1, 0.12, name="m")
    assert length > 0.25
    add_muscle(b, "m", ["ground.o", "a.p"], muscle)
    model = b.build()
    state = model.initial_state()
    forces = ForceElements(model)
    Q, out, K = forces.generalized_forces(state, 0.0, want_stiffness=True)
    f_p = _hill_passive(muscle, length)
    assert f_p > 1.0
    assert out["muscles"].passive[0] == pytest.approx(f_p, rel=1e-9)
    e = p_WP / length
    np.testing.assert_allclose(Q, -f_p * np.r_[e, np.cross(P_BP, R.T @ e)], rtol=1e-9, atol=1e-12)
    # df_P/dl against a central difference of the independent root
    h = 1e-6
    dfp = (_hill_passive(muscle, length + h) - _hill_passive(muscle, length - h)) / (2 * h)
    assert out["muscles"].dpassive[0] == pytest.approx(dfp, rel=1e-6)
    K_fd = manifold_jacobian(lambda s: forces.generalized_forces(s, 0.0)[0], state, 1e-7)
    L = out["muscles"].L
    K_material = -np.outer(L[0], L[0]) * dfp
    assert np.abs(K_material).max() > 10.0 and np.abs(K - K_material).max() > 1.0  # both parts
    np.testing.assert_allclose(K, K_fd, atol=1e-5 * np.abs(K).max())
    np.testing.assert_allclose(forces.stiffness(state, out), K, rtol=0, atol=1e-12 * np.abs(K).max())


def test_every_model_field_of_a_force_kind_has_one_set():
    """The forces stage loops over FORCE_KINDS: each kind names a Model field and a set
    class with the interface (kind, accumulate, stiffness)."""
    from dataclasses import fields

    from openfdk.model.model import Model

    names = {f.name for f in fields(Model)}
    for kind, cls in FORCE_KINDS:
        assert kind in names and cls.kind == kind
        assert callable(cls.accumulate) and callable(cls.stiffness)


def test_path_geometric_stiffness_over_two_moving_bodies():
    """A taut ligament from the ground over a via point on body a to body b (segments
    ground–a and a–b, both bodies rotated): the closed-form geometric stiffness plus the
    material part equals manifold finite differences of Q in every block (a–a, a–b,
    b–b), and its geometric part is not zero."""
    from openfdk.forces.elements import add_ligament

    b = ModelBuilder("two", gravity=(0, 0, 0))
    _body(b)
    b.add_body("b", 1.0, [1e-3] * 3, position=[0.05, -0.03, -0.45], orientation=quat_from_rotvec([-0.4, 0.1, 0.2]))
    b.add_frame("b", "q", [0.01, 0.02, -0.03])
    b.add_frame("ground", "o", [0.0, 0.01, 0.0])
    add_ligament(b, "lig", ["ground.o", "a.p", "b.q"], stiffness=3000.0, reference_strain=0.08)
    model = b.build()
    state = model.initial_state()
    forces = ForceElements(model)
    Q, out, K = forces.generalized_forces(state, 0.0, want_stiffness=True)
    T = out["ligaments"].force[0]
    assert T > 1.0
    L = out["ligaments"].L
    K_material = -np.outer(L[0], L[0]) * forces.by_kind["ligaments"]._laws(out["ligaments"].length)[2][0]
    K_fd = manifold_jacobian(lambda s: forces.generalized_forces(s, 0.0)[0], state, 1e-7)
    assert np.abs(K - K_material).max() > 0.1 * np.abs(K).max()
    assert np.abs(K_fd[:6, 6:]).max() > 1.0  # the bodies are coupled
    np.testing.assert_allclose(K, K_fd, atol=1e-6 * np.abs(K).max())


def test_spring_stiffness_along_directions_equals_differences_of_q():
    """A stretched spring on a distance between two moving bodies: K u along given
    directions (the analytic FDK Jacobian's) against central differences of Q along each
    u, independently; the geometric term (the measure's curvature) makes it differ from
    the spring's Mᵀ k M alone."""
    from openfdk.forces.elements import add_spring
    from models import q_difference_along

    b = ModelBuilder("spring2", gravity=(0, 0, 0))
    _body(b)
    b.add_body("c", 1.0, [1e-3] * 3, position=[0.2, -0.05, 0.1])
    b.add_frame("c", "q", [0.0, 0.04, -0.02])
    add_spring(b, "s", b.distance("a.p", "c.q"), 500.0, rest_value=0.05)
    model = b.build()
    state = model.initial_state()
    forces = ForceElements(model)
    _, out = forces.generalized_forces(state, 0.0)[:2]
    assert out["springs"].force[0] < -10  # stretched well beyond 5 cm: tension
    U = np.random.default_rng(7).normal(size=(state.n_coords, 4))
    KU = forces.stiffness_along(state, out, U)
    elastic = out["springs"].M.T @ (500.0 * (out["springs"].M @ U))
    for j in range(U.shape[1]):
        dQ = q_difference_along(forces, state, U[:, j])
        np.testing.assert_allclose(KU[:, j], dQ, atol=1e-5 * np.abs(dQ).max())
        assert np.abs(dQ - elastic[:, j]).max() > 1e-2 * np.abs(dQ).max()


@pytest.mark.parametrize("rule", ["openfdk", "opensim"])
def test_moved_muscles_are_the_strength_models_to_first_order(rule):
    """MuscleForces.moved (the analytic FDK Jacobian's muscles near an evaluated pose):
    strengths and passive tensions carried along l and l̇ = L v with MuscleForces.slopes
    differ from the strength models solved at the moved pose by O(h²) (the error falls
    ~100× for a 10× shorter step), and their central differences along a direction equal
    the solved models' (non-zero) to 1e-6."""
    from openfdk.forces.muscle_forces import MuscleForces

    b = ModelBuilder("muscle", gravity=(0, 0, 0))
    _body(b)
    b.add_frame("ground", "o", [0.0, 0.0, 0.0])
    add_muscle(b, "m", ["ground.o", "a.p"], Hill3ElementMuscle(200.0, 0.1, 0.12, name="m"))
    model = b.build()
    state = model.initial_state()
    state.set_v(np.array([0.05, -0.02, 0.3, 0.4, -0.1, 0.2]))
    muscles = MuscleForces(model.muscles, rule)
    out = muscles.states(state)
    slopes = muscles.slopes(out)
    u = np.array([0.3, -0.5, 0.8, 0.6, 0.2, -0.4])

    def at(h, how):
        s = state.copy()
        s.displace(h * u)
        m = muscles.moved(s, out, slopes) if how == "moved" else muscles.states(s)
        return np.r_[m.strength, m.passive]

    errors = [np.abs(at(h, "moved") - at(h, "solved")).max() for h in (1e-3, 1e-4)]
    assert errors[0] > 0 and 50 < errors[0] / errors[1] < 200
    h = 1e-6
    d_moved = (at(h, "moved") - at(-h, "moved")) / (2 * h)
    d_solved = (at(h, "solved") - at(-h, "solved")) / (2 * h)
    assert abs(d_solved[0]) > 1.0  # the strength changes along u
    if rule == "openfdk":
        assert abs(d_solved[1]) > 1.0  # so does the passive tension
    np.testing.assert_allclose(d_moved, d_solved, rtol=1e-6, atol=1e-6 * np.abs(d_solved).max())
