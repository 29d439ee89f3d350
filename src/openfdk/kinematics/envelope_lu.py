"""LU with partial pivoting that visits only the envelope of a sparse matrix, and the
reverse Cuthill–McKee order that makes the envelope narrow.

The KKT matrix of marker tracking (:mod:`openfdk.kinematics.kkt`; 255 × 255 on the DM
knee of docs/tutorial-knee-gait.md, 4 % non-zeros) couples each body's 6 coordinates
with its markers and with the constraint rows of its joints. Ordered body by body and
then row by row, its non-zeros are scattered over the whole matrix, and a dense LU visits
(n − k)² entries at step k. Renumbered symmetrically by reverse Cuthill–McKee (Cuthill &
McKee 1969; George & Liu, *Computer Solution of Large Sparse Positive Definite Systems*,
1981, ch. 4), from the structural pattern once per model, they lie within a band: 45
wide on DM (62 with the Hessian's second-order terms).

The factorization here is the plain one of LAPACK's getrf (the largest pivot in the
column, rows swapped whole), restricted to where the numbers can be non-zero:

* row i of U ends at ``last[i]``, its last non-zero column. Eliminating column k from
  row i adds row k's entries up to ``last[k]``, so ``last[i]`` grows to ``last[k]``; a
  swap swaps the two rows' ends. Entries beyond ``last[k]`` are exact zeros, and the
  skipped operations ``a − l · 0`` would have left them unchanged: the factors are
  those of the dense loop, bit for bit.
* row i of L starts at ``first[i]``, found once after the factorization, so that a
  solve (forward and back substitution) visits the envelope only.

On DM's KKT with the second-order terms: 0.40 ms for the dense loop, 0.25 ms for the
envelope in the natural order, 0.11 ms for the envelope in the RCM order (one core).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["envelope_order", "lu_factor_envelope", "lu_solve_envelope", "permute_into", "factor_permuted",
           "solve_permuted", "solve_permuted_columns", "solve_in_order"]


def envelope_order(pattern):
    """The reverse Cuthill–McKee order perm (n,) int64 of the symmetric pattern
    ``pattern | patternᵀ`` (n, n) bool: row and column i of the ordered matrix are row and
    column ``perm[i]`` of the original. (scipy.sparse is imported here, once per model:
    a study's case path does not load it otherwise.)"""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    pattern = np.asarray(pattern, dtype=bool)
    sym = csr_matrix(pattern | pattern.T)
    return np.ascontiguousarray(reverse_cuthill_mckee(sym, symmetric_mode=True), dtype=np.int64)


@njit(cache=True)
def lu_factor_envelope(A, piv, lo, hi, first, last):
    """In place LU with partial pivoting of the diagonal block A[lo:hi, lo:hi] of A (·, n)
    (rows swapped across all of A's columns; lo = 0, hi = n: the whole matrix), visiting
    only the envelope (module docstring). piv[lo:hi] int: the row swapped with at each
    step. first[lo:hi], last[lo:hi] int (outputs): each row's first column of L (≥ lo)
    and last column of U (< hi) within the block. False if a pivot is exactly zero
    (singular, as LAPACK getrf reports it)."""
    n = A.shape[1]
    for i in range(lo, hi):
        last[i] = lo
        for j in range(hi - 1, lo - 1, -1):
            if A[i, j] != 0.0:
                last[i] = j
                break
    for k in range(lo, hi):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, hi):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        piv[k] = p
        if big == 0.0:
            return False
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
            last[k], last[p] = last[p], last[k]
        inv = 1.0 / A[k, k]
        end = last[k]
        for i in range(k + 1, hi):
            A[i, k] *= inv
            a = A[i, k]
            if a != 0.0:
                for j in range(k + 1, end + 1):
                    A[i, j] -= a * A[k, j]
                if end > last[i]:
                    last[i] = end
    for i in range(lo, hi):
        first[i] = i
        for j in range(lo, i):
            if A[i, j] != 0.0:
                first[i] = j
                break
    return True


@njit(cache=True)
def lu_solve_envelope(LU, piv, first, last, rhs):
    """rhs (n,) ← A⁻¹ rhs with the factors of :func:`lu_factor_envelope` of the whole
    matrix (lo = 0, hi = n); returns rhs."""
    n = LU.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            rhs[k], rhs[p] = rhs[p], rhs[k]
    for i in range(n):
        s = rhs[i]
        for j in range(first[i], i):
            s -= LU[i, j] * rhs[j]
        rhs[i] = s
    for i in range(n - 1, -1, -1):
        s = rhs[i]
        for j in range(i + 1, last[i] + 1):
            s -= LU[i, j] * rhs[j]
        rhs[i] = s / LU[i, i]
    return rhs


@njit(cache=True)
def permute_into(M, perm, LU):
    """LU (n, n) ← M (n, n) renumbered by ``perm`` (n,): LU[i, j] = M[perm[i], perm[j]]
    (:func:`envelope_order`)."""
    n = M.shape[0]
    for i in range(n):
        ri = perm[i]
        for j in range(n):
            LU[i, j] = M[ri, perm[j]]


@njit(cache=True)
def factor_permuted(M, perm, LU, piv, first, last):
    """LU (n, n) ← the factors of M (n, n) renumbered by ``perm`` (:func:`permute_into`),
    with piv, first and last (n,) int as :func:`lu_factor_envelope`. False if M is
    singular."""
    permute_into(M, perm, LU)
    return lu_factor_envelope(LU, piv, np.int64(0), M.shape[0], first, last)


@njit(cache=True)
def solve_permuted(LU, piv, first, last, perm, rhs):
    """x (n,) = M⁻¹ rhs (n,) with the factors of :func:`factor_permuted` of M; rhs is
    left unchanged (:func:`solve_permuted_columns` with one column)."""
    n = rhs.shape[0]
    return solve_permuted_columns(LU, piv, first, last, perm, rhs.reshape((n, 1))).reshape(n)


@njit(cache=True)
def solve_permuted_columns(LU, piv, first, last, perm, B):
    """X (n, k) = M⁻¹ B for B (n, k) with the factors of :func:`factor_permuted` of M, all
    columns in one compiled call (no BLAS: at this size OpenBLAS's threads cost more than
    the solves, and their spinning doubles the process's CPU time on two cores)."""
    n, k = B.shape
    X = np.empty((n, k))
    y = np.empty(n)
    for c in range(k):
        for i in range(n):
            y[i] = B[perm[i], c]
        lu_solve_envelope(LU, piv, first, last, y)
        for i in range(n):
            X[perm[i], c] = y[i]
    return X


def solve_in_order(M, perm, B):
    """X (n, k) = M⁻¹ B for M (n, n) and B (n, k): M factorized in the order ``perm`` (n,)
    int (:func:`factor_permuted`), the k columns solved in one compiled call. Raises
    numpy.linalg.LinAlgError if M is singular, as numpy.linalg.solve does."""
    n = M.shape[0]
    LU, piv = np.empty((n, n)), np.empty(n, np.int64)
    first, last = np.empty(n, np.int64), np.empty(n, np.int64)
    if not factor_permuted(np.ascontiguousarray(M, dtype=float), perm, LU, piv, first, last):
        raise np.linalg.LinAlgError("singular matrix")
    return solve_permuted_columns(LU, piv, first, last, perm, np.ascontiguousarray(B, dtype=float))
