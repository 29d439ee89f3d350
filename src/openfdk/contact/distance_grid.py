"""Precomputed signed-distance grid of an open surface, queried by a numba trilinear kernel.

The grid covers the surface's body-frame bounding box inflated by the band half-width
``w = max_depth + 2h`` (h = spacing). Only nodes within ``w`` of some triangle (found by
marking each triangle's inflated bounding box) are evaluated, with the exact method of
:class:`~openfdk.contact.signed_distance.OpenSurfaceDistance`; every node stores
``[φ, ∂φ/∂x, ∂φ/∂y, ∂φ/∂z]`` (float32). Nodes outside the band, and nodes whose closest
point is on the boundary rim, hold φ = NaN.

Query: trilinear interpolation of φ and of the stored gradient field; a point whose cell
has any NaN corner is "not in contact" (this trims about one cell from the rim). The
interpolated gradient is normalised to give the outward unit normal. Interpolation error
of φ is ≈ (h²/8)·Σ|∂²φ/∂x_k²| ≈ h²/(4ρ) for a surface with curvature radius ρ, plus the
kinks of the faceted surface's distance field (see docs/contact.md for measurements).

Memory: 16 bytes per node over the box, ∝ box volume / h³.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numba import njit

from .mesh import SurfaceMesh
from .signed_distance import OpenSurfaceDistance

__all__ = ["SignedDistanceGrid", "build_distance_grid", "cached_distance_grid",
           "clear_grid_cache"]


@dataclass(frozen=True, eq=False)
class SignedDistanceGrid:
    """Signed-distance samples of one surface on a regular grid in its body frame B.

    Attributes
    ----------
    values : (nx, ny, nz, 4) float32 — [φ m, ∇φ (3,)] at the nodes; φ = NaN where unused.
    origin_B : (3,) m — position of node (0, 0, 0) in B.
    spacing : float, m — node spacing h.
    max_depth : float, m — deepest penetration the band was built for.
    mesh_name : str
    n_evaluated : int — number of nodes evaluated exactly (the narrow band).
    """

    values: np.ndarray
    origin_B: np.ndarray
    spacing: float
    max_depth: float
    mesh_name: str
    n_evaluated: int

    @property
    def shape(self):
        return self.values.shape[:3]

    @property
    def nbytes(self) -> int:
        return int(self.values.nbytes)

    def query(self, p_BQ):
        """Interpolated signed distance at points.

        Parameters: p_BQ : (k, 3) m, points in B.
        Returns phi (k,) m (NaN where the cell is outside the band or touches the rim),
        normal_B (k, 3) unit (NaN likewise).
        """
        P = np.ascontiguousarray(p_BQ, dtype=np.float64).reshape(-1, 3)
        phi = np.empty(P.shape[0])
        normal = np.empty((P.shape[0], 3))
        _query_points(P, self.values, self.origin_B, 1.0 / self.spacing, phi, normal)
        return phi, normal


@njit(cache=True)
def _mark_band(V, F, origin, inv_h, width, mark):
    """mark[i, j, k] = True for nodes inside any triangle's bounding box inflated by width."""
    nx, ny, nz = mark.shape
    for f in range(F.shape[0]):
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        for d in range(3):
            a = min(V[F[f, 0], d], V[F[f, 1], d], V[F[f, 2], d]) - width
            b = max(V[F[f, 0], d], V[F[f, 1], d], V[F[f, 2], d]) + width
            lo[d] = max(int(np.ceil((a - origin[d]) * inv_h)), 0)
            hi[d] = int(np.floor((b - origin[d]) * inv_h))
        hi[0] = min(hi[0], nx - 1)
        hi[1] = min(hi[1], ny - 1)
        hi[2] = min(hi[2], nz - 1)
        for i in range(lo[0], hi[0] + 1):
            for j in range(lo[1], hi[1] + 1):
                for k in range(lo[2], hi[2] + 1):
                    mark[i, j, k] = True


@njit(cache=True)
def trilinear_sample(values, origin, inv_h, y0, y1, y2, out):
    """Trilinear interpolation of [φ, ∇φ] at one point (y0, y1, y2) m in B.

    Writes out[0] = φ (m), out[1:4] = interpolated gradient (not normalised); returns
    False when the point is outside the grid or its cell has a NaN corner.
    """
    nx, ny, nz = values.shape[0], values.shape[1], values.shape[2]
    u0 = (y0 - origin[0]) * inv_h
    u1 = (y1 - origin[1]) * inv_h
    u2 = (y2 - origin[2]) * inv_h
    if not (u0 >= 0.0 and u1 >= 0.0 and u2 >= 0.0):
        return False
    i = int(u0)
    j = int(u1)
    k = int(u2)
    if i >= nx - 1 or j >= ny - 1 or k >= nz - 1:
        return False
    f0 = u0 - i
    f1 = u1 - j
    f2 = u2 - k
    for c in range(4):
        out[c] = 0.0
    # out = Σ_corners w_corner · values[corner],  w = Π (f or 1 − f)
    for di in range(2):
        w0 = f0 if di == 1 else 1.0 - f0
        for dj in range(2):
            w01 = w0 * (f1 if dj == 1 else 1.0 - f1)
            for dk in range(2):
                w = w01 * (f2 if dk == 1 else 1.0 - f2)
                node = values[i + di, j + dj, k + dk]
                if np.isnan(node[0]):
                    return False
                for c in range(4):
                    out[c] += w * node[c]
    return True


@njit(cache=True)
def _query_points(P, values, origin, inv_h, phi, normal):
    out = np.empty(4)
    for q in range(P.shape[0]):
        if trilinear_sample(values, origin, inv_h, P[q, 0], P[q, 1], P[q, 2], out):
            phi[q] = out[0]
            norm = np.sqrt(out[1] ** 2 + out[2] ** 2 + out[3] ** 2)
            for c in range(3):
                normal[q, c] = out[1 + c] / norm
        else:
            phi[q] = np.nan
            for c in range(3):
                normal[q, c] = np.nan


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
    width = float(max_depth) + 2.0 * h
    V = np.ascontiguousarray(mesh.vertices_B, dtype=np.float64)
    F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    lo = V.min(axis=0) - width
    hi = V.max(axis=0) + width
    shape = tuple(int(np.ceil((hi[d] - lo[d]) / h)) + 1 for d in range(3))
    n_nodes = shape[0] * shape[1] * shape[2]
    if n_nodes > 400_000_000:
        raise ValueError(
            f"distance grid for mesh '{mesh.name}' would need {n_nodes:.3g} nodes at "
            f"spacing {h * 1e3:g} mm; use a larger spacing or a smaller mesh region"
        )
    mark = np.zeros(shape, dtype=np.bool_)
    _mark_band(V, F, lo, 1.0 / h, width, mark)
    flat = np.flatnonzero(mark.ravel())
    values = np.full((n_nodes, 4), np.nan, dtype=np.float32)
    exact = OpenSurfaceDistance(mesh)
    for start in range(0, flat.size, chunk):
        ids = flat[start : start + chunk]
        ijk = np.stack(np.unravel_index(ids, shape), axis=1)
        p_BN = lo + h * ijk
        phi, normal_B, valid, _ = exact.query(p_BN)
        keep = valid & (phi >= -width) & (phi <= width)
        values[ids[keep], 0] = phi[keep]
        values[ids[keep], 1:] = normal_B[keep]
    values = values.reshape(shape + (4,))
    values.setflags(write=False)
    origin = lo.copy()
    origin.setflags(write=False)
    return SignedDistanceGrid(values, origin, h, float(max_depth), mesh.name, int(flat.size))


_CACHE: "OrderedDict[tuple, SignedDistanceGrid]" = OrderedDict()
_CACHE_SIZE = 16


def _fingerprint(mesh: SurfaceMesh) -> str:
    digest = hashlib.sha1()
    digest.update(np.ascontiguousarray(mesh.vertices_B).tobytes())
    digest.update(np.ascontiguousarray(mesh.faces).tobytes())
    return digest.hexdigest()


def cached_distance_grid(mesh: SurfaceMesh, spacing: float, max_depth: float) -> SignedDistanceGrid:
    """:func:`build_distance_grid`, memoised in memory by mesh content, spacing and depth.

    Contact pairs that share a surface (e.g. the models of a parameter study in one
    process) share its grid. At most 16 grids are kept (least recently used dropped).
    """
    key = (_fingerprint(mesh), float(spacing), float(max_depth))
    grid = _CACHE.get(key)
    if grid is None:
        grid = build_distance_grid(mesh, spacing, max_depth)
        _CACHE[key] = grid
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return grid


def clear_grid_cache() -> None:
    """Drop every cached distance grid."""
    _CACHE.clear()
