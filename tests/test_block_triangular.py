"""Block lower-triangular form (openfdk.kinematics.block_triangular): permuted random
block-triangular matrices are found with their blocks and solved exactly; a pattern
without a perfect matching is one block; a full-body model's Φ_q̂ is one 6×6 block per
body, and the determinate solves by blocks equal the dense LU's."""

import numpy as np

from openfdk.kinematics.block_triangular import block_lu, block_solve, block_triangular_form, dense_form


def _random_block_triangular(rng):
    sizes = rng.integers(1, 7, rng.integers(1, 8))
    n, s = int(sizes.sum()), np.cumsum([0, *sizes])
    A = np.zeros((n, n))
    for b in range(len(sizes)):
        A[s[b]:s[b + 1], s[b]:s[b + 1]] = rng.normal(size=(sizes[b], sizes[b]))
        for c in range(b):
            if rng.random() < 0.4:
                mask = rng.random((sizes[b], sizes[c])) < 0.5
                A[s[b]:s[b + 1], s[c]:s[c + 1]] = rng.normal(size=(sizes[b], sizes[c])) * mask
    return A[rng.permutation(n)][:, rng.permutation(n)], sizes


def _solve(A, form, b):
    n = A.shape[0]
    LU, piv = np.empty((n, n)), np.empty(n, np.int64)
    assert block_lu(A, form.rows, form.cols, form.starts, LU, piv)
    return block_solve(LU, piv, form.rows, form.cols, form.starts, form.ptr, form.earlier, b, np.empty(n))


def test_permuted_block_triangular_matrices_are_found_and_solved():
    rng = np.random.default_rng(1)
    for _ in range(100):
        A, sizes = _random_block_triangular(rng)
        form = block_triangular_form(A != 0)
        assert form.sizes.max() <= sizes.max()
        assert sorted(form.rows) == sorted(form.cols) == list(range(A.shape[0]))
        P = A[form.rows][:, form.cols]
        for b in range(len(form.sizes)):  # nothing right of a diagonal block
            assert not np.any(P[form.starts[b]:form.starts[b + 1], form.starts[b + 1]:])
        b = rng.normal(size=A.shape[0])
        x = np.linalg.solve(A, b)
        scale = np.linalg.cond(A) * np.abs(x).max()
        assert np.abs(_solve(A, form, b) - x).max() <= 1e-12 * scale
        assert np.abs(_solve(A, dense_form(A.shape[0]), b) - x).max() <= 1e-12 * scale


def test_structurally_singular_pattern_is_one_block_and_singular_is_reported():
    P = np.ones((3, 3), bool)
    P[:, 0] = False
    assert list(block_triangular_form(P).sizes) == [3]
    A = np.array([[1.0, 2.0], [2.0, 4.0]])
    form = dense_form(2)
    assert not block_lu(A, form.rows, form.cols, form.starts, np.empty((2, 2)), np.empty(2, np.int64))


def test_full_body_jacobian_is_one_block_per_body(tmp_path):
    from openfdk.bench.full_body_id import write_inputs
    from openfdk.io.modelfile import load_model_and_settings
    from openfdk.io.opensim.overlay import register
    from openfdk.kinematics.system import ConstraintSystem

    model_path, motion, loads = write_inputs(tmp_path, quick=True)
    register(model_path, external_loads=loads, motion=motion)  # every coordinate driven: square Φ_q̂
    model, _ = load_model_and_settings(model_path)
    system = ConstraintSystem(model)
    form = system.block_form
    assert list(form.sizes) == [6] * (model.n_coords // 6)
    state = model.initial_state()
    rng = np.random.default_rng(3)
    from openfdk.model.kernels import displace_poses

    displace_poses(state.p_WB, state.quat_WB, state.R_WB, state.moving, state.column,
                   rng.uniform(-0.2, 0.2, model.n_coords))
    A = system.jacobian(state)
    b = rng.normal(size=model.n_coords)
    np.testing.assert_allclose(_solve(A, form, b), np.linalg.solve(A, b), rtol=0, atol=1e-9)
