"""Blankevoort (1991) ligament law and the linear spring, against hand-derived closed forms."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from openfdk.forces.blankevoort import Blankevoort1991Ligament, LigamentParameterError
from openfdk.forces.spring import LinearSpring, SpringParameterError

K = 90.8  # N/m (272.4 N/m split over 3 elements, the paper's baseline)
L0 = 0.018  # m
EPS_L = 0.03
G = 9.81


def reference_force(eps, k=K, l0=L0, eps_l=EPS_L):
    """The law of the paper and docs/design.md §1 written out independently, one strain at a time."""
    if eps < 0.0:
        return 0.0
    if eps <= 2.0 * eps_l:
        return k * l0 * eps**2 / (4.0 * eps_l)
    return k * l0 * (eps - eps_l)


@pytest.fixture
def ligament():
    return Blankevoort1991Ligament(stiffness=K, slack_length=L0, transition_strain=EPS_L,
                                   name="tmj_1")


def test_force_matches_formula_at_chosen_strains(ligament):
    strains = np.array([-0.2, -1e-9, 0.0, 0.01, 0.03, 0.059, 0.06, 0.061, 0.1, 0.5])
    lengths = L0 * (1.0 + strains)
    np.testing.assert_allclose(ligament.strain(lengths), strains, rtol=0, atol=1e-14)
    expected = np.array([reference_force(e) for e in strains])
    np.testing.assert_allclose(ligament.force(lengths), expected, rtol=1e-12, atol=1e-15)
    # hand-computed numbers: toe at ε = 0.03 → k l0 ε²/(4ε_l) = k l0 · 0.0075
    assert ligament.force(L0 * 1.03) == pytest.approx(K * L0 * 0.0075, rel=1e-12)
    # linear at ε = 0.1 → k l0 (0.1 − 0.03) = k l0 · 0.07
    assert ligament.force(L0 * 1.1) == pytest.approx(K * L0 * 0.07, rel=1e-12)
    assert isinstance(ligament.force(L0 * 1.1), float)


@pytest.mark.parametrize("eps_join", [0.0, 2.0 * EPS_L])
def test_value_and_slope_continuous_at_joins(ligament, eps_join):
    delta = 1e-9
    l_left = L0 * (1.0 + eps_join - delta)
    l_right = L0 * (1.0 + eps_join + delta)
    # value: both sides agree with the branch value at the join
    f_join = reference_force(eps_join)
    assert ligament.force(l_left) == pytest.approx(f_join, abs=K * L0 * 1e-8)
    assert ligament.force(l_right) == pytest.approx(f_join, abs=K * L0 * 1e-8)
    # slope: the one-sided analytic slopes agree, and agree with the closed form
    # (0 at ε = 0, k at ε = 2ε_l)
    slope_expected = 0.0 if eps_join == 0.0 else K
    assert ligament.dforce_dlength(l_left) == pytest.approx(slope_expected, abs=K * 1e-6)
    assert ligament.dforce_dlength(l_right) == pytest.approx(slope_expected, abs=K * 1e-6)
    # one-sided finite differences from each side agree as well
    h = L0 * 1e-6
    l_join = L0 * (1.0 + eps_join)
    fd_left = (ligament.force(l_join) - ligament.force(l_join - h)) / h
    fd_right = (ligament.force(l_join + h) - ligament.force(l_join)) / h
    assert fd_left == pytest.approx(fd_right, abs=K * 1e-3)


def test_reference_strain_parametrisation():
    for eps_r in (-0.04, -0.02, 0.0, 0.02, 0.04):
        l_r = 0.0215
        lig = Blankevoort1991Ligament.from_reference(K, l_r, eps_r, name="tmj_2")
        assert lig.slack_length == pytest.approx(l_r / (1.0 + eps_r), rel=1e-15)
        # the strain at the reference length is the reference strain
        assert lig.strain(l_r) == pytest.approx(eps_r, abs=1e-14)
    with pytest.raises(LigamentParameterError, match="tmj_3.*reference_strain"):
        Blankevoort1991Ligament.from_reference(K, 0.02, -1.0, name="tmj_3")


@pytest.mark.parametrize("eps", [0.005, 0.02, 0.045, 0.07, 0.2])
def test_dforce_dlength_matches_central_differences(ligament, eps):
    length = L0 * (1.0 + eps)
    h = L0 * 1e-7
    fd = (ligament.force(length + h) - ligament.force(length - h)) / (2.0 * h)
    analytic = ligament.dforce_dlength(length)
    assert analytic != 0.0
    assert analytic == pytest.approx(fd, rel=1e-6)
    # closed form: k ε/(2ε_l) in the toe, k in the linear region
    expected = K * eps / (2.0 * EPS_L) if eps <= 2.0 * EPS_L else K
    assert analytic == pytest.approx(expected, rel=1e-12)
    assert ligament.dforce_dlength(L0 * 0.9) == 0.0


@pytest.mark.parametrize("mass", [0.01, 0.1])  # kg: one toe-region and one linear case
def test_hanging_mass_equilibrium(mass):
    k, l0 = 500.0, 0.02
    lig = Blankevoort1991Ligament(k, l0, EPS_L, damping=2.0, name="hanger")
    weight = mass * G
    # closed-form equilibrium strain:
    # toe ε = sqrt(4 ε_l m g/(k l0)), linear ε = m g/(k l0) + ε_l
    eps_toe = math.sqrt(4.0 * EPS_L * weight / (k * l0))
    eps_eq = eps_toe if eps_toe <= 2.0 * EPS_L else weight / (k * l0) + EPS_L
    expected_region = "toe" if mass < 0.05 else "linear"  # toe ends at k l0 ε_l = 0.3 N
    assert (eps_eq <= 2.0 * EPS_L) == (expected_region == "toe")
    l_eq = l0 * (1.0 + eps_eq)
    assert lig.force(l_eq) == pytest.approx(weight, rel=1e-12)

    # and the mass, released at the slack length with damping, settles there:
    # m l̈ = m g − f(l, l̇)  (l measured downwards along the ligament)
    def rhs(_t, y):
        return [y[1], G - lig.force(y[0], y[1]) / mass]

    sol = solve_ivp(rhs, (0.0, 8.0), [l0, 0.0], method="LSODA", rtol=1e-10, atol=1e-13)
    assert sol.y[0, -1] == pytest.approx(l_eq, rel=1e-6)


def test_damping_only_when_taut_and_never_pushes(ligament):
    lig = Blankevoort1991Ligament(K, L0, EPS_L, damping=3.0, name="damped")
    l_taut = L0 * 1.05
    assert lig.force(l_taut, 0.01) == pytest.approx(reference_force(0.05) + 3.0 * 0.01, rel=1e-12)
    assert lig.force(L0 * 0.99, 0.5) == 0.0  # slack: no damping force
    assert lig.force(l_taut, -10.0) == 0.0  # fast shortening: clipped, never compressive
    np.testing.assert_allclose(lig.force(np.array([l_taut, l_taut]), np.array([0.0, 0.01])),
                               [reference_force(0.05), reference_force(0.05) + 0.03], rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(stiffness=-1.0, slack_length=0.02), "'bad'.*stiffness"),
        (dict(stiffness=10.0, slack_length=0.0), "'bad'.*slack_length"),
        (dict(stiffness=10.0, slack_length=0.02, transition_strain=0.0),
         "'bad'.*transition_strain"),
        (dict(stiffness=10.0, slack_length=0.02, damping=-0.1), "'bad'.*damping"),
        (dict(stiffness=float("nan"), slack_length=0.02), "'bad'.*stiffness"),
    ],
)
def test_bad_ligament_parameters_raise_naming_the_ligament(kwargs, message):
    with pytest.raises(LigamentParameterError, match=message):
        Blankevoort1991Ligament(**kwargs, name="bad")


def test_linear_spring_closed_form():
    spring = LinearSpring(stiffness=0.1, rest_value=0.002, unit="m", name="fdk_1")
    m = np.array([-0.01, 0.002, 0.0125])
    np.testing.assert_allclose(spring.force(m), -0.1 * (m - 0.002), rtol=1e-15)
    assert spring.force(0.012) == pytest.approx(-0.001, rel=1e-12)
    np.testing.assert_array_equal(spring.dforce_dmeasure(m), [-0.1, -0.1, -0.1])
    h = 1e-4
    fd = (spring.force(0.01 + h) - spring.force(0.01 - h)) / (2 * h)
    assert spring.dforce_dmeasure(0.01) == pytest.approx(fd, rel=1e-9)
    torsion = LinearSpring(2.0, 0.1, unit="rad")
    assert torsion.force(0.3) == pytest.approx(-0.4, rel=1e-12)
    with pytest.raises(SpringParameterError, match="fdk_2.*stiffness"):
        LinearSpring(-0.1, 0.0, name="fdk_2")
