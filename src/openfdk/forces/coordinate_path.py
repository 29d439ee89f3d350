"""Muscle paths whose points depend on joint coordinates (OpenSim's ConditionalPathPoint
and MovingPathPoint).

A path is a chain of body points; besides fixed points it may hold

* **conditional points**, in the path only while a coordinate u lies in [lo, hi]
  (OpenSim's test: lo − 1e-5 ≤ u ≤ hi + 1e-5); the path switches when u crosses a bound,
  and so do its length and moment arms (as in OpenSim);
* **moving points**, whose location in a frame F of their body is a function of a
  coordinate per axis: p_F = (f_x(u), f_y(u), f_z(u)), with u clamped to its coordinate's
  range as OpenSim clamps it (a constant axis keeps its value). In the body frame
  p_B = p_BF + R_BF p_F.

Length: l = Σ |p_{k+1} − p_k| over consecutive *active* points (world positions
p = r + R p_B). Jacobian (moment arms): with e_k the unit segment directions and M the
point Jacobians, L = Σ e_kᵀ (M_{k+1} − M_k), where a moving point's M adds
R R_BF f′(u) ∂u/∂q̂ to the rigid part [I, −R [p_B]×] (∂p/∂δπ' of a body point; zero
f′ where u is clamped). A conditional point changes only which points are summed.
The acceleration bias b = L̇ v (a path length used as a driven measure) is a central
difference of L along v on the manifold, as for wrapped paths.

Coordinates are the model's named scalar measures (compiled once for every path of a
set, :class:`CoordinatePathNodes`); one numba kernel evaluates all paths.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..model.coordinate_functions import pp_evaluate
from ..model.measures import Measure

__all__ = ["PathNode", "CoordinatePath", "CoordinatePathNodes"]

#: OpenSim's tolerance on a conditional point's range (ConditionalPathPoint::isActive), rad or m
CONDITION_TOLERANCE = 1e-5


@dataclass(frozen=True, eq=False)
class PathNode:
    """One point of a coordinate-dependent path.

    body : body index; p_BF (3,) m and R_BF (3, 3): the frame F of the point in the body
    (a fixed or conditional point: its location is p_BF); condition : None or
    (coordinate measure, lo, hi) — active while lo ≤ u ≤ hi; moving : None or
    (coordinate measure, u_min, u_max, (f_x, f_y, f_z)) with each f a PiecewisePolynomial
    of u (m) or a float (m, constant), u clamped to [u_min, u_max]."""

    body: int
    p_BF: np.ndarray
    R_BF: np.ndarray
    condition: tuple = None
    moving: tuple = None


class CoordinatePathNodes:
    """The node arrays of one or more coordinate-dependent paths, and their coordinates'
    compiled program: ``evaluate(state)`` -> l (n_paths,) m, L (n_paths, n)."""

    def __init__(self, paths, names):
        from ..model.compiled import CompiledMeasures

        coords, index = [], {}

        def coordinate(measure):
            if id(measure) not in index:
                index[id(measure)] = len(coords)
                coords.append(measure)
            return index[id(measure)]

        body, p_BF, R_BF, cond, cond_lo, cond_hi, move, move_lo, move_hi = ([] for _ in range(9))
        fn_start, fparams, start = [], [], [0]
        for nodes in paths:
            for n in nodes:
                body.append(n.body)
                p_BF.append(np.asarray(n.p_BF, float))
                R_BF.append(np.asarray(n.R_BF, float))
                if n.condition is not None:
                    m, lo, hi = n.condition
                    cond.append(coordinate(m))
                    cond_lo.append(lo)
                    cond_hi.append(hi)
                else:
                    cond.append(-1)
                    cond_lo.append(0.0)
                    cond_hi.append(0.0)
                starts = [-1, -1, -1]
                values = [0.0, 0.0, 0.0]
                if n.moving is not None:
                    m, lo, hi, fns = n.moving
                    move.append(coordinate(m))
                    move_lo.append(lo)
                    move_hi.append(hi)
                    for a, f in enumerate(fns):
                        if isinstance(f, (int, float)):
                            values[a] = float(f)
                        else:
                            starts[a] = len(fparams)
                            fparams.extend(f.to_params())
                else:
                    move.append(-1)
                    move_lo.append(0.0)
                    move_hi.append(0.0)
                fn_start.append(starts)
                if n.moving is not None:  # constant axes of a moving point: their value in F
                    p_BF[-1] = np.concatenate([p_BF[-1], values])
                else:
                    p_BF[-1] = np.concatenate([p_BF[-1], np.zeros(3)])
            start.append(len(body))
        self.names = list(names)
        self.n_paths = len(self.names)
        self.coordinates = tuple(coords)  # the program's scalar measures, in its row order
        self.program = CompiledMeasures(coords)
        self.body = np.array(body, np.int64)
        self.p = np.array(p_BF, float).reshape(-1, 6)  # [p_BF (3), constant p_F (3)]
        self.R_BF = np.array(R_BF, float).reshape(-1, 3, 3)
        self.cond = np.array(cond, np.int64)
        self.cond_range = np.column_stack([cond_lo, cond_hi]).astype(float).reshape(-1, 2)
        self.move = np.array(move, np.int64)
        self.move_range = np.column_stack([move_lo, move_hi]).astype(float).reshape(-1, 2)
        self.fn_start = np.array(fn_start, np.int64).reshape(-1, 3)
        self.fparams = np.array(fparams + [0.0], float)
        self.start = np.array(start, np.int64)

    def evaluate(self, state):
        """l (n_paths,) m and L (n_paths, n_coords); FloatingPointError naming the path
        when two consecutive active points coincide (no direction)."""
        u, U, _ = self.program.evaluate(state, 1)
        return self.evaluate_with(state, u, U)

    def evaluate_with(self, state, u, U):
        """:meth:`evaluate` with the coordinates' values u (n_c,) and gradients U
        (n_c, n_coords) given: a U with rows zeroed leaves those coordinates' term of the
        moving points out of L (the points held where u puts them)."""
        l, L, bad = coordinate_path_lengths(
            state.p_WB, state.R_WB, state.column, u, U, self.body, self.p, self.R_BF, self.cond, self.cond_range,
            self.move, self.move_range, self.fn_start, self.fparams, self.start, state.n_coords)
        if bad >= 0:
            raise FloatingPointError(f"path {self.names[bad]!r}: two consecutive active points coincide")
        return l, L


@njit(cache=True)
def _point(k, R_WB, p_WB, u, body, p, R_BF, move, move_range, fn_start, fparams, out_p, out_dp):
    """World position (out_p (3,)) of node k and, for a moving point, R_WB R_BF f′(u)
    (out_dp (3,), zero otherwise or where u is clamped)."""
    b = body[k]
    p_F = np.empty(3)
    df = np.zeros(3)
    for a in range(3):
        p_F[a] = p[k, 3 + a]
    if move[k] >= 0:
        x = u[move[k]]
        clamped = x < move_range[k, 0] or x > move_range[k, 1]
        x = min(max(x, move_range[k, 0]), move_range[k, 1])
        for a in range(3):
            s = fn_start[k, a]
            if s >= 0:
                f, d1, _ = pp_evaluate(fparams, s, x)
                p_F[a] = f
                df[a] = 0.0 if clamped else d1
    for r in range(3):
        p_B = p[k, r]
        d_B = 0.0
        for c in range(3):
            p_B += R_BF[k, r, c] * p_F[c]
            d_B += R_BF[k, r, c] * df[c]
        out_dp[r] = d_B  # in B for now
        out_p[r] = p_B   # p_B for now
    # world: p = r + R p_B; dp = R (R_BF f′)
    pw = np.empty(3)
    dw = np.empty(3)
    for r in range(3):
        pw[r] = p_WB[b, r]
        dw[r] = 0.0
        for c in range(3):
            pw[r] += R_WB[b, r, c] * out_p[c]
            dw[r] += R_WB[b, r, c] * out_dp[c]
    p_B0, p_B1, p_B2 = out_p[0], out_p[1], out_p[2]
    for r in range(3):
        out_p[r] = pw[r]
        out_dp[r] = dw[r]
    return p_B0, p_B1, p_B2


@njit(cache=True)
def _add_point_jacobian(L, row, sign, e, b, column, R, p_B0, p_B1, p_B2, dw, move_k, U):
    """L[row] += sign eᵀ M of a point: eᵀ[I, −R [p_B]×] on its body's columns, and
    eᵀ dw ∂u/∂q̂ of a moving point."""
    c = column[b]
    if c >= 0:
        # eᵀ(−R [p]×) = (p × Rᵀe)ᵀ
        g0 = R[0, 0] * e[0] + R[1, 0] * e[1] + R[2, 0] * e[2]
        g1 = R[0, 1] * e[0] + R[1, 1] * e[1] + R[2, 1] * e[2]
        g2 = R[0, 2] * e[0] + R[1, 2] * e[1] + R[2, 2] * e[2]
        L[row, c] += sign * e[0]
        L[row, c + 1] += sign * e[1]
        L[row, c + 2] += sign * e[2]
        L[row, c + 3] += sign * (p_B1 * g2 - p_B2 * g1)
        L[row, c + 4] += sign * (p_B2 * g0 - p_B0 * g2)
        L[row, c + 5] += sign * (p_B0 * g1 - p_B1 * g0)
    if move_k >= 0:
        s = sign * (e[0] * dw[0] + e[1] * dw[1] + e[2] * dw[2])
        if s != 0.0:
            for j in range(U.shape[1]):
                L[row, j] += s * U[move_k, j]


@njit(cache=True)
def coordinate_path_lengths(p_WB, R_WB, column, u, U, body, p, R_BF, cond, cond_range, move, move_range, fn_start,
                            fparams, start, n):
    """Lengths l (n_paths,) m and Jacobians L (n_paths, n) of the paths (module
    docstring); returns also the index of a path with coincident consecutive points
    (−1: none). u (n_c,), U (n_c, n): the coordinates' values and Jacobians."""
    n_paths = start.shape[0] - 1
    l = np.zeros(n_paths)
    L = np.zeros((n_paths, n))
    bad = -1
    pa = np.empty(3)
    da = np.empty(3)
    pb = np.empty(3)
    db = np.empty(3)
    e = np.empty(3)
    for q in range(n_paths):
        prev = -1
        a0 = a1 = a2 = 0.0
        for k in range(start[q], start[q + 1]):
            if cond[k] >= 0:
                x = u[cond[k]]
                if x < cond_range[k, 0] - CONDITION_TOLERANCE or x > cond_range[k, 1] + CONDITION_TOLERANCE:
                    continue
            b0, b1, b2 = _point(k, R_WB, p_WB, u, body, p, R_BF, move, move_range, fn_start, fparams, pb, db)
            if prev >= 0:
                length = 0.0
                for r in range(3):
                    e[r] = pb[r] - pa[r]
                    length += e[r] * e[r]
                length = np.sqrt(length)
                if length == 0.0:
                    if bad < 0:
                        bad = q
                    continue
                for r in range(3):
                    e[r] /= length
                l[q] += length
                _add_point_jacobian(L, q, 1.0, e, body[k], column, R_WB[body[k]], b0, b1, b2, db, move[k], U)
                _add_point_jacobian(L, q, -1.0, e, body[prev], column, R_WB[body[prev]], a0, a1, a2, da, move[prev],
                                    U)
            prev = k
            a0, a1, a2 = b0, b1, b2
            for r in range(3):
                pa[r] = pb[r]
                da[r] = db[r]
    return l, L, bad


@njit(cache=True)
def coordinate_points(p_WB, R_WB, u, body, p, R_BF, cond, cond_range, move, move_range, fn_start, fparams):
    """Per node of the arrays of :class:`CoordinatePathNodes`: present (N,) bool (a
    conditional point in its range, every other point), p_B (N, 3) m the point in its
    body frame, dX_W (N, 3) m its world velocity per unit of its moving coordinate (zero
    for other points or where the coordinate is clamped); u (n_c,): coordinate values.
    The input of :func:`openfdk.forces.wrap_kernels.wrapped_moving_path_lengths`."""
    N = body.shape[0]
    present = np.ones(N, dtype=np.bool_)
    p_B = np.empty((N, 3))
    dX_W = np.zeros((N, 3))
    pw = np.empty(3)
    dw = np.empty(3)
    for k in range(N):
        if cond[k] >= 0:
            x = u[cond[k]]
            present[k] = cond_range[k, 0] - CONDITION_TOLERANCE <= x <= cond_range[k, 1] + CONDITION_TOLERANCE
        b0, b1, b2 = _point(k, R_WB, p_WB, u, body, p, R_BF, move, move_range, fn_start, fparams, pw, dw)
        p_B[k, 0], p_B[k, 1], p_B[k, 2] = b0, b1, b2
        for r in range(3):
            dX_W[k, r] = dw[r]
    return present, p_B, dX_W


class CoordinatePath(Measure):
    """Length (m) of a path through fixed, conditional and moving points (a scalar
    measure; module docstring). nodes : list of :class:`PathNode`. ``evaluate`` gives
    (l (1,), L (1, n), b (1,)); b = L̇ v by a central difference of L along v."""

    size = 1
    units = ("length",)

    def __init__(self, nodes, name=""):
        self.nodes = list(nodes)
        self.name = name
        self.kernel = CoordinatePathNodes([self.nodes], [name])

    def bodies(self):
        out = {int(n.body) for n in self.nodes}
        for n in self.nodes:
            for spec in (n.condition, n.moving):
                if spec is not None:
                    out.update(spec[0].bodies())
        return tuple(sorted(out))

    def evaluate(self, state, order=1):
        from .wrapping import path_evaluate

        return path_evaluate(self.kernel, state, order)
