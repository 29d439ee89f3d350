"""Inverse dynamics of an OpenSim model with external loads against OpenSim 4.6's
InverseDynamicsSolver.

The project's full-body model (12 bodies, 23 coordinates, spline-coupled knees, oblique
ankle axes) moves along analytic coordinate trajectories q(t) = a + b sin(2π f t + φ)
(so q̇ and q̈ are exact on both sides), with two ExternalForces from an ``ExternalLoads``
file and its ``.mot``: one expressed in the ground at a moving ground point (a ground
reaction with its free torque), one expressed in the foot's own frame at a point of the
foot. OpenSim's solver gets q, q̇ and q̈ at each sample time; openfdk drives each
coordinate by the same function (a driver with its reaction, as ``--motion`` does) and
reads the loads with ``--external-loads``. The generalised forces agree to 1e-6 N m (N)
at every sample time, where any interpolation of the load samples is exact.
Momentum balance: gravity, the loads and the residual forces equal the whole body's rate
of change of linear momentum Σ m_i a_i at every frame (a physical invariant checked on
openfdk's side alone, to 1e-8 relative).
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

opensim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.fixtures.full_body_osim import COORDINATES, write_full_body_osim  # noqa: E402
from openfdk.io.results import read_table  # noqa: E402
from openfdk.io.storage import write_storage  # noqa: E402

RATE = 100.0
N = 21


def _motion(rng):
    """{coordinate: (a, b, f, φ)} of q = a + b sin(2π f t + φ) within plausible ranges."""
    out = {}
    for name in COORDINATES:
        if name in ("pelvis_tx", "pelvis_ty", "pelvis_tz"):
            a, b = {"pelvis_tx": 0.1, "pelvis_ty": 0.95, "pelvis_tz": 0.02}[name], 0.03
        else:
            a, b = rng.uniform(-0.1, 0.1), rng.uniform(0.05, 0.25)
            if name.startswith("knee_angle"):
                a = -0.6
        out[name] = (a, b, rng.uniform(0.6, 1.4), rng.uniform(0, 2 * np.pi))
    return out


def _q(m, t, order=0):
    a, b, f, phi = m
    w = 2 * np.pi * f
    return [a + b * np.sin(w * t + phi), b * w * np.cos(w * t + phi), -b * w * w * np.sin(w * t + phi)][order]


def _loads(folder, times):
    """The GRF .mot and the ExternalLoads .xml (two forces)."""
    t = np.asarray(times)
    cols = {
        "g_vx": 80 * np.sin(3 * t), "g_vy": 700 + 50 * np.cos(2 * t), "g_vz": -30 + 10 * t,
        "g_px": 0.3 + 0.4 * t, "g_py": 0.0 * t, "g_pz": 0.1 - 0.05 * t,
        "g_tx": 0.0 * t, "g_ty": 5 * np.sin(4 * t), "g_tz": 0.0 * t,
        "b_vx": 20 + 5 * t, "b_vy": -40 * np.cos(t), "b_vz": 10 * np.sin(2 * t),
        "b_px": 0.05 + 0.0 * t, "b_py": -0.01 + 0.02 * t, "b_pz": 0.01 + 0.0 * t,
        "b_tx": 1.5 + 0.0 * t, "b_ty": -0.5 * t, "b_tz": 0.2 + 0.0 * t,
    }
    write_storage(folder / "loads.mot", t, cols, name="loads")
    (folder / "loads.xml").write_text("""<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <ExternalLoads name="loads">
    <objects>
      <ExternalForce name="ground_reaction">
        <applied_to_body>calcn_r</applied_to_body>
        <force_expressed_in_body>ground</force_expressed_in_body>
        <point_expressed_in_body>ground</point_expressed_in_body>
        <force_identifier>g_v</force_identifier>
        <point_identifier>g_p</point_identifier>
        <torque_identifier>g_t</torque_identifier>
      </ExternalForce>
      <ExternalForce name="pushing_hand">
        <applied_to_body>talus_l</applied_to_body>
        <force_expressed_in_body>talus_l</force_expressed_in_body>
        <point_expressed_in_body>talus_l</point_expressed_in_body>
        <force_identifier>b_v</force_identifier>
        <point_identifier>b_p</point_identifier>
        <torque_identifier>b_t</torque_identifier>
      </ExternalForce>
    </objects>
    <datafile>loads.mot</datafile>
  </ExternalLoads>
</OpenSimDocument>
""")
    return folder / "loads.xml"


def opensim_model_with_loads(model_path, loads_xml):
    """(the OpenSim Model of ``model_path`` with the ExternalForces of ``loads_xml`` added,
    not yet initialised; their data, ``loads.mot`` beside it, which the caller keeps
    alive while the model is used: the forces hold it by reference)."""
    model = opensim.Model(str(model_path))
    ext = opensim.ExternalLoads(str(loads_xml), True)
    data = opensim.Storage(str(loads_xml.parent / "loads.mot"))
    for i in range(ext.getSize()):
        force = ext.get(i).clone()
        force.setDataSource(data)
        model.addForce(force)
    return model, data


def mobility_slots(state, coords):
    """{coordinate name: its entry of the state's u (mobility) vector}: each found by
    setting that coordinate's speed alone."""
    slot = {}
    for c in coords:
        state.setU(opensim.Vector(state.getNU(), 0.0))
        c.setSpeedValue(state, 1.0)
        slot[c.getName()] = int(np.argmax(np.abs([state.getU().get(i) for i in range(state.getNU())])))
    return slot


def coordinate_actuators(model, names):
    """{coordinate: the CoordinateActuator ``tau_<coordinate>`` of optimal force 1 added to
    the OpenSim ``model`` (not yet initialised)} for each of ``names``."""
    out = {}
    for n in names:
        a = opensim.CoordinateActuator(n)
        a.setName(f"tau_{n}")
        a.setOptimalForce(1.0)
        model.addForce(a)
        out[n] = a
    return out


def set_motion(model, state, coords, names, motion, t):
    """The OpenSim ``state`` at time ``t`` of the motion {name: (a, b, f, φ)}: the
    coordinates ``coords`` (named ``names``) set, the model assembled, then their speeds."""
    state.setTime(float(t))
    for c, n in zip(coords, names):
        c.setValue(state, _q(motion[n], t), False)
    model.assemble(state)
    for c, n in zip(coords, names):
        c.setSpeedValue(state, _q(motion[n], t, 1))


def _opensim_id(model_path, loads_xml, motion, times):
    """OpenSim's generalised forces {coordinate: (n,)} at the sample times."""
    model, _data = opensim_model_with_loads(model_path, loads_xml)
    state = model.initSystem()
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    names = [c.getName() for c in coords]
    slot = mobility_slots(state, coords)
    assert sorted(slot.values()) == list(range(len(coords)))
    solver = opensim.InverseDynamicsSolver(model)
    out = {n: [] for n in names}
    for t in times:
        set_motion(model, state, coords, names, motion, t)
        model.realizeVelocity(state)
        udot = opensim.Vector(len(names), 0.0)
        for n in names:
            udot.set(slot[n], _q(motion[n], t, 2))
        tau = solver.solve(state, udot)
        for n in names:
            out[n].append(tau.get(slot[n]))
    return {n: np.array(v) for n, v in out.items()}


def _overlay(folder, motion, times):
    drivers = {}
    for name, (a, b, f, phi) in motion.items():
        # b sin(wt + φ) = b sin φ cos(wt) + b cos φ sin(wt)
        drivers[f"{name}_motion"] = {"measure": name, "reaction": True, "function": {
            "type": "fourier", "frequency": float(f), "a": [float(a), float(b * np.sin(phi))],
            "b": [float(b * np.cos(phi))]}}
    data = {"drivers": drivers, "analysis": {"start": float(times[0]), "end": float(times[-1]), "frames": len(times)}}
    (folder / "overlay.yaml").write_text(yaml.safe_dump(data))
    return folder / "overlay.yaml"


@pytest.mark.slow
def test_generalized_forces_equal_opensims_inverse_dynamics(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(7)
    model = write_full_body_osim(tmp_path / "full_body.osim")
    times = np.arange(N) / RATE + 0.2
    motion = _motion(rng)
    loads = _loads(tmp_path, times)
    theirs = _opensim_id(model, loads, motion, times)

    code = main(["run", str(model), "--with", str(_overlay(tmp_path, motion, times)), "--external-loads", str(loads),
                 "--out", str(tmp_path / "ours"), "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    ours = read_table(tmp_path / "ours" / "generalized_forces.csv")
    np.testing.assert_allclose(ours["time"], times, atol=1e-12)
    assert len([k for k in ours if k != "time"]) == 23
    worst = 0.0
    for name in COORDINATES:
        key = f"{name}_force" if name in ("pelvis_tx", "pelvis_ty", "pelvis_tz") else f"{name}_moment"
        worst = max(worst, float(np.max(np.abs(ours[key] - theirs[name]))))
        # the loads matter: the generalised forces are not those of the unloaded motion
    print("largest generalised-force difference", worst)
    assert worst < 1e-6, worst
    assert np.max(np.abs(theirs["pelvis_ty"])) > 100.0  # a real load case, not all zeros

    # momentum balance (openfdk alone): gravity + the two loads + the residual forces (the
    # pelvis translations are along the ground's axes) = Σ m_i a_i, at every frame
    from openfdk.io.modelfile import load_model
    from openfdk.numerics.spatial import rotation_matrix

    fdk_model = load_model(model)
    kin = read_table(tmp_path / "ours" / "kinematics.csv")
    t = np.asarray(times)
    rate = np.zeros((N, 3))
    for b in fdk_model.moving_bodies:
        rate += b.mass * np.column_stack([kin[f"{b.name}.a{c}_m_s2"] for c in "xyz"])
    g = sum(b.mass for b in fdk_model.moving_bodies) * fdk_model.gravity_W
    F_ground = np.column_stack([80 * np.sin(3 * t), 700 + 50 * np.cos(2 * t), -30 + 10 * t])
    F_body = np.column_stack([20 + 5 * t, -40 * np.cos(t), 10 * np.sin(2 * t)])
    quat = np.column_stack([kin[f"talus_l.e{k}"] for k in range(4)])
    F_talus = np.array([rotation_matrix(q) @ f for q, f in zip(quat, F_body)])
    residual = np.column_stack([ours[f"pelvis_t{c}_force"] for c in "xyz"])
    balance = g + F_ground + F_talus + residual - rate
    assert np.max(np.abs(balance)) <= 1e-8 * np.max(np.abs(rate)), np.max(np.abs(balance))
    summary = yaml.safe_load((tmp_path / "ours" / "summary.json").read_text())
    assert set(summary["residuals"]["columns"]) == {"pelvis_tilt_moment", "pelvis_list_moment", "pelvis_rotation_moment",
                                                    "pelvis_tx_force", "pelvis_ty_force", "pelvis_tz_force"}


def test_external_loads_errors_name_the_file_and_the_force(tmp_path, capsys):
    model = write_full_body_osim(tmp_path / "full_body.osim")
    times = np.arange(5) / RATE
    xml = _loads(tmp_path, times)
    bad = xml.read_text().replace("<applied_to_body>calcn_r", "<applied_to_body>hand_r")
    (tmp_path / "bad_body.xml").write_text(bad)
    bad = xml.read_text().replace("<force_identifier>g_v", "<force_identifier>nothere_")
    (tmp_path / "bad_column.xml").write_text(bad)
    for name, words in (("bad_body.xml", "hand_r"), ("bad_column.xml", "nothere_x")):
        code = main(["check", str(model), "--external-loads", str(tmp_path / name)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and words in err[0], err
