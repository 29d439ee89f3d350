"""Cycle splitting, Tables 1–2 and Figs. 5–7 of the mandible study (openfdk.mandible)."""

import io
import itertools
import math
import re

import numpy as np
import pytest

from openfdk.mandible import figures, tables
from openfdk.mandible.cycles import CycleError, normalize_cycles, split_cycles

FS = 100.0                 # Hz, as the paper's markers


# --------------------------------------------------------------------------------------
# Synthetic movements with known cycle boundaries
# --------------------------------------------------------------------------------------

def raised_cosine_cycles(periods, rest=0.5, amplitude=0.02, noise=0.0, seed=0, moving=None):
    """Closed rest, then cycles that open (raised cosine over 40 % of the cycle), close
    (to 80 %) and rest closed (to 100 %), then rest; ``moving`` (s) fixes the open–close
    duration instead (the rest of each period is closed). Returns time, signal, onsets (s)."""
    onsets = rest + np.concatenate([[0.0], np.cumsum(periods)])
    t = np.arange(round((onsets[-1] + rest) * FS) + 1) / FS
    x = np.zeros_like(t)
    for a, b in itertools.pairwise(onsets):
        duration = 0.8 * (b - a) if moving is None else moving
        s = (t - a) / duration
        inside = (s >= 0.0) & (s < 1.0)
        x[inside] = 0.5 * (1.0 - np.cos(2 * np.pi * s[inside]))
    x = amplitude * x + np.random.default_rng(seed).normal(0.0, noise, t.size)
    return t, x, onsets


def test_cycles_start_at_the_opening_onsets_with_noise_and_varying_period():
    periods = (1 / 1.2) * np.array([1.04, 0.95, 1.05, 0.97, 1.01])     # ±5 %
    t, x, onsets = raised_cosine_cycles(periods, noise=2e-4, seed=3)    # 1 % noise
    cycles = split_cycles(t, x, n_cycles=5)
    starts = np.array([a for a, _ in cycles]) / FS
    stops = np.array([b for _, b in cycles]) / FS
    # the detected onset lags the true one by the time the signal needs to rise above
    # the closed-mouth band (1 % of the rise + 4 σ of the smoothed noise ≈ 2.5 % here:
    # 1 − cos(2π s/0.8) = 0.05 → s = 0.04 → 0.033 s); never early
    lag = starts - onsets[:5]
    assert np.all(lag >= -0.01) and np.all(lag <= 0.04)
    np.testing.assert_array_equal(stops[:4], starts[1:])              # stop_k = start_{k+1}
    # the last cycle is closed to the record end: one median cycle duration long
    assert stops[4] - starts[4] == pytest.approx(np.median(np.diff(starts)), abs=0.011)
    assert stops[4] == pytest.approx(onsets[5], abs=0.06)


def test_cycles_of_a_noisy_sinusoid_start_just_after_its_minima():
    """−cos(2π(t − 0.25)): minima at 0.25 + k s; record starts mid-descent."""
    t = np.arange(0.0, 7.0, 1 / FS)
    x = -np.cos(2 * np.pi * (t - 0.25)) + np.random.default_rng(5).normal(0.0, 0.02, t.size)
    cycles = split_cycles(t, x, n_cycles=6)
    lag = np.array([t[a] for a, _ in cycles]) - (0.25 + np.arange(6))
    assert np.all(lag >= -0.02) and np.all(lag <= 0.07)               # ≤ 7 % of a period
    # the record goes on into a 7th opening, so the 6th cycle stops at its onset
    assert t[cycles[-1][1]] - 6.25 == pytest.approx(np.mean(lag), abs=0.03)


def test_period_bounds_discard_a_long_cycle():
    """A pause (a 2.4 s cycle among 1 s cycles) is dropped by max_period and named in
    the error."""
    t, x, onsets = raised_cosine_cycles(np.array([1.0, 1.0, 2.4, 1.0, 1.0, 1.0]), moving=0.8)
    cycles = split_cycles(t, x, n_cycles=5, max_period=1.5)
    starts = np.array([t[a] for a, _ in cycles])
    np.testing.assert_allclose(starts, onsets[[0, 1, 3, 4, 5]], atol=0.03)
    with pytest.raises(CycleError, match=r"skipped a cycle 2.4\d? s long at t = 2.5"):
        split_cycles(t, x, n_cycles=6, max_period=1.5)


def test_noise_alone_has_no_cycles():
    t = np.arange(0.0, 6.0, 1 / FS)
    x = np.random.default_rng(8).normal(0.0, 1e-3, t.size)
    with pytest.raises(CycleError, match="no periodic movement"):
        split_cycles(t, x)


def test_leading_partial_cycle_is_skipped():
    """The record starts mid-opening (minimum at −0.3 s): the first cycle begins at the
    first complete minimum, 0.7 s."""
    t = np.arange(0.0, 6.5, 1 / FS)
    x = -np.cos(2 * np.pi * (t - 0.7))
    cycles = split_cycles(t, x, n_cycles=5, min_period=0.6, max_period=1.6)
    assert t[cycles[0][0]] == pytest.approx(0.7, abs=0.045)
    assert len(cycles) == 5 and cycles[0][0] > 50


def test_nan_gaps_are_bridged():
    periods = np.full(5, 2.0)                                          # protrusion, 0.5 Hz
    t, x, onsets = raised_cosine_cycles(periods, amplitude=0.008, noise=5e-5, seed=1)
    x[300:320] = np.nan
    cycles = split_cycles(t, x, n_cycles=5)
    lag = np.array([t[a] for a, _ in cycles]) - onsets[:5]
    assert np.all(lag >= -0.01) and np.all(lag <= 0.04 * 2.0)         # ≤ 4 % of a period


def test_too_few_cycles_raises_naming_what_was_found():
    t, x, _ = raised_cosine_cycles(np.full(3, 1.0))
    with pytest.raises(CycleError, match=r"found 3 complete cycle\(s\).*n_cycles=5"):
        split_cycles(t, x, n_cycles=5)
    # a record cut mid-closing: the third cycle is incomplete
    cut = int(3.0 * FS)                     # onsets 0.5, 1.5, 2.5 → t = 3.0 is mid-cycle
    with pytest.raises(ValueError, match=r"found 2 complete cycle\(s\)"):
        split_cycles(t[:cut], x[:cut], n_cycles=3)
    assert isinstance(CycleError("x"), ValueError)


def test_bad_time_or_signal_raises():
    t, x, _ = raised_cosine_cycles(np.full(5, 1.0))
    with pytest.raises(CycleError, match="equal length"):
        split_cycles(t, x[:-1])
    t_bad = t.copy()
    t_bad[10] += 0.004
    with pytest.raises(CycleError, match="uniformly sampled"):
        split_cycles(t_bad, x)
    with pytest.raises(CycleError, match="constant"):
        split_cycles(t, np.zeros_like(t))


def test_normalize_cycles_resamples_linear_functions_exactly():
    t = np.arange(0.0, 3.0, 0.01)
    values = np.stack([2.0 + 3.0 * t, -t], axis=1)[:, None, :] * np.array([1.0, 2.0, 3.0])[None, :, None]
    values = np.moveaxis(values, 1, 2)                                 # (n, 2, 3)
    cycles = [(10, 117), (117, 250)]
    out = normalize_cycles(t, values, cycles, n_points=51)
    assert out.shape == (2, 51, 2, 3)
    for k, (a, b) in enumerate(cycles):
        tu = t[a] + np.linspace(0.0, 1.0, 51) * (t[b] - t[a])
        expected = np.stack([2.0 + 3.0 * tu, -tu], axis=1)[:, :, None] * np.array([1.0, 2.0, 3.0])
        np.testing.assert_allclose(out[k], expected, rtol=0, atol=1e-12)


def test_normalize_cycles_keeps_gaps_as_nan():
    t = np.arange(11) * 0.1                    # one cycle 0…1 s, 11 samples
    v = np.arange(11, dtype=float)[:, None] * np.ones((1, 3))
    v[4, 1] = np.nan                          # a gap in component 1 at t = 0.4 s
    out = normalize_cycles(t, v, [(0, 10)], n_points=21)[0]       # every 0.05 s
    u = np.linspace(0.0, 1.0, 21)
    np.testing.assert_allclose(out[:, 0], 10 * u, atol=1e-12)
    # 0.35 and 0.45 s bracket the NaN sample and 0.40 s is on it: NaN there only
    nan_rows = np.flatnonzero(np.isnan(out[:, 1]))
    np.testing.assert_array_equal(nan_rows, [7, 8, 9])
    np.testing.assert_allclose(out[6, 1], 3.0)                    # on a finite sample
    np.testing.assert_allclose(out[10, 1], 5.0)
    with pytest.raises(CycleError, match="not a valid index range"):
        normalize_cycles(t, v, [(5, 11)])


# --------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------

N_CYCLES, N_POINTS = 5, 101


def _random_side(rng, scale):
    base = np.sin(2 * np.pi * np.linspace(0, 1, N_POINTS))[None, :, None] * np.array([6, 0.4, -3])
    return scale * (base + rng.normal(0.0, 0.3, (N_CYCLES, N_POINTS, 3)))


@pytest.fixture
def kinematics_by_task():
    rng = np.random.default_rng(11)
    return {task: {model: {side: _random_side(rng, 1e-3) for side in ("left", "right")}
                   for model in ("measured", "POP", "FDK")}
            for task in ("chewing", "open_close", "protrusion")}


def _independent_metrics(c, m):
    """The paper's formulas written out again, per cycle (c, m: (n_points,))."""
    d = c - m
    r = np.corrcoef(c, m)[0, 1]
    return {"RMSD": np.sqrt(np.sum(d * d) / d.size), "r2": r * r,
            "M": np.sqrt(np.sum(c * c) / np.sum(m * m)) - 1.0,
            "P": np.arccos(np.sum(m * c) / np.sqrt(np.sum(m * m) * np.sum(c * c))) / np.pi}


def test_table1_rows_and_values(kinematics_by_task):
    rows = tables.table1(kinematics_by_task)
    assert len(rows) == 3 * 2 * 3
    keys = [(r["task"], r["side"], r["direction"]) for r in rows]
    assert keys == [(t, s, d) for t in ("chewing", "open_close", "protrusion")
                    for s in ("left", "right") for d in ("AP", "ML", "SI")]
    for row in rows:
        assert row["unit"] == "mm" and row["reference"] == "measured" and row["n_cycles"] == 5
        k = ("AP", "ML", "SI").index(row["direction"])
        res = kinematics_by_task[row["task"]]
        m = 1e3 * res["measured"][row["side"]][:, :, k]
        for model in ("FDK", "POP"):
            c = 1e3 * res[model][row["side"]][:, :, k]
            per = [_independent_metrics(c[i], m[i]) for i in range(N_CYCLES)]
            for name in ("RMSD", "r2", "M", "P"):
                v = np.array([p[name] for p in per])
                assert row[f"{model}_{name}_mean"] == pytest.approx(v.mean(), rel=1e-10, abs=1e-13)
                assert row[f"{model}_{name}_sd"] == pytest.approx(v.std(ddof=1), rel=1e-8, abs=1e-13)
                assert row[f"{model}_{name}_sd"] > 0.0


def test_table2_sign_convention_and_layout_with_both_parts():
    """POP = 0.8·FDK in every cycle: M = −0.2 (the POP force is smaller), P = 0, r² = 1,
    RMSD = 0.2·rms(FDK) per cycle."""
    rng = np.random.default_rng(2)
    fdk = {side: 20.0 + 5.0 * rng.random((N_CYCLES, N_POINTS, 3)) for side in ("left", "right")}
    forces = {"FDK": fdk, "POP": {s: 0.8 * a for s, a in fdk.items()}}
    rows = tables.table2({"chewing": {"kinematics": {}, "forces": forces}})
    assert len(rows) == 6
    for row in rows:
        assert row["unit"] == "N" and row["reference"] == "FDK"
        assert row["POP_M_mean"] == pytest.approx(-0.2, abs=1e-12)
        assert row["POP_M_sd"] == pytest.approx(0.0, abs=1e-12)
        assert row["POP_P_mean"] == pytest.approx(0.0, abs=1e-7)
        assert row["POP_r2_mean"] == pytest.approx(1.0, abs=1e-12)
        f = fdk[row["side"]][:, :, ("AP", "ML", "SI").index(row["direction"])]
        rms = 0.2 * np.sqrt(np.mean(f ** 2, axis=1))
        assert row["POP_RMSD_mean"] == pytest.approx(rms.mean(), rel=1e-12)
        assert row["POP_RMSD_sd"] == pytest.approx(rms.std(ddof=1), rel=1e-9)


def test_table_input_errors(kinematics_by_task):
    bad = {"chewing": dict(kinematics_by_task["chewing"])}
    del bad["chewing"]["POP"]
    with pytest.raises(tables.ReportInputError, match="'chewing'.*'POP' missing"):
        tables.table1(bad)
    bad = {"chewing": {m: dict(s) for m, s in kinematics_by_task["chewing"].items()}}
    bad["chewing"]["FDK"]["right"] = bad["chewing"]["FDK"]["right"][:4]
    with pytest.raises(ValueError, match="'FDK' has shape \\(4, 101, 3\\)"):
        tables.table1(bad)
    bad["chewing"]["FDK"]["right"] = np.zeros((5, 101, 2))
    with pytest.raises(ValueError, match="side 'right'.*\\(n_cycles, n_points, 3\\)"):
        tables.table1(bad)


def _parse_markdown(text):
    lines = [ln for ln in text.splitlines() if ln.startswith("| ")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    body = [[c.strip() for c in ln.strip("|").split("|")] for ln in lines[1:]]
    return header, body


def test_markdown_and_csv_round_trip(kinematics_by_task, tmp_path):
    rows = tables.table1(kinematics_by_task)
    header, body = _parse_markdown(tables.to_markdown(rows))
    assert header[:3] == ["Task", "Side", "Direction"]
    assert header[3] == "FDK RMSD (mm)" and header[7] == "POP RMSD (mm)" and header[4] == "FDK r²"
    assert len(body) == len(rows)
    for row, cells in zip(rows, body):
        assert cells[:3] == [tables.task_title(row["task"]), row["side"].capitalize(),
                             row["direction"]]
        for j, column in enumerate(header[3:]):
            model, name = column.split()[:2]
            name = {"r²": "r2"}.get(name, name)
            mean, sd = (float(v) for v in re.fullmatch(r"(-?\d+\.\d\d)±(-?\d+\.\d\d)", cells[3 + j]).groups())
            assert mean == pytest.approx(row[f"{model}_{name}_mean"], abs=0.005 + 1e-12)
            assert sd == pytest.approx(row[f"{model}_{name}_sd"], abs=0.005 + 1e-12)
    path = tables.write_csv(rows, tmp_path / "table1.csv")
    back = tables.read_csv(path)
    assert back == rows                                     # exact: floats written by repr


def test_markdown_formatting_details():
    row = {"task": "open_close", "side": "left", "direction": "ML", "reference": "FDK",
           "unit": "N", "n_cycles": 5, "POP_RMSD_mean": 12.5, "POP_RMSD_sd": 1.444,
           "POP_r2_mean": math.nan, "POP_r2_sd": math.nan, "POP_M_mean": -0.001,
           "POP_M_sd": 0.2049, "POP_P_mean": 0.5, "POP_P_sd": 0.0}
    text = tables.to_markdown([row])
    assert "| Open-close | Left | ML | 12.50±1.44 | nan±nan | 0.00±0.20 | 0.50±0.00 |" in text
    assert "RMSD in N" in text


def test_terminal_text(kinematics_by_task):
    rows = tables.table1(kinematics_by_task)
    buffer = io.StringIO()
    tables.print_table(rows, file=buffer)
    text = buffer.getvalue()
    assert text == tables.format_text(rows)
    for title in ("Chewing", "Open-close", "Protrusion"):
        assert f"{title} (5 cycles)" in text
    assert "FDK vs measured" in text and "POP vs measured" in text
    assert len(text.splitlines()) == 2 + 3 * (1 + 6)
    assert max(len(line) for line in text.splitlines()) <= 130


# --------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------

def _polycollections(ax):
    from matplotlib.collections import PolyCollection
    return [c for c in ax.collections if isinstance(c, PolyCollection)]


def test_figures_are_written_with_bands(kinematics_by_task, tmp_path):
    import matplotlib.pyplot as plt

    kin = kinematics_by_task["chewing"]
    rng = np.random.default_rng(4)
    band = {side: kin["FDK"][side].mean(axis=0) * (1.0 + 0.05 * rng.normal(size=(15, 1, 1)))
            for side in ("left", "right")}
    path = figures.plot_kinematics("chewing", kin, tmp_path / "kin.png", band=band)
    assert path == str(tmp_path / "kin.png") and (tmp_path / "kin.png").stat().st_size > 30_000

    fig = figures.kinematics_figure("chewing", kin, band=band)
    axes = np.array(fig.axes).reshape(3, 2)
    for (row, col), ax in np.ndenumerate(axes):
        polys = _polycollections(ax)
        assert len(polys) == 1 + 3                          # band + 3 models' ±1 SD
        # the band (drawn first) spans the variants' min … max in mm
        y = polys[0].get_paths()[0].vertices[:, 1]
        side = ("left", "right")[col]
        assert y.min() == pytest.approx(1e3 * band[side][:, :, row].min(), rel=1e-9)
        assert y.max() == pytest.approx(1e3 * band[side][:, :, row].max(), rel=1e-9)
    assert axes[0, 0].get_title() == "Left TMJ" and "mm" in axes[0, 0].get_ylabel()
    assert "Chewing" in fig._suptitle.get_text()
    assert len(fig.legends[0].get_texts()) == 4
    plt.close(fig)

    fig = figures.kinematics_figure("chewing", kin)         # no band
    assert all(len(_polycollections(ax)) == 3 for ax in fig.axes)
    plt.close(fig)


def test_force_and_task_figures(kinematics_by_task, tmp_path):
    rng = np.random.default_rng(9)
    forces = {model: {side: 20.0 + rng.normal(size=(5, N_POINTS, 3)) for side in ("left", "right")}
              for model in ("POP", "FDK")}
    band = {side: forces["FDK"][side][:3] for side in ("left", "right")}
    p = figures.plot_forces("open_close", forces, tmp_path / "f.png", band=band)
    assert (tmp_path / "f.png").stat().st_size > 30_000 and p.endswith("f.png")
    fig = figures.forces_figure("open_close", forces)
    assert "N" in fig.axes[0].get_ylabel() and "Open-close" in fig._suptitle.get_text()
    assert all(len(_polycollections(ax)) == 2 for ax in fig.axes)
    import matplotlib.pyplot as plt
    plt.close(fig)
    figures.plot_task("protrusion", kinematics_by_task["protrusion"], forces,
                      tmp_path / "task.png", force_band=band)
    assert (tmp_path / "task.png").stat().st_size > 50_000


def test_figure_input_errors(kinematics_by_task, tmp_path):
    kin = {m: dict(s) for m, s in kinematics_by_task["chewing"].items()}
    kin["POP"]["left"] = kin["POP"]["left"][:, :50]
    with pytest.raises(ValueError, match="model 'POP', side 'left': 50 points per cycle"):
        figures.plot_kinematics("chewing", kin, tmp_path / "x.png")
    kin = kinematics_by_task["chewing"]
    with pytest.raises(ValueError, match="band, side 'right': expected \\(n_variants, 101, 3\\)"):
        figures.plot_kinematics("chewing", kin, tmp_path / "x.png",
                                band={"left": np.zeros((3, 101, 3)), "right": np.zeros((3, 100, 3))})
    with pytest.raises(ValueError, match="side 'right' missing"):
        figures.plot_forces("chewing", {"POP": {"left": np.zeros((5, 101, 3))}}, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


# --------------------------------------------------------------------------------------
# Whole-record splitting: periods 0.3–5 s, partial cycles at both ends, fewer cycles
# --------------------------------------------------------------------------------------

def partial_edged_cycles(period, n_complete, noise=0.01, seed=0):
    """Cycles that open (raised cosine over the first 80 % of each period) and rest
    closed for the last 20 %; the record starts at 15 % of a cycle (mid-opening) and
    stops at 60 % of the cycle after the last complete one (mid-closing). Periods vary
    by ±5 %; noise is a fraction of the amplitude. Returns time, signal and the onsets
    (s) of the complete cycles plus the onset of the trailing partial one."""
    rng = np.random.default_rng(seed)
    periods = period * (1.0 + rng.uniform(-0.05, 0.05, n_complete + 2))
    onsets = np.concatenate([[-0.15 * periods[0]], -0.15 * periods[0] + np.cumsum(periods)])
    end = onsets[-2] + 0.6 * periods[-1]
    t = np.arange(0.0, end, 1.0 / FS)
    x = np.zeros_like(t)
    for a, T in zip(onsets[:-1], periods):
        s = (t - a) / (0.8 * T)
        inside = (s >= 0.0) & (s < 1.0)
        x[inside] = 0.5 * (1.0 - np.cos(2 * np.pi * s[inside]))
    x = x + rng.normal(0.0, noise, t.size)
    return t, x, onsets[1:-1]


@pytest.mark.parametrize("period,n_complete", [(0.3, 8), (0.8, 5), (1.7, 4), (2.75, 4), (5.0, 3)])
def test_whole_record_cycles_for_periods_from_0_3_to_5_s(period, n_complete):
    """Every complete cycle is found, both partial edge cycles are skipped and named,
    starts lag the true onsets by less than the closed-band rise time (≤ 5 % of the
    period plus two samples), and consecutive cycles share their boundary."""
    from openfdk.mandible.cycles import find_cycles

    t, x, onsets = partial_edged_cycles(period, n_complete)
    split = find_cycles(t, x)
    assert len(split.cycles) == n_complete
    assert split.skipped == ["a partial cycle at the start", "a partial cycle at the end"]
    starts = np.array([t[a] for a, _ in split.cycles])
    lag = starts - onsets[:n_complete]
    assert np.all(lag >= -0.5 / FS) and np.all(lag <= 0.05 * period + 2.0 / FS), lag
    for (_, b), (a, _) in itertools.pairwise(split.cycles):
        assert b == a
    # the last complete cycle stops at the opening onset of the trailing partial one
    assert t[split.cycles[-1][1]] - onsets[n_complete] == pytest.approx(np.mean(lag), abs=0.05 * period + 0.02)


def test_fewer_cycles_than_requested():
    """Five requested, three complete: split_cycles raises naming what it found,
    allow_fewer returns the three, n_cycles=None returns all of them."""
    t, x, onsets = partial_edged_cycles(2.75, 3)
    with pytest.raises(CycleError, match=r"found 3 complete cycle\(s\).*but n_cycles=5 were requested"):
        split_cycles(t, x, n_cycles=5)
    fewer = split_cycles(t, x, n_cycles=5, allow_fewer=True)
    assert len(fewer) == 3 and fewer == split_cycles(t, x, n_cycles=None)
    assert split_cycles(t, x, n_cycles=2) == fewer[:2]
    with pytest.raises(CycleError, match="n_cycles must be"):
        split_cycles(t, x, n_cycles=0)


def test_a_slow_record_cut_close_to_its_cycles_keeps_its_edge_cycles():
    """The failure of issue 14: a 2.75 s-period record cut to its first three cycles
    ± 0.05 s. The edge troughs then hold 5 closed samples — fewer than 3 % of the period
    (8 samples) — yet the cycles are complete: all three must be found, with the same
    boundaries within 3 samples (1 % of the period; the filter's edge transient moves
    the closed level of the cut record's edge troughs slightly)."""
    t, x, onsets = raised_cosine_cycles(np.full(5, 2.75), amplitude=0.01, noise=5e-5, seed=4)
    cycles = split_cycles(t, x, n_cycles=3)
    lo, hi = cycles[0][0] - 5, cycles[-1][1] + 5
    cut = split_cycles(t[lo : hi + 1], x[lo : hi + 1], n_cycles=3)
    assert len(cut) == 3
    np.testing.assert_allclose(np.array(cut) + lo, np.array(cycles), atol=3)
