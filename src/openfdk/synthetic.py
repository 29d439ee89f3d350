"""A small synthetic two-body example: a "skull" and a "jaw" with a point-on-plane joint.

Used by the kinematics demo and benchmark and by tests. The true motion satisfies the
joint exactly: the jaw rotates about the skull's y axis by θ(t) while its condyle point
slides on a plane of the skull tilted 30° down-anteriorly; the skull itself moves a
little. Eight markers (four per body on two plates in front of the "mouth"), sampled at
``rate`` Hz with optional Gaussian noise and an optional gap.
"""

from __future__ import annotations

import numpy as np

from .spatial import quat_from_rotvec, rotation_matrix, rotation_matrix_xyz

PLANE_TILT = np.deg2rad(30.0)
CONDYLE_S = np.array([0.0, -0.05, 0.0])  # condyle top in the skull frame (m)
CONDYLE_J = CONDYLE_S.copy()  # the same point in skull-aligned coordinates when closed (m)
JAW_COM_S = np.array([0.06, 0.0, -0.03])  # jaw centre of mass in the skull frame, closed
SKULL_MARKERS = np.array([[0.12, -0.025, 0.025], [0.12, 0.025, 0.025], [0.12, -0.025, 0.0], [0.12, 0.025, 0.0]]) + [0, 0, 0.01]
JAW_MARKERS = np.array([[0.06, -0.025, -0.04], [0.06, 0.025, -0.04], [0.06, -0.025, -0.065], [0.06, 0.025, -0.065]])


def plane_axes():
    """Unit normal n and in-plane sliding direction u of the joint plane (skull frame)."""
    u = np.array([np.cos(PLANE_TILT), 0.0, -np.sin(PLANE_TILT)])
    n = np.array([np.sin(PLANE_TILT), 0.0, np.cos(PLANE_TILT)])
    return n, u


def two_body_model_dict():
    """The two-body model as a model-file mapping (mm, deg): skull (tracked, no
    equilibrium rows), jaw, point-on-plane joint, 4 markers per body. Written as YAML by
    the demo; :func:`two_body_model` builds it."""
    n, u = plane_axes()
    mm = lambda v: [round(float(x) * 1e3, 9) for x in v]  # noqa: E731
    y = np.cross(n, u)
    return {
        "openfdk": 1,
        "name": "two-body jaw",
        "units": {"length": "mm", "angle": "deg"},
        "gravity": [0.0, 0.0, -9.81],
        "bodies": {
            "skull": {
                "mass": 4.0, "inertia": [0.02, 0.02, 0.02], "equilibrium": False,
                "frames": {"plane": {"position": mm(CONDYLE_S),
                                     "orientation": {"matrix": np.column_stack([u, y, n]).round(12).tolist()}}},
                "markers": {f"S{k + 1}": mm(p) for k, p in enumerate(SKULL_MARKERS)},
            },
            "jaw": {
                "mass": 0.44, "inertia": [8.6e-4, 2.9e-4, 6.1e-4], "position": mm(JAW_COM_S),
                "frames": {"condyle": mm(CONDYLE_J - JAW_COM_S)},
                "markers": {f"J{k + 1}": mm(p - JAW_COM_S) for k, p in enumerate(JAW_MARKERS)},
            },
        },
        "joints": {"tmj": {"type": "point_on_plane", "parent": "skull.plane", "child": "jaw.condyle"}},
        "analysis": {"marker_cutoff_hz": 8.0},
    }


def two_body_model():
    """The two-body model (see :func:`two_body_model_dict`)."""
    from .model.modelfile import model_from_dict

    return model_from_dict(two_body_model_dict(), source="two_body.yaml")


def true_motion(t, frequency=1.0, opening_deg=12.0, slide=0.006):
    """Poses at times t (nf,) s: returns dict of p_W (nf, 3) and R_W (nf, 3, 3) for
    'skull' and 'jaw' (centre of mass), satisfying the point-on-plane joint exactly."""
    t = np.atleast_1d(t)
    phase = 0.5 * (1 - np.cos(2 * np.pi * frequency * t))  # 0 → 1 → 0 each cycle
    theta = np.deg2rad(opening_deg) * phase
    s = slide * phase
    _, u = plane_axes()
    out = {"skull": ([], []), "jaw": ([], [])}
    for k in range(len(t)):
        R_WS = rotation_matrix_xyz([0.02 * np.sin(0.7 * t[k]), 0.03 * np.sin(0.5 * t[k]), 0.01 * np.sin(0.3 * t[k])])
        p_WS = np.array([0.002 * np.sin(0.9 * t[k]), 0.001 * np.sin(0.4 * t[k]), 0.002 * np.sin(0.6 * t[k])])
        R_SJ = rotation_matrix(quat_from_rotvec([0.0, theta[k], 0.0]))
        c_S = CONDYLE_S + s[k] * u  # condyle slides on the plane
        # jaw origin (COM): c_S = p_SJ + R_SJ (CONDYLE_J − JAW_COM_S)
        p_SJ = c_S - R_SJ @ (CONDYLE_J - JAW_COM_S)
        out["skull"][0].append(p_WS)
        out["skull"][1].append(R_WS)
        out["jaw"][0].append(p_WS + R_WS @ p_SJ)
        out["jaw"][1].append(R_WS @ R_SJ)
    return {k: (np.array(v[0]), np.array(v[1])) for k, v in out.items()}


def synthetic_markers(n_frames=500, rate=100.0, noise=0.0, seed=0, gap=None, **motion):
    """Marker positions (n_frames, 8, 3) m, labels and times for the two-body model.

    noise : standard deviation (m) of Gaussian noise per coordinate;
    gap : optional (marker index, first frame, last frame) set to NaN (occlusion).
    """
    t = np.arange(n_frames) / rate
    poses = true_motion(t, **motion)
    pS, RS = poses["skull"]
    pJ, RJ = poses["jaw"]
    xs = pS[:, None, :] + np.einsum("fij,mj->fmi", RS, SKULL_MARKERS)
    xj = pJ[:, None, :] + np.einsum("fij,mj->fmi", RJ, JAW_MARKERS - JAW_COM_S)
    x = np.concatenate([xs, xj], axis=1)
    if noise:
        x = x + np.random.default_rng(seed).normal(scale=noise, size=x.shape)
    if gap is not None:
        m, f0, f1 = gap
        x[f0 : f1 + 1, m] = np.nan
    labels = [f"S{k + 1}" for k in range(4)] + [f"J{k + 1}" for k in range(4)]
    return t, labels, x, poses
