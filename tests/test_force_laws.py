"""Nonlinear springs (polynomial, table, Blankevoort) and the 6-DOF bushing: a mass held
by each at the closed-form equilibrium F⁻¹(m g), stiffness against finite differences."""

import numpy as np
import pytest

from openfdk.fdk.analysis import run_fdk
from openfdk.forces.elements import add_external_load
from openfdk.forces.force_laws import (
    Blankevoort1991Spring, PolynomialSpring, TabulatedSpring, add_bushing, add_nonlinear_spring,
)
from openfdk.forces.forceset import ForceElements
from openfdk.model.builder import ModelBuilder
from openfdk.model.model import ModelError
from openfdk.numerics.numdiff import manifold_jacobian

G = 9.81
MASS = 3.0  # kg


def _hanging(law, initial, measure="height"):
    """A block sliding vertically (prismatic) whose height z (m, negative below the
    ground origin) or its distance from the ground origin is an FDK DOF held by ``law``."""
    b = ModelBuilder("hang", gravity=(0, 0, -G))
    b.add_body("block", MASS, [1e-3] * 3, position=[0, 0, initial])
    b.add_joint("rail", "prismatic", "ground.origin", "block.origin")
    z = b.add_measure("height", b._select(b.vector("ground.origin", "block.origin"), [2]))
    b.add_fdk_dof("z", z, initial=initial, max_step=0.01)
    m = z if measure == "height" else b.add_measure("d", b.distance("ground.origin", "block.origin"))
    add_nonlinear_spring(b, "spring", m, law)
    return b.build()


def test_polynomial_spring_holds_mass_at_inverse_force():
    k1, k3 = 200.0, 4.0e5  # F = k1 z + k3 z³ (N), z = height
    model = _hanging(PolynomialSpring([0.0, k1, 0.0, k3]), -0.01)
    res = run_fdk(model, None, np.array([0.0]), jacobian="analytic")
    assert res.converged.all(), res.messages
    roots = np.roots([k3, 0.0, k1, MASS * G])  # F(z) = −m g
    z = roots[np.abs(roots.imag) < 1e-12].real[0]
    assert res.alpha[0, 0] == pytest.approx(z, abs=1e-3 / (k1 + 3 * k3 * z**2))
    assert abs(z) > 0.02 and abs(k3 * z**3) > k1 * abs(z)  # well into the nonlinear part


def test_tabulated_spring_holds_mass_at_inverse_of_the_table():
    """An exponential law sampled every 1 mm: PCHIP interpolates it within ~1e-4
    relative, so the equilibrium is the exact law's inverse to a few µm."""
    a, c = 5.0, 60.0  # F = a (exp(−c z) − 1) resists downward motion (z < 0)
    zs = np.linspace(-0.08, 0.01, 91)
    model = _hanging(TabulatedSpring(zs, -a * (np.exp(-c * zs) - 1.0)), -0.02)
    res = run_fdk(model, None, np.array([0.0]), jacobian="analytic")
    assert res.converged.all(), res.messages
    z_exact = -np.log(MASS * G / a + 1.0) / c  # a (exp(−c z) − 1) = m g
    assert res.alpha[0, 0] == pytest.approx(z_exact, abs=5e-6)


def test_blankevoort_spring_on_a_distance_holds_mass():
    """OpenSim's hanging-block check: tension T = m g in the linear region,
    ε = T/(k l0) + ε_l, so the block hangs at l0 (1 + ε)."""
    k, l0, eps_l = 2000.0, 0.2, 0.03
    model = _hanging(Blankevoort1991Spring(k, l0, eps_l), -0.21, measure="distance")
    res = run_fdk(model, None, np.array([0.0]), jacobian="analytic")
    assert res.converged.all(), res.messages
    eps = MASS * G / (k * l0) + eps_l
    assert eps > 2 * eps_l
    assert -res.alpha[0, 0] == pytest.approx(l0 * (1 + eps), abs=1e-3 / k)


def test_bushing_deflects_by_force_over_stiffness():
    k_t, k_r = np.array([1000.0, 2000.0, 500.0]), np.array([30.0, 40.0, 20.0])
    F, Mz = np.array([3.0, -2.0, 5.0]), 0.4
    b = ModelBuilder("bushing", gravity=(0, 0, 0))
    b.add_body("plate", 1.0, [1e-3] * 3)
    add_bushing(b, "mount", "ground.origin", "plate.origin", k_t, k_r)
    pos = b.add_measure("pos", b.point("plate.origin"))
    ang = b.add_measure("ang", b.angles("ground.origin", "plate.origin"))
    for j in range(3):
        b.add_fdk_dof(f"p{j}", pos, component=j, max_step=0.01)
        b.add_fdk_dof(f"a{j}", ang, component=j, max_step=0.05)
    add_external_load(b, "push", "plate.origin", force=F, moment=[0.0, 0.0, Mz])
    model = b.build()
    res = run_fdk(model, None, np.array([0.0]), jacobian="analytic")
    assert res.converged.all(), res.messages
    alpha = dict(zip([d.name for d in model.fdk_dofs], res.alpha[0]))
    np.testing.assert_allclose([alpha["p0"], alpha["p1"], alpha["p2"]], F / k_t, atol=1e-6)
    assert alpha["a2"] == pytest.approx(Mz / k_r[2], abs=1e-6)  # one axis: B = I, exact
    assert abs(alpha["a0"]) < 1e-8 and abs(alpha["a1"]) < 1e-8


@pytest.mark.parametrize("law", [PolynomialSpring([0.5, 100.0, -300.0, 5e4], 0.01),
                                 TabulatedSpring([-0.1, -0.02, 0.0, 0.05], [-30.0, -2.0, 0.0, 9.0]),
                                 Blankevoort1991Spring(3000.0, 0.15)])
def test_stiffness_matches_finite_differences(law):
    b = ModelBuilder("k", gravity=(0, 0, 0))
    b.add_body("a", 1.0, [1, 1, 1], position=[0.05, 0.1, -0.12])
    b.add_frame("a", "p", [0.01, 0.02, 0.0])
    add_nonlinear_spring(b, "s", b.distance("ground.origin", "a.p"), law)
    model = b.build()
    state = model.initial_state()
    passive = ForceElements(model)
    Q, out, K = passive.generalized_forces(state, 0.0, want_stiffness=True)
    K_fd = manifold_jacobian(lambda s: passive.generalized_forces(s, 0.0)[0], state, 1e-7)
    assert abs(out["springs"].force[0]) > 0.1
    np.testing.assert_allclose(K, K_fd, atol=2e-5 * np.abs(K_fd).max())
    x = out["springs"].value[0]
    h = 1e-7
    dF = (law.force(x + h) - law.force(x - h)) / (2 * h)
    assert law.dforce_dmeasure(x) == pytest.approx(dF, rel=1e-6)


def test_model_file_laws_and_bushing(tmp_path):
    from openfdk.io.modelfile import load_model

    f = tmp_path / "m.yaml"
    text = """
units: {length: mm, angle: deg}
gravity: [0, 0, -9.81]
bodies:
  block: {mass: 3.0, inertia: [0.001, 0.001, 0.001], position: [0, 0, -10]}
joints:
  rail: {type: prismatic, parent: ground.origin, child: block.origin}
measures:
  z: {type: vector, from: ground.origin, to: block.origin}
fdk_dofs:
  z: {measure: z, component: 2, initial: -10, max_step: 10}
springs:
  cubic: {measure: z, component: 2, law: {type: polynomial, coefficients: [0, 200, 0, 4.0e5]}}
bushings:
  soft: {parent: ground.origin, child: block.origin, translational_stiffness: [0, 0, 0], rotational_stiffness: [1, 1, 1]}
"""
    f.write_text(text)
    model = load_model(str(f))
    res = run_fdk(model, None, np.array([0.0]), jacobian="analytic")
    assert res.converged.all(), res.messages
    roots = np.roots([4.0e5, 0.0, 200.0, MASS * G])
    assert res.alpha[0, 0] == pytest.approx(roots[np.abs(roots.imag) < 1e-12].real[0], abs=1e-6)
    f.write_text(text.replace("law: {type: polynomial, coefficients: [0, 200, 0, 4.0e5]}",
                              "law: {type: table, values: [1, 0], forces: [0, 1]}"))
    with pytest.raises(ModelError, match="springs.cubic.law: .*strictly increasing"):
        load_model(str(f))
