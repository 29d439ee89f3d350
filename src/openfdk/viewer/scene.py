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

#: body colours (display), cycled; a visual mesh's own ``color`` wins
PALETTE = ("#4f86c6", "#e0a040", "#5aa469", "#c05050", "#8a6bbe", "#3fa7a7", "#b08968", "#7f7f7f")
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
    markers = {"names": list(model.markers.names), "body": [int(i) for i in model.markers.body],
               "p_B": np.asarray(model.markers.p_BM, dtype=float).reshape(-1, 3).tolist()}
    points.append(np.array([model.bodies[i].p_WB0 for i in range(len(model.bodies))]))
    for i, b in enumerate(bodies):
        if b["points"]:
            points.append(_world(model, i, np.array(b["points"])))
    paths, wrapped = [], []
    elements = [(el, "muscle", el.path) for el in model.muscles] + \
        [(el, "ligament", el.path) for el in model.ligaments] + [(el, "spring", el.measure) for el in model.springs]
    for el, kind, measure in elements:
        pts = _path_points(model, measure)
        if pts is not None:
            paths.append({"name": el.name, "kind": kind, "points": [[i, *p.tolist()] for i, p in pts]})
            points.append(np.array([_world(model, i, np.array([p]))[0] for i, p in pts]))
        elif (w := wrapped_measure(measure)) is not None:
            # drawn from per-frame world points (frames["wrap_points"][:, offset:offset + count])
            paths.append({"name": el.name, "kind": kind, "points": [],
                          "wrap": {"offset": sum(n_points(p) for p in wrapped), "count": n_points(w)}})
            wrapped.append(w)
            points += [_world(model, int(n[0]), np.array([n[1]])) for n in w.nodes if not hasattr(n, "kind")]
    allp = np.concatenate([np.asarray(p).reshape(-1, 3) for p in points if len(p)], axis=0)
    scale = float(np.linalg.norm(allp.max(0) - allp.min(0))) or 0.1
    data = {"bodies": bodies, "meshes": meshes, "markers": markers, "paths": paths, "contacts": contacts,
            "fdk_dofs": [d.name for d in model.fdk_dofs], "gravity": model.gravity_W.tolist(),
            "center": (0.5 * (allp.max(0) + allp.min(0))).tolist(), "scale": scale}
    return Scene(data, labels, scale, wrapped)


def _world(model, body, p_B):
    """Reference-pose world positions (k, 3) m of body-frame points p_B (k, 3)."""
    from ..spatial import rotation_matrix

    b = model.bodies[body]
    return b.p_WB0 + np.asarray(p_B).reshape(-1, 3) @ rotation_matrix(b.quat_WB0).T
