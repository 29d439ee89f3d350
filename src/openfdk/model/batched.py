"""Rows of many relative-vector measures in one numba call.

Most constraint and FDK rows of joint models are projections of a relative vector:
a :class:`~openfdk.model.measures.Linear` measure C w + offset of one
:class:`~openfdk.model.measures.RelativeVector` w = R_kᵀ (p_b − p_a) (a point-on-plane
row, an FDK DOF along a plane normal, a medio-lateral component). Evaluated one by one,
each row pays a Python call chain and a numba dispatch (≈ 15 µs) for a few hundred
flops. :class:`RelativeVectorRows` stacks such measures once and evaluates all their
rows, value, Φ_q̂-rows and b (Eq. 3), in a single kernel call; the maths is the one of
:func:`~openfdk.model.kernels.relative_vector` followed by the product with C.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .kernels import relative_vector
from .measures import Linear, RelativeVector

__all__ = ["RelativeVectorRows", "ScalarRows"]


class RelativeVectorRows:
    """The rows of a list of measures, each a RelativeVector or one-term Linears of one.

    Build with :meth:`from_measures` (None when a measure is of another kind). Rows are
    in the order of the measures and, within one, of its rows.
    """

    def __init__(self, ia, s_a, ib, s_b, frame, term, C, offset):
        self.ia, self.s_a, self.ib, self.s_b, self.frame = ia, s_a, ib, s_b, frame
        self.term, self.C, self.offset = term, C, offset
        self.n_rows = int(term.size)

    @classmethod
    def from_measures(cls, measures):
        """Stack ``measures`` (sequence); None if any is not batchable or the list is empty."""
        ia, s_a, ib, s_b, frame, term, C, offset = [], [], [], [], [], [], [], []
        for j, m in enumerate(measures):
            # unwrap nested one-term Linears: C₁(C₂ w + o₂) + o₁ = (C₁C₂) w + (C₁o₂ + o₁)
            Cm, off = np.eye(m.size), np.zeros(m.size)
            while isinstance(m, Linear) and len(m.terms) == 1:
                C_in, inner = m.terms[0]
                Cm, off = Cm @ C_in, off + Cm @ m.offset
                m = inner
            if not isinstance(m, RelativeVector):
                return None
            rv = m
            ia.append(rv.point_a.body)
            s_a.append(rv.point_a.p_BP)
            ib.append(rv.point_b.body)
            s_b.append(rv.point_b.p_BP)
            frame.append(-1 if rv.frame is None else rv.frame)
            for r in range(Cm.shape[0]):
                term.append(j)
                C.append(Cm[r])
                offset.append(off[r])
        if not term:
            return None
        return cls(np.array(ia, np.int64), np.array(s_a, float).reshape(-1, 3),
                   np.array(ib, np.int64), np.array(s_b, float).reshape(-1, 3),
                   np.array(frame, np.int64), np.array(term, np.int64),
                   np.array(C, float).reshape(-1, 3), np.array(offset, float))

    def evaluate(self, state, order=1):
        """value (n_rows,) in the measures' units; M (n_rows, n_coords) = ∂value/∂q̂ for
        order ≥ 1 (else None); b (n_rows,) with value̋ = M v̇ + b for order 2 (else None)."""
        n = state.n_coords
        value = np.empty(self.n_rows)
        M = np.zeros((self.n_rows, n))
        b = np.empty(self.n_rows)
        _rows(state.p_WB, state.R_WB, state.w_BB, state.v_WB, state.column,
              self.ia, self.s_a, self.ib, self.s_b, self.frame, self.term, self.C,
              self.offset, n, order, value, M, b)
        return value, (M if order >= 1 else None), (b if order >= 2 else None)


@njit(cache=True)
def _rows(p_WB, R_WB, w_BB, v_WB, column, ia, s_a, ib, s_b, frame, term, C, offset,
          n_coords, order, value, M, b):
    """value[r] = C[r]·w_j + offset[r], M[r] = C[r] M_j, b[r] = C[r]·b_j for the
    relative vector w_j of row r's measure j = term[r] (computed once per measure)."""
    r = 0
    n_rows = term.shape[0]
    for j in range(ia.shape[0]):
        w, Mj, bj, _ = relative_vector(p_WB, R_WB, w_BB, v_WB, column, ia[j], s_a[j],
                                       ib[j], s_b[j], frame[j], n_coords, order)
        while r < n_rows and term[r] == j:
            value[r] = C[r, 0] * w[0] + C[r, 1] * w[1] + C[r, 2] * w[2] + offset[r]
            if order >= 1:
                for c in range(n_coords):
                    M[r, c] = C[r, 0] * Mj[0, c] + C[r, 1] * Mj[1, c] + C[r, 2] * Mj[2, c]
            b[r] = C[r, 0] * bj[0] + C[r, 1] * bj[1] + C[r, 2] * bj[2]
            r += 1


class ScalarRows:
    """Row 0 of each of a list of measures (FDK DOFs, springs): value (k,), M (k, n),
    b (k,), in one kernel call when every measure is a relative-vector projection with
    one row (:class:`RelativeVectorRows`), else measure by measure."""

    def __init__(self, measures):
        self.measures = list(measures)
        rows = RelativeVectorRows.from_measures(self.measures)
        self.batched = rows if rows is not None and rows.n_rows == len(self.measures) else None

    def evaluate(self, state, order=1):
        """As :meth:`RelativeVectorRows.evaluate`, one row per measure."""
        if self.batched is not None:
            return self.batched.evaluate(state, order)
        parts = [m.evaluate(state, order) for m in self.measures]
        value = np.array([p[0][0] for p in parts])
        M = np.array([p[1][0] for p in parts]).reshape(len(parts), state.n_coords) if order >= 1 else None
        b = np.array([p[2][0] for p in parts]) if order >= 2 else None
        return value, M, b
