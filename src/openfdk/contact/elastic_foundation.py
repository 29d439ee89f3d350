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
from .pressure_law import linear_pressures, nonlinear_pressures
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
#: spacings (at most 0.5, :func:`~.distance_grid.grid_candidates`): about 0.15 mm at the
#: default spacing, more than a frame's Newton steps after the first and the Jacobian's
#: differences (µm), less than a gait frame's motion
NEAR_REACH = 0.5
_NO_ROWS = np.zeros(0)  # (0,): the pressures _accumulate does not read (linear law)


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
    variable : a :class:`~.variable_layers.VariableLayers` or None — layers whose thickness
        varies over the surfaces (OpenSim-JAM's variable cartilage thickness), linear or
        non-linear; ``pressure_modulus`` is then reported only.

    The grid (grid mode) or AABB tree (exact mode) is built once here; the grid is also
    memoised per surface, spacing and depth (:func:`~.grid_cache.cached_distance_grid`).
    The object is not modified by :meth:`evaluate` except for the grid mode's candidate
    vertices, a cache that changes no result (:meth:`_candidates`).
    """

    def __init__(self, surface_A: SurfaceMesh, surface_B: SurfaceMesh, pressure_modulus: float,
                 mode: str = "grid", grid_spacing: float | None = None,
                 max_depth: float = DEFAULT_MAX_DEPTH, name: str | None = None, layers=None, variable=None):
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
        self.variable = variable
        if variable is not None:
            if layers is not None:
                raise ValueError(f"contact '{self.name}': uniform and variable layers given together")
            if variable.h_A is not None and len(variable.h_A) != surface_A.vertices_B.shape[0]:
                raise ValueError(f"contact '{self.name}': {len(variable.h_A)} vertex thicknesses for "
                                 f"{surface_A.vertices_B.shape[0]} vertices")
        self.mode = mode
        self.regions = ()  # ((name, axis (3,), origin (3,) m), ...) in b's frame: set_regions
        self._region_axis = self._region_origin = np.zeros((0, 3))  # the same, stacked (m, 3)
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
            self._slopes = self.grid.block_slope
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
        self._region_axis = np.array([axis for _, axis, _ in out], dtype=np.float64).reshape(-1, 3)
        self._region_origin = np.array([origin for _, _, origin in out], dtype=np.float64).reshape(-1, 3)

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
        return self._penetration(R_Wb.T @ R_Wa, R_Wb.T @ (r_Wa - r_Wb))

    def _penetration(self, R_ba, p_ba):
        """:meth:`penetration` at the relative pose R_ba (3, 3), p_ba (3,) m (y = R_ba s + p_ba)."""
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

        The vertices of A that can be sampled in contact after moving by up to NEAR_REACH
        grid spacings from a reference pose (:func:`~.distance_grid.grid_candidates`: a
        valid cell within reach whose φ̂ can reach the band, bounded by the interpolant's
        slope), found there, serve every pose at which no vertex has moved farther than
        that from the reference: |Δy| ≤ ‖ΔR‖_F ρ + |ΔR c + Δp| (c the vertices' centroid,
        ρ their largest distance from it). A frame's Newton iterations and the Jacobian's
        differences stay within it, so the grid is sampled at a fraction of A's vertices
        instead of all (DM knee: 23 % and 10 % of the two contacts', about twice the
        vertices in contact); farther, the candidates are found again here. The rows
        sampled are those of all vertices."""
        near = self._near
        if near is not None:
            R0, p0, cand, s_A = near
            reach = (1.0 - 1e-9) * NEAR_REACH / self._inv_h  # m, to spare for rounding against the cells searched
            if _largest_move(R_ba, p_ba, R0, p0, self._centre_A, self._radius_A) <= reach:
                return cand, s_A
        index = np.empty(self._n, np.int64)
        m = grid_candidates(self._s_A, R_ba, p_ba, self._flat, self._cells, self._slopes, *self._grid_shape,
                            self._origin, self._inv_h, self.max_depth, NEAR_REACH, index)
        cand = index[:m].copy()
        self._near = (R_ba.copy(), p_ba.copy(), cand, np.ascontiguousarray(self._s_A[cand]))
        return self._near[2], self._near[3]

    def pressures(self, depth, idx=None, closest_B=None):
        """(P (k,) Pa, dP/dd (k,) Pa/m, W (k,) J/m²) of the pair's law at depths (k,) m;
        with variable layers, at the vertices idx (k,) of A whose closest points on B are
        closest_B (k, 3) m (b's frame)."""
        depth = np.ascontiguousarray(depth, dtype=np.float64)
        if self.variable is not None:
            return self.variable.pressures(depth, idx, closest_B)
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
        p_ba = R_Wb.T @ (r_Wa - r_Wb)
        idx, depth, g_B, y_B = self._penetration(R_Wb.T @ R_Wa, p_ba)
        Q = np.zeros(12)
        K = np.zeros((12, 12))
        sums = np.zeros(7)  # [Σ w c (3), Σ w, area, max d, energy], w = P(d) a
        # the linear law is applied in _accumulate (modulus > 0), the non-linear one and
        # variable layers here (per vertex: P, dP/dd, W)
        per_vertex = self.layers is not None or self.variable is not None
        modulus = 0.0 if per_vertex else self.pressure_modulus
        P = dP = W = _NO_ROWS
        closest = None
        if per_vertex:
            if self.variable is not None:  # the closest points on B: y + d g (y is d behind B)
                closest = y_B + depth[:, None] * g_B
            P, dP, W = self.pressures(depth, idx, closest)
        k = idx.shape[0] if (want_stiffness and self.mode == "grid") else 0
        dphi, Dg = np.empty((k, 3)), np.empty((k, 3, 3))
        if k:
            grid_derivatives(np.ascontiguousarray(y_B), self._flat, *self._grid_shape[1:], self._origin, self._inv_h,
                             dphi, Dg)
        region_F = np.empty((len(self.regions), 3))  # N, b's frame
        _accumulate(self._a_A, idx, depth, g_B, y_B, R_Wa, R_Wb, r_Wb, p_ba, modulus, P, dP, W, want_stiffness,
                    Q, K, sums, dphi, Dg, self._region_axis, self._region_origin, region_F)
        if idx.size:
            warn_depth(self.name, float(sums[5]), self.max_depth)
        weight = sums[3]
        cop = sums[:3] / weight if weight > 0.0 else np.full(3, np.nan)
        if modulus > 0.0:  # P = p d: its largest is p max d
            peak = modulus * float(sums[5])
        else:
            peak = float(P.max()) if P.size else 0.0
        vertex_pressure = None
        if want_vertex_pressure:
            vertex_pressure = np.zeros(self._n)
            vertex_pressure[idx] = self.pressures(depth, idx, closest)[0] if modulus > 0.0 else P
        region_force_W = None
        if self.regions:
            # force on a of each vertex: P a_i along B's outward normal, summed over the
            # region's vertices in _accumulate (b's frame), then to world
            region_force_W = {name: R_Wb @ region_F[j] for j, (name, _, _) in enumerate(self.regions)}
        return ContactResult(
            Q=Q,
            force_W=Q[0:3].copy(),
            moment_W=R_Wa @ Q[3:6],
            cop_W=cop,
            area=float(sums[4]),
            peak_pressure=peak,
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
def _accumulate(a_A, idx, depth, g_B, y_B, R_Wa, R_Wb, r_Wb, p_ba, modulus, P, dP, W, want_K, Q, K, sums, dphi,
                Dg, region_axis, region_origin, region_F):
    """Sum Q (12,), K (12, 12) and [Σ w c (3), Σ w, area, max d, energy] over contact vertices.

    modulus N/m³: > 0 for the linear law, P = p d, dP/dd = p, W = ½ p d² with p = modulus
    (then P, dP, W are not read); 0: P, dP, W (k,) give the pressure law at each contact
    vertex's depth (Pa, Pa/m, J/m²; :meth:`ElasticFoundation.pressures`). w = P a ("p a d"
    for the linear law), the stiffness k = dP/dd a (p a). p_ba (3,) m: a's origin in b's
    frame, so that s_b = R_ba s = y − p_ba.

    Everything per vertex is summed in b's frame (ỹ: the cross-product matrix of y). With
    the normal's line ĝ = [g; y × g] = J g, J = [I; ỹ] (6, 3), and s × n_A = R_ab (s_b × g),
    u = [n; s × n_A; −n; −y × g] = T ĝ for the vertex-independent
    T (12, 6) = [[R_Wb, 0]; [−R_ab p̃_ba, R_ab]; [−R_Wb, 0]; [0, −I]]:
        Q = T Σ w ĝ,    −Σ k u vᵀ = T (−Σ k J g eᵀ Jᵀ) Tᵀ,
    with v = T J e, e = ∇φ̂ (grid K: ∂d/∂q̂ = −vᵀ of the interpolant) or e = g (exact mode:
    −Σ k u uᵀ). The grid's curvature term Σ w (∂u/∂g) D (∂y/∂q̂), D = ∂g/∂y, has the same
    form: ∂u/∂g = T J and ∂y/∂q̂ = [I, −ỹ] Tᵀ = Jᵀ Tᵀ. So both are T H Tᵀ with
        H = Σ J A Jᵀ = Σ [A, −A ỹ; ỹ A, −ỹ A ỹ],    A = −k g eᵀ + w D (3, 3),
    summed per vertex (3×3 and 6×3 products instead of 12×12) and expanded once. The
    "d ∂u/∂q̂ |_g" blocks (module docstring) are sums of w g, w n_A sᵀ = R_ab (w g s_bᵀ) R_ba
    and w y gᵀ (identity ã b̃ = b aᵀ − (a·b) I), assembled after the loop from G = Σ w g,
    N = Σ w g yᵀ and τ = Σ w g·y.

    dphi (k, 3), Dg (k, 3, 3) 1/m: the grid's exact ∇φ̂ and ∂g/∂y at the vertices
    (:func:`~.distance_grid.grid_derivatives`), or empty (0 rows: exact mode, or no K).
    region_axis, region_origin (m, 3) (unit; m), b's frame: the pair's regions;
    region_F (m, 3) N ← Σ w g over the vertices with (y − origin)·axis > 0 (b's frame).
    """
    grid_K = want_K and dphi.shape[0] == idx.shape[0] and idx.shape[0] > 0
    n_regions = region_axis.shape[0]
    region_F[:, :] = 0.0
    gh = np.empty(6)  # ĝ = [g; y × g]
    JA = np.empty((6, 3))  # J A = [A; ỹ A]
    q6 = np.zeros(6)  # Σ w ĝ
    H = np.zeros((6, 6))  # Σ J A Jᵀ
    c_sum = np.zeros(3)  # Σ w (y + d g): the contact points on B, b's frame
    G = np.zeros(3)  # Σ w g
    N = np.zeros((3, 3))  # Σ w g yᵀ
    tau = 0.0  # Σ w g·y
    for m in range(idx.shape[0]):
        i = idx[m]
        d = depth[m]
        a = a_A[i]
        if modulus > 0.0:
            P_m, dP_m, W_m = modulus * d, modulus, 0.5 * modulus * d * d
        else:
            P_m, dP_m, W_m = P[m], dP[m], W[m]
        k = dP_m * a  # dP/dd a_i (p a_i for the linear law), N/m
        w = P_m * a  # |f_i| = P(d_i) a_i (p a_i d_i), N
        g0, g1, g2 = g_B[m, 0], g_B[m, 1], g_B[m, 2]
        y0, y1, y2 = y_B[m, 0], y_B[m, 1], y_B[m, 2]
        gh[0], gh[1], gh[2] = g0, g1, g2
        gh[3] = y1 * g2 - y2 * g1
        gh[4] = y2 * g0 - y0 * g2
        gh[5] = y0 * g1 - y1 * g0
        for r in range(6):
            q6[r] += w * gh[r]
        c_sum[0] += w * (y0 + d * g0)
        c_sum[1] += w * (y1 + d * g1)
        c_sum[2] += w * (y2 + d * g2)
        sums[3] += w
        sums[4] += a
        if d > sums[5]:
            sums[5] = d
        sums[6] += W_m * a  # U = Σ a W(d) (½ p a d²)
        for j in range(n_regions):
            if ((y0 - region_origin[j, 0]) * region_axis[j, 0] + (y1 - region_origin[j, 1]) * region_axis[j, 1]
                    + (y2 - region_origin[j, 2]) * region_axis[j, 2]) > 0.0:
                region_F[j, 0] += w * g0
                region_F[j, 1] += w * g1
                region_F[j, 2] += w * g2
        if want_K:
            e0, e1, e2 = (dphi[m, 0], dphi[m, 1], dphi[m, 2]) if grid_K else (g0, g1, g2)
            for c in range(3):  # column c of A = −k g eᵀ + w D and of ỹ A
                ke = -k * (e0 if c == 0 else (e1 if c == 1 else e2))
                A0, A1, A2 = ke * g0, ke * g1, ke * g2
                if grid_K:
                    A0 += w * Dg[m, 0, c]
                    A1 += w * Dg[m, 1, c]
                    A2 += w * Dg[m, 2, c]
                JA[0, c], JA[1, c], JA[2, c] = A0, A1, A2
                JA[3, c] = y1 * A2 - y2 * A1
                JA[4, c] = y2 * A0 - y0 * A2
                JA[5, c] = y0 * A1 - y1 * A0
            for r in range(6):  # H[r] += [X, −X ỹ], X = (J A)[r] (row), −X ỹ = (y × X)ᵀ
                X0, X1, X2 = JA[r, 0], JA[r, 1], JA[r, 2]
                H[r, 0] += X0
                H[r, 1] += X1
                H[r, 2] += X2
                H[r, 3] += y1 * X2 - y2 * X1
                H[r, 4] += y2 * X0 - y0 * X2
                H[r, 5] += y0 * X1 - y1 * X0
            G[0] += w * g0
            G[1] += w * g1
            G[2] += w * g2
            for r in range(3):
                wg = w * g_B[m, r]
                N[r, 0] += wg * y0
                N[r, 1] += wg * y1
                N[r, 2] += wg * y2
            tau += w * (g0 * y0 + g1 * y1 + g2 * y2)
    R_ab = R_Wa.T @ R_Wb
    R_ba = R_ab.T
    T = np.zeros((12, 6))  # u = T ĝ
    P_ab = R_ab @ _skew(p_ba)
    for r in range(3):
        for c in range(3):
            T[r, c] = R_Wb[r, c]
            T[3 + r, c] = -P_ab[r, c]
            T[3 + r, 3 + c] = R_ab[r, c]
            T[6 + r, c] = -R_Wb[r, c]
        T[9 + r, 3 + r] = -1.0
    for r in range(12):  # Q = T Σ w ĝ
        Q[r] += (T[r, 0] * q6[0] + T[r, 1] * q6[1] + T[r, 2] * q6[2]
                 + T[r, 3] * q6[3] + T[r, 4] * q6[4] + T[r, 5] * q6[5])
    for r in range(3):  # Σ w c_W = r_Wb Σ w + R_Wb Σ w (y + d g)
        sums[r] += r_Wb[r] * sums[3] + R_Wb[r, 0] * c_sum[0] + R_Wb[r, 1] * c_sum[1] + R_Wb[r, 2] * c_sum[2]
    if want_K:
        K += (T @ H) @ T.T
        I3 = np.eye(3)
        M2 = N.T.copy()  # Σ w y gᵀ
        M1 = R_ab @ (N - np.outer(G, p_ba)) @ R_ba  # Σ w n_A sᵀ, s = R_ab (y − p_ba)
        sigma = tau - (p_ba[0] * G[0] + p_ba[1] * G[1] + p_ba[2] * G[2])  # Σ w s·n_A
        Rb_G = R_Wb @ _skew(G)  # Σ w R_Wb g̃
        G_RbT = _skew(G) @ R_Wb.T  # Σ w g̃ R_Wbᵀ
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
