"""The Millard muscle (docs/muscles.md, "Millard muscle") without OpenSim: the model
file's ``model: millard`` (units, curve keys, one-line errors), a MuscleSet mixing Hill
and Millard muscles, the derivatives of its states against central differences, and the
inverse-dynamics rule against an independent root of the equilibrium (scipy's brentq).
OpenSim 4.6 is the oracle in tests/test_opensim_millard.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from openfdk.forces import millard_curves as mc
from openfdk.forces.hill import Hill3ElementMuscle, MuscleSet
from openfdk.forces.millard import MillardMuscle
from openfdk.forces.rigid_tendon import opensim_strengths
from openfdk.io.modelfile import model_from_dict
from openfdk.model.model import ModelError


def _model(muscle):
    data = {
        "openfdk": 1, "units": {"length": "mm", "angle": "deg"},
        "bodies": {"link": {"mass": 1.0, "inertia": [0.01, 0.01, 0.01], "points": {"i": [0, -300, 0]}},
                   "ground": {"points": {"o": [0, 50, 0]}}},
        "coordinates": {"q": {"default": 0.0, "range": [-90, 60]}},
        "joints": {"hinge": {"type": "custom", "parent": "ground", "child": "link",
                             "rotations": [{"axis": [0, 0, 1], "coordinate": "q"}]}},
        "muscles": {"mu": {"path": ["ground.o", "link.i"], **muscle}},
    }
    return model_from_dict(data, source="millard.yaml")


MUSCLE = {"model": "millard", "max_isometric_force": 900.0, "optimal_fibre_length": 100.0,
          "tendon_slack_length": 240.0, "pennation_angle_at_optimal": 10.0, "maximum_pennation_angle": 80.0,
          "fiber_damping": 0.0, "tendon_force_length": {"strain_at_one_norm_force": 0.04},
          "active_force_length": {"shallow_ascending_slope": 0.7}}


def test_model_file_millard_entry():
    """Lengths in the file's unit (mm), angles in its unit (deg), the curves by name."""
    law = _model(MUSCLE).muscles[0].law
    assert isinstance(law, MillardMuscle)
    assert law.optimal_fibre_length == pytest.approx(0.1) and law.tendon_slack_length == pytest.approx(0.24)
    assert law.pennation_angle_at_optimal == pytest.approx(math.radians(10))
    assert law.maximum_pennation_angle == pytest.approx(math.radians(80))
    assert law.tendon_force_length == mc.TendonForceLengthCurve(0.04)
    assert law.active_force_length.shallow_ascending_slope == 0.7
    fal, fv, _, _ = law.curves_in_use()  # classic model (no damping): f_L floor 0.1
    assert fal.minimum_value == 0.1 and fv.concentric_slope_at_vmax == 0.125


@pytest.mark.parametrize("change,words", [
    ({"tendon_force_length": {"strain_at_one_norm": 0.04}}, "strain_at_one_norm_force"),
    ({"fast_fibre_fraction": 0.4}, "Hill-model key"),
    ({"tendon_force_length": {"strain_at_one_norm_force": 0.04, "curviness": 0.5}}, "all be given or all be absent"),
    ({"active_force_length": {"shallow_ascending_slope": 5.0}}, "shallow_ascending_slope"),
    ({"ignore_tendon_compliance": "yes"}, "true or false"),
    ({"fiber_damping": -1}, "fiber_damping"),
])
def test_model_file_errors_are_one_line(change, words):
    with pytest.raises(ModelError) as exc:
        _model({**MUSCLE, **change})
    msg = str(exc.value)
    assert "\n" not in msg and "millard.yaml" in msg and "muscles.mu" in msg and words in msg, msg


def test_millard_keys_need_model_millard():
    with pytest.raises(ModelError, match="belongs to 'model: millard'"):
        _model({"max_isometric_force": 900.0, "optimal_fibre_length": 100.0, "tendon_slack_length": 240.0,
                "fiber_damping": 0.1})


MUSCLES = [
    MillardMuscle(900.0, 0.1, 0.24, 0.2, name="damped"),
    Hill3ElementMuscle(700.0, 0.08, 0.2, pennation_angle_at_optimal=0.1, name="hill"),
    MillardMuscle(1200.0, 0.09, 0.22, 0.3, fiber_damping=0.0, maximum_pennation_angle=1.2,
                  fibre_force_length=mc.FiberForceLengthCurve(0.02, 0.65, 0.25, 4.0, 0.6), name="classic"),
    MillardMuscle(500.0, 0.1, 0.23, 0.0, ignore_tendon_compliance=True, name="rigid"),
]


def test_muscle_set_mixes_hill_and_millard():
    """A set of Hill and Millard muscles gives each muscle's own single evaluation, and
    OpenSim's static-optimisation strengths by kind."""
    s = MuscleSet(MUSCLES)
    l = np.array([0.35, 0.29, 0.33, 0.34])
    v = np.array([0.1, -0.2, 0.05, -0.3])
    strength, passive = s.evaluate(l, v)
    for k, m in enumerate(MUSCLES):
        assert (strength[k], passive[k]) == pytest.approx(m.evaluate(l[k], v[k]), rel=1e-14)
    f_opt = opensim_strengths(s, l, v)
    assert f_opt[1] == pytest.approx(opensim_strengths(MuscleSet([MUSCLES[1]]), l[1:2], v[1:2])[0])
    from openfdk.forces.millard import opensim_so_strength
    for k in (0, 2, 3):
        assert f_opt[k] == opensim_so_strength(MUSCLES[k], l[k], v[k])[0]


def test_muscle_set_states_do_not_depend_on_the_previous_call():
    """A set copies the Millard rows whose l_MT and v_MT equal its previous call's instead
    of solving them again: every row equals each muscle's own single evaluation, after
    calls that change some rows, all rows or none."""
    s = MuscleSet(MUSCLES)
    l0, v0 = np.array([0.35, 0.29, 0.33, 0.34]), np.array([0.1, -0.2, 0.05, -0.3])
    for l, v in ((l0, v0), (l0 + [0.0, 0.0, 0.004, 0.0], v0), (l0, v0 + [0.02, 0.0, 0.0, 0.0]), (l0, v0),
                 (l0 - 0.003, v0 + 0.01)):
        strength, passive = s.evaluate(l, v)
        for k, m in enumerate(MUSCLES):
            assert (strength[k], passive[k]) == pytest.approx(m.evaluate(l[k], v[k]), rel=1e-14)
        assert strength[0] > 0.0 and strength[2] > 0.0


@pytest.mark.parametrize("muscle", [m for m in MUSCLES if isinstance(m, MillardMuscle)], ids=lambda m: m.name)
def test_state_derivatives_match_central_differences(muscle):
    rng = np.random.default_rng(7)
    for _ in range(20):
        l = muscle.tendon_slack_length + muscle.optimal_fibre_length * rng.uniform(0.8, 1.4)
        v = rng.uniform(-0.4, 0.4)
        st = muscle.evaluate_states(l, v)
        h = 1e-7
        up, down = muscle.evaluate_states(l + h, v), muscle.evaluate_states(l - h, v)
        ds_dl = (up.strength - down.strength) / (2 * h)
        dp_dl = (up.passive_force - down.passive_force) / (2 * h)
        ds_dv = (muscle.evaluate_states(l, v + h).strength - muscle.evaluate_states(l, v - h).strength) / (2 * h)
        scale = muscle.max_isometric_force / muscle.optimal_fibre_length
        assert abs(st.dstrength_dlength[0] - ds_dl[0]) <= 1e-5 * scale
        assert abs(st.dpassive_dlength[0] - dp_dl[0]) <= 1e-5 * scale
        assert abs(st.dstrength_dspeed[0] - ds_dv[0]) <= 1e-5 * scale


def _independent_tendon_force(muscle, l_mt, v_mt, a):
    """T(a) from brentq on the equilibrium written from docs/muscles.md."""
    fal, fv, fpe, fse = (c.table() for c in muscle.curves_in_use())
    f0, lf0, lt0 = muscle.max_isometric_force, muscle.optimal_fibre_length, muscle.tendon_slack_length
    h = lf0 * math.sin(muscle.pennation_angle_at_optimal)
    vmax = muscle.max_contraction_velocity * lf0
    l_min = max(muscle.active_force_length.min_norm_active_fiber_length * lf0,
                h / math.sin(muscle.maximum_pennation_angle))

    def residual(x):
        l_f = math.hypot(x, h)
        cos_a = x / l_f
        fibre = a * mc.evaluate_curve(fal, l_f / lf0)[0] * mc.evaluate_curve(fv, v_mt * cos_a / vmax)[0]
        fibre += mc.evaluate_curve(fpe, l_f / lf0)[0]
        return f0 * mc.evaluate_curve(fse, (l_mt - x) / lt0)[0] - f0 * fibre * cos_a

    x_lo, x_hi = math.sqrt(l_min ** 2 - h * h), l_mt - lt0
    x = brentq(residual, x_lo, x_hi, xtol=1e-15, rtol=1e-15)
    return f0 * mc.evaluate_curve(fse, (l_mt - x) / lt0)[0]


@pytest.mark.parametrize("muscle", [MUSCLES[0], MUSCLES[2]], ids=lambda m: m.name)
def test_equilibria_match_an_independent_root(muscle):
    rng = np.random.default_rng(11)
    for _ in range(15):
        l = muscle.tendon_slack_length + muscle.optimal_fibre_length * rng.uniform(0.9, 1.4)
        v = rng.uniform(-0.3, 0.3)
        s, f_p = muscle.evaluate(l, v)
        t1 = _independent_tendon_force(muscle, l, v, 1.0)
        t0 = _independent_tendon_force(muscle, l, 0.0, 0.0) if f_p > 0 else 0.0
        assert s + f_p == pytest.approx(t1, rel=1e-9, abs=1e-9)
        assert f_p == pytest.approx(t0, rel=1e-9, abs=1e-9)
