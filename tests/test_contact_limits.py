"""Contact limits are reported: penetration near max_depth warns once, the distance-grid
memory is estimated before the build (a clear error with the spacing that fits), and the
grid cache on disk can be inspected and cleared from the command line."""

import warnings

import numpy as np
import pytest

from openfdk.contact.distance_grid import build_distance_grid
from openfdk.contact.elastic_foundation import ElasticFoundation
from openfdk.contact.limits import ContactDepthWarning, check_grid_memory, grid_estimate
from openfdk.contact.shapes import flat_patch


def _pair(max_depth=2e-3):
    top = flat_patch(0.01, 0.01, 0.001, name="top")
    floor = flat_patch(0.03, 0.03, 0.002, name="floor")
    return ElasticFoundation(top, floor, 1e9, mode="exact", max_depth=max_depth, name="pad")


def test_penetration_near_max_depth_warns_once():
    c = _pair(2e-3)
    I = np.eye(3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        c.evaluate(np.array([0, 0, -1.0e-3]), I, np.zeros(3), I)  # 50 %: quiet
        assert not [w for w in caught if issubclass(w.category, ContactDepthWarning)]
        for depth in (1.85e-3, 1.9e-3, 1.95e-3):  # ≥ 90 %: one warning for the run
            res = c.evaluate(np.array([0, 0, -depth]), I, np.zeros(3), I)
            assert res.n_contact > 0
    depth_warnings = [w for w in caught if issubclass(w.category, ContactDepthWarning)]
    assert len(depth_warnings) == 1
    assert "contact 'pad'" in str(depth_warnings[0].message) and "max_depth (2 mm)" in str(depth_warnings[0].message)


def test_grid_estimate_matches_the_built_grid():
    mesh = flat_patch(0.02, 0.015, 0.001, name="patch")
    for h in (0.5e-3, 0.3e-3):
        shape, n, build, stored = grid_estimate(mesh.vertices_B, h, 2e-3)
        grid = build_distance_grid(mesh, h, 2e-3)
        assert grid.values.shape[:3] == shape
        assert stored == pytest.approx(grid.values.nbytes + grid.cell_valid.nbytes, rel=0.02)


def test_grid_over_the_memory_limit_is_refused_with_a_spacing_that_fits(monkeypatch):
    mesh = flat_patch(0.05, 0.05, 0.002, name="plateau.stl")
    monkeypatch.setenv("OPENFDK_GRID_MEMORY_MB", "20")
    with pytest.raises(ValueError, match=r"mesh 'plateau.stl' would need about [0-9.]+ GB .*limit 20 MB.*grid_spacing >= ") as err:
        build_distance_grid(mesh, 0.1e-3, 3e-3)
    fit = float(str(err.value).split("grid_spacing >= ")[1].split(" mm")[0]) * 1e-3
    check_grid_memory("plateau.stl", mesh.vertices_B, fit, 3e-3)  # the suggested spacing fits


def test_cache_info_and_clear(tmp_path, monkeypatch, capsys):
    from openfdk.cli import main
    from openfdk.contact.grid_cache import cached_distance_grid, clear_grid_cache

    monkeypatch.setenv("OPENFDK_CACHE_DIR", str(tmp_path))
    clear_grid_cache()
    cached_distance_grid(flat_patch(0.01, 0.01, 0.001, name="tiny"), 0.5e-3, 1e-3)
    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path) in out and ": 1 grid files" in out
    size = sum(f.stat().st_size for f in (tmp_path / "distance-grids").glob("*.npz"))
    assert f"{size / 2**20:.1f} MB" in out and size > 0
    assert main(["cache", "clear"]) == 0
    assert "removed 1 grid files" in capsys.readouterr().out
    assert not list((tmp_path / "distance-grids").glob("*.npz"))
    assert main(["cache", "info"]) == 0
    assert ": 0 grid files" in capsys.readouterr().out


def test_the_contacts_exact_step_model_holds_the_depth_warning_back():
    """The FDK step's model evaluates the contacts at predicted poses q̂ ⊕ U Δα that are
    not poses of the model (fdk/contact_step.py): a depth near max_depth there does not
    warn, while the same pose evaluated as a result does. The model's forces are the
    contact's all the same: a flat 10 mm × 10 mm pad pressed δ = 1.9 mm (95 % of
    max_depth) into a floor carries p δ A = 1e9 · 1.9e-3 · 1e-4 = 190 N (each vertex's
    prism a_i d_i, Σ a_i = A)."""
    from types import SimpleNamespace

    from openfdk.contact.sections import add_contact
    from openfdk.fdk.contact_step import ContactSplit
    from openfdk.model.builder import ModelBuilder

    b = ModelBuilder("pad on floor", gravity=(0, 0, -9.81))
    b.add_body("pad", 0.1, [1e-5] * 3)
    add_contact(b, "pad", "pad", flat_patch(0.01, 0.01, 0.001, name="top.stl"), "ground",
                flat_patch(0.03, 0.03, 0.002, name="floor.stl"), 1e9, mode="exact", max_depth=2e-3)
    model = b.build()
    state = model.initial_state()
    delta = 1.9e-3
    state.set_q(np.array([0.0, 0.0, -delta, 1.0, 0.0, 0.0, 0.0]))
    split = ContactSplit(np.zeros((6, 1)), np.zeros((1, 6)), np.arange(6), np.array([[0, -1]]))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        Q, _ = split.terms(SimpleNamespace(contacts=model.contacts), state)
        assert not [w for w in caught if issubclass(w.category, ContactDepthWarning)]
        np.testing.assert_allclose(Q[:3], [0.0, 0.0, 1e9 * delta * 1e-4], rtol=1e-9, atol=1e-9)
        model.contacts[0].evaluate(state)  # the same pose as a result
    assert len([w for w in caught if issubclass(w.category, ContactDepthWarning)]) == 1
