"""The distance-grid cache: a grid read back from disk is the grid that was built, a
changed mesh or setting never meets a stale grid, damaged files are rebuilt, and the
disk cache can be turned off."""

import numpy as np
import pytest

from openfdk.contact import distance_grid, grid_cache
from openfdk.contact.grid_cache import cached_distance_grid, clear_grid_cache
from openfdk.contact.shapes import sphere_cap

SPACING, DEPTH = 1e-3, 2e-3


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("OPENFDK_CACHE_DIR", str(tmp_path / "cache"))
    clear_grid_cache()
    yield tmp_path / "cache" / "distance-grids"
    clear_grid_cache()


@pytest.fixture
def cap():
    return sphere_cap(0.01, 0.6, 1e-3, name="cap")


def _forbid_builds(monkeypatch):
    def fail(*a, **k):
        raise AssertionError("the grid was rebuilt")

    monkeypatch.setattr(grid_cache, "build_distance_grid", fail)


def test_grid_read_from_disk_equals_the_built_grid(cache_dir, cap, monkeypatch):
    built = distance_grid.build_distance_grid(cap, SPACING, DEPTH)
    first = cached_distance_grid(cap, SPACING, DEPTH)
    assert len(list(cache_dir.glob("*.npz"))) == 1
    clear_grid_cache()  # memory only: the next call must come from disk
    _forbid_builds(monkeypatch)
    again = cached_distance_grid(cap, SPACING, DEPTH)
    assert again is not first
    np.testing.assert_array_equal(again.values, built.values)
    np.testing.assert_array_equal(again.cell_valid, built.cell_valid)
    np.testing.assert_array_equal(again.origin_B, built.origin_B)
    assert (again.spacing, again.max_depth, again.n_evaluated) == (SPACING, DEPTH, built.n_evaluated)
    assert not again.values.flags.writeable
    # read from the disk cache as a memory map of the .npz member (only touched pages resident)
    assert isinstance(again.values, np.memmap) and not isinstance(built.values, np.memmap)
    p = np.array([[0.0, 0.0, -0.0095], [0.001, -0.002, -0.009]])  # inside the ball, near the cap
    np.testing.assert_array_equal(again.query(p)[0], built.query(p)[0])
    assert np.all(np.isfinite(built.query(p)[0]))


def test_changed_mesh_or_setting_gets_its_own_grid(cache_dir, cap):
    cached_distance_grid(cap, SPACING, DEPTH)
    cached_distance_grid(cap, SPACING, 2 * DEPTH)
    moved = sphere_cap(0.01, 0.6, 1e-3, name="cap", center=(0.0, 0.0, 1e-4))
    g = cached_distance_grid(moved, SPACING, DEPTH)
    assert len(list(cache_dir.glob("*.npz"))) == 3
    # the moved cap's grid is its own: φ at its apex is 0, not the original's 0.1 mm
    apex = np.array([[0.0, 0.0, -0.01 + 1e-4]])
    assert abs(g.query(apex)[0][0]) < 1e-5


def test_damaged_cache_file_is_rebuilt_with_a_warning(cache_dir, cap):
    cached_distance_grid(cap, SPACING, DEPTH)
    (path,) = cache_dir.glob("*.npz")
    path.write_bytes(b"not a grid")
    clear_grid_cache()
    with pytest.warns(RuntimeWarning, match="unreadable"):
        g = cached_distance_grid(cap, SPACING, DEPTH)
    assert g.n_evaluated > 0 and path.stat().st_size > 1000  # replaced by the rebuilt grid


def test_disk_cache_off(tmp_path, monkeypatch, cap):
    monkeypatch.setenv("OPENFDK_CACHE_DIR", "off")
    clear_grid_cache()
    assert grid_cache.grid_cache_dir() is None
    cached_distance_grid(cap, SPACING, DEPTH)
    clear_grid_cache()
    assert not any(tmp_path.rglob("*.npz"))
