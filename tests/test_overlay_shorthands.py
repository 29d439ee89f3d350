"""The overlay's ``fdk:`` and ``lock:`` lists (io/opensim/overlay.py): OpenSim
coordinates made FDK DOFs or held, by name, as the knee-in-gait overlay uses them."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.bench.fuzz_inputs import OSIM_TEXT
from openfdk.io.modelfile import load_model_and_settings
from openfdk.kinematics.analysis import run_determinate
from openfdk.model.compiled import CompiledMeasures
from openfdk.model.errors import ModelError


@pytest.fixture
def leg(tmp_path):
    (tmp_path / "leg.osim").write_text(OSIM_TEXT)
    return tmp_path


def _overlay(folder, text, name="with.yaml"):
    (folder / name).write_text("opensim: leg.osim\nignore: [Mesh]\n" + text)
    return folder / name


def test_fdk_and_lock_lists_become_dofs_and_held_coordinates(leg):
    model, settings = load_model_and_settings(_overlay(leg, "fdk: [knee]\nlock: [{hip_q: 0.3}]\n"))
    (dof,) = model.fdk_dofs
    assert dof.name == "knee" and dof.initial == -0.5  # the coordinate's <default_value>
    # determinate now: the hip held at 0.3 rad, the knee at α; the solved pose's
    # coordinates (OpenSim's definitions, evaluated by their own measures) say so
    res = run_determinate(model, np.array([0.0, 0.1]), alpha=[-0.2])
    assert res.converged.all()
    coords = {c.name: c for c in model.coordinates}
    state = model.initial_state()
    state.set_q(res.q[1])
    values = CompiledMeasures([coords["hip_q"].measure, coords["knee"].measure]).evaluate(state, 0)[0]
    np.testing.assert_allclose(values, [0.3, -0.2], atol=1e-9)


def test_fdk_as_a_mapping_is_still_the_settings_section(leg):
    model, settings = load_model_and_settings(_overlay(leg, "fdk_dofs: {knee: {measure: knee}}\n"
                                                            "fdk: {max_iterations: 7}\n"))
    assert settings.fdk.max_iterations == 7 and [d.name for d in model.fdk_dofs] == ["knee"]
    # the list form beside the settings
    model, settings = load_model_and_settings(_overlay(leg, "fdk_dofs: [knee]\nfdk: {max_iterations: 5}\n"))
    assert settings.fdk.max_iterations == 5 and [(d.name, d.initial) for d in model.fdk_dofs] == [("knee", -0.5)]


@pytest.mark.parametrize("text, expected", [
    ("fdk: [kne]\n", "with.yaml: fdk[0]: 'kne' is not a coordinate of the model; did you mean 'knee'?"),
    ("fdk: [knee]\nfdk_dofs: [knee]\n", "with.yaml: fdk_dofs: give the FDK coordinates once"),
    ("lock: knee\n", "with.yaml: lock: expected a list of coordinate names, got str"),
    ("lock: [hip_q, hip_q]\n", "with.yaml: lock[1]: 'hip_q' is listed twice"),
    ("lock: [{hip_q: .nan}]\n", "with.yaml: lock[0]: hip_q: expected a finite number (rad or m), got nan"),
    ("lock: [{hip_q: true}]\n", "with.yaml: lock[0]: hip_q: expected a finite number (rad or m), got True"),
    ("fdk: [knee]\nlock: [knee]\n", "with.yaml: lock: 'knee' is also listed under fdk"),
    ("fdk: [knee]\nfdk_dofs: {knee: {measure: knee}}\n", "with.yaml: fdk_dofs.knee: also made by the fdk list"),
])
def test_bad_lists_are_one_line_errors(leg, text, expected):
    with pytest.raises(ModelError) as err:
        load_model_and_settings(_overlay(leg, text))
    assert str(err.value).startswith(expected)


def test_reserves_leave_out_fdk_and_locked_coordinates(leg):
    """A reserve on an FDK coordinate would carry the very load FDK must balance (the
    DM knee's five secondary coordinates took 4–8 kN in their reserves): reserves are
    made for free coordinates only."""
    plain, _ = load_model_and_settings(_overlay(leg, "reserves: {optimal_force: 1.0}\n", "plain.yaml"))
    held, _ = load_model_and_settings(_overlay(leg, "reserves: {optimal_force: 1.0}\nfdk: [knee]\n"
                                                    "lock: [hip_q]\n"))
    before = {a.coordinate for a in plain.actuators}
    after = {a.coordinate for a in held.actuators}
    assert {"knee", "hip_q"} <= before
    assert after == before - {"knee", "hip_q"}


def test_frames_on_opensim_bodies_are_where_opensim_puts_the_points(leg):
    """``frames: {osim_body: {name: [x, y, z]}}``: a point given in an OpenSim body's frame
    becomes a frame of the openfdk body holding it (its origin at the centre of mass,
    bodies welded together merged); at a pose its world position equals
    OpenSim's findStationLocationInGround of the same station, for every body of the leg
    (the thigh's centre of mass is off its origin, so the offset is not zero)."""
    opensim = pytest.importorskip("opensim")
    osim = opensim.Model(str(leg / "leg.osim"))
    osim_state = osim.initSystem()
    bodies = [osim.getBodySet().get(i).getName() for i in range(osim.getBodySet().getSize())]
    points = {b: [0.013 * (i + 1), -0.021, 0.007 * (i - 1)] for i, b in enumerate(bodies)}
    frames = "\n".join(f"  {b}: {{pt_{b}: {points[b]}}}" for b in bodies)
    model, _ = load_model_and_settings(_overlay(leg, f"frames:\n{frames}\n"))
    state = model.initial_state()
    # OpenSim at openfdk's pose (its initial state need not be the coordinates' defaults)
    for c in model.coordinates:
        osim.getCoordinateSet().get(c.name).setValue(osim_state, float(c.measure.evaluate(state, 0)[0][0]), False)
    osim.realizePosition(osim_state)
    index = {body.name: i for i, body in enumerate(model.bodies)}
    for b in bodies:
        (name,) = [q for q in model.frames if q.endswith(f".pt_{b}")]
        frame = model.frame(name)
        i = index[frame.body]
        got = state.p_WB[i] + state.R_WB[i] @ frame.p_BF
        v = osim.getBodySet().get(b).findStationLocationInGround(osim_state, opensim.Vec3(*points[b]))
        np.testing.assert_allclose(got, [v.get(0), v.get(1), v.get(2)], atol=1e-12)
        assert np.linalg.norm(frame.p_BF - points[b]) > 1e-3 or b != "thigh"  # the COM offset counted


@pytest.mark.parametrize("text,expected", [
    ("frames: {thig: {a: [0, 0, 0]}}\n", "frames.thig: not a body of the OpenSim model; did you mean .thigh.?"),
    ("frames: {thigh: {a: [0, 0]}}\n", "frames.thigh.a: expected [x, y, z] in m"),
    ("frames: [femur]\n", "frames: expected a mapping of OpenSim body names"),
])
def test_bad_frames_are_one_line_errors(leg, text, expected):
    with pytest.raises(ModelError, match=expected.replace("[", r"\[").replace("]", r"\]")) as info:
        load_model_and_settings(_overlay(leg, text))
    assert "\n" not in str(info.value)
