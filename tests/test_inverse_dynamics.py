"""Inverse dynamics and recruitment against closed forms (paper Eqs. 11–14)."""

import numpy as np
import pytest

from openfdk.analysis.inverse_dynamics import run_inverse_dynamics
from openfdk.forces.elements import add_external_load, add_muscle, set_recruitment
from openfdk.forces.hill import ConstantStrengthMuscle
from openfdk.kinematics.analysis import run_determinate
from openfdk.model.builder import ModelBuilder
from openfdk.model.timefunctions import Constant, Polynomial

G = 9.81
# pin frame axes (columns): x = world x, y = world −z, z = world +y
R_PIN = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])


def pendulum(mass=2.0, L=0.5, omega=3.0, joint="revolute"):
    """A bob with its centre of mass L below a pivot at the world origin, rotated about
    the pin's z axis (world +y) at constant rate ω by a motor (a driver with reaction)."""
    b = ModelBuilder("pendulum", gravity=(0, 0, -G))
    b.add_body("bob", mass, [0.01, 0.02, 0.03], position=[0, 0, -L])
    b.add_frame("ground", "pin", [0, 0, 0], orientation=R_PIN)
    b.add_frame("bob", "pin", [0, 0, L], orientation=R_PIN)
    if joint == "revolute":
        b.add_joint("pin", "revolute", parent="ground.pin", child="bob.pin")
        b.add_driver("motor", b.angles("ground.pin", "bob.pin"), Polynomial([[0.0], [omega]]), components=[2], reaction=True)
    else:
        b.add_joint("pin", "spherical", parent="ground.pin", child="bob.pin")
        b.add_driver("motor", b.angles("ground.pin", "bob.pin"), Polynomial([[0.0, 0.0, 0.0], [0.0, 0.0, omega]]), reaction=True)
    return b.build()


def test_hanging_body_reaction_equals_weight():
    model = pendulum(omega=0.0, joint="spherical")
    kin = run_determinate(model, np.array([0.0, 0.5]))
    res = run_inverse_dynamics(model, kin)
    assert res.converged.all()
    col = {n: i for i, n in enumerate(res.column_names)}
    # pin reaction = force on the bob in pin-frame components: y = world −z
    np.testing.assert_allclose(res.forces[:, col["pin.y"]], -2.0 * G, rtol=1e-10)
    np.testing.assert_allclose(res.forces[:, [col["pin.x"], col["pin.z"]]], 0.0, atol=1e-9)
    np.testing.assert_allclose(res.forces[:, [col["motor[0]"], col["motor[1]"], col["motor[2]"]]], 0.0, atol=1e-9)


def test_driven_pendulum_reaction_includes_centripetal_term():
    """Constant-rate pendulum: F_pin = m (a − g) with a = −ω² r (centripetal), and the
    motor torque balances gravity: τ = m g L sin θ about the pin axis (θ̈ = 0, and the
    gyroscopic term vanishes for rotation about a principal axis)."""
    m, L, w = 2.0, 0.5, 3.0
    model = pendulum(m, L, w)
    t = np.linspace(0, 2, 41)
    kin = run_determinate(model, t)
    res = run_inverse_dynamics(model, kin)
    assert kin.converged.all() and res.converged.all()
    col = {n: i for i, n in enumerate(res.column_names)}
    th = w * t
    # rotation by θ about the pin z = world +y: r = Ry(θ) (0, 0, −L) = (−L sin θ, 0, −L cos θ)
    r = np.stack([-L * np.sin(th), 0 * th, -L * np.cos(th)], axis=1)
    np.testing.assert_allclose(kin.q[:, :3], r, atol=1e-10)
    F_W = m * (-(w**2) * r - np.array([0, 0, -G]))
    F_pin = F_W @ R_PIN  # world -> pin-frame components
    np.testing.assert_allclose(res.forces[:, [col["pin.x"], col["pin.y"], col["pin.z"]]], F_pin, atol=1e-8)
    assert np.max(np.abs(F_W[:, 0])) > 5.0  # the centripetal part is really there
    # gravity's moment about the pivot is r × m g = (0, −m g L sin θ, 0): the motor gives +
    np.testing.assert_allclose(res.forces[:, col["motor"]], m * G * L * np.sin(th), atol=1e-8)


def two_muscle_hinge(s1, s2, a1, a2, M, p=3.0):
    """(Model, its AnalysisSettings: polynomial recruitment of power p). A bar hinged
    about world z at the origin, held by a driver without reaction; two
    constant-strength muscles pull in +y at distances a1, a2 along the bar (moment arms
    a1, a2 about z); an external moment −M about z. No gravity."""
    b = ModelBuilder("hinge", gravity=(0, 0, 0))
    b.add_body("bar", 1.0, [0.01, 0.01, 0.01], position=[0.1, 0, 0])
    b.add_frame("bar", "pivot", [-0.1, 0, 0])
    b.add_frame("bar", "i1", [a1 - 0.1, 0, 0])
    b.add_frame("bar", "i2", [a2 - 0.1, 0, 0])
    b.add_frame("ground", "o1", [a1, 1.0, 0])
    b.add_frame("ground", "o2", [a2, 1.0, 0])
    b.add_joint("hinge", "revolute", parent="ground.origin", child="bar.pivot")
    b.add_driver("hold", b.angles("ground.origin", "bar.origin"), Constant([0.0]), components=[2])
    add_muscle(b, "m1", ["ground.o1", "bar.i1"], ConstantStrengthMuscle(s1, "m1"))
    add_muscle(b, "m2", ["ground.o2", "bar.i2"], ConstantStrengthMuscle(s2, "m2"))
    add_external_load(b, "load", "bar.origin", moment=[0, 0, -M])
    set_recruitment(b, "polynomial", p)
    return b.build(), b.settings()


def _two_muscle_closed_form(s1, s2, a1, a2, M, p):
    """min Σ (f_i/s_i)^p s.t. a1 f1 + a2 f2 = M: the stationarity condition
    p f_i^(p−1)/s_i^p = λ a_i gives f_i = k (a_i s_i^p)^(1/(p−1)), k from the moment."""
    u = np.array([(a1 * s1**p) ** (1 / (p - 1)), (a2 * s2**p) ** (1 / (p - 1))])
    return M / (a1 * u[0] + a2 * u[1]) * u


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_two_muscles_closed_form(p):
    """The closed form of :func:`_two_muscle_closed_form` for the model's settings."""
    s1, s2, a1, a2, M = 100.0, 300.0, 0.05, 0.12, 6.0
    model, settings = two_muscle_hinge(s1, s2, a1, a2, M, p)
    kin = run_determinate(model, np.array([0.0]))
    res = run_inverse_dynamics(model, kin, settings=settings)
    assert res.converged.all(), res.messages
    f = _two_muscle_closed_form(s1, s2, a1, a2, M, p)
    np.testing.assert_allclose(res.forces[0, :2], f, rtol=1e-7)
    # the hinge carries the muscles' pull: reaction y = −(f1 + f2)
    col = {n: i for i, n in enumerate(res.column_names)}
    assert res.forces[0, col["hinge.y"]] == pytest.approx(-f.sum(), rel=1e-7)


def test_one_model_analysed_with_two_settings():
    """The settings are apart from the model: one Model object analysed with power 2 and
    then power 3 gives each power's closed form, the defaults (power 3) the power-3
    result, and the model is left as it was (its fields are the same objects)."""
    import dataclasses

    from openfdk.forces.elements import RecruitmentSettings
    from openfdk.model.settings import AnalysisSettings

    s1, s2, a1, a2, M = 100.0, 300.0, 0.05, 0.12, 6.0
    model, _ = two_muscle_hinge(s1, s2, a1, a2, M, 3.0)
    before = {f.name: getattr(model, f.name) for f in dataclasses.fields(model)}
    kin = run_determinate(model, np.array([0.0]))
    forces = {}
    for p in (2.0, 3.0):
        settings = AnalysisSettings(recruitment=RecruitmentSettings("polynomial", p))
        forces[p] = run_inverse_dynamics(model, kin, settings=settings).forces[0, :2]
        np.testing.assert_allclose(forces[p], _two_muscle_closed_form(s1, s2, a1, a2, M, p), rtol=1e-7)
    assert np.abs(forces[2.0] - forces[3.0]).max() > 1.0  # the two criteria really differ
    np.testing.assert_allclose(run_inverse_dynamics(model, kin).forces[0, :2], forces[3.0], rtol=1e-9)
    assert all(getattr(model, name) is value for name, value in before.items())
    assert not hasattr(model, "settings")


def test_weak_muscle_saturates_at_strength():
    """The cubic criterion activates muscle i in proportion to sqrt(a_i s_i), so the
    muscle with the larger a·s saturates first: f1 = s1 and f2 carries the rest."""
    s1, s2, a1, a2, M = 100.0, 20.0, 0.12, 0.05, 12.8
    model, _ = two_muscle_hinge(s1, s2, a1, a2, M, 3.0)
    res = run_inverse_dynamics(model, run_determinate(model, np.array([0.0])))
    assert res.converged.all()
    f1 = res.forces[0, 0]
    # without the bound f1 would be k (a1 s1^3)^(1/2) > s1 for these numbers
    u1, u2 = (a1 * s1**3) ** 0.5, (a2 * s2**3) ** 0.5
    assert M / (a1 * u1 + a2 * u2) * u1 > s1
    assert f1 == pytest.approx(s1, rel=1e-6)
    assert res.forces[0, 1] == pytest.approx((M - a1 * s1) / a2, rel=1e-6)


def test_infeasible_frame_is_flagged_and_run_continues():
    """Moment larger than both muscles can deliver: flagged, not a crash."""
    model, _ = two_muscle_hinge(10.0, 10.0, 0.05, 0.12, 100.0)
    res = run_inverse_dynamics(model, run_determinate(model, np.array([0.0, 0.1])))
    assert not res.converged.any()
    assert "bar.Mz" in res.messages[0]


def test_slider_crank_motor_power_equals_rate_of_mechanical_energy(request):
    """Physical invariant for a frictionless mechanism: the motor's power τ θ̇ equals
    d/dt (kinetic + potential energy); the joint reactions do no work."""
    from openfdk.io.modelfile import load_model

    model = load_model(request.config.rootpath / "examples/slider_crank.yaml")
    h = 1e-4
    centres = np.array([0.13, 0.41, 0.77])
    times = np.sort(np.concatenate([centres - h, centres, centres + h]))
    kin = run_determinate(model, times)
    res = run_inverse_dynamics(model, kin)
    assert kin.converged.all() and res.converged.all()

    def energy(k):
        E = 0.0
        for b in model.moving_bodies:
            c = b.column
            i = c // 6
            v, w = kin.v[k, c : c + 3], kin.v[k, c + 3 : c + 6]
            r = kin.q[k, 7 * i : 7 * i + 3]
            E += 0.5 * b.mass * v @ v + 0.5 * w @ b.inertia_B @ w - b.mass * model.gravity_W @ r
        return E

    tau = res.forces[:, res.column_names.index("crank_drive")]
    omega = 2 * np.pi
    for j in range(3):
        k = 3 * j + 1
        dE = (energy(k + 1) - energy(k - 1)) / (2 * h)
        assert abs(tau[k] * omega) > 0.5  # the motor does real work here
        assert tau[k] * omega == pytest.approx(dE, rel=1e-5, abs=1e-6)


def test_gyroscopic_torque_of_a_body_spinning_about_a_non_principal_axis():
    """A body held at its centre of mass by a spherical joint and spun at constant ω
    about a fixed world axis n by a motor (three angle drivers with reaction): with
    ω̇ = 0 the motor must supply the gyroscopic moment ω × J ω (body frame), and the
    joint carries the weight."""
    J = np.diag([0.01, 0.02, 0.04])
    b = ModelBuilder("spinner", gravity=(0, 0, -G))
    b.add_body("top", 1.5, J)
    b.add_joint("ball", "spherical", parent="ground.origin", child="top.origin")
    w = 5.0
    # θ_x = θ_y = 0 and θ_z = w t: rotation about world z; the body's principal axes are
    # tilted so that z is not principal (orientation fixed in the body frame via the frame)
    from openfdk.numerics.spatial import quat_from_rotvec, rotation_matrix

    R_tilt = rotation_matrix(quat_from_rotvec([0.4, -0.3, 0.0]))
    b.add_frame("top", "spin", [0, 0, 0], orientation=R_tilt.T)
    b.add_driver("motor", b.angles("ground.origin", "top.spin"), Polynomial([[0.0, 0.0, 0.0], [0.0, 0.0, w]]), reaction=True)
    model = b.build()
    kin = run_determinate(model, np.array([0.0, 0.3]))
    res = run_inverse_dynamics(model, kin)
    assert kin.converged.all() and res.converged.all()
    col = {n: i for i, n in enumerate(res.column_names)}
    np.testing.assert_allclose(res.forces[:, [col["ball.x"], col["ball.y"], col["ball.z"]]], [[0, 0, 1.5 * G]] * 2, atol=1e-9)
    # the body-frame angular velocity is R_WBᵀ (0, 0, w); the motor's generalised torque
    # (rows in the driver's Cardan rates) must reproduce ω × J ω in the body frame
    from openfdk.kinematics.system import ConstraintSystem

    state = model.initial_state()
    state.set_q(kin.q[1])
    state.set_v(kin.v[1])
    omega_B = kin.v[1, 3:6]
    expected = np.cross(omega_B, J @ omega_B)
    assert np.linalg.norm(expected) > 0.1
    _, A, _, _ = ConstraintSystem(model).evaluate(state, 0.3, order=1)
    motor_rows = [i for i, n in enumerate(model.constraint_row_names()) if n.startswith("motor")]
    torque_B = A[motor_rows][:, 3:6].T @ res.forces[1, [col["motor[0]"], col["motor[1]"], col["motor[2]"]]]
    np.testing.assert_allclose(torque_B, expected, atol=1e-9)


def test_pop_jaw_tmj_forces_are_compressive_and_symmetric():
    """The synthetic POP jaw (24 Hill muscles, push-only 20 kN TMJ elements) over a
    symmetric open–close: every frame converges, TMJ forces are compressive (≥ 0 by
    construction of the bounded column, and non-trivial), left ≈ right."""
    from openfdk.io.c3d import MarkerTrial
    from openfdk.io.markers import MarkerTrajectories
    from openfdk.kinematics.analysis import run_tracking
    from openfdk.io.modelfile import model_from_dict
    from openfdk.fixtures.synthetic_jaw import jaw_markers, jaw_model_dict

    model = model_from_dict(jaw_model_dict(), "jaw.yaml")
    t, labels, x, _ = jaw_markers(150, noise=0.0)
    traj = MarkerTrajectories(MarkerTrial(tuple(labels), 100.0, t, x), cutoff_hz=None)
    res = run_inverse_dynamics(model, run_tracking(model, traj, t))
    assert res.converged.all()
    r = res.forces[:, res.column_names.index("tmj_r_contact")]
    l_ = res.forces[:, res.column_names.index("tmj_l_contact")]
    assert r.min() >= 0 and r.max() > 1.0
    np.testing.assert_allclose(r, l_, rtol=2e-2, atol=0.05)
