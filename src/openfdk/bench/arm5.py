"""Benchmark model ``arm5`` and its per-stage timings (issue 12).

``arm5``: a fixed upper arm (ground) and a forearm (1.2 kg) on one elbow hinge (a
revolute joint about the world −y axis), five Hill-type muscles on straight-line paths
(biceps, brachialis, brachioradialis, triceps, anconeus), three forearm markers, and a
sinusoidal flexion θ(t) = 30° + 35° sin(2π·0.5 t) driven for 2 s at 100 Hz (201 frames).
Gravity is −z; at θ = 0 the forearm is horizontal along +x, flexion raises it.

Timings (median over repeats, milliseconds per frame, start-up and compilation excluded
by a warm-up call). They are the process's CPU time (``time.process_time``): the stages
are single-threaded, so this is the one-core time, and it stays meaningful on a machine
shared with other jobs (wall time there counts the time the process waits for a core):

* ``arm5_determinate_kinematics_ms``: determinate kinematics from the driver (positions,
  velocities, accelerations; paper Eqs. 1–3) — :func:`run_determinate`;
* ``arm5_tracking_ms``: marker tracking of the 3 markers without the driver (Eqs. 4–10)
  — :func:`run_tracking`; the markers are the driven motion's, exact;
* ``arm5_inverse_dynamics_ms``: the equilibrium C f = d alone (Eqs. 12–14), kinematics
  given — ``InverseDynamics.equilibrium`` for every frame of the determinate result;
* ``arm5_inverse_dynamics_recruitment_ms``: equilibrium + cubic recruitment (Eq. 11),
  kinematics given — :func:`run_inverse_dynamics`.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

RATE_HZ = 100.0
DURATION_S = 2.0

# muscle: (origin on the upper arm (ground) m, insertion on the forearm measured from the
# elbow in the forearm's reference frame m, F0 N, optimal fibre length m)
_MUSCLES = {
    "biceps": ([0.020, 0.0, 0.300], [0.045, 0.0, 0.012], 600.0, 0.12),
    "brachialis": ([0.012, 0.0, 0.120], [0.030, 0.0, 0.008], 700.0, 0.08),
    "brachioradialis": ([0.015, 0.0, 0.090], [0.240, 0.0, 0.010], 250.0, 0.15),
    "triceps": ([-0.030, 0.0, 0.250], [-0.025, 0.0, 0.004], 1200.0, 0.09),
    "anconeus": ([-0.008, 0.015, 0.020], [0.030, 0.010, -0.012], 300.0, 0.02),
}
_MARKERS = {"FA1": [0.08, 0.02, 0.025], "FA2": [0.22, -0.025, 0.02], "FA3": [0.24, 0.025, -0.015]}
_COM = np.array([0.15, 0.0, 0.0])  # forearm centre of mass from the elbow, reference pose (m)


def arm5_model_dict(driver=True):
    """Model-file mapping (SI units) of arm5; ``driver=False`` drops the flexion driver
    (for marker tracking: the 3 markers then fix the one remaining DOF)."""
    ground_frames = {"elbow": {"position": [0.0, 0.0, 0.0], "orientation": [90.0, 0.0, 0.0]}}
    forearm_frames = {"elbow": {"position": (-_COM).tolist(), "orientation": [90.0, 0.0, 0.0]}}
    muscles = {}
    for name, (origin, insertion, f0, lf0) in _MUSCLES.items():
        ground_frames[f"{name}_o"] = list(origin)
        forearm_frames[f"{name}_i"] = (np.array(insertion) - _COM).tolist()
        # tendon slack length: fibres at their optimal length at θ = 30° (mid-motion)
        theta = np.deg2rad(30.0)
        c, s = np.cos(theta), np.sin(theta)
        R = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])  # rotation about −y
        length = float(np.linalg.norm(R @ np.array(insertion) - np.array(origin)))
        muscles[name] = {
            "path": [f"ground.{name}_o", f"forearm.{name}_i"],
            "max_isometric_force": f0, "optimal_fibre_length": lf0,
            "tendon_slack_length": round(max(length - lf0, 0.01), 9),
        }
    data = {
        "openfdk": 1,
        "name": "arm5",
        "units": {"length": "m", "angle": "deg"},
        "gravity": [0.0, 0.0, -9.81],
        "bodies": {
            "ground": {"fixed": True, "frames": ground_frames},
            "forearm": {"mass": 1.2, "inertia": [1.5e-3, 1.2e-2, 1.2e-2], "position": _COM.tolist(),
                        "frames": forearm_frames,
                        "markers": {k: (np.array(p) - _COM).tolist() for k, p in _MARKERS.items()}},
        },
        "measures": {"flexion": {"type": "angles", "frame": "ground.elbow", "of": "forearm.elbow"}},
        "joints": {"elbow": {"type": "revolute", "parent": "ground.elbow", "child": "forearm.elbow"}},
        "muscles": muscles,
        "recruitment": {"criterion": "polynomial", "power": 3},
    }
    if driver:
        data["drivers"] = {"flexion": {"measure": "flexion", "components": [2], "function": {
            "type": "fourier", "frequency": 0.5, "a": [30.0, 0.0], "b": [35.0]}}}
    return data


def arm5_models():
    """(driven model, tracking model) of arm5."""
    from ..model.modelfile import model_from_dict

    return model_from_dict(arm5_model_dict(True), "arm5.yaml"), model_from_dict(arm5_model_dict(False), "arm5_tracking.yaml")


def arm5_times():
    """Analysis times (201,) s: 2 s at 100 Hz."""
    return np.arange(int(round(DURATION_S * RATE_HZ)) + 1) / RATE_HZ


def arm5_marker_trajectories(kin, tracking_model):
    """Marker trajectories of the driven motion ``kin`` (KinematicsResult), exact."""
    from ..io.c3d import MarkerTrial
    from ..io.markers import MarkerTrajectories

    markers = tracking_model.markers
    state = tracking_model.initial_state()
    x = np.empty((len(kin.time), markers.size, 3))
    for k in range(len(kin.time)):
        state.set_q(kin.q[k])
        x[k] = markers.positions(state)
    trial = MarkerTrial(tuple(markers.labels), RATE_HZ, np.asarray(kin.time), x, "arm5")
    return MarkerTrajectories(trial, cutoff_hz=None)


def _equilibrium_only(solver, model, kin):
    """C, d of every frame (kinematics given); returns the last C."""
    state = model.initial_state()
    C = None
    for k in range(len(kin.time)):
        state.set_q(kin.q[k])
        state.set_v(kin.v[k])
        C = solver.equilibrium(state, kin.vdot[k], kin.time[k], kin.alpha)[0]
    return C


def stage_timings(repeats=5):
    """Per-frame times (ms) of the four stages, medians over ``repeats`` runs each,
    stages interleaved. Returns dict name -> ms."""
    from ..analysis.inverse_dynamics import InverseDynamics, run_inverse_dynamics
    from ..kinematics.analysis import run_determinate, run_tracking

    model, tracking_model = arm5_models()
    times = arm5_times()
    nf = len(times)
    kin = run_determinate(model, times)
    if not kin.converged.all():
        raise RuntimeError(f"arm5 determinate kinematics failed: {kin.failed_frames()[:1]}")
    traj = arm5_marker_trajectories(kin, tracking_model)
    solver = InverseDynamics(model)
    # warm-up: numba kernels loaded from the cache (or compiled) outside the timings
    run_tracking(tracking_model, traj, times[:5])
    run_inverse_dynamics(model, kin, solver=solver)

    def determinate():
        return run_determinate(model, times).converged.all()

    def tracking():
        return run_tracking(tracking_model, traj, times).converged.all()

    def equilibrium():
        return _equilibrium_only(solver, model, kin) is not None

    def recruitment():
        return run_inverse_dynamics(model, kin, solver=solver).converged.all()

    stages = {
        "arm5_determinate_kinematics_ms": determinate,
        "arm5_tracking_ms": tracking,
        "arm5_inverse_dynamics_ms": equilibrium,
        "arm5_inverse_dynamics_recruitment_ms": recruitment,
    }
    samples = {k: [] for k in stages}
    for _ in range(repeats):
        for name, fn in stages.items():
            t0 = time.process_time()
            ok = fn()
            samples[name].append((time.process_time() - t0) * 1e3 / nf)
            if not ok:
                raise RuntimeError(f"{name}: not every frame converged")
    return {k: statistics.median(v) for k, v in samples.items()}


def run(quick=False):
    """Benchmark records (ms per frame) of the four arm5 stages."""
    out = stage_timings(repeats=2 if quick else 7)
    return [{"name": k, "value": v, "unit": "ms/frame"} for k, v in out.items()]
