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

* A's rim when a loaded vertex of A is an end of a rim edge of A (A's patch would
  continue past its last vertices);
* B's rim when the vertices of A that are cut off by B's rim carry at least
  :data:`CUT_SHARE` of the patch's load. A vertex is cut off when its closest point c on B
  is on B's rim (:class:`~.signed_distance.OpenSurfaceDistance`), it lies within
  ``max_depth`` of c and behind the plane of the rim triangle there: depth
  e_i = −(p_i − c)·n_rim > 0, the depth it would have if B went on flat. The share cut
  off is Σ a_i e_i over cut vertices / (that + Σ a_i d_i over loaded ones) (a_i: vertex
  areas; the missing fraction of the load B would carry if it went on). This uses the exact
  distance in both modes; grid mode trims about one more cell (h) at the rim.
"""

from __future__ import annotations

import warnings

import numpy as np
from numba import njit

from .mesh import MeshWarning, undirected_edge_keys

#: share of the patch's load cut off by the opposite surface's rim above which a frame counts
CUT_SHARE = 0.05
#: the check's expected cost per frame and contact in the units the figures' drawing cost
#: is weighed in (axes, :func:`openfdk.plots.run.figure_plan`; about 54 ms each for DM's
#: body-pose figure): DM's tibiofemoral and patellofemoral pairs take 9.7 and 5.8 ms a
#: frame, 0.14 axes on average (:class:`openfdk.plots.parallel.SideJob`)
WEIGHT_PER_FRAME = 0.14
#: the k-d tree's approximation in the rim test's bound of a point's distance to B: the
#: vertex found is within (1 + eps) times the nearest's distance (any vertex gives an upper
#: bound; a looser one only leaves more points for the exact query)
NEAREST_EPS = 3.0


def rim_edges(faces, with_faces=False):
    """(r, 2) int vertex pairs of the edges of ``faces`` (m, 3) that have one face; with
    ``with_faces`` also (r,) the index of that face."""
    faces = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    # one int64 key per edge: a 1-D unique (np.unique(axis=0) took 21 ms on DM's 25k faces)
    _, first, counts = np.unique(undirected_edge_keys(e), return_index=True, return_counts=True)
    rim = first[counts == 1]  # rows of e, in the order of the sorted (lo, hi) pairs
    if with_faces:
        return e[rim], rim % len(faces)
    return e[rim]


@njit(cache=True)
def _nearest_segment(P, A, B):
    """(k,) index of the segment A[j]–B[j] (r, 3) nearest to each point P (k, 3), m (the
    first of equally near ones). One pass over the segments per point, no (k, r, 3)
    temporaries: DM's tibial insert, 452 points against 580 rim edges, 12 ms with numpy's
    broadcasting."""
    k, r = P.shape[0], A.shape[0]
    out = np.zeros(k, dtype=np.int64)
    for i in range(k):
        best = np.inf
        for j in range(r):
            ab0, ab1, ab2 = B[j, 0] - A[j, 0], B[j, 1] - A[j, 1], B[j, 2] - A[j, 2]
            ap0, ap1, ap2 = P[i, 0] - A[j, 0], P[i, 1] - A[j, 1], P[i, 2] - A[j, 2]
            t = (ap0 * ab0 + ap1 * ab1 + ap2 * ab2) / max(ab0 * ab0 + ab1 * ab1 + ab2 * ab2, 1e-300)
            t = min(max(t, 0.0), 1.0)
            d0, d1, d2 = ap0 - t * ab0, ap1 - t * ab1, ap2 - t * ab2
            d = d0 * d0 + d1 * d1 + d2 * d2
            if d < best:
                best, out[i] = d, j
    return out


class RimCheck:
    """The rims of one contact pair's meshes, for repeated per-frame tests.

    pair : :class:`~.elastic_foundation.ElasticFoundation`.
    """

    def __init__(self, pair):
        from .signed_distance import OpenSurfaceDistance

        self.pair = pair
        A, B = pair.surface_A, pair.surface_B
        self.rim_A = np.zeros(A.n_vertices, dtype=bool)
        self.rim_A[rim_edges(A.faces).ravel()] = True
        eB, fB = rim_edges(B.faces, with_faces=True)
        self.B_is_open = len(eB) > 0
        self._seg_B = (B.vertices_B[eB[:, 0]], B.vertices_B[eB[:, 1]])
        self._n_rim_B = B.face_normals_B[fB]  # (r, 3) normal of each rim edge's triangle
        self._distance_B = OpenSurfaceDistance(B) if self.B_is_open else None
        if self.B_is_open:
            from scipy.spatial import cKDTree

            # a point within max_depth of a rim point on edge (u, v) is within
            # max_depth + |uv|/2 of u or v: candidates for the exact query, found at once
            # (B's rim vertices in a k-d tree once; each frame asks it for A's vertices'
            # nearest, one vectorised query: 2.5 ms for DM's tibial insert, where a ball
            # around each rim vertex in a tree of A's vertices took 11 ms, the same set)
            self._rim_V_B = B.vertices_B[np.unique(eB.ravel())]
            self._tree_rim_B = cKDTree(self._rim_V_B)
            self._half_rim_edge = 0.5 * float(np.linalg.norm(self._seg_B[1] - self._seg_B[0], axis=1).max())
            self._rim_reach_B = pair.max_depth + self._half_rim_edge
            # every vertex of B, for an upper bound of a point's distance to B
            self._tree_V_B = cKDTree(B.vertices_B)

    @property
    def is_open(self):
        return bool(self.rim_A.any() or self.B_is_open)

    def at_rim(self, r_Wa, R_Wa, r_Wb, R_Wb):
        """(patch on A's rim: bool, share of the load cut off by B's rim: float ≥ 0) at the
        given poses (m, rotation matrices); see the module docstring."""
        idx, depth = self.pair.penetration(r_Wa, R_Wa, r_Wb, R_Wb)[:2]
        if idx.size == 0:
            return False, 0.0
        on_A = bool(self.rim_A[idx].any())
        if self._distance_B is None:
            return on_A, 0.0
        a = self.pair._a_A
        R_Wa, R_Wb = np.asarray(R_Wa, float), np.asarray(R_Wb, float)
        y = (self.pair._s_A @ R_Wa.T + np.asarray(r_Wa, float) - np.asarray(r_Wb, float)) @ R_Wb  # b's frame
        reach = self._rim_reach_B
        gap, _ = self._tree_rim_B.query(y, distance_upper_bound=reach * (1.0 + 1e-12))
        near = np.flatnonzero(gap <= reach)
        if len(near):
            # a point is cut off only if its closest point on B is on the rim, at least
            # gap − half an edge away (every rim point is within half an edge of a rim
            # vertex); a vertex of B nearer than that is a nearer point of B: no exact
            # query needed (any vertex bounds the distance, so the k-d tree's approximate
            # nearest serves). DM's tibial insert: 5 340 candidates, 850 left, 12 → 5 ms
            to_B, _ = self._tree_V_B.query(y[near], eps=NEAREST_EPS)
            near = near[to_B >= gap[near] - self._half_rim_edge]
        if len(near) == 0:
            return on_A, 0.0
        phi, _, valid, c = self._distance_B.query(y[near])
        cut = np.flatnonzero(~valid & (np.abs(phi) <= self.pair.max_depth))
        if cut.size == 0:
            return on_A, 0.0
        n = self._n_rim_B[_nearest_segment(np.ascontiguousarray(c[cut]), *self._seg_B)]
        e = -np.einsum("ij,ij->i", y[near[cut]] - c[cut], n)  # depth behind the rim triangle's plane
        behind = e > 0.0
        missing = float((a[near[cut]][behind] * e[behind]).sum())
        share = missing / max(missing + float((a[idx] * depth).sum()), 1e-300)
        return on_A, share


def contact_rim_frames(model, q, times=None):
    """Per contact and mesh whose patch reaches the rim: (contact name, "vertices" or
    "surface", mesh name (the file as written in the model file), frame indices, largest
    share of the load cut off (surface; NaN for vertices)).

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
    worst = {c.name: 0.0 for c, _ in checks}
    for k in finite:
        try:
            state.set_q(q[k])
        except ValueError:
            continue
        for c, chk in checks:
            a, b = c.body_a, c.body_b
            on_A, share = chk.at_rim(state.p_WB[a], state.R_WB[a], state.p_WB[b], state.R_WB[b])
            if on_A:
                hits[(c.name, "vertices")].append(int(k))
            if share >= CUT_SHARE:
                hits[(c.name, "surface")].append(int(k))
                worst[c.name] = max(worst[c.name], share)
    for c, chk in checks:
        for role, mesh in (("vertices", chk.pair.surface_A), ("surface", chk.pair.surface_B)):
            frames = hits[(c.name, role)]
            if frames:
                out.append((c.name, role, mesh.name, frames, worst[c.name] if role == "surface" else np.nan))
    return out


def warn_contact_rims(model, kin):
    """One :class:`MeshWarning` per contact mesh whose patch reaches its rim in the run
    ``kin`` (a KinematicsResult: ``q`` (n, 7 n_moving), ``time`` (n,) s)."""
    if not getattr(model, "contacts", ()) or kin is None or len(kin.time) == 0:
        return
    report_contact_rims(contact_rim_frames(model, kin.q), kin.time)


def report_contact_rims(hits, time):
    """The warnings of :func:`warn_contact_rims` for ``hits`` (a list as
    :func:`contact_rim_frames` returns it) of a run with frame times ``time`` (n,) s,
    each attributed to the caller's caller (:func:`warn_contact_rims`'s caller)."""
    for name, role, mesh, frames, share in hits:
        cut = f", up to {100 * share:.0f} % of the patch's load cut off" if np.isfinite(share) else ""
        warnings.warn(
            f"contact '{name}': the contact patch reaches the border of mesh contacts.{name}.{role} "
            f"(file {mesh}) on {len(frames)} of {len(time)} frames (first at t={time[frames[0]]:.3f} s); "
            f"forces there are truncated (no load past an open mesh's rim{cut}): extend the mesh beyond the "
            "contact region", MeshWarning, stacklevel=3)
