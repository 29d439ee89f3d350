"""Benchmark: inverse dynamics including marker-tracking kinematics of the synthetic
POP-type jaw (2 bodies, 8 markers, two point-on-plane TMJs and a medio-lateral
constraint, 24 Hill-type muscles, 2 push-only TMJ reactions, cubic recruitment), in
frames per second over a 1 000-frame open–close trial (median of runs, compilation
excluded by a warm-up); plus the Hill MuscleSet evaluation time for 24 muscles."""

from __future__ import annotations

import statistics
import time

import numpy as np


def run(quick=False):
    from ..analysis.inverse_dynamics import run_inverse_dynamics
    from ..io.c3d import MarkerTrial
    from ..io.markers import MarkerTrajectories
    from ..kinematics.analysis import run_tracking
    from ..io.modelfile import model_and_settings_from_dict
    from ..fixtures.synthetic_jaw import jaw_markers, jaw_model_dict

    n_frames = 100 if quick else 1000
    repeats = 1 if quick else 3
    model, settings = model_and_settings_from_dict(jaw_model_dict(), "synthetic_jaw.yaml")
    t, labels, x, _ = jaw_markers(n_frames, noise=1e-4, seed=2)
    traj = MarkerTrajectories(MarkerTrial(tuple(labels), 100.0, t, x, "synthetic"), cutoff_hz=8.0)
    run_inverse_dynamics(model, run_tracking(model, traj, t[:10]), settings=settings)  # warm-up
    rates, id_rates = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        kin = run_tracking(model, traj, t)
        t1 = time.perf_counter()
        dyn = run_inverse_dynamics(model, kin, settings=settings)
        t2 = time.perf_counter()
        if not dyn.converged.all():
            raise RuntimeError(f"benchmark trial did not converge: {dyn.failed_frames()[:1]}")
        rates.append(n_frames / (t2 - t0))
        id_rates.append(n_frames / (t2 - t1))
    from ..analysis.inverse_dynamics import InverseDynamics

    muscles = InverseDynamics(model).muscles.strength_models
    l = np.array([m.optimal_fibre_length + m.tendon_slack_length for m in muscles.muscles]) * 1.05
    v = np.linspace(-0.05, 0.05, len(l))
    muscles.evaluate(l, v)
    n = 200 if quick else 2000
    samples = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n):
            muscles.evaluate(l, v)
        samples.append((time.perf_counter() - t0) / n)
    return [
        {"name": "inverse_dynamics_with_tracking_jaw24_fps", "value": statistics.median(rates), "unit": "frames/s"},
        {"name": "inverse_dynamics_only_jaw24_fps", "value": statistics.median(id_rates), "unit": "frames/s"},
        {"name": "hill_muscleset_eval_24_us", "value": statistics.median(samples) * 1e6, "unit": "us"},
    ]
