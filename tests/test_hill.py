"""Muscle models: curve values from the documented equations (written out again here),
joins, tendon–fibre equilibrium checked with an independent root finder, derivatives by
central differences, the vectorised MuscleSet and parameter errors (timing lives in
`openfdk bench`)."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from openfdk.forces.hill import (
    ConstantStrengthMuscle,
    Hill3ElementMuscle,
    MuscleParameterError,
    MuscleSet,
    active_force_length,
    force_velocity,
    hill_curvature,
    passive_force_length,
    tendon_force_strain,
)

# ---- docs/muscles.md equations, written independently of the implementation -----------
GAMMA, F_LEN, K_PE, EPS0_M, EPS0_T, V_MAX = 0.45, 1.4, 3.0, 0.6, 0.053, 10.0
F_TOE, K_TOE = 0.33, 3.0


def doc_curvature(ff):
    return 0.1 + 0.4 * ff  # A = 0.1 + 0.4 ff


def doc_f_l(l):
    return math.exp(-((l - 1.0) ** 2) / GAMMA)


def doc_f_v(v, a_curv, f_len=F_LEN):
    if v <= -1.0:
        return 0.0
    if v <= 0.0:
        return (1.0 + v) / (1.0 - v / a_curv)
    c = (1.0 + 1.0 / a_curv) / (f_len - 1.0)
    return (1.0 + c * f_len * v) / (1.0 + c * v)


def doc_f_pe(l):
    return 0.0 if l <= 1.0 else (math.exp(K_PE * (l - 1.0) / EPS0_M) - 1.0) / (math.exp(K_PE) - 1.0)


def doc_tendon_constants(eps0):
    """ε_toe, k_lin from C¹ at ε_toe and f_T(ε0) = 1, solved numerically (independent)."""
    def slope_mismatch(eps_toe):
        toe_slope = F_TOE * K_TOE * math.exp(K_TOE) / ((math.exp(K_TOE) - 1.0) * eps_toe)
        return toe_slope - (1.0 - F_TOE) / (eps0 - eps_toe)
    eps_toe = brentq(slope_mismatch, 1e-6 * eps0, (1.0 - 1e-9) * eps0, xtol=1e-16, rtol=1e-15)
    return eps_toe, (1.0 - F_TOE) / (eps0 - eps_toe)


def doc_f_t(eps, eps0=EPS0_T):
    eps_toe, k_lin = doc_tendon_constants(eps0)
    if eps <= 0.0:
        return 0.0
    if eps <= eps_toe:
        return F_TOE * (math.exp(K_TOE * eps / eps_toe) - 1.0) / (math.exp(K_TOE) - 1.0)
    return F_TOE + k_lin * (eps - eps_toe)


def doc_forces(muscle, l_f, l_mt, v_mt, activation):
    """(tendon force, fibre force along the tendon) in N for fibre length l_f."""
    f0, lf0 = muscle.max_isometric_force, muscle.optimal_fibre_length
    lt0 = muscle.tendon_slack_length
    h = lf0 * math.sin(muscle.pennation_angle_at_optimal)
    x = math.sqrt(l_f**2 - h**2)
    cos_a = x / l_f
    tendon = f0 * doc_f_t((l_mt - x - lt0) / lt0, muscle.tendon_strain_at_max_force)
    v_norm = v_mt * cos_a / (muscle.max_contraction_velocity * lf0)
    a_curv = doc_curvature(muscle.fast_fibre_fraction)
    fibre = f0 * (activation * doc_f_l(l_f / lf0) * doc_f_v(v_norm, a_curv) + doc_f_pe(l_f / lf0))
    return tendon, fibre * cos_a


def doc_equilibrium_tendon_force(muscle, l_mt, v_mt, activation, x_max):
    """Tendon force at the equilibrium found by brentq on the along-tendon fibre length."""
    h = muscle.optimal_fibre_length * math.sin(muscle.pennation_angle_at_optimal)

    def residual(x):
        t, m = doc_forces(muscle, math.hypot(x, h), l_mt, v_mt, activation)
        return t - m

    x_min = 1e-6 * muscle.optimal_fibre_length
    if residual(x_max) >= 0.0:
        return doc_forces(muscle, math.hypot(x_max, h), l_mt, v_mt, activation)[0], x_max
    x = brentq(residual, x_min, x_max, xtol=1e-15, rtol=1e-15)
    return doc_forces(muscle, math.hypot(x, h), l_mt, v_mt, activation)[0], x


# jaw muscles of the reference table (right side), F0 N, Lf0 m, Lt0 m
JAW = [
    ("superficial_masseter", 272.8, 0.0226, 0.0258),
    ("deep_anterior_masseter", 73.8, 0.0218, 0.0171),
    ("anterior_temporalis", 308.0, 0.0307, 0.0242),
    ("medial_pterygoid", 240.0, 0.0141, 0.0276),
    ("inferior_lateral_pterygoid", 112.8, 0.0223, 0.0090),
    ("anterior_mylohyoid", 63.6, 0.0240, 0.0010),
]


@pytest.fixture(scope="module")
def masseter():
    return Hill3ElementMuscle(272.8, 0.0226, 0.0258, pennation_angle_at_optimal=0.2,
                              name="masseter")


# ---- curves ----------------------------------------------------------------------------
def test_curve_values_at_documented_points():
    a_curv = doc_curvature(0.4)
    assert float(hill_curvature(0.4)) == pytest.approx(0.26, rel=1e-15)
    assert force_velocity(0.0, a_curv)[0] == pytest.approx(1.0, abs=1e-15)
    assert force_velocity(-1.0, a_curv)[0] == 0.0
    assert force_velocity(-1.5, a_curv)[0] == 0.0
    assert force_velocity(1e9, a_curv)[0] == pytest.approx(F_LEN, rel=1e-7)
    for v in (-0.9, -0.5, -0.1, 0.05, 0.3, 2.0):
        assert force_velocity(v, a_curv)[0] == pytest.approx(doc_f_v(v, a_curv), rel=1e-14)
    # hand numbers: ṽ = −0.5 with A = 0.26 → 0.5/(1 + 0.5/0.26) = 0.171052…
    assert force_velocity(-0.5, a_curv)[0] == pytest.approx(0.5 / (1.0 + 0.5 / 0.26), rel=1e-14)
    assert active_force_length(1.0)[0] == 1.0
    half_width = math.sqrt(GAMMA * math.log(2.0))  # f_L = 1/2 at 1 ± sqrt(γ ln 2)
    for l in (1.0 - half_width, 1.0 + half_width):
        assert active_force_length(l)[0] == pytest.approx(0.5, rel=1e-13)
    assert passive_force_length(1.0 + EPS0_M)[0] == pytest.approx(1.0, rel=1e-13)
    assert passive_force_length(0.8)[0] == 0.0
    assert tendon_force_strain(EPS0_T)[0] == pytest.approx(1.0, rel=1e-12)
    assert tendon_force_strain(-0.01)[0] == 0.0
    for e in (0.005, 0.02, 0.03, 0.08):
        assert tendon_force_strain(e)[0] == pytest.approx(doc_f_t(e), rel=1e-11)
    # Thelen (2003) rounds the tendon constants to 0.609 ε0 and 1.712/ε0
    eps_toe, k_lin = doc_tendon_constants(0.04)
    assert eps_toe / 0.04 == pytest.approx(0.609, abs=5e-4)
    assert k_lin * 0.04 == pytest.approx(1.712, abs=2e-3)


def _limits(curve, x_join, delta=1e-9):
    left_value, left_slope = curve(x_join - delta)
    right_value, right_slope = curve(x_join + delta)
    return left_value, right_value, left_slope, right_slope


@pytest.mark.parametrize(
    "name, curve, x_join, slope_continuous",
    [
        ("f_V at ṽ = 0", lambda v: force_velocity(v, 0.26), 0.0, True),
        ("f_V at ṽ = −1", lambda v: force_velocity(v, 0.26), -1.0, False),
        ("f_PE at l̃ = 1", lambda l: passive_force_length(l), 1.0, False),
        ("f_T at ε = 0", lambda e: tendon_force_strain(e), 0.0, False),
        ("f_T at ε_toe", lambda e: tendon_force_strain(e), doc_tendon_constants(EPS0_T)[0], True),
    ],
)
def test_curves_continuous_at_every_join(name, curve, x_join, slope_continuous):
    left_value, right_value, left_slope, right_slope = _limits(curve, x_join)
    assert left_value == pytest.approx(right_value, abs=1e-7), name
    if slope_continuous:
        assert left_slope == pytest.approx(right_slope, rel=1e-6), name
        assert left_slope != 0.0
    else:  # documented kink (C0 only): the slopes differ
        assert abs(left_slope - right_slope) > 1e-3, name


@pytest.mark.parametrize(
    "curve, points",
    [
        (lambda x: active_force_length(x), (0.5, 0.9, 1.3)),
        (lambda x: force_velocity(x, 0.26), (-0.7, -0.2, 0.1, 0.8)),
        (lambda x: passive_force_length(x), (1.05, 1.4)),
        (lambda x: tendon_force_strain(x), (0.01, 0.03, 0.07)),
    ],
)
def test_curve_slopes_match_central_differences(curve, points):
    h = 1e-6
    for x in points:
        fd = (curve(x + h)[0] - curve(x - h)[0]) / (2.0 * h)
        assert curve(x)[1] != 0.0
        assert curve(x)[1] == pytest.approx(fd, rel=1e-6)


# ---- muscle–tendon unit ---------------------------------------------------------------
@pytest.mark.parametrize("alpha0", [0.0, 0.3])
def test_strength_rigid_tendon_limit_is_f0_cos_alpha(alpha0):
    f0, lf0, lt0 = 200.0, 0.02, 0.03
    # tendon strain 1e-7 at F0: stretches 3 nm, so the fibre stays at Lf0 to 1.5e-7
    muscle = Hill3ElementMuscle(f0, lf0, lt0, tendon_strain_at_max_force=1e-7,
                                pennation_angle_at_optimal=alpha0, name="stiff")
    l_mt = lt0 + lf0 * math.cos(alpha0)  # fibre at its optimal length, tendon at slack
    strength, passive = muscle.evaluate(l_mt, 0.0)
    assert strength == pytest.approx(f0 * math.cos(alpha0), rel=1e-6)
    assert passive == pytest.approx(0.0, abs=1e-6)  # f_PE(1) = 0 (up to rounding of l_MT)
    # the limit is approached as the tendon stiffens: error ∝ ε0_T
    errors = [abs(Hill3ElementMuscle(f0, lf0, lt0, tendon_strain_at_max_force=e,
                                     pennation_angle_at_optimal=alpha0).evaluate(l_mt, 0.0)[0]
                  - f0 * math.cos(alpha0)) for e in (1e-2, 1e-3, 1e-4)]
    assert errors[0] > errors[1] > errors[2]


def test_passive_force_zero_below_slack_and_f0_at_documented_stretch():
    f0, lf0, lt0 = 150.0, 0.025, 0.02
    stiff = Hill3ElementMuscle(f0, lf0, lt0, tendon_strain_at_max_force=1e-7, name="stiff")
    # fibre stretched to l̃ = 1 + ε0_M → f_PE = 1 → f_P = F0 (rigid tendon, α = 0)
    assert stiff.evaluate(lt0 + lf0 * (1.0 + EPS0_M), 0.0)[1] == pytest.approx(f0, rel=2e-6)
    # l̃ = 1.3 → F0 (e^{1.5} − 1)/(e^3 − 1)
    expected = f0 * (math.exp(K_PE * 0.3 / EPS0_M) - 1.0) / (math.exp(K_PE) - 1.0)
    assert stiff.evaluate(lt0 + lf0 * 1.3, 0.0)[1] == pytest.approx(expected, rel=2e-6)
    compliant = Hill3ElementMuscle(f0, lf0, lt0, name="compliant")
    lengths = np.array([0.5 * lt0, lt0, lt0 + 0.5 * lf0, lt0 + lf0])
    _, passive = compliant.evaluate(lengths, np.zeros(4))
    np.testing.assert_array_equal(passive, 0.0)
    states = compliant.evaluate_states(lengths, np.zeros(4))
    np.testing.assert_array_equal(states.status, [1, 1, 0, 0])
    np.testing.assert_array_equal(states.strength[:2], 0.0)


def test_collapsed_state_is_flagged():
    # α0 = 0 and l_MT = Lt0 + 1 % Lf0: even a vanishing fibre out-pulls the barely
    # stretched tendon (strain ≤ 0.0088 → f_T ≤ 0.03, f_L ≥ f_L(0) = e^(−1/γ) ≈ 0.108).
    # (With pennation, cos α → 0 as the fibre shortens, so an equilibrium always exists.)
    masseter = Hill3ElementMuscle(272.8, 0.0226, 0.0258, name="unpennate")
    l_mt = masseter.tendon_slack_length + 0.01 * masseter.optimal_fibre_length
    st = masseter.evaluate_states(l_mt, 0.0)
    assert st.status[0] == 2
    assert st.passive_force[0] == 0.0
    lf0 = masseter.optimal_fibre_length
    eps_t = (l_mt - 1e-6 * lf0 - masseter.tendon_slack_length) / masseter.tendon_slack_length
    assert st.strength[0] == pytest.approx(272.8 * doc_f_t(eps_t), rel=1e-9)


@pytest.mark.parametrize("name, f0, lf0, lt0", JAW)
@pytest.mark.parametrize("stretch, v_mt", [(0.85, 0.0), (1.0, -0.05), (1.15, 0.03), (1.3, 0.0)])
def test_tendon_fibre_equilibrium_at_returned_states(name, f0, lf0, lt0, stretch, v_mt):
    muscle = Hill3ElementMuscle(f0, lf0, lt0, pennation_angle_at_optimal=0.15, name=name)
    l_mt = stretch * (lf0 * math.cos(0.15) + lt0)
    st = muscle.evaluate_states(l_mt, v_mt)
    assert st.status[0] == 0
    t1, m1 = doc_forces(muscle, st.fibre_length_active[0], l_mt, v_mt, 1.0)
    t0, m0 = doc_forces(muscle, st.fibre_length_passive[0], l_mt, v_mt, 0.0)
    if t0 > 0.0:
        assert t0 == pytest.approx(m0, abs=1e-8)  # tendon force = fibre force along tendon
    assert t1 == pytest.approx(m1, abs=1e-8)
    assert st.passive_force[0] == pytest.approx(t0, abs=1e-9)
    assert st.strength[0] == pytest.approx(t1 - t0, abs=1e-9)
    # an independent root finder (brentq on the documented equations) gives the same state
    h = lf0 * math.sin(0.15)
    t0_ref, x0_ref = doc_equilibrium_tendon_force(muscle, l_mt, 0.0, 0.0, l_mt - lt0)
    if t0_ref == 0.0 or doc_f_pe(math.hypot(l_mt - lt0, h) / lf0) == 0.0:
        t0_ref, x0_ref = 0.0, l_mt - lt0
    t1_ref, _ = doc_equilibrium_tendon_force(muscle, l_mt, v_mt, 1.0, x0_ref)
    assert st.passive_force[0] == pytest.approx(t0_ref, abs=1e-7)
    assert st.strength[0] == pytest.approx(t1_ref - t0_ref, abs=1e-7)


def test_strength_decreases_with_shortening_speed(masseter):
    l_mt = masseter.optimal_fibre_length + masseter.tendon_slack_length
    v_max = masseter.max_contraction_velocity * masseter.optimal_fibre_length  # 0.226 m/s
    speeds = np.linspace(-0.95 * v_max, 0.5 * v_max, 41)  # m/s, shortening → lengthening
    strength, passive = masseter.evaluate(np.full_like(speeds, l_mt), speeds)
    assert np.all(np.diff(strength) > 0.0)  # less shortening → stronger
    assert strength[0] < 0.1 * masseter.evaluate(l_mt, 0.0)[0]
    assert strength[-1] > masseter.evaluate(l_mt, 0.0)[0]  # eccentric: above isometric
    # beyond V_max (fibre speed v_MT cos α) no active force is left
    assert masseter.evaluate(l_mt, -1.05 * v_max / math.cos(0.2))[0] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(passive, passive[0], rtol=0, atol=1e-12)  # f_P ignores v_MT


@pytest.mark.parametrize("stretch, v_mt", [(0.9, 0.01), (1.05, -0.04), (1.2, 0.02), (1.3, -0.01)])
def test_derivatives_match_central_differences(masseter, stretch, v_mt):
    l_mt = stretch * (masseter.optimal_fibre_length + masseter.tendon_slack_length)
    st = masseter.evaluate_states(l_mt, v_mt)
    dl, dv = 1e-7, 1e-6
    s_l = [masseter.evaluate(l_mt + d, v_mt) for d in (dl, -dl)]
    s_v = [masseter.evaluate(l_mt, v_mt + d) for d in (dv, -dv)]
    fd_s_l = (s_l[0][0] - s_l[1][0]) / (2 * dl)
    fd_p_l = (s_l[0][1] - s_l[1][1]) / (2 * dl)
    fd_s_v = (s_v[0][0] - s_v[1][0]) / (2 * dv)
    assert st.dstrength_dlength[0] != 0.0 and st.dstrength_dspeed[0] != 0.0
    assert st.dstrength_dlength[0] == pytest.approx(fd_s_l, rel=1e-5, abs=1e-3)
    assert st.dstrength_dspeed[0] == pytest.approx(fd_s_v, rel=1e-5, abs=1e-3)
    assert st.dpassive_dlength[0] == pytest.approx(fd_p_l, rel=1e-5, abs=1e-3)
    if stretch > 1.1:
        assert st.dpassive_dlength[0] > 0.0


def test_muscle_set_equals_per_muscle_evaluation():
    muscles = [Hill3ElementMuscle(f0, lf0, lt0, name=n) for n, f0, lf0, lt0 in JAW]
    muscles.insert(2, ConstantStrengthMuscle(20000.0, name="tmj_contact"))
    muscles.append(ConstantStrengthMuscle(150.0, name="simple"))
    muscles.append(Hill3ElementMuscle(100.0, 0.02, 0.01, pennation_angle_at_optimal=0.4,
                                      fast_fibre_fraction=0.8, name="pennate"))
    rng = np.random.default_rng(7)
    muscle_set = MuscleSet(muscles)
    for _ in range(5):
        l_mt = np.array([(m.optimal_fibre_length + m.tendon_slack_length)
                         if isinstance(m, Hill3ElementMuscle) else 0.05 for m in muscles])
        l_mt *= rng.uniform(0.8, 1.3, len(muscles))
        v_mt = rng.uniform(-0.1, 0.1, len(muscles))
        strength, passive = muscle_set.evaluate(l_mt, v_mt)
        for i, m in enumerate(muscles):
            s_i, p_i = m.evaluate(l_mt[i], v_mt[i])
            assert strength[i] == s_i and passive[i] == p_i, m.name
    assert strength[2] == 20000.0 and passive[2] == 0.0
    assert muscle_set.names[2] == "tmj_contact" and muscle_set.n_muscles == len(muscles)
    with pytest.raises(MuscleParameterError, match=r"shape \(9,\)"):
        muscle_set.evaluate(np.ones(3), np.ones(3))
    bad = np.full(len(muscles), 0.05)
    bad[4] = np.nan
    with pytest.raises(MuscleParameterError, match="muscle 4 'medial_pterygoid'"):
        muscle_set.evaluate(bad, np.zeros(len(muscles)))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(max_isometric_force=-10.0), "'temporalis'.*max_isometric_force"),
        (dict(optimal_fibre_length=0.0), "'temporalis'.*optimal_fibre_length"),
        (dict(tendon_slack_length=-0.01), "'temporalis'.*tendon_slack_length"),
        (dict(pennation_angle_at_optimal=2.0), "'temporalis'.*pennation"),
        (dict(fast_fibre_fraction=1.5), "'temporalis'.*fast_fibre_fraction"),
        (dict(max_eccentric_force=1.0), "'temporalis'.*max_eccentric_force"),
    ],
)
def test_bad_parameters_raise_naming_the_muscle(kwargs, message):
    base = dict(max_isometric_force=308.0, optimal_fibre_length=0.0307, tendon_slack_length=0.0242)
    with pytest.raises(MuscleParameterError, match=message):
        Hill3ElementMuscle(**{**base, **kwargs}, name="temporalis")
    with pytest.raises(MuscleParameterError, match="'reaction'.*strength"):
        ConstantStrengthMuscle(0.0, name="reaction")
    with pytest.raises(MuscleParameterError, match="appears twice"):
        MuscleSet([ConstantStrengthMuscle(1.0, "a"), ConstantStrengthMuscle(2.0, "a")])
