"""openfdk.contact.unique_rows: equal rows grouped and numbered by first appearance,
checked against an independent reference (numpy's np.unique(axis=0), renumbered by
first index) and the defining invariants."""

import numpy as np
import pytest

from openfdk.contact.unique_rows import first_appearance_rows


def _reference(rows):
    """np.unique(axis=0) (a different sort: rows as structured items), renumbered by
    each group's first index."""
    _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    number = np.empty_like(order)
    number[order] = np.arange(order.size)
    return first[order], number[inverse.ravel()]


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64])
def test_matches_numpy_unique_on_repeated_rows(dtype):
    rng = np.random.default_rng(7)
    table = rng.integers(-5, 5, size=(40, 3)).astype(dtype)
    rows = table[rng.integers(0, 40, size=500)]  # every row repeated ≈ 12 times, in random order
    first, inverse = first_appearance_rows(rows)
    ref_first, ref_inverse = _reference(rows)
    np.testing.assert_array_equal(first, ref_first)
    np.testing.assert_array_equal(inverse, ref_inverse)
    assert first.size > 1 and first.size < rows.shape[0]  # duplicates were found, and not everything merged


def test_invariants_and_first_appearance_order():
    rows = np.array([[2.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 1], [1, 0, 0], [0, 0, 1]])
    first, inverse = first_appearance_rows(rows)
    np.testing.assert_array_equal(first, [0, 1, 3])  # [2,0,0] first seen at 0, [1,0,0] at 1, [0,0,1] at 3
    np.testing.assert_array_equal(inverse, [0, 1, 0, 2, 1, 2])
    np.testing.assert_array_equal(rows[first][inverse], rows)
    assert first.dtype == inverse.dtype == np.int64


def test_rows_equal_by_value():
    """-0.0 equals 0.0 (one vertex); rows differing in one coordinate by one ulp stay apart."""
    x = 0.1
    rows = np.array([[0.0, 1.0, x], [-0.0, 1.0, x], [0.0, 1.0, np.nextafter(x, 1.0)]])
    first, inverse = first_appearance_rows(rows)
    np.testing.assert_array_equal(first, [0, 2])
    np.testing.assert_array_equal(inverse, [0, 0, 1])


def test_empty_and_single_row():
    first, inverse = first_appearance_rows(np.zeros((0, 3)))
    assert first.shape == inverse.shape == (0,)
    first, inverse = first_appearance_rows(np.array([[1.0, 2.0, 3.0]]))
    np.testing.assert_array_equal(first, [0])
    np.testing.assert_array_equal(inverse, [0])


def test_not_a_table_is_refused():
    with pytest.raises(ValueError, match="2-D"):
        first_appearance_rows(np.zeros(3))


def test_mesh_drops_repeated_triangles_keeping_the_first():
    """surface_mesh removes a triangle on the same three vertices as an earlier one (any
    order), says how many, and keeps the others in their order."""
    from openfdk.contact.mesh import MeshWarning, surface_mesh

    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    tetra = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])  # closed, outward normals
    faces = np.vstack([tetra[:2], [[3, 0, 1]], tetra[2:], [[2, 3, 1]]])  # faces 1 and 2 repeated, rotated
    with pytest.warns(MeshWarning, match="2 duplicate triangle"):
        mesh = surface_mesh(V, faces, "tetra")
    np.testing.assert_array_equal(mesh.faces, tetra)
    np.testing.assert_allclose(mesh.vertex_areas.sum(), 1.5 + np.sqrt(3) / 2)  # 3 right triangles of ½ + one of √3/2
