"""`openfdk cycles`: a run's gait cycles from its measured loads, and its results as mean ±
SD over them (openfdk.analysis.gait_cycles).

The run is written by the test: frames at 100 Hz over 6 s, a foot whose vertical load
ramps linearly (8 000 N/s) up at known times S_k and down 0.6 s later, so the heel
strikes, where the load rises through 20 N, are T_k = S_k + 20 / 8 000 s in closed form
(between two frames, where linear interpolation is exact). The quantities are linear in
t (y = a + b t) or, within a cycle, in % (then mean and SD over the cycles are closed
forms of the T_k).
"""

from __future__ import annotations

import io
import json

import numpy as np
import pandas as pd
import pytest

from openfdk.analysis.gait_cycles import gait_cycles, heel_strikes, strikes_text
from openfdk.cli.commands import main
from openfdk.fixtures.gait_cycles_run import RAMP, RATE, STARTS, WEIGHT, foot_load as _load, write_cycles_run
from openfdk.results.run import read_results


def test_heel_strikes_are_where_the_foot_load_rises_through_the_threshold(tmp_path):
    t = write_cycles_run(tmp_path)
    results = read_results(tmp_path)
    cycles = gait_cycles(results, "calcn_r")
    T = STARTS + 20.0 / RAMP
    np.testing.assert_allclose(cycles.strikes, T, rtol=0, atol=1e-12)
    assert cycles.n_cycles == len(STARTS) - 1
    # the foot's load is the two plates' vertical components (the third is on the other foot)
    np.testing.assert_allclose(cycles.load, _load(t), rtol=0, atol=1e-9)
    # a higher threshold moves each strike by (v* − 20) / RAMP
    np.testing.assert_allclose(gait_cycles(results, "calcn_r", threshold=100.0).strikes, STARTS + 100.0 / RAMP,
                               rtol=0, atol=1e-12)


def test_toe_off_is_where_the_swing_begins(tmp_path):
    """The load ramps down from S_k + 0.6 s at 8 000 N/s from 800 N: it falls through
    100 N at S_k + 0.6875 s (both frames either side on the ramp), the toe-off; the
    stance is its share of the cycle."""
    write_cycles_run(tmp_path)
    cycles = gait_cycles(read_results(tmp_path), "calcn_r", threshold=100.0)
    T = STARTS + 100.0 / RAMP
    np.testing.assert_allclose(cycles.toe_offs, STARTS[:-1] + 0.6 + 700.0 / RAMP, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cycles.stance_percent, 100.0 * (0.6875 - 0.0125) / np.diff(T), rtol=1e-12)
    listed = pd.read_csv(io.StringIO(strikes_text(cycles)))
    np.testing.assert_allclose(listed["toe_off_s"], cycles.toe_offs, rtol=0, atol=1e-6)
    np.testing.assert_allclose(listed["stance_percent"], cycles.stance_percent, rtol=1e-12)


def test_a_quantity_over_the_cycles_has_the_closed_form_mean_and_sd(tmp_path):
    write_cycles_run(tmp_path)
    cycles = gait_cycles(read_results(tmp_path), "calcn_r")
    T = STARTS + 20.0 / RAMP
    p = np.arange(101) / 100.0
    at = T[:-1, None] + p[None, :] * np.diff(T)[:, None]  # (cycles, 101) s
    # y = a + b t is linear within each cycle: its mean and SD over the cycles at p are those of y(T_k + p D_k)
    for name, a, b in (("knee.|F|_N", WEIGHT, 0.5 * WEIGHT), ("knee.medial_N", 0.7 * WEIGHT, 0.35 * WEIGHT),
                       ("rot_rad", 0.0, 0.01), ("tx_m", 0.0, 0.001)):
        y = a + b * at
        np.testing.assert_allclose(cycles.per_cycle[name], y, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(cycles.mean(name), y.mean(axis=0), rtol=1e-12)
        np.testing.assert_allclose(cycles.sd(name), y.std(axis=0, ddof=1), rtol=1e-9)
        assert np.all(cycles.sd(name) > 0)
        assert np.all(cycles.count(name) == 4)
    assert cycles.kinds["rot_rad"] == "angle" and cycles.kinds["tx_m"] == "length"
    assert cycles.kinds["knee.|F|_N"] == "force"
    # the foot's load over the cycle: 20 N at 0 %, 800 N in stance, 0 at the end of swing
    load = cycles.per_cycle["calcn_r.vertical_load_N"]
    np.testing.assert_allclose(load[:, 0], 20.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(load[:, 30], 800.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(load[:, 100], 20.0, rtol=0, atol=1e-9)  # the next heel strike


def test_failed_frames_leave_their_cycle_out_there_and_nothing_is_interpolated_across_them(tmp_path):
    T = STARTS + 20.0 / RAMP
    k = int(np.ceil((T[1] + 0.5 * (T[2] - T[1])) * RATE))  # a frame half-way through cycle 2
    t = write_cycles_run(tmp_path, failed=(k,))
    cycles = gait_cycles(read_results(tmp_path), "calcn_r")
    assert list(cycles.failed) == [0, 1, 0, 0]
    gap = (T[1] + np.arange(101) / 100.0 * (T[2] - T[1]) > t[k - 1]) & (
        T[1] + np.arange(101) / 100.0 * (T[2] - T[1]) < t[k + 1])
    assert gap.sum() >= 1
    row = cycles.per_cycle["knee.|F|_N"][1]
    assert np.all(np.isnan(row[gap])) and np.all(np.isfinite(row[~gap]))
    count = cycles.count("knee.|F|_N")
    assert np.all(count[gap] == 3) and np.all(count[~gap] == 4)
    # the mean there is the other three cycles'
    others = cycles.per_cycle["knee.|F|_N"][[0, 2, 3]][:, gap]
    np.testing.assert_allclose(cycles.mean("knee.|F|_N")[gap], others.mean(axis=0), rtol=1e-12)


def test_a_blip_of_load_in_swing_is_no_heel_strike():
    t = np.arange(601) / RATE
    v = _load(t)
    v[int(round(1.2 * RATE))] = 40.0  # one frame above 20 N, 0.7 s after the first stance began
    strikes = heel_strikes(t, v, 20.0, 0.2, 0.2)
    np.testing.assert_allclose(strikes, STARTS + 20.0 / RAMP, rtol=0, atol=1e-12)
    # a load not known before a rise: no heel strike there
    v2 = _load(t)
    v2[int(round((STARTS[2] - 0.1) * RATE))] = np.nan
    strikes = heel_strikes(t, v2, 20.0, 0.2, 0.2)
    np.testing.assert_allclose(strikes, np.delete(STARTS, 2) + 20.0 / RAMP, rtol=0, atol=1e-12)


def test_a_foot_that_touches_before_it_loads_strikes_at_its_first_touch():
    """A load that rises through 20 N, dips back below it for 30 ms and then loads the
    foot (DM's tm_set1 at 15.4 s): the heel strike is the first crossing."""
    t = np.arange(601) / RATE
    v = _load(t)
    for s in STARTS[1:3]:
        touch = (t > s + 0.02) & (t < s + 0.05)  # the 3 frames after the crossing, back to 15 N
        v[touch] = 15.0
    strikes = heel_strikes(t, v, 20.0, 0.2, 0.2)
    np.testing.assert_allclose(strikes, STARTS + 20.0 / RAMP, rtol=0, atol=1e-12)


def test_the_command_writes_the_table_the_list_and_the_figure(tmp_path, capsys):
    write_cycles_run(tmp_path / "run")
    assert main(["cycles", str(tmp_path / "run"), "--foot", "calcn_r"]) == 0
    out = capsys.readouterr().out
    assert "4 cycle(s)" in out
    # |F| = 1 + 0.5 t BW rises through each cycle: its mean peaks at 100 %, 1 + 0.5 mean(T_2..T_5)
    peak = 1.0 + 0.5 * np.mean(STARTS[1:] + 20.0 / RAMP)
    assert f"knee: mean peak {peak:.2f} BW at 100 %" in out, out
    folder = tmp_path / "run" / "cycles"
    table = pd.read_csv(folder / "cycles.csv")
    assert list(table["percent"]) == list(range(101))
    cycles = gait_cycles(read_results(tmp_path / "run"), "calcn_r")
    np.testing.assert_allclose(table["knee.|F|_N.mean"], cycles.mean("knee.|F|_N"), rtol=1e-15)
    np.testing.assert_allclose(table["rot_rad.sd"], cycles.sd("rot_rad"), rtol=1e-15)
    listed = pd.read_csv(folder / "cycles_list.csv")
    np.testing.assert_allclose(listed["start_s"], (STARTS + 20.0 / RAMP)[:-1], rtol=0, atol=1e-6)
    np.testing.assert_allclose(listed["duration_s"], np.diff(STARTS), rtol=0, atol=2e-6)
    png = (folder / "cycles.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000


@pytest.mark.parametrize("change, args, words", [
    (None, ["--foot", "toes_r"], "--foot 'toes_r': no measured load acts on it; the loads act on calcn_l, calcn_r"),
    ("no_loads", ["--foot", "calcn_r"], "no measured loads in summary.json (input.external_loads)"),
    ("gravity", ["--foot", "calcn_r"], "input.gravity_W_m_s2 must be 3 finite numbers"),
    (None, ["--foot", "calcn_l"], "--foot 'calcn_l': 0 heel strike(s)"),
    (None, ["--foot", "calcn_r", "--threshold", "-1"], "--threshold: must be a positive force in N"),
    # 800 N is the stance's plateau: no rise reaches 900 N
    (None, ["--foot", "calcn_r", "--threshold", "900"], "0 heel strike(s)"),
])
def test_a_run_without_cycles_is_one_line(tmp_path, capsys, change, args, words):
    write_cycles_run(tmp_path / "run")
    path = tmp_path / "run" / "summary.json"
    summary = json.loads(path.read_text())
    if change == "no_loads":
        del summary["input"]["external_loads"]
    if change == "gravity":
        summary["input"]["gravity_W_m_s2"] = [0, 0]
    path.write_text(json.dumps(summary))
    code = main(["cycles", str(tmp_path / "run"), *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0], err
    assert not (tmp_path / "run" / "cycles" / "cycles.csv").exists()


def test_a_folder_that_is_no_run_is_one_line(tmp_path, capsys):
    code = main(["cycles", str(tmp_path), "--foot", "calcn_r"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no kinematics.csv" in err[0], err


def test_the_viewer_draws_the_measured_loads_where_they_carry_20_N(tmp_path):
    """Without grf.csv (an ExternalLoads run), the viewer's ground-reaction arrows are the
    measured loads as forces.csv records them, hidden below 20 N."""
    from openfdk.viewer.frames import grf_frames
    from openfdk.viewer.pack import unpack
    from openfdk.viewer.results import read_results as read_tables

    t = write_cycles_run(tmp_path)
    arrows = {a["name"]: a for a in grf_frames(read_tables(tmp_path))}
    assert sorted(arrows) == ["p1", "p2", "p3"]
    v = _load(t)
    for name, F_expected in (("p1", np.stack([5 + 0 * t, 0 * t, 0.25 * v], axis=1)),
                             ("p2", np.stack([-4 + 0 * t, 3 + 0 * t, 0.75 * v], axis=1))):
        F = unpack(arrows[name]["force"]).astype(float).reshape(-1, 3)
        shown = np.linalg.norm(F_expected, axis=1) >= 20.0
        assert 0 < shown.sum() < len(t)  # hidden in swing (5 N)
        np.testing.assert_allclose(F[shown], F_expected[shown], rtol=1e-6, atol=1e-3)
        assert np.all(np.isnan(F[~shown]))


def test_a_reader_that_leaves_early_ends_the_command_quietly(tmp_path, capsys, monkeypatch):
    """`openfdk cycles RUN | head -1`: the pipe closes after the first line; the files are
    written, and the command stops printing without an error message, exit 141 (128 +
    SIGPIPE, what a shell reports for a tool the closed pipe killed)."""
    import sys

    class Closed:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            pass

    write_cycles_run(tmp_path / "run")
    monkeypatch.setattr(sys, "stdout", Closed())
    assert main(["cycles", str(tmp_path / "run"), "--foot", "calcn_r", "--no-plot"]) == 141
    assert capsys.readouterr().err == ""
    assert (tmp_path / "run" / "cycles" / "cycles.csv").is_file()
