"""Driver time functions against finite differences, and FDK DOFs as kinematic inputs."""

import numpy as np
import pytest

from models import slider_crank
from openfdk.kinematics.analysis import run_determinate, run_tracking
from openfdk.model.builder import ModelBuilder
from openfdk.model.timefunctions import Constant, Fourier, Polynomial, SplineThroughData
from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict


@pytest.mark.parametrize(
    "f",
    [
        Polynomial([[0.1, -1.0], [2.0, 0.5], [-3.0, 0.0], [0.7, 1.0]]),
        Fourier(1.3, [0.2, 1.0, -0.4], [0.5, 0.25]),
        SplineThroughData(np.linspace(0, 2, 9), np.sin(np.linspace(0, 2, 9))),
    ],
)
def test_time_function_derivatives(f):
    h = 1e-5
    for t in (0.13, 0.77, 1.41):
        v, dv, ddv = f.derivatives(t)
        vp, vm = f.derivatives(t + h)[0], f.derivatives(t - h)[0]
        np.testing.assert_allclose(dv, (vp - vm) / (2 * h), rtol=1e-6, atol=1e-8)
        dp, dm = f.derivatives(t + h)[1], f.derivatives(t - h)[1]
        np.testing.assert_allclose(ddv, (dp - dm) / (2 * h), rtol=1e-5, atol=1e-6)
        assert np.all(np.abs(dv) > 0)


def test_fourier_closed_form():
    f = Fourier(2.0, [1.0, 0.5], [0.25])
    t = 0.1
    w = 4 * np.pi
    assert f.derivatives(t)[0][0] == pytest.approx(1 + 0.5 * np.cos(w * t) + 0.25 * np.sin(w * t))


def test_spline_driver_refuses_to_extrapolate():
    f = SplineThroughData([0, 1, 2], [0, 1, 0])
    with pytest.raises(ValueError, match="outside its data"):
        f.derivatives(2.5)


def test_constant_function():
    v, dv, ddv = Constant([1.0, 2.0]).derivatives(3.0)
    assert list(v) == [1.0, 2.0] and not dv.any() and not ddv.any()


def test_fdk_dof_is_an_input_of_determinate_kinematics():
    """A slider on a prismatic rail whose position is an FDK DOF: the kinematics put
    it at α with zero velocity and acceleration (α̇ = α̈ = 0)."""
    b = ModelBuilder("slider")
    b.add_body("block", 1.0, [1, 1, 1], position=[0, 0, 0.3])
    b.add_joint("rail", "prismatic", parent="ground.origin", child="block.origin")
    b.add_fdk_dof("height", b.vector("ground.origin", "block.origin"), initial=0.3, component=2)
    model = b.build()
    res = run_determinate(model, np.array([0.0, 0.1]), alpha=[0.125])
    assert res.converged.all()
    np.testing.assert_allclose(res.q[:, 2], 0.125, atol=1e-12)
    np.testing.assert_allclose(res.v, 0.0, atol=1e-12)
    np.testing.assert_allclose(res.vdot, 0.0, atol=1e-12)
    # default α = the declared initial value
    assert run_determinate(model, np.array([0.0])).q[0, 2] == pytest.approx(0.3)


def test_fdk_dof_is_a_hard_constraint_in_marker_tracking():
    """The two-body jaw with the joint-plane normal distance declared an FDK DOF: the
    tracked condyle sits α off the plane, and the markers absorb the mismatch."""
    from openfdk.io.modelfile import model_from_dict

    data = two_body_model_dict()
    data["joints"] = {}
    data["measures"] = {"gap": {"type": "plane_distance", "plane": "skull.plane", "point": "jaw.condyle"}}
    data["fdk_dofs"] = {"tmj_normal": {"measure": "gap", "initial": 0.0}}
    model = model_from_dict(data, "fdk.yaml")
    t, labels, x, truth = synthetic_markers(40, noise=0.0)

    class Exact:
        time = t

        def evaluate(self, tt):
            k = int(round(tt * 100))
            return x[k], np.zeros((8, 3)), np.zeros((8, 3)), np.ones(8, bool)

    alpha = 0.8e-3
    res = run_tracking(model, Exact(), t, alpha=[alpha])
    assert res.converged.all()
    state = model.initial_state()
    gap = model.fdk_dofs[0].measure
    for k in (0, 20, 39):
        state.set_q(res.q[k])
        assert gap.evaluate(state, 0)[0][0] == pytest.approx(alpha, abs=1e-10)
    assert np.nanmax(np.abs(res.marker_residual)) > 3e-5  # the data disagree with α ≠ 0


def test_alpha_shape_is_checked():
    model = slider_crank()
    with pytest.raises(ValueError, match="one per FDK DOF"):
        run_determinate(model, np.array([0.0]), alpha=[1.0])
