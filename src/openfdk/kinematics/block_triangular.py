"""Block lower-triangular form of a square sparse matrix, and the LU solves that use it.

A tree of joints driven by its coordinates gives a square Φ_q̂ (m = n = 6 n_moving)
whose rows of one joint (its joint rows and its coordinates' driver rows) involve only
the child body and its parent. Ordered from the root outwards, the matrix is block
lower triangular with one 6×6 diagonal block per body: a solve is a forward
substitution with one small LU per block instead of one LU of the whole matrix
(72×72 for a 12-body model: ≈ 40 µs, against ≈ 2 µs by blocks).

The form (Dulmage & Mendelsohn's fine decomposition; Duff & Reid, ACM TOMS 4 (1978)
137, "An implementation of Tarjan's algorithm for the block triangularization of a
matrix"): a perfect matching of rows to columns on the sparsity pattern puts a
structurally non-zero entry on every diagonal position (augmenting paths, Kuhn's
algorithm); with it, column j depends on column k when the row matched to j has an
entry in k, and the strongly connected components of that graph (Tarjan's algorithm,
which emits each component after every one it depends on) are the diagonal blocks in
the order of a forward substitution. The blocks are unique whatever the matching. A
closed kinematic loop is one larger block; a pattern without a perfect matching
(structurally singular) is one block of the whole matrix — then the solve is the plain
LU with partial pivoting.

Pivoting is partial within each diagonal block (det A = Π det A_bb, so A is singular
exactly when a block is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .envelope_lu import lu_factor_envelope, lu_solve_envelope


@dataclass(frozen=True)
class BlockForm:
    """Permutations of a square (n, n) matrix to block lower-triangular form.

    rows, cols : (n,) int, row i of the form is row ``rows[i]`` of the matrix (column j:
    ``cols[j]``); starts : (n_blocks + 1,) int, block b is [starts[b], starts[b+1]) of
    both; ptr (n_blocks + 1,), earlier (·,) int: the form's columns left of block b
    with a structural entry in one of its rows are earlier[ptr[b]:ptr[b+1]]."""

    rows: np.ndarray
    cols: np.ndarray
    starts: np.ndarray
    ptr: np.ndarray
    earlier: np.ndarray

    @property
    def sizes(self):
        """(n_blocks,) the diagonal blocks' sizes."""
        return np.diff(self.starts)


def dense_form(n):
    """The trivial form of an (n, n) matrix: one block, no permutation."""
    i = np.arange(n, dtype=np.int64)
    return BlockForm(i, i.copy(), np.array([0, n], np.int64), np.zeros(2, np.int64), np.zeros(0, np.int64))


def _perfect_matching(adj, n):
    """row_of[col] of a perfect matching of the bipartite graph ``adj`` (row -> its
    columns), or None (a greedy pass, then Kuhn's augmenting paths, iterative)."""
    row_of = [-1] * n
    unmatched = []
    for r in range(n):  # greedy: most rows find a free column at once
        free = next((c for c in adj[r] if row_of[c] < 0), -1)
        if free >= 0:
            row_of[free] = r
        else:
            unmatched.append(r)
    for r0 in unmatched:
        seen = [False] * n
        # depth-first search for an augmenting path from row r0: stack of (row, next index)
        stack, parent_col = [[r0, 0]], []
        found = -1
        while stack:
            r, i = stack[-1]
            if i >= len(adj[r]):
                stack.pop()
                if parent_col:
                    parent_col.pop()
                continue
            stack[-1][1] = i + 1
            c = adj[r][i]
            if seen[c]:
                continue
            seen[c] = True
            parent_col.append(c)
            if row_of[c] < 0:
                found = c
                break
            stack.append([row_of[c], 0])
        if found < 0:
            return None
        # flip the path: the rows on the stack take the columns parent_col in order
        for (r, _), c in zip(stack, parent_col):
            row_of[c] = r
    return row_of


def _components(succ, n):
    """Strongly connected components of the graph succ (node -> its successors), each
    emitted after every component it reaches (Tarjan's algorithm, iterative)."""
    index, low, on_stack = [-1] * n, [0] * n, [False] * n
    stack, out, counter = [], [], 0
    for root in range(n):
        if index[root] >= 0:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter
                counter += 1
                stack.append(v)
                on_stack[v] = True
            recurse = False
            while i < len(succ[v]):
                w = succ[v][i]
                i += 1
                if index[w] < 0:
                    work.append((v, i))
                    work.append((w, 0))
                    recurse = True
                    break
                if on_stack[w]:
                    low[v] = min(low[v], index[w])
            if recurse:
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    comp.append(w)
                    if w == v:
                        break
                out.append(sorted(comp))
            if work:
                u = work[-1][0]
                low[u] = min(low[u], low[v])
    return out


_FORMS = {}  # (n, pattern bytes) -> BlockForm: a model's pattern is analysed once per process
_MAX_FORMS = 64


def block_triangular_form(pattern):
    """The :class:`BlockForm` of a square boolean sparsity pattern (n, n) (module
    docstring); one block when the pattern has no perfect matching."""
    pattern = np.ascontiguousarray(pattern, dtype=bool)
    n = pattern.shape[0]
    if pattern.shape != (n, n):
        raise ValueError(f"block_triangular_form: a square pattern is needed, got {pattern.shape}")
    key = (n, np.packbits(pattern).tobytes())
    form = _FORMS.get(key)
    if form is None:
        if len(_FORMS) >= _MAX_FORMS:
            _FORMS.clear()
        form = _FORMS[key] = _analyse(pattern, n)
    return form


def _analyse(pattern, n):
    adj = [list(np.flatnonzero(pattern[r])) for r in range(n)]
    row_of = _perfect_matching(adj, n)
    if row_of is None:
        return dense_form(n)
    succ = [[int(k) for k in adj[row_of[j]] if k != j] for j in range(n)]
    blocks = _components(succ, n)
    cols = np.array([j for b in blocks for j in b], np.int64)
    rows = np.array([row_of[j] for j in cols], np.int64)
    starts = np.cumsum([0] + [len(b) for b in blocks]).astype(np.int64)
    position = np.empty(n, np.int64)
    position[cols] = np.arange(n)
    ptr, earlier = [0], []
    for b in range(len(blocks)):
        s = starts[b]
        used = sorted({int(position[k]) for r in rows[s:starts[b + 1]] for k in adj[r] if position[k] < s})
        earlier += used
        ptr.append(len(earlier))
    return BlockForm(rows, cols, starts, np.array(ptr, np.int64), np.array(earlier, np.int64))


@njit(cache=True)
def block_lu(A, rows, cols, starts, LU, piv):
    """LU (n, n) ← A in block form (rows, cols of a :class:`BlockForm`) with each diagonal
    block factorised in place, partial pivoting within the block (whole rows swapped;
    piv (n,) the row swapped with at each step). False at an exactly zero pivot (the
    matrix is singular, as LAPACK's getrf reports it)."""
    n = A.shape[0]
    for i in range(n):
        ri = rows[i]
        for j in range(n):
            LU[i, j] = A[ri, cols[j]]
    for b in range(starts.shape[0] - 1):
        if not lu_factor_range(LU, piv, starts[b], starts[b + 1]):
            return False
    return True


@njit(cache=True)
def lu_factor_range(A, piv, lo, hi):
    """In place LU with partial pivoting of the diagonal block A[lo:hi, lo:hi] (rows
    swapped across all of A's columns, so the coupling to later columns moves with
    them); piv[lo:hi] int. False if a pivot is exactly zero (singular, as LAPACK getrf
    reports it). lo = 0, hi = n: the LU of the whole matrix. The elimination visits the
    rows' envelopes only (:func:`~.envelope_lu.lu_factor_envelope`: the same factors)."""
    n = A.shape[0]
    return lu_factor_envelope(A, piv, lo, hi, np.empty(n, np.int64), np.empty(n, np.int64))


@njit(cache=True)
def lu_factor(A, piv):
    """In place LU with partial pivoting of A (n, n); piv (n,) int. False if a pivot is
    exactly zero (singular, as LAPACK getrf reports it)."""
    return lu_factor_range(A, piv, np.int64(0), A.shape[0])


@njit(cache=True)
def lu_solve(LU, piv, rhs):
    """Solve with the factors of :func:`lu_factor`; rhs (n,) is overwritten and returned
    (:func:`~.envelope_lu.lu_solve_envelope` over whole rows)."""
    n = LU.shape[0]
    return lu_solve_envelope(LU, piv, np.zeros(n, np.int64), np.full(n, n - 1, np.int64), rhs)


@njit(cache=True)
def block_solve(LU, piv, rows, cols, starts, ptr, earlier, rhs, x):
    """x (n,) ← A⁻¹ rhs (n,) with the factors of :func:`block_lu`: block by block, the
    right-hand side less the earlier blocks' columns, then the block's own L and U."""
    n = LU.shape[0]
    y = np.empty(n)
    for i in range(n):
        y[i] = rhs[rows[i]]
    for b in range(starts.shape[0] - 1):
        s, e = starts[b], starts[b + 1]
        for k in range(s, e):
            p = piv[k]
            if p != k:
                y[k], y[p] = y[p], y[k]
        for i in range(s, e):
            acc = y[i]
            for q in range(ptr[b], ptr[b + 1]):
                c = earlier[q]
                acc -= LU[i, c] * y[c]
            for j in range(s, i):
                acc -= LU[i, j] * y[j]
            y[i] = acc
        for i in range(e - 1, s - 1, -1):
            acc = y[i]
            for j in range(i + 1, e):
                acc -= LU[i, j] * y[j]
            y[i] = acc / LU[i, i]
    for j in range(n):
        x[cols[j]] = y[j]
    return x


__all__ = ["BlockForm", "block_triangular_form", "dense_form", "block_lu", "block_solve"]
