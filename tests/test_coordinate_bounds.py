"""Clamped coordinates held within their ranges by marker tracking (kinematics/coordinate_bounds.py).

A planar three-link chain written with OpenSim's API (pin joints q1, q2 clamped, q3 free)
tracks markers of a motion that leaves both clamped ranges, on both sides, and comes
back. The tracked coordinates must be the bounded least-squares fit: an independent
solve written here (scipy's bounded trust-region least squares in the three joint
angles, with the chain's forward kinematics in closed form) to 1e-7 rad at every frame.
The unbounded fit differs from it by far more at the frames past a bound (the bounds
act), and OpenSim 4.6's IK of the same files agrees with both.
"""

from __future__ import annotations

import numpy as np
import pytest

osim = pytest.importorskip("opensim")
from scipy.optimize import least_squares  # noqa: E402

from openfdk.cli import main  # noqa: E402
from openfdk.fixtures.full_body_osim import write_trc  # noqa: E402

#: joint origins in the parent (m): the shoulder in the ground, then each link's end
ORIGIN = [np.array([0.0, 1.0, 0.0]), np.array([0.0, -0.4, 0.0]), np.array([0.0, -0.35, 0.0])]
#: markers on each link (m, link frame): off the axis and off the plane
MARKERS = [[(0.05, -0.1, 0.02), (-0.04, -0.3, -0.03)], [(0.03, -0.12, 0.04), (-0.05, -0.28, 0.0)],
           [(0.04, -0.1, -0.02), (-0.03, -0.2, 0.03)]]
RANGE = {"q1": (-0.5, 0.5), "q2": (0.0, 1.2)}
RATE_HZ, N_FRAMES = 50.0, 60


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _markers(q):
    """(6, 3) m: the markers' positions of the chain at joint angles q (3,) rad."""
    out, p, R = [], np.zeros(3), np.eye(3)
    for link in range(3):
        p = p + R @ ORIGIN[link]
        R = R @ _rz(q[link])
        out += [p + R @ np.array(m) for m in MARKERS[link]]
    return np.array(out)


def _chain_osim(path):
    m = osim.Model()
    m.setName("chain")
    parent = m.getGround()
    for link in range(3):
        body = osim.Body(f"link{link + 1}", 1.0, osim.Vec3(0, -0.15, 0), osim.Inertia(0.01, 0.002, 0.01))
        m.addBody(body)
        joint = osim.PinJoint(f"j{link + 1}", parent, osim.Vec3(*ORIGIN[link]), osim.Vec3(0, 0, 0), body,
                              osim.Vec3(0, 0, 0), osim.Vec3(0, 0, 0))
        m.addJoint(joint)
        c = joint.updCoordinate()
        c.setName(f"q{link + 1}")
        if c.getName() in RANGE:
            c.setRangeMin(RANGE[c.getName()][0])
            c.setRangeMax(RANGE[c.getName()][1])
            c.set_clamped(True)
        else:
            c.setRangeMin(-3.0)
            c.setRangeMax(3.0)
        for k, mk in enumerate(MARKERS[link]):
            m.addMarker(osim.Marker(f"M{link + 1}{k + 1}", body, osim.Vec3(*mk)))
        parent = body
    m.finalizeConnections()
    m.initSystem()
    assert m.printToXML(str(path))
    return path


def _trial(path, seed=7):
    """The markers (nf, 6, 3) m of a motion past both clamped ranges, with 2 mm noise."""
    t = np.arange(N_FRAMES) / RATE_HZ
    w = 2 * np.pi * 0.9
    q = np.stack([0.1 + 0.6 * np.sin(w * t), 0.6 + 0.8 * np.sin(w * t + 1.0), 0.3 * np.cos(w * t)], axis=1)
    x = np.array([_markers(qk) for qk in q]) + np.random.default_rng(seed).normal(0.0, 2e-3, (N_FRAMES, 6, 3))
    write_trc(path, [f"M{i + 1}{k + 1}" for i in range(3) for k in range(2)], t, x, RATE_HZ, digits=8)
    return t, q, x


def _fit(x, q0, bounded):
    """The least-squares joint angles (3,) rad of markers x (6, 3) m, within RANGE if
    ``bounded``: scipy's trust-region reflective solver, to machine precision."""
    lo = [RANGE["q1"][0], RANGE["q2"][0], -np.inf] if bounded else -np.inf
    hi = [RANGE["q1"][1], RANGE["q2"][1], np.inf] if bounded else np.inf
    start = np.clip(q0, lo, hi) if bounded else q0
    sol = least_squares(lambda q: (_markers(q) - x).ravel(), start, bounds=(lo, hi), method="trf",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    return sol.x


def _read_coordinates(folder):
    data = np.genfromtxt(folder / "coordinates.csv", delimiter=",", names=True)
    return np.stack([data[f"q{i}_rad"] for i in (1, 2, 3)], axis=1)


@pytest.fixture(scope="module")
def chain(tmp_path_factory):
    d = tmp_path_factory.mktemp("chain")
    model = _chain_osim(d / "chain.osim")
    t, q_true, x = _trial(d / "chain.trc")
    code = main(["kinematics", str(model), str(d / "chain.trc"), "--cutoff", "0", "--out", str(d / "ours"), "-q"])
    assert code == 0
    bounded = np.array([_fit(x[k], q_true[k], True) for k in range(N_FRAMES)])
    free = np.array([_fit(x[k], q_true[k], False) for k in range(N_FRAMES)])
    return d, t, x, bounded, free, _read_coordinates(d / "ours")


def test_tracking_is_the_bounded_least_squares_fit(chain):
    _, _, _, bounded, free, ours = chain
    assert ours.shape == (N_FRAMES, 3)
    np.testing.assert_allclose(ours, bounded, atol=1e-7, rtol=0)
    # every frame within the ranges (to the tolerance the bounds are held to)
    for i, name in enumerate(("q1", "q2")):
        assert np.all(ours[:, i] >= RANGE[name][0] - 1e-9) and np.all(ours[:, i] <= RANGE[name][1] + 1e-9)
    # the bounds act: the unbounded fit leaves both ranges, on both sides for q2, and
    # differs from the bounded one by far more than the tolerance there, the free q3 too
    past = np.zeros(N_FRAMES, bool)
    for i, name in enumerate(("q1", "q2")):
        past |= (free[:, i] < RANGE[name][0]) | (free[:, i] > RANGE[name][1])
    assert np.any(free[:, 0] > RANGE["q1"][1] + 0.05)
    assert np.any(free[:, 1] < RANGE["q2"][0] - 0.05) and np.any(free[:, 1] > RANGE["q2"][1] + 0.05)
    assert np.max(np.abs(free - bounded)[past]) > 0.05
    assert np.max(np.abs(free[past, 2] - bounded[past, 2])) > 1e-3  # the coupled fit, not a clip
    # ... and the motion comes back inside after each stretch at a bound: the bounds are released
    on_bound = np.isclose(ours[:, 0], RANGE["q1"][1], atol=1e-9)
    assert on_bound.any() and not on_bound[-1] and np.any(np.diff(on_bound.astype(int)) == -1)
    # away from the bounds, the same fit as without them
    inside = ~past
    np.testing.assert_allclose(ours[inside], free[inside], atol=1e-7, rtol=0)


def test_the_summary_lists_the_coordinates_held_at_a_bound(chain):
    """summary.json's kinematics.coordinates_at_bounds: per clamped coordinate and bound,
    the frames the bounded fit rests there (those of the independent solve) and the first."""
    import json

    d, t, _, bounded, _, _ = chain
    at = json.loads((d / "ours" / "summary.json").read_text())["kinematics"]["coordinates_at_bounds"]
    expected = {}
    for i, name in enumerate(("q1", "q2")):
        for side, bound in zip(("lower", "upper"), RANGE[name]):
            on = np.abs(bounded[:, i] - bound) < 1e-7
            if on.any():
                expected.setdefault(name, {})[side] = {"value_rad": bound, "frames": int(on.sum()),
                                                       "first_time_s": pytest.approx(float(t[on][0]), abs=1e-9)}
    assert set(expected["q2"]) == {"lower", "upper"} and "q3" not in at
    assert at == expected


def test_opensim_ik_of_the_clamped_chain_agrees(chain):
    d, t, x, bounded, _, ours = chain
    model = osim.Model(str(d / "chain.osim"))
    tool = osim.InverseKinematicsTool()
    tool.setModel(model)
    tool.setMarkerDataFileName(str(d / "chain.trc"))
    tool.set_accuracy(1e-10)
    tool.setStartTime(float(t[0]))
    tool.setEndTime(float(t[-1]))
    tool.setResultsDir(str(d))
    tool.setOutputMotionFileName(str(d / "opensim_ik.mot"))
    assert tool.run()
    from openfdk.io.storage import read_storage

    times, cols, degrees = read_storage(d / "opensim_ik.mot")
    theirs = np.stack([np.radians(cols[f"q{i}"]) if degrees else cols[f"q{i}"] for i in (1, 2, 3)], axis=1)
    assert theirs.shape == ours.shape
    for i, name in enumerate(("q1", "q2")):  # OpenSim's answer is within the ranges too
        assert np.all(theirs[:, i] >= RANGE[name][0] - 1e-9) and np.all(theirs[:, i] <= RANGE[name][1] + 1e-9)
    cost = lambda q: np.array([np.sum((_markers(q[k]) - x[k]) ** 2) for k in range(N_FRAMES)])  # noqa: E731
    # openfdk's is the least squared error within the ranges: never above OpenSim's ...
    # (to 1e-8 of it: the files' last digits, OpenSim's bounds held to its accuracy)
    assert np.all(cost(ours) <= cost(theirs) * (1 + 1e-8))
    # ... and the same coordinates where OpenSim's optimiser converges (most frames; at
    # some frames past a bound its L-BFGS-B stops up to 0.6° short, docs/opensim-import.md)
    diff = np.max(np.abs(theirs - ours), axis=1)
    assert np.median(diff) < 1e-4 and np.mean(diff < 1e-4) > 0.6


def _tracking_step(folder):
    from openfdk.analysis.jobs import load_trajectories, model_and_settings
    from openfdk.kinematics.analysis import TrackingStep, alpha_inputs, tracking_times

    model, settings, _ = model_and_settings(str(folder / "chain.osim"))
    _, traj = load_trajectories(model, str(folder / "chain.trc"), cutoff_hz=0.0, settings=settings)
    times = tracking_times(traj, None)
    return lambda: TrackingStep(model, traj, times, alpha_inputs(model, None)), len(times)


def _frames(step, ks, last):
    out = {}
    for k in ks:
        out.update(dict(step.step(k)))
    if ks[-1] == last:
        out.update(dict(step.finish()))
    return out


def test_a_run_resumed_at_a_bound_equals_the_uninterrupted_run(chain):
    """The active bounds travel with a checkpoint (each pending frame's set, through the
    checkpoint file format); a crafted set is refused."""
    from openfdk.trial.checkpoint_format import decode, encode

    d, _, _, _, _, ours = chain
    new_step, nf = _tracking_step(d)
    whole = _frames(new_step(), list(range(nf)), nf - 1)
    on_bound = np.flatnonzero(np.isclose(ours[:, 0], RANGE["q1"][1], atol=1e-9))
    k0 = int(on_bound[len(on_bound) // 2])  # interrupted in the middle of a stretch at a bound
    first = new_step()
    part = _frames(first, list(range(k0 + 1)), nf - 1)
    assert first.active  # the last solved frame rests on a bound
    carry = decode(encode(first.carry()))
    resumed = new_step()
    resumed.restore(carry)
    assert resumed.active == first.active
    part.update(_frames(resumed, list(range(k0 + 1, nf)), nf - 1))
    assert sorted(part) == sorted(whole) == list(range(nf))
    for j in range(nf):
        np.testing.assert_allclose(part[j]["kin.q"], whole[j]["kin.q"], atol=1e-9, rtol=0)
        # (the rates to 1e-7: the Newton steps' curvature, which a checkpoint does not
        # carry, changes the last KKT matrix the rate solves use by rounding)
        np.testing.assert_allclose(part[j]["kin.v"], whole[j]["kin.v"], atol=1e-7, rtol=0)
    # a checkpoint naming a bound the model does not have
    pending = carry[4]
    pending[max(pending)]["active"] = [[7, 1]]
    with pytest.raises(ValueError, match="clamped coordinates"):
        new_step().restore(carry)
