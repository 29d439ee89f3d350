"""Does a contact patch reach the border (rim) of an open mesh? One warning per run.

Contact meshes are usually open: only the joint region is meshed (a cup, a condyle cap).
The elastic foundation (:mod:`.elastic_foundation`) loads a vertex of the vertex surface A
only when its closest point on B is not on B's rim, and A has no vertices past its own
rim. When the patch grows or slides onto a rim, the loads are truncated there: the
resultant force stops growing with penetration as it should, f^FDK gets a fold and FDK
may stall (docs/contact.md, "Open meshes"). Nothing in the results shows it, hence
:func:`warn_contact_rims`.

Rim = the edges with one incident face, computed once per mesh (:func:`rim_edges`).
A frame's patch reaches

* A's rim when a loaded vertex of A is an end of a rim edge of A;
* B's rim when the contact point c_i = y_i + d_i g_i (b's frame, m) of a loaded vertex is
  closer to a rim edge of B than ``tol_B`` = the mean rim-edge length of B, plus two grid
  spacings in grid mode (the grid has no values within about one cell of the rim).
"""

from __future__ import annotations

import warnings

import numpy as np

from .mesh import MeshWarning


def rim_edges(faces):
    """(r, 2) int vertex pairs of the edges of ``faces`` (m, 3) that have one face."""
    faces = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(e, axis=0, return_counts=True)
    return keys[counts == 1]


def _point_segment_distance(P, A, B):
    """(k,) m — distance from each point P (k, 3) to the nearest segment A[j]–B[j] (r, 3)."""
    if len(P) == 0 or len(A) == 0:
        return np.full(len(P), np.inf)
    AB = B - A  # (r, 3)
    L2 = np.maximum(np.einsum("ij,ij->i", AB, AB), 1e-300)
    AP = P[:, None, :] - A[None, :, :]  # (k, r, 3)
    t = np.clip(np.einsum("krj,rj->kr", AP, AB) / L2, 0.0, 1.0)
    D = AP - t[..., None] * AB[None]
    return np.sqrt(np.einsum("krj,krj->kr", D, D).min(axis=1))


class RimCheck:
    """The rims of one contact pair's meshes, for repeated per-frame tests.

    pair : :class:`~.elastic_foundation.ElasticFoundation`.
    """

    def __init__(self, pair):
        self.pair = pair
        A, B = pair.surface_A, pair.surface_B
        self.rim_A = np.zeros(A.n_vertices, dtype=bool)
        self.rim_A[rim_edges(A.faces).ravel()] = True
        eB = rim_edges(B.faces)
        self.seg0_B, self.seg1_B = B.vertices_B[eB[:, 0]], B.vertices_B[eB[:, 1]]
        mean_edge = float(np.linalg.norm(self.seg1_B - self.seg0_B, axis=1).mean()) if len(eB) else 0.0
        self.tol_B = mean_edge + (2.0 * pair.grid_spacing if pair.mode == "grid" else 0.0)

    @property
    def is_open(self):
        return bool(self.rim_A.any() or len(self.seg0_B))

    def at_rim(self, r_Wa, R_Wa, r_Wb, R_Wb):
        """(patch on A's rim, patch at B's rim) at the given poses (m, rotation matrices)."""
        idx, depth, g_B, y_B = self.pair.penetration(r_Wa, R_Wa, r_Wb, R_Wb)
        if idx.size == 0:
            return False, False
        on_A = bool(self.rim_A[idx].any())
        c_B = y_B + depth[:, None] * g_B  # contact points on B, b's frame
        on_B = bool((_point_segment_distance(c_B, self.seg0_B, self.seg1_B) <= self.tol_B).any())
        return on_A, on_B


def contact_rim_frames(model, q, times=None):
    """Per contact and mesh whose patch reaches the rim: (contact name, "vertices" or
    "surface", mesh name (the file as written in the model file), frame indices).

    q : (n_frames, 7 n_moving) — the poses (frames with non-finite entries are skipped)."""
    out = []
    contacts = getattr(model, "contacts", ())
    if not contacts:
        return out
    q = np.asarray(q, dtype=float)
    finite = np.flatnonzero(np.isfinite(q).all(axis=1)) if q.ndim == 2 else []
    checks = [(c, RimCheck(c.pair)) for c in contacts]
    checks = [(c, chk) for c, chk in checks if chk.is_open]
    if not checks:
        return out
    state = model.initial_state()
    hits = {(c.name, role): [] for c, _ in checks for role in ("vertices", "surface")}
    for k in finite:
        try:
            state.set_q(q[k])
        except ValueError:
            continue
        for c, chk in checks:
            a, b = c.body_a, c.body_b
            on_A, on_B = chk.at_rim(state.p_WB[a], state.R_WB[a], state.p_WB[b], state.R_WB[b])
            if on_A:
                hits[(c.name, "vertices")].append(int(k))
            if on_B:
                hits[(c.name, "surface")].append(int(k))
    for c, chk in checks:
        for role, mesh in (("vertices", chk.pair.surface_A), ("surface", chk.pair.surface_B)):
            frames = hits[(c.name, role)]
            if frames:
                out.append((c.name, role, mesh.name, frames))
    return out


def warn_contact_rims(model, kin):
    """One :class:`MeshWarning` per contact mesh whose patch reaches its rim in the run
    ``kin`` (a KinematicsResult: ``q`` (n, 7 n_moving), ``time`` (n,) s)."""
    if not getattr(model, "contacts", ()) or kin is None or len(kin.time) == 0:
        return
    for name, role, mesh, frames in contact_rim_frames(model, kin.q):
        warnings.warn(
            f"contact '{name}': the contact patch reaches the border of mesh contacts.{name}.{role} "
            f"(file {mesh}) on {len(frames)} of {len(kin.time)} frames (first at t={kin.time[frames[0]]:.3f} s); "
            "forces there are truncated (no load past an open mesh's rim): extend the mesh beyond the "
            "contact region", MeshWarning, stacklevel=2)
