"""Benchmark: force plates from a C3D file (:func:`openfdk.io.force_plates.read_force_plates`).

The trial is written once with ezc3d in a temporary directory: 10 s at 100 Hz (1 000
frames) of 10 markers and 4 plates sampled at 1 000 Hz (30 analog channels: two type-2
plates, one type-3, one type-4 with a full calibration matrix; float storage, ANALOG:SCALE
0.5), each plate loaded by three 0.6 s gait-like stances at moving
centres of pressure, with 2 N / 2 N·m of seeded noise.

Record ``force_plates_read_ms``: one ``read_force_plates(path)`` call with its defaults —
the file check (:func:`~openfdk.io.c3d.inspect_c3d`), decoding the analog channels,
baseline, the 6 Hz zero-lag Butterworth filter of force and moment at 1 000 Hz,
decimation to 100 Hz, centre of pressure, free moment and the 20 N threshold — for all
four plates; CPU time of the process (``time.process_time``, as the other benchmarks),
median of 9 runs (``--quick``: 3) after one warm-up call (numba's filter kernel loaded
or compiled, the file in the OS cache).  The record's ``detail`` has the wall time too.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

SECONDS, POINT_RATE, RATIO = 10.0, 100.0, 10
KINDS = (2, 2, 3, 4)


def _stances(n, rate, shift, rng):
    """Plate-frame action force (n, 3) N, centre of pressure (n, 2) mm, Tz (n,) N·mm."""
    t = np.arange(n) / rate
    force, cop, tz = np.zeros((n, 3)), np.zeros((n, 2)), np.zeros(n)
    for start in (1.0 + shift, 4.0 + shift, 7.0 + shift):
        u = (t - start) / 0.6
        on = (u >= 0) & (u < 1)
        shape = np.sin(np.pi * u[on]) + 0.25 * np.sin(3 * np.pi * u[on])
        force[on] = np.column_stack((60 * np.cos(np.pi * u[on]), 30 * shape, 750 * shape))
        cop[on] = np.column_stack((-120 + 240 * u[on], 20 * np.sin(2 * np.pi * u[on])))
        tz[on] = 3000 * np.sin(2 * np.pi * u[on])
    force += rng.normal(0, 2.0, force.shape)
    tz += rng.normal(0, 2000.0, n)
    return force, cop, tz


def write_trial(path: Path, seed: int = 11) -> Path:
    """Write the benchmark trial (module docstring) to ``path``."""
    import ezc3d

    rng = np.random.default_rng(seed)
    n_frames = int(SECONDS * POINT_RATE)
    n = n_frames * RATIO
    origin2, origin3 = np.array([1.5, -2.0, -40.0]), np.array([120.0, 200.0, -45.0])
    cal = np.eye(6) + 0.01 * rng.standard_normal((6, 6))
    columns, channel, corners, origins = [], np.zeros((8, 4), dtype=int), [], []
    for k, kind in enumerate(KINDS):
        force, cop, tz = _stances(n, POINT_RATE * RATIO, 0.7 * k, rng)
        r = np.array([0.0, 0.0, origin3[2]]) if kind == 3 else origin2
        m_o = np.cross(np.column_stack((cop, np.zeros(n))) + r, force)
        m_o[:, 2] += tz
        if kind == 3:
            a, b = origin3[:2]
            d, e = m_o[:, 2] / (2 * b), m_o[:, 2] / (2 * a)
            x, y, s = m_o[:, 0] / b, m_o[:, 1] / a, force[:, 2]
            block = np.column_stack(((force[:, 0] - d) / 2, (force[:, 0] + d) / 2,
                                     (force[:, 1] + e) / 2, (force[:, 1] - e) / 2,
                                     (s + x - y) / 4, (s + x + y) / 4,
                                     (s - x + y) / 4, (s - x - y) / 4))
        else:
            block = np.column_stack((force, m_o))
            if kind == 4:
                block = np.linalg.solve(cal, block.T).T
        first = sum(len(c) for c in columns) // n
        channel[:block.shape[1], k] = np.arange(first + 1, first + 1 + block.shape[1])
        columns.append(block.T.reshape(-1))
        x0 = 700.0 * k
        corners.append(np.array([[x0 + 300, 0, 0], [x0 - 300, 0, 0],
                                 [x0 - 300, 500, 0], [x0 + 300, 500, 0]]).T)   # z down
        origins.append(origin3 if kind == 3 else origin2)
    values = np.concatenate(columns).reshape(-1, n).T                          # (n, 30)
    n_channels = values.shape[1]
    scale = np.full(n_channels, 0.5)

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [POINT_RATE]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = [f"M{i}" for i in range(10)]
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d["data"]["points"] = np.concatenate(
        (rng.normal(500, 100, (3, 10, n_frames)), np.ones((1, 10, n_frames))))
    analog = c3d["parameters"]["ANALOG"]
    analog["RATE"]["value"] = [POINT_RATE * RATIO]
    analog["LABELS"]["value"] = [f"A{i + 1}" for i in range(n_channels)]
    analog["SCALE"]["value"] = scale
    analog["UNITS"]["value"] = [
        u for kind in KINDS for u in {2: ["N"] * 3 + ["Nmm"] * 3, 3: ["N"] * 8, 4: ["V"] * 6}[kind]]
    c3d["data"]["analogs"] = values.T[None]          # ezc3d stores value / (SCALE × GEN_SCALE)
    fp = c3d["parameters"]["FORCE_PLATFORM"]
    fp["USED"]["value"] = [len(KINDS)]
    fp["TYPE"]["value"] = list(KINDS)
    fp["ZERO"]["value"] = [1, 10]
    fp["CHANNEL"]["value"] = channel
    fp["CORNERS"]["value"] = np.stack(corners, axis=2)
    fp["ORIGIN"]["value"] = np.column_stack(origins)
    fp["CAL_MATRIX"]["value"] = np.stack([cal if kind == 4 else np.eye(6) for kind in KINDS], axis=2)
    c3d.write(str(path))
    return path


def run(quick=False):
    from ..io.force_plates import read_force_plates

    repeats = 3 if quick else 9
    with tempfile.TemporaryDirectory() as folder:
        path = write_trial(Path(folder) / "force_plates_bench.c3d")
        plates = read_force_plates(path)                      # warm-up
        if len(plates) != len(KINDS) or any(p.never_loaded for p in plates):
            raise RuntimeError("benchmark trial: expected 4 loaded plates")
        cpu, wall = [], []
        for _ in range(repeats):
            w0, c0 = time.perf_counter(), time.process_time()
            read_force_plates(path)
            cpu.append(time.process_time() - c0)
            wall.append(time.perf_counter() - w0)
    return [{"name": "force_plates_read_ms", "value": statistics.median(cpu) * 1e3, "unit": "ms",
             "detail": (f"4 plates (types {', '.join(map(str, KINDS))}), {SECONDS:g} s at "
                        f"{POINT_RATE * RATIO:g} Hz analog / {POINT_RATE:g} Hz points, 6 Hz "
                        f"filter; median of {repeats}; wall {statistics.median(wall) * 1e3:.1f} ms")}]
