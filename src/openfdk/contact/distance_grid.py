"""Precomputed signed-distance grid of an open surface, queried by a numba trilinear kernel.

The grid covers the surface's body-frame bounding box inflated by the band half-width
``w = max_depth + 2h`` (h = spacing). Only candidate nodes near the band
−w ≤ φ ≤ 2h (found by marking each triangle's box swept back by w along its normals)
are evaluated, with the exact method of
:class:`~openfdk.contact.signed_distance.OpenSurfaceDistance`; every node stores
``[φ, ∂φ/∂x, ∂φ/∂y, ∂φ/∂z]`` (float32), the gradient by central differences of the node
values (:func:`_difference_gradient`). Nodes outside the band, and nodes whose closest
point is on the boundary rim, hold φ = NaN.

Query (:func:`sample_grid`): trilinear weights applied to the corner values
corrected by half their tangent-plane step, which cancels the h²-term of plain trilinear
interpolation (plain trilinear errs by ≈ (h²/8)·Σ|∂²φ/∂x_k²| ≈ h²/(4ρ) for curvature
radius ρ); the node gradients are interpolated trilinearly and normalised to give the
outward unit normal. A point whose cell has any NaN corner is "not in contact" (this
trims about one cell from the rim). The faceted surface's distance field has kinks
behind the mesh edges; they limit the accuracy (docs/contact.md has measurements).

Memory: 17 bytes per node over the box (16 for the node, 1 for the cell mask),
∝ box volume / h³.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit

from .mesh import SurfaceMesh
from .signed_distance import OpenSurfaceDistance

__all__ = ["SignedDistanceGrid", "build_distance_grid", "sample_grid", "band_occupancy"]

BLOCK = 4  # edge, in cells, of the blocks of SignedDistanceGrid.block_valid


@dataclass(frozen=True, eq=False)
class SignedDistanceGrid:
    """Signed-distance samples of one surface on a regular grid in its body frame B.

    Attributes
    ----------
    values : (nx, ny, nz, 4) float32 — [φ m, ∇φ (3,)] at the nodes; φ = NaN where unused.
    cell_valid : (nx−1, ny−1, nz−1) uint8 — 1 where all 8 corners of a cell hold values.
    origin_B : (3,) m — position of node (0, 0, 0) in B.
    spacing : float, m — node spacing h.
    max_depth : float, m — deepest penetration the band was built for.
    mesh_name : str
    n_evaluated : int — number of nodes evaluated exactly (the narrow band).
    """

    values: np.ndarray
    cell_valid: np.ndarray
    origin_B: np.ndarray
    spacing: float
    max_depth: float
    mesh_name: str
    n_evaluated: int

    @functools.cached_property
    def block_valid(self):
        """(⌈(nx−1)/B⌉, ⌈(ny−1)/B⌉, ⌈(nz−1)/B⌉) uint8, B = :data:`BLOCK` — 1 where any
        cell of the B×B×B block is valid. A few tens of kB that stay in cache: most
        query points near but outside the band are rejected without reading
        ``cell_valid`` (MBs, whose random reads were most of a contact query's time)."""
        return block_occupancy(self.cell_valid, BLOCK)

    @functools.cached_property
    def block_slope(self):
        """(⌈(nx−1)/B⌉, ⌈(ny−1)/B⌉, ⌈(nz−1)/B⌉) float32, m/m, B = :data:`BLOCK` — a bound
        of the interpolant's slope |∇φ̂| in each block's valid cells (:func:`block_slopes`;
        0 where none is valid), about 1: it bounds how far φ̂ changes when a contact's
        vertices move (:func:`grid_candidates`). 4 bytes per 64 cells."""
        nx, ny, nz = self.shape
        out = np.zeros(self.block_valid.shape, dtype=np.float32)
        block_slopes(self.values.reshape(-1), self.cell_valid.reshape(-1), nx, ny, nz, 1.0 / self.spacing,
                     BLOCK, out)
        return out

    @property
    def shape(self):
        return self.values.shape[:3]

    @property
    def nbytes(self) -> int:
        return int(self.values.nbytes + self.cell_valid.nbytes)

    def query(self, p_BQ):
        """Interpolated signed distance at points.

        Parameters: p_BQ : (k, 3) m, points in B.
        Returns phi (k,) m (NaN where the cell is outside the band or touches the rim),
        normal_B (k, 3) unit (NaN likewise).
        """
        P = np.ascontiguousarray(p_BQ, dtype=np.float64).reshape(-1, 3)
        k = P.shape[0]
        index = np.empty(k, np.int64)
        phi = np.empty(k)
        normal = np.empty((k, 3))
        y = np.empty((k, 3))
        nx, ny, nz = self.shape
        sample_grid(P, np.eye(3), np.zeros(3), self.values.reshape(-1),
                    self.cell_valid.reshape(-1), self.block_valid, nx, ny, nz, self.origin_B,
                    1.0 / self.spacing, self.max_depth, False, index, phi, normal, y)
        return phi, normal


@njit(cache=True)
def _mark_boxes(box_lo, box_hi, origin, inv_h, mark):
    """mark[i, j, k] = True for nodes inside any of the boxes (box_lo, box_hi) (m, 3) m."""
    nx, ny, nz = mark.shape
    for f in range(box_lo.shape[0]):
        i0 = max(int(np.ceil((box_lo[f, 0] - origin[0]) * inv_h)), 0)
        j0 = max(int(np.ceil((box_lo[f, 1] - origin[1]) * inv_h)), 0)
        k0 = max(int(np.ceil((box_lo[f, 2] - origin[2]) * inv_h)), 0)
        i1 = min(int(np.floor((box_hi[f, 0] - origin[0]) * inv_h)), nx - 1)
        j1 = min(int(np.floor((box_hi[f, 1] - origin[1]) * inv_h)), ny - 1)
        k1 = min(int(np.floor((box_hi[f, 2] - origin[2]) * inv_h)), nz - 1)
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                for k in range(k0, k1 + 1):
                    mark[i, j, k] = True


def _swept_face_boxes(mesh, depth_behind, margin):
    """Per-triangle boxes (lo, hi) (m, 3) m enclosing the region within the band.

    Each box bounds the triangle swept ``depth_behind`` backwards along its face normal
    and along its three vertex normals, inflated by ``margin`` plus
    ``depth_behind·2 sin(angle between the face normal and its vertex normals)`` so that
    points behind edges and vertices (whose closest-point direction lies between the
    normals of adjacent faces) are covered too.
    """
    V, F = mesh.vertices_B, mesh.faces
    n_f = mesh.face_normals_B
    corners = V[F]  # (m, 3, 3)
    n_v = mesh.vertex_normals_B[F]  # (m, 3, 3)
    swept = np.concatenate(
        [corners, corners - depth_behind * n_f[:, None, :], corners - depth_behind * n_v], axis=1
    )
    cos_spread = np.clip(np.einsum("fkd,fd->fk", n_v, n_f).min(axis=1), -1.0, 1.0)
    spread = margin + 2.0 * depth_behind * np.sqrt(1.0 - cos_spread**2)
    return swept.min(axis=1) - spread[:, None], swept.max(axis=1) + spread[:, None]


def block_occupancy(cell_valid, b):
    """(⌈n0/b⌉, ⌈n1/b⌉, ⌈n2/b⌉) uint8 — 1 where any cell of the b×b×b block is valid.

    cell_valid : (n0, n1, n2) uint8, the grid's cells; b : int, block edge in cells.
    """
    n = cell_valid.shape
    padded = np.zeros(tuple(-(-m // b) * b for m in n), dtype=np.uint8)
    padded[: n[0], : n[1], : n[2]] = cell_valid
    m = tuple(v // b for v in padded.shape)
    return np.ascontiguousarray(padded.reshape(m[0], b, m[1], b, m[2], b).max(axis=(1, 3, 5)))


@njit(cache=True)
def sample_grid(points, R, t, flat, cells, blocks, nx, ny, nz, origin, inv_h, max_depth,
                contact_only, index, phi, grad, p_out):
    """Transform points and interpolate φ and ∇φ at them (the numba query kernel).

    Each point is mapped to y = R·x + t (B's frame, m), then
        φ̂(y) = Σ_c w_c [φ_c + ½ ∇φ_c · (y − x_c)],      ∇̂φ(y) = Σ_c w_c ∇φ_c,
    with trilinear weights w_c of the 8 corners x_c of the cell holding y. Plain
    trilinear interpolation overestimates a convex φ by ½ Σ_k φ_kk t_k(1−t_k)h²; the
    blend of corner tangent planes Σ w_c [φ_c + ∇φ_c·(y − x_c)] underestimates it by the
    same amount, so their average (above) is exact for quadratic φ (error O(h³)).
    A point outside the grid box, or whose cell has a NaN corner (``cells`` mask = 0:
    outside the band or at the rim), has no value — decided from the 1-byte mask before
    the 16-byte nodes are read.

    Parameters
    ----------
    points : (n, 3) m. R : (3, 3), t : (3,) m — map into B.
    flat : the grid's values (nx, ny, nz, 4) raveled; cells : cell_valid raveled;
    blocks : :attr:`SignedDistanceGrid.block_valid` (3-D, blocks of ``BLOCK`` cells).
    origin : (3,) m; inv_h : 1/m; max_depth : m.
    contact_only : if True, keep only points with 0 < −φ̂ ≤ max_depth, compacted in
        order (index[m] = point number); else every point, φ = NaN where no value.
    index (n,) int, phi (n,) m, grad (n, 3) unit normal, p_out (n, 3) m (y) — outputs.

    Returns the number of rows written.
    """
    sk = 4
    sj = 4 * nz
    si = 4 * nz * ny
    half_h = 0.5 / inv_h
    count = 0
    for q in range(points.shape[0]):
        x0 = points[q, 0]
        x1 = points[q, 1]
        x2 = points[q, 2]
        y0 = R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2 + t[0]
        y1 = R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2 + t[1]
        y2 = R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2 + t[2]
        u0 = (y0 - origin[0]) * inv_h
        u1 = (y1 - origin[1]) * inv_h
        u2 = (y2 - origin[2]) * inv_h
        ok = u0 >= 0.0 and u1 >= 0.0 and u2 >= 0.0
        i = 0
        j = 0
        k = 0
        if ok:
            i = int(u0)
            j = int(u1)
            k = int(u2)
            ok = i < nx - 1 and j < ny - 1 and k < nz - 1
        if ok:  # the small block mask first, then the cell's own byte
            ok = blocks[i // BLOCK, j // BLOCK, k // BLOCK] != 0
        if ok:
            ok = cells[(i * (ny - 1) + j) * (nz - 1) + k] != 0
        if not ok:
            if not contact_only:
                index[count] = q
                phi[count] = np.nan
                grad[count, 0] = np.nan
                grad[count, 1] = np.nan
                grad[count, 2] = np.nan
                p_out[count, 0] = y0
                p_out[count, 1] = y1
                p_out[count, 2] = y2
                count += 1
            continue
        value, g0, g1, g2 = _cell_interpolant(flat, si, sj, sk, i * si + j * sj + k * sk, u0 - i, u1 - j, u2 - k,
                                              half_h)
        if contact_only and (value >= 0.0 or -value > max_depth):
            continue
        norm = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        index[count] = q
        phi[count] = value
        grad[count, 0] = g0 / norm
        grad[count, 1] = g1 / norm
        grad[count, 2] = g2 / norm
        p_out[count, 0] = y0
        p_out[count, 1] = y1
        p_out[count, 2] = y2
        count += 1
    return count


@njit(cache=True)
def grid_derivatives(y, flat, ny, nz, origin, inv_h, dphi, Dg):
    """Exact derivatives of :func:`sample_grid`'s interpolants at points y (k, 3) m (B's
    frame) whose cells are valid (the rows it returned):

        ∇φ̂ = Σ_c ∇w_c [φ_c + ½ ∇φ_c·(y − x_c)] + ½ Σ_c w_c ∇φ_c           (dphi (k, 3))
        ∂g/∂y = (I − g gᵀ) (Σ_c ∇φ_c ∇w_cᵀ) / |ĝ|,  ĝ = Σ_c w_c ∇φ_c, g = ĝ/|ĝ|  (Dg (k, 3, 3), 1/m)

    with ∇w_c the gradients of the trilinear weights (1/m). ∇φ̂ differs from g by the
    interpolation error (O(h)); ∂g/∂y is the curvature of B as the grid sees it."""
    sk = 4
    sj = 4 * nz
    si = 4 * nz * ny
    half_h = 0.5 / inv_h
    for q in range(y.shape[0]):
        u0 = (y[q, 0] - origin[0]) * inv_h
        u1 = (y[q, 1] - origin[1]) * inv_h
        u2 = (y[q, 2] - origin[2]) * inv_h
        i, j, k = int(u0), int(u1), int(u2)
        f0, f1, f2 = u0 - i, u1 - j, u2 - k
        base = i * si + j * sj + k * sk
        d0 = d1 = d2 = 0.0  # ∇φ̂
        gh0 = gh1 = gh2 = 0.0  # ĝ
        G00 = G01 = G02 = G10 = G11 = G12 = G20 = G21 = G22 = 0.0  # Σ ∇φ_c ∇w_cᵀ
        for di in range(2):
            W0 = f0 if di == 1 else 1.0 - f0  # the corner's three 1-D weights and their slopes (1/m)
            S0 = inv_h if di == 1 else -inv_h
            for dj in range(2):
                W1 = f1 if dj == 1 else 1.0 - f1
                S1 = inv_h if dj == 1 else -inv_h
                for dk in range(2):
                    W2 = f2 if dk == 1 else 1.0 - f2
                    S2 = inv_h if dk == 1 else -inv_h
                    w = W0 * W1 * W2
                    c = base + di * si + dj * sj + dk * sk
                    n0, n1, n2 = flat[c + 1], flat[c + 2], flat[c + 3]
                    value = flat[c] + half_h * (n0 * (f0 - di) + n1 * (f1 - dj) + n2 * (f2 - dk))
                    gw0, gw1, gw2 = S0 * W1 * W2, W0 * S1 * W2, W0 * W1 * S2  # ∇w_c
                    d0 += gw0 * value + 0.5 * w * n0
                    d1 += gw1 * value + 0.5 * w * n1
                    d2 += gw2 * value + 0.5 * w * n2
                    gh0 += w * n0
                    gh1 += w * n1
                    gh2 += w * n2
                    G00 += n0 * gw0
                    G01 += n0 * gw1
                    G02 += n0 * gw2
                    G10 += n1 * gw0
                    G11 += n1 * gw1
                    G12 += n1 * gw2
                    G20 += n2 * gw0
                    G21 += n2 * gw1
                    G22 += n2 * gw2
        dphi[q, 0], dphi[q, 1], dphi[q, 2] = d0, d1, d2
        norm = np.sqrt(gh0 * gh0 + gh1 * gh1 + gh2 * gh2)
        g0, g1, g2 = gh0 / norm, gh1 / norm, gh2 / norm
        gG0 = g0 * G00 + g1 * G10 + g2 * G20  # gᵀ G
        gG1 = g0 * G01 + g1 * G11 + g2 * G21
        gG2 = g0 * G02 + g1 * G12 + g2 * G22
        Dg[q, 0, 0] = (G00 - g0 * gG0) / norm  # (G − g gᵀ G) / |ĝ|
        Dg[q, 0, 1] = (G01 - g0 * gG1) / norm
        Dg[q, 0, 2] = (G02 - g0 * gG2) / norm
        Dg[q, 1, 0] = (G10 - g1 * gG0) / norm
        Dg[q, 1, 1] = (G11 - g1 * gG1) / norm
        Dg[q, 1, 2] = (G12 - g1 * gG2) / norm
        Dg[q, 2, 0] = (G20 - g2 * gG0) / norm
        Dg[q, 2, 1] = (G21 - g2 * gG1) / norm
        Dg[q, 2, 2] = (G22 - g2 * gG2) / norm


@njit(cache=True)
def _cell_interpolant(flat, si, sj, sk, base, f0, f1, f2, half_h):
    """(φ̂ m, Σ_c w_c ∇φ_c (3 values, not normalised)) of :func:`sample_grid` at the point
    (f0, f1, f2) ∈ [0, 1]³ (fractions of a spacing) of the cell whose first node is at
    ``base`` in ``flat`` (the grid's values raveled, strides si, sj, sk):
    φ̂ = Σ_c w_c [φ_c + ½ ∇φ_c·(y − x_c)], with y − x_c = h (f − the corner's offset);
    half_h = h/2 (m)."""
    value = 0.0
    g0 = 0.0
    g1 = 0.0
    g2 = 0.0
    for di in range(2):
        w0 = f0 if di == 1 else 1.0 - f0
        for dj in range(2):
            w01 = w0 * (f1 if dj == 1 else 1.0 - f1)
            for dk in range(2):
                w = w01 * (f2 if dk == 1 else 1.0 - f2)
                c = base + di * si + dj * sj + dk * sk
                n0 = flat[c + 1]
                n1 = flat[c + 2]
                n2 = flat[c + 3]
                value += w * (flat[c] + half_h * (n0 * (f0 - di) + n1 * (f1 - dj) + n2 * (f2 - dk)))
                g0 += w * n0
                g1 += w * n1
                g2 += w * n2
    return value, g0, g1, g2


@njit(cache=True)
def _cell_value(flat, ny, nz, i, j, k, f0, f1, f2, half_h):
    """φ̂ (m) of :func:`sample_grid` at the point (f0, f1, f2) ∈ [0, 1]³ of cell (i, j, k)
    (:func:`_cell_interpolant`); ny, nz node counts."""
    sj = 4 * nz
    si = sj * ny
    return _cell_interpolant(flat, si, sj, np.int64(4), i * si + j * sj + k * 4, f0, f1, f2, half_h)[0]


@njit(cache=True)
def slope_bound(flat, ny, nz, i, j, k, inv_h):
    """A bound (m/m) of |∇φ̂| of :func:`sample_grid`'s φ̂ in the valid cell (i, j, k), from
    its node values.

    In the cell, with f ∈ [0, 1]³ the point's fractions of a spacing h, differentiating
    φ̂ = Σ_c w_c [φ_c + ½ h ∇φ_c·(f − o_c)] (o_c ∈ {0, 1}³ the corner's offset) along axis a
    gives ∂φ̂/∂y_a = Σ_e W_e T_e / h over the cell's 4 edges e along a, W_e ≥ 0 the bilinear
    weights of the other two axes (Σ W_e = 1) and, Δ the difference along e (far − near),
        T_e = Δφ + ½ h [Δ∂_aφ (2 f_a − 1) + Σ_{b≠a} Δ∂_bφ (f_b − o_b)],
    where |2 f_a − 1|, |f_b − o_b| ≤ 1. So |∂φ̂/∂y_a| ≤ B_a = max_e (|Δφ|/h + ½ |Δ∇φ|₁) and
    |∇φ̂| ≤ |B|. For the node values of a plane (φ linear, ∇φ = n) |B| = |n| = 1; curvature
    and the distance field's kinks add the differences of ∇φ (DM knee's femoral component,
    h = 0.5 mm: 1.02 at the median cell, 1.6 at the 99th percentile, 2.4 at the worst).

    flat: the grid's values raveled; ny, nz node counts; inv_h = 1/h (1/m)."""
    sk = 4
    sj = 4 * nz
    si = 4 * nz * ny
    B0 = 0.0
    B1 = 0.0
    B2 = 0.0
    for corner in range(8):  # the edges from the corners at offset 0 along their axis
        di, dj, dk = corner >> 2, (corner >> 1) & 1, corner & 1
        c = (i + di) * si + (j + dj) * sj + (k + dk) * sk
        for axis in range(3):
            if axis == 0 and di == 0:
                e = c + si
            elif axis == 1 and dj == 0:
                e = c + sj
            elif axis == 2 and dk == 0:
                e = c + sk
            else:
                continue
            T = (abs(flat[e] - flat[c]) * inv_h  # |Δφ|/h + ½ |Δ∇φ|₁
                 + 0.5 * (abs(flat[e + 1] - flat[c + 1]) + abs(flat[e + 2] - flat[c + 2])
                          + abs(flat[e + 3] - flat[c + 3])))
            if axis == 0:
                B0 = max(B0, T)
            elif axis == 1:
                B1 = max(B1, T)
            else:
                B2 = max(B2, T)
    return np.sqrt(B0 * B0 + B1 * B1 + B2 * B2)


@njit(cache=True)
def block_slopes(flat, cells, nx, ny, nz, inv_h, b, out):
    """out (⌈(nx−1)/b⌉, ⌈(ny−1)/b⌉, ⌈(nz−1)/b⌉) ← the largest :func:`slope_bound` (m/m) of
    the valid cells of each b×b×b block of cells, times 1 + 1e-6 (so that float32
    storage rounds it up), 0 where none is valid.

    flat, cells: the grid's values and cell mask raveled; nx, ny, nz node counts;
    inv_h 1/m; b int, the block edge in cells."""
    out[:, :, :] = 0.0
    for i in range(nx - 1):
        for j in range(ny - 1):
            for k in range(nz - 1):
                if cells[(i * (ny - 1) + j) * (nz - 1) + k] != 0:
                    L = slope_bound(flat, ny, nz, i, j, k, inv_h) * (1.0 + 1e-6)
                    if L > out[i // b, j // b, k // b]:
                        out[i // b, j // b, k // b] = L


@njit(cache=True)
def _may_contact(phi, change, max_depth, spare):
    """Whether a φ̂ within ``change`` (m) of ``phi`` (m) can be in contact, −max_depth ≤
    φ̂ < 0, with ``spare`` (m) for rounding."""
    return phi - change < spare and phi + change >= -max_depth - spare


@njit(cache=True)
def grid_candidates(points, R, t, flat, cells, slopes, nx, ny, nz, origin, inv_h, max_depth, r, index):
    """The points that :func:`sample_grid` (contact_only) can find in contact,
    −max_depth ≤ φ̂ < 0, after each moved by at most reach = r·h (r ≤ ½, h the spacing)
    from y = R·x + t. No other point can be sampled in contact at such a pose, so
    sampling only these gives the same rows.

    A point y' within reach of y has a value only in a valid cell C (``cells`` mask ≠ 0)
    met by the ball of radius reach about y, hence by the cube of half-edge reach about y:
    2×2×2 cells (y ± r h are exact for r = ½; a point whose rounded cube spans 3 cells
    along an axis, possible when r is within rounding of ½, is kept). Let L bound |∇φ̂|
    over the cube's cells (``slopes``, per block of cells). If the cells of the box
    spanned by y's own cell O and C are all valid, the segment y y' stays in them (the
    box is convex), where φ̂ is continuous with |∇φ̂| ≤ L: |φ̂(y') − φ̂(y)| ≤ L·reach.
    Otherwise (O or a cell between invalid), from the point p_C of C nearest y:
    |φ̂(y') − φ̂(p_C)| ≤ L·|y' − p_C|, and C being convex, (y − p_C)·(y' − p_C) ≤ 0, so
    |y' − p_C|² ≤ reach² − |y − p_C|². A point is kept when one of its cells C within
    reach allows contact by these bounds (reach²(1 + 1e-9) in place of reach² and
    1e-9·reach to spare for rounding).

    points (n, 3) m, R (3, 3), t (3,) m; the grid's values and cells raveled,
    :attr:`SignedDistanceGrid.block_slope` (0 where no cell is valid), its node counts,
    origin (3,) m and 1/spacing (1/m); max_depth m; r, the reach in spacings; index (n,)
    int, written. Returns the count written (increasing point numbers)."""
    if not 0.0 <= r <= 0.5:
        raise ValueError("grid_candidates: the reach must be at most half a grid spacing")
    reach = r / inv_h  # m
    half_h = 0.5 / inv_h
    spare = 1e-9 * reach  # m, for rounding
    count = 0
    for q in range(points.shape[0]):
        x0 = points[q, 0]
        x1 = points[q, 1]
        x2 = points[q, 2]
        u0 = (R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2 + t[0] - origin[0]) * inv_h
        u1 = (R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2 + t[1] - origin[1]) * inv_h
        u2 = (R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2 + t[2] - origin[2]) * inv_h
        # the cube's cells i0..i1 (i1 ≤ i0 + 1), clipped to the grid
        a0, b0 = int(np.floor(u0 - r)), int(np.floor(u0 + r))
        a1, b1 = int(np.floor(u1 - r)), int(np.floor(u1 + r))
        a2, b2 = int(np.floor(u2 - r)), int(np.floor(u2 + r))
        i0, i1 = max(a0, 0), min(b0, nx - 2)
        j0, j1 = max(a1, 0), min(b1, ny - 2)
        k0, k1 = max(a2, 0), min(b2, nz - 2)
        if i0 > i1 or j0 > j1 or k0 > k1:
            continue
        if b0 - a0 > 1 or b1 - a1 > 1 or b2 - a2 > 1:  # rounding of u ± r (r ≈ ½): kept
            index[count] = q
            count += 1
            continue
        # L from the block array (small; 0 where no cell is valid, as for most points)
        bi0, bi1, bj0, bj1, bk0, bk1 = i0 // BLOCK, i1 // BLOCK, j0 // BLOCK, j1 // BLOCK, k0 // BLOCK, k1 // BLOCK
        L = max(max(max(slopes[bi0, bj0, bk0], slopes[bi0, bj0, bk1]),
                    max(slopes[bi0, bj1, bk0], slopes[bi0, bj1, bk1])),
                max(max(slopes[bi1, bj0, bk0], slopes[bi1, bj0, bk1]),
                    max(slopes[bi1, bj1, bk0], slopes[bi1, bj1, bk1])))
        if L == 0.0:
            continue
        # valid cells of the cube: bit 4 di + 2 dj + dk for cell (i0 + di, j0 + dj, k0 + dk)
        valid = 0
        for c in range(8):
            i, j, k = i0 + (c >> 2), j0 + ((c >> 1) & 1), k0 + (c & 1)
            if i <= i1 and j <= j1 and k <= k1 and cells[(i * (ny - 1) + j) * (nz - 1) + k] != 0:
                valid |= 1 << c
        if valid == 0:
            continue
        # y's own cell O (bit o; −1: outside the grid or invalid) and φ̂(y); C = O is within reach
        io, jo, ko = int(np.floor(u0)), int(np.floor(u1)), int(np.floor(u2))
        o = -1
        if 0 <= io - i0 <= 1 and 0 <= jo - j0 <= 1 and 0 <= ko - k0 <= 1:
            o = 4 * (io - i0) + 2 * (jo - j0) + (ko - k0)
            if (valid >> o) & 1 == 0:
                o = -1
        keep = False
        phi_y = 0.0
        if o >= 0:
            phi_y = _cell_value(flat, ny, nz, io, jo, ko, u0 - io, u1 - jo, u2 - ko, half_h)
            keep = _may_contact(phi_y, L * reach, max_depth, spare)
        c = 0
        while not keep and c < 8:
            if (valid >> c) & 1 != 0 and c != o:
                if o >= 0:  # the cells of the box spanned by O and C: per axis, the cells at O's or C's offset
                    box = (((0xF0 if o & 4 != 0 else 0x0F) | (0xF0 if c & 4 != 0 else 0x0F))
                           & ((0xCC if o & 2 != 0 else 0x33) | (0xCC if c & 2 != 0 else 0x33))
                           & ((0xAA if o & 1 != 0 else 0x55) | (0xAA if c & 1 != 0 else 0x55)))
                    between = box & valid == box
                else:
                    between = False
                if not between:  # (else C allows contact only if O does, and O does not)
                    i, j, k = i0 + (c >> 2), j0 + ((c >> 1) & 1), k0 + (c & 1)
                    p0 = min(max(u0, i), i + 1.0)  # p_C
                    p1 = min(max(u1, j), j + 1.0)
                    p2 = min(max(u2, k), k + 1.0)
                    # y' in C within reach: |y' − p_C|² ≤ |y' − y|² − |y − p_C|² (spacings²)
                    rest = r * r * (1.0 + 1e-9) - ((p0 - u0) ** 2 + (p1 - u1) ** 2 + (p2 - u2) ** 2)
                    if rest >= 0.0:
                        phi = _cell_value(flat, ny, nz, i, j, k, p0 - i, p1 - j, p2 - k, half_h)
                        keep = _may_contact(phi, L * np.sqrt(rest) / inv_h, max_depth, spare)
            c += 1
        if keep:
            index[count] = q
            count += 1
    return count


def band_occupancy(mesh: SurfaceMesh, max_depth: float, voxel: float):
    """Coarse boolean voxels covering every point within the band behind ``mesh``.

    No distance is computed: voxel centres inside the swept, inflated triangle boxes of
    :func:`_swept_face_boxes` (depth ``max_depth``) are marked. A point within the band
    (−max_depth ≤ φ ≤ 0) always rounds to a marked voxel centre, so the mask culls
    points before exact closest-point queries without losing any contact.

    Returns mask (nx, ny, nz) bool, origin_B (3,) m of voxel centre (0, 0, 0), voxel m.
    """
    V = mesh.vertices_B
    pad = max_depth + voxel
    lo = V.min(axis=0) - pad
    hi = V.max(axis=0) + pad
    shape = tuple(int(np.ceil((hi[d] - lo[d]) / voxel)) + 1 for d in range(3))
    mask = np.zeros(shape, dtype=np.bool_)
    box_lo, box_hi = _swept_face_boxes(mesh, max_depth, 1e-6)
    half_diagonal = 0.5 * np.sqrt(3.0) * voxel
    _mark_boxes(box_lo - half_diagonal, box_hi + half_diagonal, lo, 1.0 / voxel, mask)
    return mask, lo, float(voxel)


def _difference_gradient(phi, grad_exact, h):
    """Node gradients (nx, ny, nz, 3) of φ by central differences of the node values.

    The exact gradient of a faceted surface's distance field is piecewise constant (a
    face normal per closest triangle); sampling it at nodes aliases with the triangle
    size. Central differences average the slope over 2h instead, so that the interpolated
    normals, like the interpolated depths, converge to the mesh's mean slope. Where a
    neighbour is NaN a one-sided difference is used, and the exact gradient where both are.
    """
    grad = grad_exact.copy()
    for axis in range(3):
        ahead = np.full_like(phi, np.nan)
        behind = np.full_like(phi, np.nan)
        sl_a = [slice(None)] * 3
        sl_b = [slice(None)] * 3
        sl_a[axis] = slice(0, -1)
        sl_b[axis] = slice(1, None)
        ahead[tuple(sl_a)] = phi[tuple(sl_b)]  # φ at i + 1
        behind[tuple(sl_b)] = phi[tuple(sl_a)]  # φ at i − 1
        central = (ahead - behind) / (2.0 * h)
        forward = (ahead - phi) / h
        backward = (phi - behind) / h
        g = np.where(np.isfinite(central), central,
                     np.where(np.isfinite(forward), forward,
                              np.where(np.isfinite(backward), backward, grad_exact[..., axis])))
        grad[..., axis] = g
    return grad


def build_distance_grid(mesh: SurfaceMesh, spacing: float, max_depth: float,
                        *, chunk: int = 200_000) -> SignedDistanceGrid:
    """Sample the exact signed distance of ``mesh`` on a narrow-band grid (not cached).

    Parameters
    ----------
    mesh : SurfaceMesh — the surface, in its body frame.
    spacing : float, m — node spacing h.
    max_depth : float, m — deepest penetration to represent; band half-width
        w = max_depth + 2h.
    chunk : int — nodes per libigl query (bounds temporary memory).
    """
    if not spacing > 0.0:
        raise ValueError(f"grid spacing for mesh '{mesh.name}' must be > 0 m, got {spacing!r}")
    if not max_depth > 0.0:
        raise ValueError(f"max_depth for mesh '{mesh.name}' must be > 0 m, got {max_depth!r}")
    h = float(spacing)
    from .limits import check_grid_memory

    check_grid_memory(mesh.name, mesh.vertices_B, h, float(max_depth))  # before any allocation
    width = float(max_depth) + 2.0 * h
    V = np.ascontiguousarray(mesh.vertices_B, dtype=np.float64)
    lo = V.min(axis=0) - width
    hi = V.max(axis=0) + width
    shape = tuple(int(np.ceil((hi[d] - lo[d]) / h)) + 1 for d in range(3))
    # centre the lattice on the box: a mirrored surface then gets the mirrored lattice
    # (left/right symmetric joints see the same interpolation error on both sides)
    lo = 0.5 * (lo + hi) - 0.5 * h * (np.array(shape) - 1)
    n_nodes = shape[0] * shape[1] * shape[2]
    if n_nodes > 400_000_000:
        raise ValueError(
            f"distance grid for mesh '{mesh.name}' would need {n_nodes:.3g} nodes at "
            f"spacing {h * 1e3:g} mm; use a larger spacing or a smaller mesh region"
        )
    # narrow band: nodes with −(max_depth + 2h) ≤ φ ≤ 2h are needed (a cell touching a
    # point with φ ≤ 0 has corners within √3·h of it)
    front = 2.0 * h
    mark = np.zeros(shape, dtype=np.bool_)
    box_lo, box_hi = _swept_face_boxes(mesh, width, front)
    _mark_boxes(box_lo, box_hi, lo, 1.0 / h, mark)
    flat = np.flatnonzero(mark.ravel())
    phi_nodes = np.full(n_nodes, np.nan)
    grad_nodes = np.full((n_nodes, 3), np.nan)
    exact = OpenSurfaceDistance(mesh)
    for start in range(0, flat.size, chunk):
        ids = flat[start : start + chunk]
        ijk = np.stack(np.unravel_index(ids, shape), axis=1)
        p_BN = lo + h * ijk
        phi, normal_B, valid, _ = exact.query(p_BN)
        keep = valid & (phi >= -width) & (phi <= front)
        phi_nodes[ids[keep]] = phi[keep]
        grad_nodes[ids[keep]] = normal_B[keep]
    phi_nodes = phi_nodes.reshape(shape)
    grad_nodes = _difference_gradient(phi_nodes, grad_nodes.reshape(shape + (3,)), h)
    values = np.empty(shape + (4,), dtype=np.float32)
    values[..., 0] = phi_nodes
    values[..., 1:] = grad_nodes
    values.setflags(write=False)
    finite = np.isfinite(phi_nodes)
    cell_valid = np.ones((shape[0] - 1, shape[1] - 1, shape[2] - 1), dtype=np.uint8)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                cell_valid &= finite[di : shape[0] - 1 + di, dj : shape[1] - 1 + dj,
                                     dk : shape[2] - 1 + dk]
    cell_valid.setflags(write=False)
    origin = lo.copy()
    origin.setflags(write=False)
    return SignedDistanceGrid(values, cell_valid, origin, h, float(max_depth), mesh.name, int(flat.size))
