"""Tests of openfdk.io.c3d: reading, writing and refusing malformed C3D files.

Independent references: a minimal C3D writer written here from the C3D User Guide
layout (``build_c3d``, not using ezc3d) and a minimal header/data parser
(``parse_c3d_floats``) that checks what ``write_c3d`` puts on disk.  Files that could
crash the process if they reached ezc3d are read in a subprocess, so a regression shows
up as a failed test rather than a dead test run.
"""

from __future__ import annotations

import struct
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from openfdk.io.c3d import (
    C3DError,
    MarkerTrial,
    MissingMarkerError,
    inspect_c3d,
    read_c3d,
    write_c3d,
)

# float32 storage: |x| ≤ 1 m is stored with relative error ≤ 2⁻²⁴ ≈ 6e-8, i.e. ≤ 6e-8 m
FLOAT32_TOLERANCE_M = 1e-6


# ---------------------------------------------------------------------------------------
# An independent minimal C3D writer and reader (C3D User Guide layout)
# ---------------------------------------------------------------------------------------

def build_c3d(labels, points, rate, *, units="mm", residuals=None, scale=-1.0,
              first_frame=1, processor=84, analog_channels=0, analog_per_frame=0,
              analog_scale_count=None) -> bytes:
    """Bytes of a C3D file; ``points (n_frames, n_points, 3)`` in file units.

    ``scale < 0``: float32 storage; ``scale > 0``: int16 × scale.  ``processor`` 84
    Intel, 85 DEC (VAX floats), 86 MIPS (big-endian).
    """
    n_frames, n_points, _ = points.shape
    residuals = np.zeros((n_frames, n_points)) if residuals is None else residuals
    endian = ">" if processor == 86 else "<"

    def f32(values):
        values = np.asarray(values, dtype=float).reshape(-1)
        if processor == 85:          # VAX F float = IEEE float of 4·x with halves swapped
            raw = np.asarray(values * 4.0, dtype="<f4").view(np.uint8).reshape(-1, 4)
            return raw[:, [2, 3, 0, 1]].tobytes()
        return np.asarray(values, dtype=endian + "f4").tobytes()

    def i16(values):
        return np.asarray(values, dtype=endian + "i2").tobytes()

    def record(name, item_id, body):
        return (struct.pack("bb", len(name), item_id) + name.encode()
                + struct.pack(endian + "H", 2 + len(body)) + body)

    def group(group_id, name):
        return record(name, -group_id, b"\x00")

    def param(group_id, name, code, dims, data):
        return record(name, group_id, struct.pack("bB", code, len(dims)) + bytes(dims)
                      + data + b"\x00")

    def chars(strings):
        width = max([len(s) for s in strings] + [1])
        return [width, len(strings)], b"".join(s.ljust(width).encode() for s in strings)

    n_scales = analog_channels if analog_scale_count is None else analog_scale_count
    records = [
        group(1, "POINT"),
        param(1, "USED", 2, [], i16([n_points])),
        param(1, "FRAMES", 2, [], i16([n_frames])),
        param(1, "LABELS", -1, *chars(labels)),
        param(1, "UNITS", -1, [len(units)], units.encode()),
        param(1, "SCALE", 4, [], f32([scale])),
        param(1, "RATE", 4, [], f32([rate])),
        group(2, "ANALOG"),
        param(2, "USED", 2, [], i16([analog_channels])),
        param(2, "RATE", 4, [], f32([rate * analog_per_frame])),
        param(2, "GEN_SCALE", 4, [], f32([1.0])),
        param(2, "SCALE", 4, [n_scales], f32(np.ones(n_scales))),
        param(2, "OFFSET", 2, [n_scales], i16(np.zeros(n_scales))),
    ]
    body = b"".join(records)
    n_param_blocks = (4 + len(body) + 20 + 511) // 512
    data_block = 2 + n_param_blocks
    body += param(1, "DATA_START", 2, [], i16([data_block]))
    section = (struct.pack("BBBB", 1, 0x50, n_param_blocks, processor) + body)
    section = section.ljust(512 * n_param_blocks, b"\x00")
    n_analog_values = analog_channels * analog_per_frame
    header = (struct.pack("BB", 2, 0x50)
              + np.array([n_points, n_analog_values, first_frame,
                          first_frame + n_frames - 1, 0], dtype=endian + "u2").tobytes()
              + f32([scale])
              + np.array([data_block, analog_per_frame], dtype=endian + "u2").tobytes()
              + f32([rate])).ljust(512, b"\x00")
    if scale < 0:
        rows = np.concatenate([points, residuals[:, :, None]], axis=2).reshape(n_frames, -1)
        data = b"".join(f32(row) + f32(np.zeros(n_analog_values)) for row in rows)
    else:
        stored = np.concatenate([np.round(points / scale),
                                 np.where(residuals < 0, -1, 0)[:, :, None]], axis=2)
        data = b"".join(i16(row) + i16(np.zeros(n_analog_values))
                        for row in stored.reshape(n_frames, -1))
    return header + section + data.ljust(-(-len(data) // 512) * 512, b"\x00")


def parse_c3d_floats(raw: bytes):
    """Minimal reader of an Intel float C3D without analog data: header fields and the
    ``(n_frames, n_points, 4)`` float32 records (x, y, z, residual)."""
    parameter_block = raw[0]
    words = struct.unpack("<HHHHH", raw[2:12])
    fields = {
        "key": raw[1],
        "processor": raw[(parameter_block - 1) * 512 + 3],
        "n_points": words[0],
        "n_analog": words[1],
        "first_frame": words[2],
        "last_frame": words[3],
        "scale": struct.unpack("<f", raw[12:16])[0],
        "data_block": struct.unpack("<H", raw[16:18])[0],
        "rate": struct.unpack("<f", raw[20:24])[0],
    }
    n_frames = fields["last_frame"] - fields["first_frame"] + 1
    start = (fields["data_block"] - 1) * 512
    records = np.frombuffer(raw, dtype="<f4", count=n_frames * fields["n_points"] * 4,
                            offset=start).reshape(n_frames, fields["n_points"], 4)
    return fields, records


def read_in_subprocess(path) -> subprocess.CompletedProcess:
    """read_c3d(path) in a fresh interpreter: prints 'OK' or 'C3DError: …'."""
    code = textwrap.dedent(f"""
        from openfdk.io.c3d import read_c3d, C3DError
        try:
            read_c3d({str(path)!r})
            print("OK")
        except C3DError as exc:
            print("C3DError:", exc)
    """)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=False)


def trajectory(n_frames=120, rate=100.0):
    """Known positions (n_frames, 3 markers, 3) m with a gap; labels."""
    t = np.arange(n_frames) / rate
    p = np.stack([
        np.stack([0.1 * np.sin(2 * np.pi * t), 0.05 * np.cos(3 * t), 0.9 + 0 * t], axis=1),
        np.stack([-0.3 + 0.01 * t, 0.2 * t ** 2, 1.1 - 0.1 * t], axis=1),
        np.stack([0.25 * np.ones_like(t), -0.4 + 0.02 * np.sin(5 * t), 0.5 * t], axis=1),
    ], axis=1)
    p[30:45, 1] = np.nan                      # marker B occluded for 15 frames
    p[-1, 2] = np.nan                         # marker C lost at the last frame
    return ["Lower_FL", "Lower FR", "Upper_B"], p, rate


# ---------------------------------------------------------------------------------------
# Round trips and cross-checks
# ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("units", ["mm", "cm", "m"])
def test_write_read_round_trip(tmp_path, units):
    labels, p_WM, rate = trajectory()
    path = tmp_path / f"trial_{units}.c3d"
    write_c3d(path, labels, p_WM, rate, units=units)
    trial = read_c3d(path)
    assert trial.labels == tuple(labels)
    assert trial.rate == rate
    assert trial.n_frames == p_WM.shape[0] and trial.n_markers == 3
    np.testing.assert_allclose(trial.time, np.arange(p_WM.shape[0]) / rate, rtol=0, atol=1e-12)
    assert np.array_equal(np.isnan(trial.positions), np.isnan(p_WM))
    np.testing.assert_allclose(trial.positions, p_WM, rtol=0, atol=FLOAT32_TOLERANCE_M)
    assert trial.source == str(path)


def test_write_refuses_millimetres_passed_as_metres(tmp_path):
    """Positions are metres: lab coordinates in mm (here 300–1500 "m") are refused with
    a message that says so, instead of a file 1000× too large."""
    labels, p_WM, rate = trajectory()
    with pytest.raises(C3DError, match=r"must be in metres.*looks like millimetres"):
        write_c3d(tmp_path / "mm.c3d", labels, 1e3 * p_WM + 300.0, rate)
    write_c3d(tmp_path / "m.c3d", labels, p_WM + 0.3, rate)       # the same data in m: fine


def test_written_file_matches_independent_parser(tmp_path):
    labels, p_WM, rate = trajectory()
    path = tmp_path / "trial.c3d"
    write_c3d(path, labels, p_WM, rate, units="mm")
    fields, records = parse_c3d_floats(path.read_bytes())
    assert fields["key"] == 0x50 and fields["processor"] == 84
    assert fields["n_points"] == 3 and fields["n_analog"] == 0
    assert fields["first_frame"] == 1 and fields["last_frame"] == p_WM.shape[0]
    assert fields["scale"] < 0                                  # float storage
    assert fields["rate"] == pytest.approx(rate)
    missing = np.isnan(p_WM).any(axis=2)
    assert np.all(records[missing][:, 3] == -1.0)              # residual −1 marks a gap
    assert np.all(records[~missing][:, 3] >= 0.0)
    np.testing.assert_allclose(records[~missing][:, :3], 1e3 * p_WM[~missing],
                               rtol=0, atol=1e3 * FLOAT32_TOLERANCE_M)
    # the layout inspect_c3d reports equals the independent parse
    layout = inspect_c3d(path)
    assert (layout.n_points, layout.n_frames, layout.is_float, layout.processor) == (
        3, p_WM.shape[0], True, "Intel")
    assert layout.data_start_block == fields["data_block"]


@pytest.mark.parametrize("processor", [84, 85])
@pytest.mark.parametrize("scale", [-1.0, 0.05])
def test_read_independently_written_file(tmp_path, processor, scale):
    """Files built byte by byte here (Intel / DEC, float / int16 storage), with a
    non-unit first frame, a residual −1 gap and a 0,0,0 gap."""
    rng = np.random.default_rng(3)
    points_mm = rng.uniform(-500.0, 500.0, size=(30, 4, 3))
    residuals = np.zeros((30, 4))
    residuals[5:9, 2] = -1.0
    points_mm[12, 0] = 0.0                                     # a gap written as zeros
    path = tmp_path / "hand.c3d"
    path.write_bytes(build_c3d([" a", "b ", "c", "d"], points_mm, 120.0,
                               residuals=residuals, scale=scale, processor=processor,
                               first_frame=11))
    trial = read_c3d(path)
    expected = 1e-3 * points_mm
    expected[5:9, 2] = np.nan
    expected[12, 0] = np.nan
    assert trial.labels == ("a", "b", "c", "d")
    assert trial.rate == pytest.approx(120.0)
    # time[k] = (first_frame − 1 + k) / rate
    np.testing.assert_allclose(trial.time, (10 + np.arange(30)) / 120.0, atol=1e-12)
    assert np.array_equal(np.isnan(trial.positions), np.isnan(expected))
    # int16 storage rounds to the scale (0.05 mm): error ≤ scale/2
    tolerance = FLOAT32_TOLERANCE_M if scale < 0 else 0.5 * scale * 1e-3 + 1e-9
    np.testing.assert_allclose(trial.positions, expected, rtol=0, atol=tolerance)


def test_big_endian_file_is_inspected_and_refused_cleanly(tmp_path):
    points_mm = np.arange(2 * 2 * 3, dtype=float).reshape(2, 2, 3) + 1.0
    path = tmp_path / "sgi.c3d"
    path.write_bytes(build_c3d(["a", "b"], points_mm, 50.0, processor=86))
    layout = inspect_c3d(path)                                 # big-endian header parsed
    assert (layout.processor, layout.n_points, layout.n_frames, layout.rate) == (
        "MIPS", 2, 2, 50.0)
    with pytest.raises(C3DError, match="sgi.c3d"):             # ezc3d has no MIPS reader
        read_c3d(path)


# ---------------------------------------------------------------------------------------
# Malformed files: an exception naming the file, never a crash
# ---------------------------------------------------------------------------------------

def test_truncated_file_is_refused(tmp_path):
    labels, p_WM, rate = trajectory(n_frames=400)
    path = tmp_path / "trial.c3d"
    write_c3d(path, labels, p_WM, rate)
    raw = path.read_bytes()
    data_start = (raw[16] + 256 * raw[17] - 1) * 512
    cut = data_start + 1000                                    # inside the data section
    truncated = tmp_path / "cut.c3d"
    truncated.write_bytes(raw[:cut])
    with pytest.raises(C3DError) as info:
        read_c3d(truncated)
    message = str(info.value)
    assert "cut.c3d is truncated" in message
    assert "400 frames of 3 points" in message
    assert f"{400 * 3 * 4 * 4} bytes" in message               # 4 float32 per point
    assert f"ends after {cut} bytes" in message
    result = read_in_subprocess(truncated)                     # and the process survives
    assert result.returncode == 0 and "truncated" in result.stdout


def test_empty_missing_and_garbage_files(tmp_path):
    with pytest.raises(C3DError, match="no such C3D file"):
        read_c3d(tmp_path / "absent.c3d")
    empty = tmp_path / "empty.c3d"
    empty.write_bytes(b"")
    with pytest.raises(C3DError, match="empty.c3d: the file is empty"):
        read_c3d(empty)
    short = tmp_path / "short.c3d"
    short.write_bytes(b"\x02\x50" + bytes(100))
    with pytest.raises(C3DError, match="only 102 bytes"):
        read_c3d(short)
    rng = np.random.default_rng(7)
    garbage = bytearray(rng.integers(0, 256, 8192, dtype=np.uint8).tobytes())
    garbage[1] = 0x51
    bad_key = tmp_path / "garbage.c3d"
    bad_key.write_bytes(bytes(garbage))
    with pytest.raises(C3DError, match="byte 2 is 0x51, expected 0x50"):
        read_c3d(bad_key)
    # random bytes behind a plausible first word: refused by the deeper checks
    for seed in range(20):
        rng = np.random.default_rng(seed)
        garbage = bytearray(rng.integers(0, 256, 8192, dtype=np.uint8).tobytes())
        garbage[0:2] = b"\x02\x50"
        path = tmp_path / f"garbage_{seed}.c3d"
        path.write_bytes(bytes(garbage))
        with pytest.raises(C3DError, match=f"garbage_{seed}.c3d"):
            read_c3d(path)


def test_unknown_units_and_duplicate_labels(tmp_path):
    points_mm = np.ones((5, 2, 3))
    inches = tmp_path / "inches.c3d"
    inches.write_bytes(build_c3d(["a", "b"], points_mm, 100.0, units="in"))
    with pytest.raises(C3DError, match=r"inches.c3d: POINT:UNITS is 'in'; expected one of mm, cm, m"):
        read_c3d(inches)
    twice = tmp_path / "twice.c3d"
    twice.write_bytes(build_c3d(["a", "a "], points_mm, 100.0))
    with pytest.raises(C3DError, match=r"twice.c3d: duplicate marker labels \['a'\]"):
        read_c3d(twice)
    with pytest.raises(C3DError, match="units 'inch'"):
        write_c3d(tmp_path / "w.c3d", ["a", "b"], np.zeros((3, 2, 3)), 100.0, units="inch")
    with pytest.raises(C3DError, match=r"duplicate marker labels \['a'\]"):
        write_c3d(tmp_path / "w.c3d", ["a", "a"], np.zeros((3, 2, 3)), 100.0)


def test_analog_scales_shorter_than_channels_never_reach_ezc3d(tmp_path):
    """ezc3d segfaults on this file (measured); the check refuses it first."""
    points_mm = np.ones((10, 2, 3))
    ok = tmp_path / "analog.c3d"
    ok.write_bytes(build_c3d(["a", "b"], points_mm, 100.0, analog_channels=4,
                             analog_per_frame=10))
    np.testing.assert_allclose(read_c3d(ok).positions, 1e-3)   # analog data skipped over
    bad = tmp_path / "no_scales.c3d"
    bad.write_bytes(build_c3d(["a", "b"], points_mm, 100.0, analog_channels=4,
                              analog_per_frame=10, analog_scale_count=0))
    result = read_in_subprocess(bad)
    assert result.returncode == 0, result.stderr
    assert "ANALOG:SCALE has 0 values for 4 analog channels" in result.stdout


def test_mutated_files_never_crash(tmp_path):
    """Seeded random corruption of header and parameter bytes: every file is read or
    refused with C3DError, in a subprocess that must exit normally."""
    labels, p_WM, rate = trajectory(n_frames=20)
    base = tmp_path / "base.c3d"
    write_c3d(base, labels, p_WM, rate)
    hand = tmp_path / "hand.c3d"
    hand.write_bytes(build_c3d(["a", "b", "c"], np.ones((20, 3, 3)), 100.0,
                               analog_channels=2, analog_per_frame=5))
    code = textwrap.dedent(f"""
        import struct, numpy as np
        from openfdk.io.c3d import read_c3d, C3DError
        rng = np.random.default_rng(2024)
        bases = [open(p, "rb").read() for p in ({str(base)!r}, {str(hand)!r})]
        outcomes = {{"read": 0, "C3DError": 0}}
        for i in range(300):
            b = bytearray(bases[i % 2])
            section_end = min(len(b), 512 * (1 + max(b[514], 1)))
            for _ in range(rng.integers(1, 4)):
                mode = rng.integers(3)
                if mode == 0:
                    b[rng.integers(0, 24)] = rng.integers(256)
                elif mode == 1:
                    b[rng.integers(512, section_end)] = rng.integers(256)
                else:
                    pos = rng.integers(0, section_end - 2)
                    b[pos:pos + 2] = struct.pack("<H", int(rng.choice([0, 1, 0x7FFF, 0xFFFF])))
            if rng.random() < 0.15:
                b = b[:rng.integers(1, len(b))]
            path = {str(tmp_path / "mutant.c3d")!r}
            open(path, "wb").write(bytes(b))
            try:
                read_c3d(path)
                outcomes["read"] += 1
            except C3DError:
                outcomes["C3DError"] += 1
        print(outcomes["read"], outcomes["C3DError"])
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    n_read, n_refused = map(int, result.stdout.split())
    assert n_read + n_refused == 300 and n_refused > 0 and n_read > 0


# ---------------------------------------------------------------------------------------
# MarkerTrial
# ---------------------------------------------------------------------------------------

def make_trial():
    labels = ("Lower_FL", "Lower_FR", "Lower_BL", "Upper_FL")
    positions = np.arange(5 * 4 * 3, dtype=float).reshape(5, 4, 3)
    return MarkerTrial(labels=labels, rate=100.0, time=np.arange(5) / 100.0,
                       positions=positions, source="session/trial.c3d")


def test_select_orders_markers_and_names_all_missing():
    trial = make_trial()
    chosen = trial.select(["Upper_FL", "Lower_FL"])
    assert chosen.labels == ("Upper_FL", "Lower_FL")
    np.testing.assert_array_equal(chosen.positions, trial.positions[:, [3, 0]])
    with pytest.raises(MissingMarkerError) as info:
        trial.select(["Lower_FL", "Upper_BR", "lower_fr", "Skull_X"])
    message = str(info.value)
    assert info.value.missing == ("Upper_BR", "lower_fr", "Skull_X")
    for name in ("'Upper_BR'", "'lower_fr'", "'Skull_X'", "session/trial.c3d",
                 "Available: Lower_FL, Lower_FR, Lower_BL, Upper_FL"):
        assert name in message
    assert "'lower_fr' ~ 'Lower_FR'" in message                # near match suggested


def test_index_suggests_near_matches():
    trial = make_trial()
    assert trial.index("Lower_BL") == 2
    with pytest.raises(MissingMarkerError, match=r"marker 'lower_blx' missing from "
                       r"session/trial.c3d; did you mean 'Lower_BL'"):
        trial.index("lower_blx")
    assert isinstance(MissingMarkerError("m", [], "", []), ValueError)
    assert issubclass(C3DError, ValueError)


def test_trial_is_read_only_and_validated():
    trial = make_trial()
    with pytest.raises(ValueError):
        trial.positions[0, 0, 0] = 1.0
    with pytest.raises(ValueError, match="shape"):
        MarkerTrial(labels=("a",), rate=100.0, time=np.arange(3), positions=np.zeros((3, 2, 3)))
    with pytest.raises(ValueError, match="duplicate"):
        MarkerTrial(labels=("a", "a"), rate=100.0, time=np.arange(3),
                    positions=np.zeros((3, 2, 3)))
    with pytest.raises(ValueError, match="rate"):
        MarkerTrial(labels=("a",), rate=0.0, time=np.arange(3), positions=np.zeros((3, 1, 3)))
