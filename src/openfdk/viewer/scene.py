"""The static part of a view, from the model: bodies, display meshes, markers and the
attachment points of force elements (all in body frames, m).

What moves is computed in the page from the body poses of each frame:
``p_W = r_WB + R_WB p_B`` for every mesh vertex, marker and path point.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.measures import Distance, Linear
from ..model.visuals import visual_mesh_B
from .decimate import decimate
from .pack import index_kind, pack
from .results import ViewError
from .wrapview import n_points, wrapped_measure

#: body colours (display: origin dot, sticks, default visual-mesh colour), cycled: neutral
#: greys, so that no body reads as a hue of the force colour scale; a visual mesh's own
#: ``color`` wins
PALETTE = ("#5c5c5c", "#8a8a8a", "#707070", "#a3a3a3", "#4a4a4a", "#7d7d7d", "#969696", "#636363")
CONTACT_COLOR = "#d9d4c7"
MAX_MESH_VERTICES = 4000


@dataclass
class Scene:
    """JSON-able static scene and, per contact, the display cluster of every vertex of
    its vertex surface (to map pressures); ``scale`` m is the scene size."""

    data: dict
    contact_labels: list = field(default_factory=list)
    scale: float = 0.1
    #: the WrappedPath of every scene path drawn from per-frame world points, in order
    wrapped: list = field(default_factory=list)
    #: per body, a few body-frame points (k, 3) m spanning its geometry (mesh vertices,
    #: markers, named points, path points): with the poses, the motion's bounds
    hull_B: list = field(default_factory=list)


def _mesh_entry(vertices_B, faces, body, kind, name, color, max_vertices):
    v, f, labels = decimate(vertices_B, faces, max_vertices)
    return {"body": body, "kind": kind, "name": name, "color": color,
            "vertices": pack(v, "f32"), "faces": pack(f, index_kind(len(v)))}, labels, v


def _path_points(model, measure):
    """[(body index, p_B (3,) m), ...] of a chain-of-segments measure, or None."""
    terms = measure.terms if isinstance(measure, Linear) else [(np.ones((1, 1)), measure)]
    pts = []
    for C, m in terms:
        if not isinstance(m, Distance) or C.shape != (1, 1) or C[0, 0] != 1.0:
            return None
        a, b = m.vector.point_a, m.vector.point_b
        ends = [(int(a.body), a.p_BP), (int(b.body), b.p_BP)]
        if pts and (pts[-1][0] != ends[0][0] or not np.allclose(pts[-1][1], ends[0][1])):
            return None
        pts += ends[1:] if pts else ends
    return pts


def build_scene(model, max_vertices=MAX_MESH_VERTICES):
    """Scene of ``model``: bodies (name, fixed, colour, reference pose), meshes (contact
    surfaces and visual meshes (read by :func:`~openfdk.model.visuals.visual_mesh_B`:
    STL, VTP, OBJ or PLY, with their scale and placement), decimated to ≤ max_vertices), markers (body, p_BM),
    paths (muscles, ligaments, path springs: body points; wrapped paths: a slice of the
    per-frame world points, see :mod:`.wrapview`), contacts (vertex-surface mesh
    index) and the FDK DOF names. Raises ViewError naming a visual mesh that cannot be
    read."""
    bodies = [{"name": b.name, "fixed": bool(b.fixed or b.column < 0), "color": PALETTE[k % len(PALETTE)],
               "p0": b.p_WB0.tolist(), "q0": b.quat_WB0.tolist(),
               "points": [f.p_BF.tolist() for f in model.frames.values() if f.body == b.name and np.any(f.p_BF)]}
              for k, b in enumerate(model.bodies)]
    meshes, contacts, labels, points = [], [], [], []
    geometry_B = [[np.zeros((1, 3))] + ([np.array(b["points"])] if b["points"] else []) for b in bodies]
    for c in model.contacts:
        pair = c.pair
        entry_a, lab, va = _mesh_entry(pair.surface_A.vertices_B, pair.surface_A.faces, c.body_a, "contact",
                                       f"{c.name} ({pair.surface_A.name})", CONTACT_COLOR, max_vertices)
        entry_b, _, vb = _mesh_entry(pair.surface_B.vertices_B, pair.surface_B.faces, c.body_b, "contact",
                                     f"{c.name} ({pair.surface_B.name})", CONTACT_COLOR, max_vertices)
        contacts.append({"name": c.name, "mesh": len(meshes), "body_a": c.body_a, "body_b": c.body_b})
        meshes += [entry_a, entry_b]
        labels.append(lab)
        points += [_world(model, c.body_a, va), _world(model, c.body_b, vb)]
        geometry_B[c.body_a].append(va)
        geometry_B[c.body_b].append(vb)
    for vis in model.visuals:
        try:
            vertices_B, faces = visual_mesh_B(vis)   # .stl, .vtp, .obj, .ply; units, scale, placement
        except ValueError as exc:
            raise ViewError(f"{model.source}: {vis.entry}.mesh: {exc}") from None
        body = model.body(vis.body).index
        entry, _, v = _mesh_entry(vertices_B, faces, body, "visual", vis.entry,
                                  vis.color or bodies[body]["color"], max_vertices)
        meshes.append(entry)
        points.append(_world(model, body, v))
        geometry_B[body].append(v)
    markers = {"names": list(model.markers.names), "body": [int(i) for i in model.markers.body],
               "p_B": np.asarray(model.markers.p_BM, dtype=float).reshape(-1, 3).tolist()}
    for i, p_B in zip(markers["body"], markers["p_B"]):
        geometry_B[i].append(np.array([p_B]))
    points.append(np.array([model.bodies[i].p_WB0 for i in range(len(model.bodies))]))
    for i, b in enumerate(bodies):
        if b["points"]:
            points.append(_world(model, i, np.array(b["points"])))
    paths, wrapped, drawn = [], [], []
    elements = [(el, "muscle", el.path) for el in model.muscles] + \
        [(el, "ligament", el.path) for el in model.ligaments] + [(el, "spring", el.measure) for el in model.springs]
    for el, kind, measure in elements:
        pts = _path_points(model, measure)
        if pts is not None:
            paths.append({"name": el.name, "kind": kind, "points": [[i, *p.tolist()] for i, p in pts]})
            drawn.append(el)
            points.append(np.array([_world(model, i, np.array([p]))[0] for i, p in pts]))
            for i, p in pts:
                geometry_B[i].append(np.array([p]))
        elif (w := wrapped_measure(measure)) is not None:
            # drawn from per-frame world points (frames["wrap_points"][:, offset:offset + count])
            paths.append({"name": el.name, "kind": kind, "points": [],
                          "wrap": {"offset": sum(n_points(p) for p in wrapped), "count": n_points(w)}})
            drawn.append(el)
            wrapped.append(w)
            points += [_world(model, int(n[0]), np.array([n[1]])) for n in w.nodes if not hasattr(n, "kind")]
    allp = np.concatenate([np.asarray(p).reshape(-1, 3) for p in points if len(p)], axis=0)
    scale = float(np.linalg.norm(allp.max(0) - allp.min(0))) or 0.1
    path_widths(paths, drawn, scale)
    data = {"bodies": bodies, "meshes": meshes, "markers": markers, "paths": paths, "contacts": contacts,
            "wrap_surfaces": wrap_surfaces(wrapped, scale),
            "fdk_dofs": [d.name for d in model.fdk_dofs], "gravity": model.gravity_W.tolist(),
            "center": (0.5 * (allp.max(0) + allp.min(0))).tolist(), "scale": scale}
    hull = [extreme_points(np.concatenate([np.asarray(g, float).reshape(-1, 3) for g in geo])) for geo in geometry_B]
    return Scene(data, labels, scale, wrapped, hull)


def wrap_surfaces(wrapped, scale):
    """The wrapping surfaces the drawn paths use, once each: {name, kind, body, p_BS (3,)
    m, R_BS (3, 3) row-major, dims (3,) m (radius ×3 or semi-axes), length m (a
    cylinder's drawn length: 4 radii, at most 0.3 × the scene scale; the surface is
    infinite along its z)}. Drawn semi-transparent on their bodies."""
    out, seen = [], set()
    for w in wrapped:
        for node in w.nodes:
            if not hasattr(node, "kind") or node.name in seen:
                continue
            seen.add(node.name)
            dims = np.asarray(node.dims, float)
            out.append({"name": node.name, "kind": node.kind, "body": int(node.body),
                        "p_BS": np.asarray(node.p_BS, float).tolist(), "R_BS": np.asarray(node.R_BS, float).tolist(),
                        "dims": dims.tolist(), "length": float(min(4.0 * dims[0], 0.3 * scale))})
    return out


#: tube radius of a path, × scene scale: the weakest … strongest of its kind (∝ √strength)
TUBE_RADIUS = (0.0025, 0.009)


def strength(element):
    """(value, unit) of a force element's strength: a muscle's maximum isometric force
    (or constant strength), N; a ligament's stiffness, N/m; (None, "") otherwise."""
    law = getattr(element, "law", None)
    for attr, unit in (("max_isometric_force", "N"), ("strength", "N"), ("stiffness", "N/m")):
        v = getattr(law, attr, None)
        if isinstance(v, (int, float)) and np.isfinite(v):
            return float(v), unit
    return None, ""


def path_widths(paths, elements, scale):
    """Set each path's "strength", "strength_unit" and tube "radius_m": TUBE_RADIUS × scale,
    from the smallest (weakest) to the largest (the strongest of its kind), ∝ √strength;
    the smallest without a strength."""
    vals = [strength(el) for el in elements]
    top = {}
    for p, (v, _u) in zip(paths, vals):
        if v is not None and v > 0:
            top[p["kind"]] = max(top.get(p["kind"], 0.0), v)
    lo, hi = TUBE_RADIUS
    for p, (v, u) in zip(paths, vals):
        frac = np.sqrt(v / top[p["kind"]]) if v is not None and v > 0 else 0.0
        p.update({"strength": v, "strength_unit": u, "radius_m": scale * (lo + (hi - lo) * float(frac))})


def _directions():
    """The 26 directions of a 3 × 3 × 3 grid and 24 more (unit vectors)."""
    g = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)],
                 float)
    extra = np.array([[a, b, 0.0] for a in (-2, 2) for b in (-1, 1)] + [[b, a, 0.0] for a in (-2, 2) for b in (-1, 1)]
                     + [[a, 0.0, b] for a in (-2, 2) for b in (-1, 1)] + [[b, 0.0, a] for a in (-2, 2) for b in (-1, 1)]
                     + [[0.0, a, b] for a in (-2, 2) for b in (-1, 1)] + [[0.0, b, a] for a in (-2, 2) for b in (-1, 1)])
    d = np.concatenate([g, extra])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def extreme_points(p_B):
    """The points of p_B (k, 3) that are extreme along 50 directions (≤ 50 points): a
    small set whose rotated bounding box is close to that of all the points."""
    p_B = np.asarray(p_B, float).reshape(-1, 3)
    p_B = p_B[np.all(np.isfinite(p_B), axis=1)]
    if len(p_B) <= 50:
        return p_B
    return p_B[np.unique(np.argmax(p_B @ _directions().T, axis=0))]


def _world(model, body, p_B):
    """Reference-pose world positions (k, 3) m of body-frame points p_B (k, 3)."""
    from ..numerics.spatial import rotation_matrix

    b = model.bodies[body]
    return b.p_WB0 + np.asarray(p_B).reshape(-1, 3) @ rotation_matrix(b.quat_WB0).T
