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
            m["tendon_slack_length"] = float(round(max(1e3 * np.linalg.norm(i - o) - spec["optimal_fibre_length"], 1.0), 6))
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


CONDYLE_RADIUS = 0.005  # m, spherical condyle head of the TMJ-like FDK test model
CARTILAGE = 0.001  # m, the paper's condyle offset for missing cartilage
LIGAMENT_ORIGINS = np.array([[0.010, -0.058, -0.004]])  # articular tubercle, right (m)
LIGAMENT_INSERTIONS = np.array([[-0.003, -0.052, -0.014], [0.0, -0.054, -0.017], [0.003, -0.052, -0.020]])


def write_jaw_meshes(directory, edge=0.0006):
    """Write the TMJ-like surfaces of :func:`jaw_fdk_model_dict` as STL files (m):
    condyle_{r,l}.stl (sphere caps, normals outward, in the subject frame at the closed
    pose) and fossa_{r,l}.stl (planar patches on the POP planes, normals down into the
    joint space). Returns the directory."""
    from pathlib import Path

    import trimesh

    from .contact.shapes import flat_patch, sphere_cap

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    for side, tag in ((-1, "r"), (1, "l")):
        n = plane_normal(side)
        top = np.array([0.0, side * HALF_WIDTH, 0.0])
        cap = sphere_cap(CONDYLE_RADIUS, np.deg2rad(70), edge, pole=n, center=top - CONDYLE_RADIUS * n)
        trimesh.Trimesh(cap.vertices_B, cap.faces, process=False).export(d / f"condyle_{tag}.stl")
        patch = flat_patch(0.024, 0.024, 2 * edge)
        R = np.array(_frame_from_normal(n)) @ np.diag([1.0, -1.0, -1.0])  # patch normal → −n
        trimesh.Trimesh(patch.vertices_B @ R.T + top, patch.faces, process=False).export(d / f"fossa_{tag}.stl")
    return d


def jaw_fdk_model_dict(mesh_dir=".", n_muscles_per_side=12, ligament_stiffness=90.8, spring=0.1):
    """The TMJ-like FDK test model (mm, deg): the POP jaw of :func:`jaw_model_dict` with
    its TMJ planes and medio-lateral constraint replaced by 3 FDK DOFs (each condyle's
    distance from its plane, the medio-lateral shift), elastic-foundation contact of
    spherical condyles (1 mm cartilage offset, 10 GN/m³) against the planes, 3 ligament
    elements per side and weak springs (0.1 N/m) on the FDK DOFs. Meshes from
    :func:`write_jaw_meshes` in ``mesh_dir`` (paths written relative to it)."""
    data = jaw_model_dict(n_muscles_per_side)
    mm = lambda v: [round(float(x) * 1e3, 9) for x in v]  # noqa: E731
    data["name"] = "synthetic FDK jaw"
    del data["joints"], data["constraints"], data["reactions"]
    skull, jaw = data["bodies"]["skull"]["frames"], data["bodies"]["mandible"]["frames"]
    ligaments, contacts = {}, {}
    for side, tag in ((-1, "r"), (1, "l")):
        flip = np.array([1.0, -1.0, 1.0]) if side == 1 else np.ones(3)
        skull[f"tubercle_{tag}"] = mm(LIGAMENT_ORIGINS[0] * flip)
        for e, p in enumerate(LIGAMENT_INSERTIONS):
            jaw[f"neck_{tag}{e + 1}"] = mm(p * flip - COM_J)
            ligaments[f"tmj_ligament_{tag}{e + 1}"] = {
                "path": [f"skull.tubercle_{tag}", f"mandible.neck_{tag}{e + 1}"],
                "stiffness": ligament_stiffness, "reference_strain": 0.0,
            }
        contacts[f"tmj_{tag}"] = {
            "vertices": {"body": "mandible", "mesh": f"{mesh_dir}/condyle_{tag}.stl", "units": "m",
                         "placement": {"position": mm(-COM_J)}, "offset": CARTILAGE * 1e3},
            "surface": {"body": "skull", "mesh": f"{mesh_dir}/fossa_{tag}.stl", "units": "m"},
            "pressure_modulus": 1.0e10,
        }
    data["measures"]["gap_r"] = {"type": "plane_distance", "plane": "skull.plane_r", "point": "mandible.condyle_r"}
    data["measures"]["gap_l"] = {"type": "plane_distance", "plane": "skull.plane_l", "point": "mandible.condyle_l"}
    data["fdk_dofs"] = {
        "tmj_r_normal": {"measure": "gap_r", "initial": 0.0},
        "tmj_l_normal": {"measure": "gap_l", "initial": 0.0},
        "ml_shift": {"measure": "ml", "component": 1, "initial": 0.0},
    }
    data["springs"] = {
        f"fdk_spring_{k}": {"measure": m, **({"component": 1} if m == "ml" else {}), "stiffness": spring}
        for k, m in (("r", "gap_r"), ("l", "gap_l"), ("ml", "ml"))
    }
    data["ligaments"] = ligaments
    data["contacts"] = contacts
    return data
