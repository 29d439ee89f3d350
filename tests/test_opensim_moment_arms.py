"""moment_arms.csv (``openfdk run --moment-arms``) against OpenSim 4.6: each muscle's
``computeMomentArm`` about each coordinate, and the derivative of OpenSim's own path
length (central differences, the other coordinates held and the constraints assembled),
on the project's 92-muscle model (wrapping cylinders, conditional and moving path points)
and on a knee whose patella follows the knee angle through a coordinate coupler."""

from __future__ import annotations

import numpy as np
import pytest

opensim = pytest.importorskip("opensim")

from openfdk.cli import main  # noqa: E402
from openfdk.io.results import read_table  # noqa: E402
from test_opensim_inverse_dynamics import N, RATE, _motion, _overlay, _q  # noqa: E402

#: central-difference step of a coordinate (rad or m)
STEP = 1e-6


def _set(model, state, values):
    """The coordinates ``values`` {name: value} set."""
    cs = model.getCoordinateSet()
    for name, v in values.items():
        cs.get(name).setValue(state, float(v), False)
    model.realizePosition(state)


def _opensim_moment_arms(path, values_at, frames, coordinates, follow=lambda values: values):
    """{(muscle, coordinate): [(computeMomentArm, −dl/dq by central differences)] per
    frame} of every muscle and coordinate of the OpenSim model at ``path`` (the first 0
    where the path does not span the coordinate); ``values_at(k)`` the coordinates' values
    at frame k."""
    model = opensim.Model(str(path))
    state = model.initSystem()
    cs, ms = model.getCoordinateSet(), model.getMuscles()
    out = {}
    for k in frames:
        values = values_at(k)
        for name in coordinates:
            arms = []
            for sign in (1.0, -1.0):
                _set(model, state, follow({**values, name: values[name] + sign * STEP}))
                arms.append([ms.get(i).getLength(state) for i in range(ms.getSize())])
            _set(model, state, follow(values))
            fd = -(np.array(arms[0]) - np.array(arms[1])) / (2 * STEP)
            for i in range(ms.getSize()):  # OpenSim's solver (≈ 10 ms a call) where the path spans the coordinate
                api = ms.get(i).computeMomentArm(state, cs.get(name)) if abs(fd[i]) > 1e-9 else 0.0
                out.setdefault((ms.get(i).getName(), name), []).append((api, fd[i]))
    return out


@pytest.mark.slow
def test_moment_arms_equal_opensims_on_the_92_muscle_model(tmp_path, capsys):
    from openfdk.fixtures.full_body_osim import COORDINATES, write_full_body_osim

    model = write_full_body_osim(tmp_path / "muscles.osim", muscles=True)
    times = np.arange(N) / RATE + 0.2
    motion = _motion(np.random.default_rng(7))
    out = tmp_path / "run"
    assert main(["run", str(model), "--with", str(_overlay(tmp_path, motion, times)), "--ignore", "forces",
                 "--out", str(tmp_path / "plain"), "--no-plots", "-q"]) == 0
    assert not (tmp_path / "plain" / "moment_arms.csv").exists()  # only when asked for
    assert main(["run", str(model), "--with", str(_overlay(tmp_path, motion, times)), "--out", str(out),
                 "--no-plots", "-q", "--moment-arms"]) == 0, capsys.readouterr().err
    ours = read_table(out / "moment_arms.csv")
    frames = [0, N // 2, N - 1]
    theirs = _opensim_moment_arms(model, lambda k: {n: _q(motion[n], times[k]) for n in COORDINATES}, frames,
                                  COORDINATES)
    spanned = {key for key, values in theirs.items() if max(abs(fd) for _, fd in values) > 1e-7}
    assert {tuple(c.split(".", 1)) for c in ours if c != "time"} == spanned  # the pairs OpenSim's paths span
    worst_api, worst_fd, inconsistent = 0.0, 0.0, set()
    for (muscle, coordinate), values in theirs.items():
        mine = ours.get(f"{muscle}.{coordinate}")
        for k, (api, fd) in zip(frames, values):
            r = 0.0 if mine is None else float(mine[k])
            worst_fd = max(worst_fd, abs(r - fd))
            if abs(api - fd) > 1e-6:  # OpenSim's computeMomentArm off its own length's derivative
                inconsistent.add((muscle, coordinate))
            else:
                worst_api = max(worst_api, abs(r - api))
    print("largest difference: computeMomentArm", worst_api, "m, its length's derivative", worst_fd, "m;",
          "computeMomentArm off its own derivative:", sorted(inconsistent))
    assert len(spanned) > 200 and max(abs(float(np.max(np.abs(ours[c])))) for c in ours if c != "time") > 0.05
    from openfdk.plots.run import figure_plan, moment_arm_panels
    from openfdk.results.run import read_results

    results = read_results(out)  # Python reads the table; the figure draws the coordinates most muscles span
    np.testing.assert_array_equal(results.moment_arms["rect_fem_r.knee_angle_r"].to_numpy(),
                                  ours["rect_fem_r.knee_angle_r"])
    panels, total = moment_arm_panels(results)
    counts = {}
    for muscle, coordinate in spanned:
        counts[coordinate] = counts.get(coordinate, 0) + 1
    assert total == len(counts) and len(panels) == 8
    assert min(len(p[3]) for p in panels) >= sorted(counts.values())[-8]
    assert "moment_arms" in [name for name, _, _ in figure_plan(results)]
    assert worst_api < 1e-8, worst_api
    assert worst_fd < 1e-5, worst_fd  # the wrapped psoas paths: the two lengths differ by a few µm
    # the iliopsoas wrapped over the pelvis about the hip, where OpenSim's lengthening speed
    # misses its own length's derivative (by up to 0.3 mm); nowhere else
    assert inconsistent <= {(f"{m}_{s}", f"hip_{c}_{s}") for m in ("psoas", "iliacus") for s in "rl"
                            for c in ("flexion", "adduction", "rotation")}


@pytest.mark.slow
@pytest.mark.parametrize("splines", [False, True], ids=["coupler_row", "placed_by_the_knee"])
def test_moment_arms_through_a_coupled_patella_equal_opensims(tmp_path, capsys, splines):
    """A quadriceps over a patella that follows the knee angle (OpenSim's
    CoordinateCouplerConstraint): its moment arm about the knee includes the patella's
    motion, as OpenSim's (the coupler enforced), and the coupler's dependent coordinate
    has none (it is not held)."""
    from test_opensim_joint_loads import _coupled_knee

    path = _coupled_knee(tmp_path / "knee.osim", splines=splines)
    model = opensim.Model(str(path))
    quads = opensim.Thelen2003Muscle("quads", 3000.0, 0.1, 0.2, 0.0)
    quads.addNewPathPoint("origin", model.getBodySet().get("thigh"), opensim.Vec3(0.03, -0.1, 0.0))
    quads.addNewPathPoint("over_patella", model.getBodySet().get("patella"), opensim.Vec3(0.03, 0.01, 0.0))
    quads.addNewPathPoint("insertion", model.getBodySet().get("shank"), opensim.Vec3(0.04, -0.06, 0.0))
    model.addForce(quads)
    model.finalizeConnections()
    model.printToXML(str(path))
    times = np.arange(N) / RATE + 0.2
    motion = {"hip_q": (0.2, 0.3, 0.9, 0.5), "knee_q": (-0.8, 0.5, 1.1, 1.0)}
    assert main(["run", str(path), "--with", str(_overlay(tmp_path, motion, times)), "--out", str(tmp_path / "out"),
                 "--no-plots", "-q", "--moment-arms"]) == 0, capsys.readouterr().err
    ours = read_table(tmp_path / "out" / "moment_arms.csv")
    assert [c for c in ours if c != "time"] == ["quads.knee_q"]  # beta is the coupler's: no moment arm of its own
    frames = [0, N // 2, N - 1]
    def at(k):
        return {n: _q(motion[n], times[k]) for n in motion}

    def coupled(values):  # the coupler's function, beta = 0.8 knee + 0.05
        return {**values, "beta": 0.8 * values["knee_q"] + 0.05}

    theirs = _opensim_moment_arms(path, at, frames, ["knee_q"], coupled)[("quads", "knee_q")]
    for k, (api, fd) in zip(frames, theirs):
        assert ours["quads.knee_q"][k] == pytest.approx(api, abs=1e-8)
        assert ours["quads.knee_q"][k] == pytest.approx(fd, abs=1e-8)
    beta_held = _opensim_moment_arms(path, lambda k: coupled(at(k)), frames, ["knee_q"])[("quads", "knee_q")]
    assert max(abs(fd - a) for (a, _), (_, fd) in zip(theirs, beta_held)) > 1e-3  # the patella's motion counts
