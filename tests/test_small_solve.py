"""small_solve (compiled LU for the small per-frame solves): residual of A X = B, the
pivoting path, and the LinAlgError of an exactly singular matrix."""

import numpy as np
import pytest

from openfdk.kinematics.frame_kernels import small_solve


def test_small_solve_vector_and_matrix_rhs():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(7, 7))
    A[0, 0] = 0.0  # forces a row exchange at the first pivot
    X = rng.normal(size=(7, 3))
    B = A @ X
    assert np.allclose(small_solve(A, B), X, rtol=0, atol=1e-12)
    assert np.allclose(small_solve(A, B[:, 1]), X[:, 1], rtol=0, atol=1e-12)
    assert np.abs(X).min() > 0.0 and A[0, 0] == 0.0  # inputs left untouched


def test_small_solve_singular_raises():
    A = np.array([[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(np.linalg.LinAlgError):
        small_solve(A, np.ones(2))
