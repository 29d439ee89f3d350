"""Benchmark: marker-tracking kinematics of the synthetic two-body model (2 bodies,
8 markers, one point-on-plane joint): positions, velocities and accelerations over
2 000 frames at 100 Hz with 0.2 mm marker noise, in frames per second (median of runs;
numba compilation excluded by a warm-up run)."""

from __future__ import annotations

import statistics
import time


def run(quick=False):
    from ..io.c3d import MarkerTrial
    from ..io.markers import MarkerTrajectories
    from ..kinematics.analysis import run_tracking
    from ..fixtures.synthetic import synthetic_markers, two_body_model

    n_frames = 200 if quick else 2000
    repeats = 1 if quick else 3
    model = two_body_model()
    t, labels, x, _ = synthetic_markers(n_frames, rate=100.0, noise=2e-4, seed=1)
    trial = MarkerTrial(tuple(labels), 100.0, t, x, "synthetic")
    t0 = time.perf_counter()
    traj = MarkerTrajectories(trial, cutoff_hz=6.0)
    build = time.perf_counter() - t0
    run_tracking(model, traj, t[:20])  # warm-up: numba kernels loaded/compiled
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = run_tracking(model, traj, t)
        rates.append(n_frames / (time.perf_counter() - t0))
        if not res.converged.all():
            raise RuntimeError(f"benchmark trial did not converge: {res.failed_frames()[:1]}")
    return [
        {"name": "kinematics_tracking_2body_8markers_fps", "value": statistics.median(rates), "unit": "frames/s"},
        {"name": "marker_trajectories_build_2000frames_ms", "value": build * 1e3 * (2000 / n_frames), "unit": "ms"},
    ]
