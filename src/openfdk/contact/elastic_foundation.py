"""Elastic-foundation contact between two triangle meshes (docs/design.md §1; Andersen et al. 2017).

A pair couples a *vertex surface* A on body a with an *opposite surface* B on body b.
For every vertex i of A at p_W = r_Wa + R_Wa s_i (s_i in a's frame):

    d_i = −φ_B(y_i),  y_i = R_Wbᵀ (p_W − r_Wb)       penetration depth behind B (m)
    v_i = a_i d_i                                     penetration volume (a_i: tributary area)
    f_i = p v_i n_i,  n_i = R_Wb ∇φ_B(y_i)            force on a, along B's outward normal

with p the pressure modulus (N/m³; 10 GN/m³ in the paper). A vertex contributes only when
0 < d_i ≤ max_depth and its closest point on B is not on B's boundary rim (meshes are
open: a point beyond the rim is neither in front of nor behind B; a point deeper than
max_depth is taken to be far behind B, e.g. behind the opposite side of a bone, and is
ignored — choose max_depth well above the expected penetration). The force on b is −f_i
along the same line of action (through p_W and its closest point on B), so the pair
exerts no net moment. The loads derive from the elastic energy
U = ½ Σ p a_i d_i², f_i = −∂U/∂p_W (exact mode; to interpolation accuracy in grid mode).

Generalized forces (common brief): Q = [F_a; M_a; F_b; M_b] with forces in world and
moments about each body's centre of mass in its body frame:
    Q_a = Σ p a_i d_i [n_i; s_i × (R_Waᵀ n_i)],   Q_b = Σ p a_i d_i [−n_i; −y_i × g_i],
g_i = ∇φ_B(y_i) in b's frame. Equivalently Q = −Σ p a_i d_i (∂d_i/∂q̂)ᵀ.

Stiffness K = ∂Q/∂q̂ (12×12) for q̂ = [δr_a, δπ_a, δr_b, δπ_b]: per vertex, with
u_i = [n; s×n_A; −n; −y×g] (so ∂d_i/∂q̂ = −u_iᵀ exactly),
    K_i = p a_i (−u_i u_iᵀ + d_i ∂u_i/∂q̂ |_{g fixed in b}),
i.e. every term is kept (the normal turning with body b, the lever arms changing with
both bodies' rotations) **except**, in exact mode, ∂g_i/∂y_i, the Hessian of φ_B — the
rate at which B's normal changes along B (curvature, magnitude κ/(1 − κ d) for a surface
of curvature κ). The neglected part is p a_i d_i (∂u_i/∂g)(∂g/∂y)(∂y/∂q̂), of relative
size ≈ d·κ against the retained p a_i u uᵀ; it vanishes for a flat B, and for a faceted
B in exact mode whenever the closest point lies inside a triangle. In grid mode K is the
exact derivative of the Q computed: the grid's interpolants are differentiated
(:func:`~.distance_grid.grid_derivatives`), the curvature term is added, and the first
term is −p a_i u_i v_iᵀ with v_i = u_i(∇φ̂) (the depth's own gradient ∇φ̂, which differs
from the interpolated normal g by the interpolation error). Vertices entering or leaving
contact make K one-sided there (Q is continuous, K jumps by p a_i u uᵀ), and so do
grid cell faces (the interpolants' slopes jump there).

Non-linear law (``layers``; :mod:`.pressure_law`, Bei & Fregly 2004): p d_i becomes the
pressure P(d_i), p in the first term of K_i its slope dP/dd, and U = Σ a_i W(d_i).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .distance_grid import band_occupancy, grid_candidates, grid_derivatives, sample_grid
from .grid_cache import cached_distance_grid
from .limits import warn_depth
from .mesh import SurfaceMesh
from .signed_distance import OpenSurfaceDistance

__all__ = [
    "ElasticFoundation",
    "ContactResult",
    "DEFAULT_GRID_SPACING",
    "DEFAULT_MAX_DEPTH",
]

#: default grid spacing h, m: depth error ≤ 0.01 mm in the contact band for surfaces
#: with curvature radius ≥ 5 mm (measurements in docs/contact.md)
DEFAULT_GRID_SPACING = 0.3e-3
#: default band depth, m: vertices deeper than this behind B are ignored
DEFAULT_MAX_DEPTH = 3e-3
#: reach of the candidate vertices (:meth:`ElasticFoundation._candidates`), in grid
#: spacings: about 0.15 mm at the default spacing, more than a frame's Newton steps after
#: the first and the Jacobian's differences (µm), less than a gait frame's motion
NEAR_REACH = 0.5


@njit(cache=True)
def _largest_move(R, p, R0, p0, c, rho):
    """A bound (m) of |(R − R0) s + p − p0| over points s within ``rho`` (m) of ``c`` (3,):
    ‖R − R0‖_F ρ + |(R − R0) c + p − p0|. R, R0 (3, 3); p, p0 (3,) m."""
    f = 0.0
    m = 0.0
    for i in range(3):
        w = p[i] - p0[i]
        for j in range(3):
            d = R[i, j] - R0[i, j]
            f += d * d
            w += d * c[j]
        m += w * w
    return np.sqrt(f) * rho + np.sqrt(m)


@dataclass(frozen=True, eq=False)
class ContactResult:
    """Loads of one contact evaluation.

    Attributes
    ----------
    Q : (12,) — generalized forces on (a, b): [F_a N (world); M_a N·m (about a's COM,
        a's frame); F_b N (world); M_b N·m (about b's COM, b's frame)].
    force_W : (3,) N — resultant contact force on body a, world (−force_W acts on b).
    moment_W : (3,) N·m — resultant moment on a about its centre of mass r_Wa, world.
    cop_W : (3,) m — centre of pressure: Σ p_i a_i c_i / Σ p_i a_i over the contact points
        c_i (closest points on B); NaN when there is no contact.
    area : float, m² — Σ a_i over the vertices in contact.
    peak_pressure : float, Pa — max p·d_i (0 without contact).
    max_penetration : float, m — max d_i (0 without contact).
    n_contact : int — vertices in contact.
    energy : float, J — elastic energy ½ Σ p a_i d_i².
    vertex_pressure : (n,) Pa or None — p·d_i for every vertex of A (0 out of contact).
    K : (12, 12) or None — ∂Q/∂q̂, units N/m, N, N·m/rad blocks (see module docstring).
    region_force_W : {region: (3,) N} or None — the contact force on a of the vertices in
        each of the pair's ``regions`` (world), e.g. a knee's medial and lateral halves.
    """

    Q: np.ndarray
    force_W: np.ndarray
    moment_W: np.ndarray
    cop_W: np.ndarray
    area: float
    peak_pressure: float
    max_penetration: float
    n_contact: int
    energy: float
    vertex_pressure: np.ndarray | None = None
    K: np.ndarray | None = None
    region_force_W: dict | None = None


class ElasticFoundation:
    """Elastic-foundation contact pair: vertices of ``surface_A`` against ``surface_B``.

    Parameters
    ----------
    surface_A : SurfaceMesh — vertex surface, fixed in body a (its frame, m).
    surface_B : SurfaceMesh — opposite surface, fixed in body b; its normals point out of
        b's bone toward the joint space.
    pressure_modulus : float, N/m³ — p (the paper: 10e9).
    mode : "grid" (default; precomputed signed-distance grid of B, numba kernel) or
        "exact" (libigl AABB closest points on every call).
    grid_spacing : float, m — grid node spacing (default :data:`DEFAULT_GRID_SPACING`).
    max_depth : float, m — band depth (default :data:`DEFAULT_MAX_DEPTH`).
    name : str — label for messages.
    layers : (m, 2) array or None — the non-linear law's layers [K Pa, h m], m = 1 or 2
        (:mod:`.pressure_law`); None: the linear law P = p d. With layers,
        ``pressure_modulus`` is the law's slope at d = 0, 1/Σ h/K (reported only).

    The grid (grid mode) or AABB tree (exact mode) is built once here; the grid is also
    memoised per surface, spacing and depth (:func:`~.grid_cache.cached_distance_grid`).
    The object is not modified by :meth:`evaluate` except for the grid mode's candidate
    vertices, a cache that changes no result (:meth:`_candidates`).
    """

    def __init__(self, surface_A: SurfaceMesh, surface_B: SurfaceMesh, pressure_modulus: float,
                 mode: str = "grid", grid_spacing: float | None = None,
                 max_depth: float = DEFAULT_MAX_DEPTH, name: str | None = None, layers=None):
        self.name = name or f"{surface_A.name} vs {surface_B.name}"
        if not (isinstance(surface_A, SurfaceMesh) and isinstance(surface_B, SurfaceMesh)):
            raise TypeError(f"contact '{self.name}': surfaces must be SurfaceMesh objects")
        if not (np.isfinite(pressure_modulus) and pressure_modulus > 0.0):
            raise ValueError(
                f"contact '{self.name}': pressure_modulus must be > 0 N/m³, got {pressure_modulus!r}"
            )
        if not (np.isfinite(max_depth) and max_depth > 0.0):
            raise ValueError(f"contact '{self.name}': max_depth must be > 0 m, got {max_depth!r}")
        if mode not in ("grid", "exact"):
            raise ValueError(f"contact '{self.name}': mode must be 'grid' or 'exact', got {mode!r}")
        self.surface_A = surface_A
        self.surface_B = surface_B
        self.pressure_modulus = float(pressure_modulus)
        self.layers = None
        if layers is not None:
            layers = np.array(layers, dtype=np.float64).reshape(-1, 2)
            if not (1 <= layers.shape[0] <= 2 and np.all(np.isfinite(layers)) and np.all(layers > 0.0)):
                raise ValueError(f"contact '{self.name}': the non-linear law needs 1 or 2 layers of positive "
                                 f"modulus (Pa) and thickness (m), got {layers.tolist()!r}")
            self.layers = layers
            self.pressure_modulus = float(1.0 / np.sum(layers[:, 1] / layers[:, 0]))
        self.mode = mode
        self.regions = ()  # ((name, axis (3,), origin (3,) m), ...) in b's frame: set_regions
        self.max_depth = float(max_depth)
        self.grid_spacing = float(DEFAULT_GRID_SPACING if grid_spacing is None else grid_spacing)
        self._s_A = np.ascontiguousarray(surface_A.vertices_B, dtype=np.float64)
        self._a_A = np.ascontiguousarray(surface_A.vertex_areas, dtype=np.float64)
        n = self._s_A.shape[0]
        # per-call scratch is allocated in evaluate; the one state kept between calls is the
        # grid mode's candidate vertices (:meth:`_candidates`), which changes no result
        self._n = n
        centre = self._s_A.mean(axis=0) if n else np.zeros(3)
        self._centre_A, self._radius_A = centre, float(np.max(np.linalg.norm(self._s_A - centre, axis=1), initial=0.0))
        self._near = None
        if mode == "grid":
            self.grid = cached_distance_grid(surface_B, self.grid_spacing, self.max_depth)
            self._flat = self.grid.values.reshape(-1)
            self._cells = self.grid.cell_valid.reshape(-1)
            self._blocks = self.grid.block_valid
            self._grid_shape = tuple(int(v) for v in self.grid.shape)
            self._origin = np.asarray(self.grid.origin_B, dtype=np.float64)
            self._inv_h = 1.0 / self.grid.spacing
            self._exact = None
        else:
            self.grid = None
            self._exact = OpenSurfaceDistance(surface_B)
            # cull mask: coarse voxels (about max_depth/2, ≥ 0.5 mm) around the band of B;
            # its extent is B's bounding box in b's frame inflated by the band depth
            voxel = max(0.5 * self.max_depth, 0.5e-3)
            self._cull_mask, self._cull_origin, self._cull_voxel = band_occupancy(
                surface_B, self.max_depth, voxel)

    def set_regions(self, regions):
        """Regions of the contact force (outputs only): ``regions`` is a sequence of
        (name, axis (3,), origin (3,) m) in body b's frame; a vertex of A in contact
        belongs to a region when (y − origin)·axis > 0, y its position in b's frame
        (a knee's medial and lateral halves: the insert's frame, axes ∓z)."""
        out = []
        for name, axis, origin in regions:
            axis, origin = np.asarray(axis, dtype=float).reshape(3), np.asarray(origin, dtype=float).reshape(3)
            norm = float(np.linalg.norm(axis))
            if not (np.all(np.isfinite(axis)) and norm > 0.0 and np.all(np.isfinite(origin))):
                raise ValueError(f"contact '{self.name}': region {name!r} needs a finite non-zero axis and a "
                                 "finite origin")
            out.append((str(name), axis / norm, origin))
        self.regions = tuple(out)

    def __repr__(self) -> str:
        return (
            f"ElasticFoundation({self.name!r}, p={self.pressure_modulus:.3g} N/m³, "
            f"mode={self.mode!r}, max_depth={self.max_depth * 1e3:g} mm"
            + (f", h={self.grid_spacing * 1e3:g} mm)" if self.mode == "grid" else ")")
        )

    def penetration(self, r_Wa, R_Wa, r_Wb, R_Wb):
        """Vertices of A in contact and their depths.

        Parameters: r_Wa (3,) m, R_Wa (3, 3), r_Wb (3,) m, R_Wb (3, 3) — body poses.
        Returns idx (k,) int vertex indices, depth (k,) m, g_B (k, 3) outward unit normals
        of B at the vertices (b's frame), y_B (k, 3) m vertex positions in b's frame.
        """
        r_Wa, R_Wa, r_Wb, R_Wb = _pose(r_Wa, R_Wa, r_Wb, R_Wb)
        # y = R_Wbᵀ (r_Wa + R_Wa s − r_Wb) = R_ba s + p_ba
        R_ba = R_Wb.T @ R_Wa
        p_ba = R_Wb.T @ (r_Wa - r_Wb)
        if self.mode == "grid":
            cand, s_A = self._candidates(R_ba, p_ba)
            n = s_A.shape[0]
            idx = np.empty(n, np.int64)
            depth = np.empty(n)
            g_B = np.empty((n, 3))
            y_B = np.empty((n, 3))
            # cull + interpolate in one numba pass; vertices outside the grid box (B's box
            # inflated by the band) are rejected by the bounds test before any lookup
            k = sample_grid(s_A, R_ba, p_ba, self._flat, self._cells, self._blocks,
                            *self._grid_shape, self._origin, self._inv_h, self.max_depth,
                            True, idx, depth, g_B, y_B)
            depth[:k] *= -1.0  # d_i = −φ_B(y_i)
            return (idx[:k] if cand is None else cand[idx[:k]]), depth[:k], g_B[:k], y_B[:k]
        y_all = self._s_A @ R_ba.T + p_ba
        # cull vertices outside B's inflated box, then outside the band voxels, before
        # any closest-point query
        ijk = np.rint((y_all - self._cull_origin) / self._cull_voxel).astype(np.int64)
        shape = np.array(self._cull_mask.shape)
        inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
        cand = np.flatnonzero(inside)
        cand = cand[self._cull_mask[ijk[cand, 0], ijk[cand, 1], ijk[cand, 2]]]
        phi, g_B, valid, _ = self._exact.query(y_all[cand])
        depth = -phi
        hit = valid & (depth > 0.0) & (depth <= self.max_depth)
        return cand[hit], depth[hit], g_B[hit], y_all[cand[hit]]

    def _candidates(self, R_ba, p_ba):
        """(vertex numbers (m,) or None for all, their positions s_A (m, 3) m) that can be
        in contact at the relative pose R_ba (3, 3), p_ba (3,) m.

        The vertices of A with a valid grid cell within NEAR_REACH grid spacings, found at
        a reference pose (:func:`~.distance_grid.grid_candidates`), serve every pose at
        which no vertex has moved farther than that from the reference: |Δy| ≤
        ‖ΔR‖_F ρ + |ΔR c + Δp| (c the vertices' centroid, ρ their largest distance from
        it). A frame's Newton iterations and the Jacobian's differences stay within it, so
        the grid is sampled at a fifth of the insert's vertices instead of all; farther,
        the candidates are found again here. The rows sampled are those of all vertices."""
        near = self._near
        if near is not None:
            R0, p0, cand, s_A = near
            if _largest_move(R_ba, p_ba, R0, p0, self._centre_A, self._radius_A) <= NEAR_REACH / self._inv_h:
                return cand, s_A
        index = np.empty(self._n, np.int64)
        m = grid_candidates(self._s_A, R_ba, p_ba, self._cells, *self._grid_shape, self._origin, self._inv_h,
                            NEAR_REACH / self._inv_h, index)
        cand = index[:m].copy()
        self._near = (R_ba.copy(), p_ba.copy(), cand, np.ascontiguousarray(self._s_A[cand]))
        return self._near[2], self._near[3]

    def pressures(self, depth):
        """(P (k,) Pa, dP/dd (k,) Pa/m, W (k,) J/m²) of the pair's law at depths (k,) m."""
        from .pressure_law import linear_pressures, nonlinear_pressures

        depth = np.ascontiguousarray(depth, dtype=np.float64)
        if self.layers is None:
            return linear_pressures(self.pressure_modulus, depth)
        P, dP, W = np.empty_like(depth), np.empty_like(depth), np.empty_like(depth)
        nonlinear_pressures(depth, self.layers, P, dP, W)
        return P, dP, W

    def evaluate(self, r_Wa, R_Wa, r_Wb, R_Wb, want_stiffness: bool = False,
                 want_vertex_pressure: bool = False) -> ContactResult:
        """Contact loads at the given poses.

        Parameters
        ----------
        r_Wa : (3,) m — centre of mass of body a in world. R_Wa : (3, 3) — orientation.
        r_Wb : (3,) m, R_Wb : (3, 3) — the same for body b.
        want_stiffness : bool — also compute K = ∂Q/∂q̂ (12, 12).
        want_vertex_pressure : bool — also return the pressure of every vertex of A.

        Returns a :class:`ContactResult`.
        """
        r_Wa, R_Wa, r_Wb, R_Wb = _pose(r_Wa, R_Wa, r_Wb, R_Wb)
        idx, depth, g_B, y_B = self.penetration(r_Wa, R_Wa, r_Wb, R_Wb)
        Q = np.zeros(12)
        K = np.zeros((12, 12))
        sums = np.zeros(7)  # [Σ w c (3), Σ w, area, max d, energy], w = P(d) a
        P, dP, W = self.pressures(depth)
        k = idx.shape[0] if (want_stiffness and self.mode == "grid") else 0
        dphi, Dg = np.empty((k, 3)), np.empty((k, 3, 3))
        if k:
            grid_derivatives(np.ascontiguousarray(y_B), self._flat, *self._grid_shape[1:], self._origin, self._inv_h,
                             dphi, Dg)
        _accumulate(self._s_A, self._a_A, idx, depth, g_B, y_B, R_Wa, R_Wb, r_Wb,
                    P, dP, W, want_stiffness, Q, K, sums, dphi, Dg)
        if idx.size:
            warn_depth(self.name, float(depth.max()), self.max_depth)
        weight = sums[3]
        cop = sums[:3] / weight if weight > 0.0 else np.full(3, np.nan)
        vertex_pressure = None
        if want_vertex_pressure:
            vertex_pressure = np.zeros(self._n)
            vertex_pressure[idx] = P
        region_force_W = None
        if self.regions:
            # force on a of each vertex: P a_i along B's outward normal (the resultant's
            # terms in _accumulate), summed over the region's vertices, then to world
            f_B = (P * self._a_A[idx])[:, None] * g_B
            region_force_W = {name: R_Wb @ f_B[(y_B - origin) @ axis > 0.0].sum(axis=0)
                              for name, axis, origin in self.regions}
        return ContactResult(
            Q=Q,
            force_W=Q[0:3].copy(),
            moment_W=R_Wa @ Q[3:6],
            cop_W=cop,
            area=float(sums[4]),
            peak_pressure=float(P.max()) if P.size else 0.0,
            max_penetration=float(sums[5]),
            n_contact=int(idx.size),
            energy=float(sums[6]),
            vertex_pressure=vertex_pressure,
            K=K if want_stiffness else None,
            region_force_W=region_force_W,
        )


def _pose(r_Wa, R_Wa, r_Wb, R_Wb):
    return (np.asarray(r_Wa, dtype=np.float64).reshape(3),
            np.ascontiguousarray(R_Wa, dtype=np.float64).reshape(3, 3),
            np.asarray(r_Wb, dtype=np.float64).reshape(3),
            np.ascontiguousarray(R_Wb, dtype=np.float64).reshape(3, 3))


@njit(cache=True)
def _skew(v):
    S = np.zeros((3, 3))
    S[0, 1] = -v[2]
    S[0, 2] = v[1]
    S[1, 0] = v[2]
    S[1, 2] = -v[0]
    S[2, 0] = -v[1]
    S[2, 1] = v[0]
    return S


@njit(cache=True)
def _skew_into(v0, v1, v2, S):
    """S (3, 3) ← the cross-product matrix of (v0, v1, v2)."""
    S[0, 0] = S[1, 1] = S[2, 2] = 0.0
    S[0, 1], S[0, 2] = -v2, v1
    S[1, 0], S[1, 2] = v2, -v0
    S[2, 0], S[2, 1] = -v1, v0


@njit(cache=True)
def _accumulate(s_A, a_A, idx, depth, g_B, y_B, R_Wa, R_Wb, r_Wb, P, dP, W, want_K, Q, K, sums, dphi, Dg):
    """Sum Q (12,), K (12, 12) and [Σ w c (3), Σ w, area, max d, energy] over contact vertices.

    P, dP, W (k,): the pressure law at each contact vertex's depth (Pa, Pa/m, J/m²;
    :meth:`ElasticFoundation.pressures`; the linear law: p d, p, ½ p d²). Per vertex
    (w = P a, "p a d" below for the linear law; the stiffness p a is dP/dd a): Q += w u with u = [n; s × n_A; −n; −y × g]. For K, besides
    −Σ p a u uᵀ, the "d ∂u/∂q̂" blocks are sums of w g, w n_A sᵀ, w y gᵀ (identity
    ã b̃ = b aᵀ − (a·b) I), assembled after the loop (module docstring).
    dphi (k, 3), Dg (k, 3, 3) 1/m: the grid's exact ∇φ̂ and ∂g/∂y at the vertices
    (:func:`~.distance_grid.grid_derivatives`), or empty (k = 0 rows: exact mode): then
    K's first term is −Σ dP/dd a u vᵀ with v = u(∇φ̂) (∂d/∂q̂ = −vᵀ of the interpolant)
    instead of −Σ dP/dd a u uᵀ, and the curvature term Σ w (∂u/∂g)(∂g/∂y)(∂y/∂q̂) is added.
    """
    grid_K = want_K and dphi.shape[0] == idx.shape[0] and idx.shape[0] > 0
    v = np.empty(12)
    Bu = np.zeros((12, 3))  # ∂u/∂g
    Ay = np.zeros((3, 12))  # ∂y/∂q̂
    M = np.zeros((3, 12))
    S_s = np.zeros((3, 3))
    S_y = np.zeros((3, 3))
    R_ba = R_Wb.T @ R_Wa
    R_ab = R_Wa.T @ R_Wb
    # the vertex-independent blocks of ∂u/∂g and ∂y/∂q̂ (grid_K): ±R_Wb, ±R_Wbᵀ
    for r in range(3):
        for c in range(3):
            Bu[r, c] = R_Wb[r, c]
            Bu[6 + r, c] = -R_Wb[r, c]
            Ay[r, c] = R_Wb[c, r]
            Ay[r, 6 + c] = -R_Wb[c, r]
    u = np.empty(12)
    UU = np.zeros((12, 12))
    KC = np.zeros((12, 12))  # the curvature term (grid_K)
    G_sum = np.zeros(3)  # Σ w g
    M1 = np.zeros((3, 3))  # Σ w n_A sᵀ
    M2 = np.zeros((3, 3))  # Σ w y gᵀ
    sigma = 0.0  # Σ w s·n_A
    tau = 0.0  # Σ w g·y
    for m in range(idx.shape[0]):
        i = idx[m]
        d = depth[m]
        k = dP[m] * a_A[i]  # dP/dd a_i (p a_i for the linear law), N/m
        w = P[m] * a_A[i]  # |f_i| = P(d_i) a_i (p a_i d_i), N
        g0, g1, g2 = g_B[m, 0], g_B[m, 1], g_B[m, 2]
        y0, y1, y2 = y_B[m, 0], y_B[m, 1], y_B[m, 2]
        s0, s1, s2 = s_A[i, 0], s_A[i, 1], s_A[i, 2]
        # n = R_Wb g (world), n_A = R_ab g (a's frame)
        n0 = R_Wb[0, 0] * g0 + R_Wb[0, 1] * g1 + R_Wb[0, 2] * g2
        n1 = R_Wb[1, 0] * g0 + R_Wb[1, 1] * g1 + R_Wb[1, 2] * g2
        n2 = R_Wb[2, 0] * g0 + R_Wb[2, 1] * g1 + R_Wb[2, 2] * g2
        a0 = R_ab[0, 0] * g0 + R_ab[0, 1] * g1 + R_ab[0, 2] * g2
        a1 = R_ab[1, 0] * g0 + R_ab[1, 1] * g1 + R_ab[1, 2] * g2
        a2 = R_ab[2, 0] * g0 + R_ab[2, 1] * g1 + R_ab[2, 2] * g2
        # u = [n; s × n_A; −n; −y × g]
        u[0] = n0
        u[1] = n1
        u[2] = n2
        u[3] = s1 * a2 - s2 * a1
        u[4] = s2 * a0 - s0 * a2
        u[5] = s0 * a1 - s1 * a0
        u[6] = -n0
        u[7] = -n1
        u[8] = -n2
        u[9] = -(y1 * g2 - y2 * g1)
        u[10] = -(y2 * g0 - y0 * g2)
        u[11] = -(y0 * g1 - y1 * g0)
        # Q_i = p a_i d_i u (Q = −Σ p a d (∂d/∂q̂)ᵀ)
        for c in range(12):
            Q[c] += w * u[c]
        # contact point on B: c_W = r_Wb + R_Wb (y + d g)
        c0 = y0 + d * g0
        c1 = y1 + d * g1
        c2 = y2 + d * g2
        for r in range(3):
            sums[r] += w * (r_Wb[r] + R_Wb[r, 0] * c0 + R_Wb[r, 1] * c1 + R_Wb[r, 2] * c2)
        sums[3] += w
        sums[4] += a_A[i]
        if d > sums[5]:
            sums[5] = d
        sums[6] += W[m] * a_A[i]  # U = Σ a W(d) (½ p a d²)
        if grid_K:
            # v = u with g replaced by ∇φ̂ (so that ∂d/∂q̂ = −vᵀ exactly)
            e0, e1, e2 = dphi[m, 0], dphi[m, 1], dphi[m, 2]
            b0 = R_ab[0, 0] * e0 + R_ab[0, 1] * e1 + R_ab[0, 2] * e2
            b1 = R_ab[1, 0] * e0 + R_ab[1, 1] * e1 + R_ab[1, 2] * e2
            b2 = R_ab[2, 0] * e0 + R_ab[2, 1] * e1 + R_ab[2, 2] * e2
            for r in range(3):
                v[r] = R_Wb[r, 0] * e0 + R_Wb[r, 1] * e1 + R_Wb[r, 2] * e2
                v[6 + r] = -v[r]
            v[3] = s1 * b2 - s2 * b1
            v[4] = s2 * b0 - s0 * b2
            v[5] = s0 * b1 - s1 * b0
            v[9] = -(y1 * e2 - y2 * e1)
            v[10] = -(y2 * e0 - y0 * e2)
            v[11] = -(y0 * e1 - y1 * e0)
            for r in range(12):
                kur = k * u[r]
                for c in range(12):
                    UU[r, c] += kur * v[c]
            # curvature: w (∂u/∂g)(∂g/∂y)(∂y/∂q̂), ∂u/∂g = [R_Wb; s̃ R_ab; −R_Wb; −ỹ],
            # ∂y/∂q̂ = [R_Wbᵀ, −R_ba s̃, −R_Wbᵀ, ỹ]
            _skew_into(s0, s1, s2, S_s)
            _skew_into(y0, y1, y2, S_y)
            for r in range(3):
                for c in range(3):
                    Bu[9 + r, c] = -S_y[r, c]
                    Bu[3 + r, c] = S_s[r, 0] * R_ab[0, c] + S_s[r, 1] * R_ab[1, c] + S_s[r, 2] * R_ab[2, c]
                    Ay[r, 9 + c] = S_y[r, c]
                    Ay[r, 3 + c] = -(R_ba[r, 0] * S_s[0, c] + R_ba[r, 1] * S_s[1, c] + R_ba[r, 2] * S_s[2, c])
            for r in range(3):  # M = w ∂g/∂y ∂y/∂q̂ (3, 12)
                for c in range(12):
                    M[r, c] = w * (Dg[m, r, 0] * Ay[0, c] + Dg[m, r, 1] * Ay[1, c] + Dg[m, r, 2] * Ay[2, c])
            for r in range(12):
                for c in range(12):
                    KC[r, c] += Bu[r, 0] * M[0, c] + Bu[r, 1] * M[1, c] + Bu[r, 2] * M[2, c]
        elif want_K:
            for r in range(12):
                kur = k * u[r]
                for c in range(r, 12):
                    UU[r, c] += kur * u[c]
        if want_K:
            G_sum[0] += w * g0
            G_sum[1] += w * g1
            G_sum[2] += w * g2
            M1[0, 0] += w * a0 * s0
            M1[0, 1] += w * a0 * s1
            M1[0, 2] += w * a0 * s2
            M1[1, 0] += w * a1 * s0
            M1[1, 1] += w * a1 * s1
            M1[1, 2] += w * a1 * s2
            M1[2, 0] += w * a2 * s0
            M1[2, 1] += w * a2 * s1
            M1[2, 2] += w * a2 * s2
            sigma += w * (s0 * a0 + s1 * a1 + s2 * a2)
            M2[0, 0] += w * y0 * g0
            M2[0, 1] += w * y0 * g1
            M2[0, 2] += w * y0 * g2
            M2[1, 0] += w * y1 * g0
            M2[1, 1] += w * y1 * g1
            M2[1, 2] += w * y1 * g2
            M2[2, 0] += w * y2 * g0
            M2[2, 1] += w * y2 * g1
            M2[2, 2] += w * y2 * g2
            tau += w * (g0 * y0 + g1 * y1 + g2 * y2)
    if grid_K:
        K -= UU  # −Σ dP/dd a u vᵀ
        K += KC
    elif want_K:
        # −Σ p a u uᵀ (symmetric)
        for r in range(12):
            for c in range(r, 12):
                K[r, c] -= UU[r, c]
                if c != r:
                    K[c, r] -= UU[r, c]
    if want_K:
        I3 = np.eye(3)
        Rb_G = R_Wb @ _skew(G_sum)  # Σ w R_Wb g̃
        G_RbT = _skew(G_sum) @ R_Wb.T  # Σ w g̃ R_Wbᵀ
        A = M1 - sigma * I3  # Σ w s̃ ñ_A
        K[0:3, 9:12] -= Rb_G  # ∂n/∂δπ_b = −R_Wb g̃
        K[6:9, 9:12] += Rb_G
        K[3:6, 3:6] += A  # ∂(s × n_A)/∂δπ_a = s̃ ñ_A
        K[3:6, 9:12] -= A @ R_ab  # ∂(s × n_A)/∂δπ_b = −s̃ R_ab g̃ = −s̃ ñ_A R_ab
        # ∂(g̃ y)/∂q̂ with δy = R_Wbᵀ(δr_a − R_Wa s̃ δπ_a − δr_b) + ỹ δπ_b
        K[9:12, 0:3] += G_RbT
        K[9:12, 3:6] -= R_ba @ (M1.T - sigma * I3)  # g̃ R_ba s̃ = R_ba ñ_A s̃
        K[9:12, 6:9] -= G_RbT
        K[9:12, 9:12] += M2 - tau * I3  # g̃ ỹ = y gᵀ − (g·y) I
