"""The moving part of a view: per-frame body poses, measured markers, element forces,
contact loads and pressures, world polylines of wrapped paths (:mod:`.wrapview`), and
the FDK side-panel series.

Poses come from kinematics.csv (``<body>.x_m … <body>.e3``); measured marker positions
are the model markers minus the residuals Ψ = p_WM(q) − x_M (kinematics.csv
``<marker>.residual_{x,y,z}_m``); forces from forces.csv. Contact pressures are not in
the tables: they are re-evaluated here (elastic foundation, docs/design.md §1) at each frame's
recorded poses, mapped onto the decimated display mesh (maximum over the vertices of a
display cluster) and quantised to 255 levels of the trial's peak pressure.
"""

from __future__ import annotations

import numpy as np

from ..numerics.spatial import rotation_matrix
from .pack import index_kind, pack
from .results import ViewError
from .wrapview import wrapped_polylines


def body_poses(model, results):
    """(nf, nb, 7) [m, -]: r_WB and Euler parameters (e0 first) of every body, fixed
    bodies at their reference pose; NaN where the kinematics gave none."""
    kin, nf = results.kinematics, results.n_frames
    out = np.empty((nf, len(model.bodies), 7))
    for i, b in enumerate(model.bodies):
        keys = [f"{b.name}.{c}_m" for c in "xyz"] + [f"{b.name}.e{j}" for j in range(4)]
        if b.column < 0 or keys[0] not in kin:
            if b.column >= 0:
                raise ViewError(f"{results.directory / 'kinematics.csv'}: no columns for body {b.name!r} of the model "
                                f"(expected {keys[0]!r}); is this the model that produced the run?")
            out[:, i, :3], out[:, i, 3:] = b.p_WB0, b.quat_WB0
            continue
        for j, k in enumerate(keys):
            if k not in kin:
                raise ViewError(f"{results.directory / 'kinematics.csv'}: column {k!r} missing")
            out[:, i, j] = kin[k]
    return out


def measured_markers(model, results, poses):
    """(nf, nm, 3) m measured marker positions x_M = p_WM(q) − Ψ, NaN in gaps; None
    when kinematics.csv has no residual columns (a determinate run)."""
    kin = results.kinematics
    names = list(model.markers.names)
    if not names or f"{names[0]}.residual_x_m" not in kin:
        return None
    nf = results.n_frames
    out = np.full((nf, len(names), 3), np.nan)
    for k, name in enumerate(names):
        cols = [f"{name}.residual_{c}_m" for c in "xyz"]
        if cols[0] not in kin:
            continue
        missing = [c for c in cols if c not in kin]
        if missing:
            raise ViewError(f"{results.directory / 'kinematics.csv'}: column {missing[0]!r} missing; the residual "
                            f"of marker {name!r} is incomplete")
        res = np.stack([kin[c] for c in cols], axis=1)
        b, p_B = int(model.markers.body[k]), model.markers.p_BM[k]
        out[:, k] = poses[:, b, :3] + np.einsum("fij,j->fi", rotations(poses[:, b, 3:]), p_B) - res
    return out


def rotations(e):
    """Rotation matrices (nf, 3, 3) of Euler parameters e (nf, 4), e0 first; NaN rows
    stay NaN (:func:`openfdk.numerics.spatial.rotation_matrix` applied to whole columns)."""
    return np.moveaxis(rotation_matrix(np.asarray(e, dtype=float).T), -1, 0)


def _col(forces, key, nf):
    v = forces.get(key)
    return np.asarray(v, dtype=float) if v is not None and not isinstance(v, list) else np.full(nf, np.nan)


def path_forces(scene, results):
    """(nf, n_paths) N (springs: N or N m) of the scene's paths, from forces.csv."""
    nf, f = results.n_frames, results.forces
    cols = []
    for p in scene.data["paths"]:
        key = f"{p['name']}.force" if p["kind"] == "spring" else f"{p['name']}.force_N"
        cols.append(_col(f, key, nf))
    return np.stack(cols, axis=1) if cols else np.zeros((nf, 0))


def contact_frames(model, scene, results, poses):
    """Per contact: force on the vertex body (nf, 3) N world and centre of pressure
    (nf, 3) m (forces.csv), and the sparse quantised pressure on the display mesh."""
    out = []
    nf, f = results.n_frames, results.forces
    for c, lab in zip(model.contacts, scene.contact_labels):
        F = np.stack([_col(f, f"{c.name}.F{a}_N", nf) for a in "xyz"], axis=1)
        cop = np.stack([_col(f, f"{c.name}.cop_{a}_m", nf) for a in "xyz"], axis=1)
        n_disp = int(lab.max()) + 1
        per_frame = []
        for k in range(nf):
            qa, qb = poses[k, c.body_a], poses[k, c.body_b]
            if not (np.all(np.isfinite(qa)) and np.all(np.isfinite(qb))):
                per_frame.append((np.zeros(0, int), np.zeros(0)))
                continue
            res = c.pair.evaluate(qa[:3], rotation_matrix(qa[3:]), qb[:3], rotation_matrix(qb[3:]),
                                  want_vertex_pressure=True)
            disp = np.zeros(n_disp)
            np.maximum.at(disp, lab, res.vertex_pressure)
            idx = np.flatnonzero(disp > 0)
            per_frame.append((idx, disp[idx]))
        p_max = max((float(p.max()) for _, p in per_frame if len(p)), default=0.0)
        offsets = np.cumsum([0] + [len(i) for i, _ in per_frame])
        idx = np.concatenate([i for i, _ in per_frame]) if offsets[-1] else np.zeros(0, int)
        lev = np.concatenate([p for _, p in per_frame]) if offsets[-1] else np.zeros(0)
        level = np.clip(np.ceil(255 * lev / p_max), 1, 255) if p_max > 0 else np.zeros(0)
        out.append({"force": pack(F), "cop": pack(cop), "p_max": p_max, "offsets": pack(offsets, "u32"),
                    "index": pack(idx, index_kind(n_disp)), "level": pack(level, "u8")})
    return out


def _run_table(results, name):
    """The columns of the run folder's table ``name`` (grf.csv, joint_loads.csv), or None
    without it or when its rows are not the run's frames."""
    from pathlib import Path

    from ..io.results import read_table

    folder = getattr(results, "directory", None)
    if folder is None or not (Path(folder) / name).is_file():
        return None
    data = read_table(Path(folder) / name)
    if getattr(results, "span", None) is not None and "time" in data:  # a window of the run: its rows within
        keep = results.within_span(data["time"])
        data = {k: (np.asarray(v)[keep] if not isinstance(v, list) else [x for x, k2 in zip(v, keep) if k2])
                for k, v in data.items()}
    return data if len(data["time"]) == results.n_frames else None


#: a measured load below this force (N) is drawn as unloaded (the plates' threshold_n)
UNLOADED_N = 20.0


def external_load_frames(results):
    """Per measured load of the run (forces.csv ``<load>.external_F?_N`` and
    ``_p?_m``, as applied: an ExternalLoads file's forces): the force (nf, 3) N and its
    point (nf, 3) m, world; NaN where it is below :data:`UNLOADED_N` or the frame has
    none. [] without such columns."""
    forces = getattr(results, "forces", None) or {}
    suffix = ".external_Fx_N"
    out = []
    for name in sorted(c[: -len(suffix)] for c in forces if c.endswith(suffix)):
        columns = [f"{name}.external_F{a}_N" for a in "xyz"] + [f"{name}.external_p{a}_m" for a in "xyz"]
        if not all(c in forces for c in columns):
            continue
        values = np.stack([np.asarray(forces[c], float) for c in columns], axis=1)
        F, P = values[:, :3].copy(), values[:, 3:].copy()
        with np.errstate(invalid="ignore"):
            off = ~(np.linalg.norm(F, axis=1) >= UNLOADED_N)
        F[off], P[off] = np.nan, np.nan
        out.append({"name": name, "force": pack(F), "cop": pack(P)})
    return out


def grf_frames(results):
    """Per force plate of the run's ``grf.csv`` (ground reactions applied to the model):
    the force on the subject (nf, 3) N and its centre of pressure (nf, 3) m, world; NaN
    where the plate is unloaded. Without grf.csv (or when its rows are not the run's),
    the measured loads of forces.csv (:func:`external_load_frames`)."""
    data = _run_table(results, "grf.csv")
    if data is None:
        return external_load_frames(results)
    out = []
    for name in sorted({k.split(".")[0] for k in data if k.endswith("_N") and ".F" in k}):
        F = np.stack([np.asarray(data[f"{name}.F{a}_N"], float) for a in "xyz"], axis=1)
        cop = np.stack([np.asarray(data[f"{name}.cop{a}_m"], float) for a in "xyz"], axis=1)
        out.append({"name": name, "force": pack(F), "cop": pack(cop)})
    return out


def joint_load_frames(results):
    """Per joint of the run's ``joint_loads.csv`` (an OpenSim model's joints, as OpenSim's
    JointReaction reports them): the force on the joint's child body (nf, 3) N, world, and
    the joint's child frame origin (nf, 3) m, where the arrow starts; NaN on failed
    frames. [] without joint_loads.csv or when its rows are not the run's."""
    from ..io.joint_load_outputs import joint_load_bases

    data = _run_table(results, "joint_loads.csv")
    if data is None:
        return []
    out = []
    for base in joint_load_bases(list(data))[0]:  # in the ground, not the joint_reaction reports
        F = np.stack([np.asarray(data[f"{base}_f{a}"], float) for a in "xyz"], axis=1)
        P = np.stack([np.asarray(data[f"{base}_p{a}"], float) for a in "xyz"], axis=1)
        out.append({"name": base.rsplit("_on_", 1)[0], "force": pack(F), "cop": pack(P)})
    return out


def reaction_frames(model, results, poses):
    """Per one-sided reaction on a point_on_plane joint (the POP model's TMJ contacts): the
    force on the child body (nf, 3) N, world, and its point of application (nf, 3) m, the
    child's point on the plane, so that POP and FDK runs compare by eye. The reaction f
    (forces.csv ``<name>.reaction``) acts along ``direction`` × the plane normal n_W (the
    row n·(p_child − p_parent), in the parent frame, has the gradient n_W on the child's
    point). [] when the model has none."""
    from ..model.measures import Linear, RelativeVector

    out = []
    nf, f = results.n_frames, results.forces
    by_name = {c.name: c for c in model.constraints}
    for u in model.unilateral_reactions:
        c = by_name.get(u.constraint)
        if c is None or c.joint_type != "point_on_plane" or not isinstance(c.measure, Linear):
            continue
        C, rel = c.measure.terms[0]
        a = np.asarray(C, float)[u.row]
        if isinstance(rel, Linear):  # a parent frame turned in its body: n_B = R_BF a
            RT, rel = rel.terms[0]
            a = np.asarray(RT, float).T @ a
        if not isinstance(rel, RelativeVector) or rel.frame is None:
            continue
        k, child = rel.frame, rel.point_b
        mag = _col(f, f"{u.name}.reaction", nf)
        F, P = np.full((nf, 3), np.nan), np.full((nf, 3), np.nan)
        for i in range(nf):
            qk, qc = poses[i, k], poses[i, child.body]
            if not (np.all(np.isfinite(qk)) and np.all(np.isfinite(qc)) and np.isfinite(mag[i])):
                continue
            F[i] = u.direction * mag[i] * (rotation_matrix(qk[3:]) @ a)
            P[i] = qc[:3] + rotation_matrix(qc[3:]) @ child.p_BP
        out.append({"name": u.name, "force": pack(F), "cop": pack(P)})
    return out


def panel_series(model, results, measured, scene_paths=()):
    """Side-panel series: FDK α (mm or deg) and residual f^FDK (N or N m) per DOF, the
    forces of springs that are not drawn as paths, FDK convergence and iterations, kinematics/forces convergence, marker RMS residual (mm).
    Each {"name", "unit", "values": packed (nf,), "flag": bool for 0/1 series}."""
    nf, kin, f = results.n_frames, results.kinematics, results.forces
    series = []
    for d in model.fdk_dofs:
        angle = d.measure.units[0] == "angle"
        series.append({"name": f"{d.name} α", "unit": "deg" if angle else "mm",
                       "values": pack(_col(f, f"fdk.{d.name}.alpha", nf) * (180 / np.pi if angle else 1e3))})
        series.append({"name": f"{d.name} residual", "unit": "N m" if angle else "N",
                       "values": pack(_col(f, f"fdk.{d.name}.residual", nf))})
    drawn = {p["name"] for p in scene_paths}
    for el in model.springs:  # springs on measures that are not paths (e.g. FDK DOF springs)
        if el.name not in drawn and f"{el.name}.force" in f:
            unit = {"m": "N", "rad": "N m"}.get(getattr(el.law, "unit", ""), "")
            series.append({"name": f"spring {el.name}", "unit": unit, "values": pack(_col(f, f"{el.name}.force", nf))})
    for key, name in (("fdk_converged", "FDK converged"), ("fdk_iterations", "FDK iterations")):
        if key in f:
            series.append({"name": name, "unit": "", "values": pack(_col(f, key, nf)), "flag": key.endswith("converged")})
    series.append({"name": "kinematics converged", "unit": "", "values": pack(_col(kin, "converged", nf)), "flag": True})
    if f:
        series.append({"name": "forces converged", "unit": "", "values": pack(_col(f, "converged", nf)), "flag": True})
    if measured is not None:
        names = list(model.markers.names)
        res = np.stack([np.stack([_col(kin, f"{m}.residual_{c}_m", nf) for c in "xyz"], axis=1) for m in names], axis=1)
        sq = np.sum(res ** 2, axis=2)
        n_seen = np.sum(np.isfinite(sq), axis=1)
        rms = np.full(nf, np.nan)
        rms[n_seen > 0] = np.sqrt(np.nansum(sq[n_seen > 0], axis=1) / n_seen[n_seen > 0]) * 1e3
        series.append({"name": "marker RMS residual", "unit": "mm", "values": pack(rms)})
    return series


def failed_frames(results):
    """[(frame, message)] of frames whose kinematics or forces failed (from the tables)."""
    out = {}
    for table in (results.kinematics, results.forces):
        if not table or "converged" not in table:
            continue
        msgs = table.get("message") if isinstance(table.get("message"), list) else [""] * results.n_frames
        for k in np.flatnonzero(np.asarray(table["converged"]) == 0):
            out.setdefault(int(k), msgs[k] or f"frame {k} did not converge")
    return sorted(out.items())


#: frames sampled (evenly, first and last included) for the bounds of body geometry
BOUNDS_FRAMES = 400


def motion_bounds(scene, poses, measured=None, wrap_points=None):
    """{"min", "max"} (3,) m world bounding box of what moves over the whole trial: the
    origins of the moving bodies at every frame, their geometry (``scene.hull_B``: mesh
    vertices, markers, points; at ≤ BOUNDS_FRAMES evenly spaced frames), the measured
    markers and wrapped-path points. Fixed bodies count only when no body moves. NaN
    frames (failed kinematics) are skipped; None when no frame has a pose."""
    poses = np.asarray(poses, float)
    nf = len(poses)
    moving = [i for i, b in enumerate(scene.data["bodies"]) if not b["fixed"]] or list(range(poses.shape[1]))
    chunks = [poses[:, moving, :3].reshape(-1, 3)]
    sample = np.unique(np.linspace(0, nf - 1, min(nf, BOUNDS_FRAMES)).round().astype(int)) if nf else []
    for i in moving:
        hull = scene.hull_B[i] if i < len(scene.hull_B) else np.zeros((1, 3))
        q = poses[sample, i]
        chunks.append((q[:, None, :3] + np.einsum("fij,kj->fki", rotations(q[:, 3:]), hull)).reshape(-1, 3))
    for extra in (measured, wrap_points):
        if extra is not None and np.size(extra):
            chunks.append(np.asarray(extra, float).reshape(-1, 3))
    allp = np.concatenate(chunks)
    allp = allp[np.all(np.isfinite(allp), axis=1)]
    if not len(allp):
        return None
    return {"min": allp.min(0).tolist(), "max": allp.max(0).tolist()}


#: a force arrow's length for the largest force of its kind over the trial, × scene scale
ARROW_FRACTION = 0.35


def arrow_scale(items, scale):
    """{"fmax": N, "length_m": m} of force arrows (packed (nf, 3) N "force" of each item):
    the largest force magnitude over the trial and the arrow length that stands for it
    (ARROW_FRACTION × the model's size ``scale``); None without items or force."""
    from .pack import unpack

    f = [np.linalg.norm(unpack(c["force"]).astype(float).reshape(-1, 3), axis=1) for c in items]
    f = np.concatenate(f) if f else np.zeros(0)
    f = f[np.isfinite(f)]
    if not len(f) or f.max() <= 0:
        return None
    return {"fmax": float(f.max()), "length_m": ARROW_FRACTION * float(scale)}


def build_frames(model, scene, results):
    """JSON-able per-frame data of the view (see the module docstring)."""
    poses = body_poses(model, results)
    measured = measured_markers(model, results, poses)
    forces = path_forces(scene, results)
    wrap = wrapped_polylines(model, scene.wrapped, poses)
    with np.errstate(invalid="ignore"):
        fmax = [float(np.nanmax(np.abs(forces[:, j]))) if np.any(np.isfinite(forces[:, j])) else 0.0
                for j in range(forces.shape[1])]
    contacts, grf = contact_frames(model, scene, results, poses), grf_frames(results)
    reactions = reaction_frames(model, results, poses)
    joint_loads = joint_load_frames(results)
    return {
        "time": pack(results.time),
        "poses": pack(poses),
        "measured": pack(measured) if measured is not None else None,
        "path_force": pack(forces), "path_fmax": fmax,
        "wrap_points": pack(wrap),
        "bounds": motion_bounds(scene, poses, measured, wrap),
        "contacts": contacts, "grf": grf, "reactions": reactions, "joint_loads": joint_loads,
        "arrow_scale": {"contact": arrow_scale(contacts, scene.scale), "grf": arrow_scale(grf, scene.scale),
                        "reaction": arrow_scale(reactions, scene.scale),
                        "joint_load": arrow_scale(joint_loads, scene.scale)},
        "panel": panel_series(model, results, measured, scene.data["paths"]),
        "failed": failed_frames(results),
    }
