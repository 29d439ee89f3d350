"""A synthetic two-sided jaw model for benchmarks and tests of the inverse dynamics:
skull (tracked, no equilibrium rows) and mandible held by two point-on-plane TMJs (planes
30° down-anteriorly, 5° medial cant; paper/DESIGN.md §2) and a medio-lateral constraint,
24 Hill-type muscles from the packaged reference table (de Zee et al. 2007; tendon slack
lengths calibrated so that fibres are optimal in the closed pose), push-only
20 kN TMJ reactions, cubic recruitment, 4 brace markers per body.

The true motion used by :func:`jaw_markers` is a symmetric open–close (rotation about y
plus a slide of both condyles along the planes' common down-anterior direction), which
satisfies both plane constraints and the medio-lateral constraint exactly.
"""

from __future__ import annotations

from importlib import resources

import numpy as np
import yaml

from .spatial import quat_from_rotvec, rotation_matrix

HALF_WIDTH = 0.0495  # m, half the intercondylar distance (99 mm)
TILT, CANT = np.deg2rad(30.0), np.deg2rad(5.0)
COM_J = np.array([0.045, 0.0, -0.050])  # mandible centre of mass, closed pose (m)
BRACE = 0.025  # half-size of the 50 mm brace plates (m)
SKULL_BRACE = np.array([[0.13, -BRACE, 0.035], [0.13, BRACE, 0.035], [0.13, -BRACE, 0.01], [0.13, BRACE, 0.01]])
JAW_BRACE = np.array([[0.12, -BRACE, -0.045], [0.12, BRACE, -0.045], [0.12, -BRACE, -0.07], [0.12, BRACE, -0.07]])


def muscle_table():
    """The packaged right-side muscle table (mm, N) as a dict."""
    text = resources.files("openfdk").joinpath("data/mandible/muscles.yaml").read_text()
    return yaml.safe_load(text)


def plane_normal(side):
    """Unit normal of a TMJ plane (pointing up, out of the joint space into the skull):
    tilted 30° about y (down-anteriorly) and canted 5° medially. side = +1 left, −1 right."""
    n = np.array([np.sin(TILT), 0.0, np.cos(TILT)])
    # cant about the x axis: the normal leans medially (toward the mid-sagittal plane)
    c, s = np.cos(CANT), np.sin(CANT)
    return np.array([n[0], -side * s * n[2], c * n[2]])


def slide_direction():
    """Down-anterior unit direction lying in both planes."""
    return np.array([np.cos(TILT), 0.0, -np.sin(TILT)])


def _frame_from_normal(n):
    u = slide_direction()
    u = u - (u @ n) * n
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(n, u), n]).round(12).tolist()


def jaw_model_dict(n_muscles_per_side=12):
    """Model-file mapping (mm, deg) of the synthetic POP-type jaw."""
    mm = lambda v: [round(float(x) * 1e3, 9) for x in v]  # noqa: E731
    table = muscle_table()
    defaults = table.get("defaults", {})
    skull_frames, jaw_frames, muscles = {}, {}, {}
    for side, tag in ((-1, "r"), (1, "l")):
        c = np.array([0.0, side * HALF_WIDTH, 0.0])
        skull_frames[f"plane_{tag}"] = {"position": mm(c), "orientation": {"matrix": _frame_from_normal(plane_normal(side))}}
        jaw_frames[f"condyle_{tag}"] = mm(c - COM_J)
        for k, (name, spec) in enumerate(table["muscles"].items()):
            if k >= n_muscles_per_side:
                break
            flip = np.array([1.0, -1.0, 1.0]) if side == 1 else np.ones(3)  # left mirrors y
            o = np.array(spec["origin"]) * flip * 1e-3
            i = np.array(spec["insertion"]) * flip * 1e-3
            skull_frames[f"{name}_o_{tag}"] = mm(o)
            jaw_frames[f"{name}_i_{tag}"] = mm(i - COM_J)
            m = {key: spec[key] for key in ("max_isometric_force", "optimal_fibre_length")}
            m.update({key: v for key, v in defaults.items()})
            # calibration (as AnyBody's 3-element model): the tendon slack length is set
            # so that the fibres are at their optimal length in the closed reference pose
            m["tendon_slack_length"] = round(max(1e3 * np.linalg.norm(i - o) - spec["optimal_fibre_length"], 1.0), 6)
            muscles[f"{name}_{tag}"] = {"path": [f"skull.{name}_o_{tag}", f"mandible.{name}_i_{tag}"], **m}
    jaw_frames["ml_point"] = mm(-COM_J)
    return {
        "openfdk": 1,
        "name": "synthetic POP jaw",
        "units": {"length": "mm", "angle": "deg"},
        "bodies": {
            "skull": {"mass": 4.0, "inertia": [0.02, 0.02, 0.02], "equilibrium": False, "frames": skull_frames,
                      "markers": {f"S{k + 1}": mm(p) for k, p in enumerate(SKULL_BRACE)}},
            "mandible": {"mass": 0.44, "inertia": [8.6e-4, 2.9e-4, 6.1e-4], "position": mm(COM_J), "frames": jaw_frames,
                         "markers": {f"J{k + 1}": mm(p - COM_J) for k, p in enumerate(JAW_BRACE)}},
        },
        "measures": {"ml": {"type": "vector", "from": "skull.origin", "to": "mandible.ml_point", "expressed_in": "skull"}},
        "joints": {
            "tmj_r": {"type": "point_on_plane", "parent": "skull.plane_r", "child": "mandible.condyle_r"},
            "tmj_l": {"type": "point_on_plane", "parent": "skull.plane_l", "child": "mandible.condyle_l"},
        },
        "constraints": {"ml": {"measure": "ml", "components": [1]}},
        "muscles": muscles,
        # the plane normals point into the skull: the skull pushes the condyle along −n
        "reactions": {
            "tmj_r_contact": {"joint": "tmj_r", "direction": "pull", "strength": 20000},
            "tmj_l_contact": {"joint": "tmj_l", "direction": "pull", "strength": 20000},
        },
        "recruitment": {"criterion": "polynomial", "power": 3},
        "analysis": {"marker_cutoff_hz": 8.0},
    }


def jaw_true_motion(t, frequency=0.8, opening_deg=8.0, slide=0.003):
    """Skull and mandible poses (p_W (nf, 3) m, R_W (nf, 3, 3)) of a symmetric open–close."""
    t = np.atleast_1d(t)
    phase = 0.5 * (1 - np.cos(2 * np.pi * frequency * t))
    u = slide_direction()
    poses = {"skull": ([], []), "mandible": ([], [])}
    for k in range(len(t)):
        R_WS = rotation_matrix(quat_from_rotvec([0.01 * np.sin(0.7 * t[k]), 0.02 * np.sin(0.5 * t[k]), 0.0]))
        p_WS = np.array([0.001 * np.sin(0.9 * t[k]), 0.0, 0.001 * np.sin(0.6 * t[k])])
        R_SJ = rotation_matrix(quat_from_rotvec([0.0, np.deg2rad(opening_deg) * phase[k], 0.0]))
        c_R = np.array([0.0, -HALF_WIDTH, 0.0])
        p_SJ = c_R + slide * phase[k] * u - R_SJ @ (c_R - COM_J)
        poses["skull"][0].append(p_WS)
        poses["skull"][1].append(R_WS)
        poses["mandible"][0].append(p_WS + R_WS @ p_SJ)
        poses["mandible"][1].append(R_WS @ R_SJ)
    return {k: (np.array(a), np.array(b)) for k, (a, b) in poses.items()}


def jaw_markers(n_frames=500, rate=100.0, noise=0.0, seed=0):
    """(t, labels, x (nf, 8, 3) m, truth poses) of the symmetric open–close."""
    t = np.arange(n_frames) / rate
    poses = jaw_true_motion(t)
    pS, RS = poses["skull"]
    pJ, RJ = poses["mandible"]
    xs = pS[:, None] + np.einsum("fij,mj->fmi", RS, SKULL_BRACE)
    xj = pJ[:, None] + np.einsum("fij,mj->fmi", RJ, JAW_BRACE - COM_J)
    x = np.concatenate([xs, xj], axis=1)
    if noise:
        x = x + np.random.default_rng(seed).normal(scale=noise, size=x.shape)
    return t, [f"S{k + 1}" for k in range(4)] + [f"J{k + 1}" for k in range(4)], x, poses
