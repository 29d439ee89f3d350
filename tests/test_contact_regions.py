"""Regions of a contact force (contact/sections.py ``regions``, ElasticFoundation.set_regions):
two condyle spheres pressed into a flat plate to different depths, split into medial and
lateral halves by the plate body's x axis. Each half's force equals the elastic-foundation
closed form of its own sphere, F = π p R δ² (linear law, δ ≪ R: the pressure p δ_i
integrated over the penetrated cap), the halves add up to the whole, and forces.csv
carries them."""

from __future__ import annotations

import csv

import numpy as np

from openfdk.contact.stl import write_stl
import pytest

from openfdk.cli import main
from openfdk.contact.shapes import flat_patch, sphere_cap
from openfdk.forces.forceset import ForceElements
from openfdk.io.modelfile import load_model
from openfdk.model.errors import ModelError

R = 0.02           # m, condyle radius
P_MOD = 1.0e10     # N/m³
DEPTH = {"medial": 0.3e-3, "lateral": 0.15e-3}   # m, penetration of each condyle
X = {"medial": -0.02, "lateral": 0.02}           # m, condyle centres along the plate's x


def _write_stl(path, vertices, faces):
    """Binary STL of vertices (n, 3) m written in mm."""
    return write_stl(path, 1e3 * np.asarray(vertices), faces)


def _model(folder, regions="regions: {medial: {axis: [-1, 0, 0]}, lateral: {axis: [1, 0, 0]}}"):
    """The femur (two caps, pole −z) welded above the plate z = 0 so that each condyle
    sinks DEPTH[side] into it."""
    caps = []
    for side in ("medial", "lateral"):
        cap = sphere_cap(R, np.radians(20), 0.15e-3)
        caps.append((cap.vertices_B + [X[side], 0.0, R - DEPTH[side]], cap.faces))
    V = np.vstack([caps[0][0], caps[1][0]])
    F = np.vstack([caps[0][1], caps[1][1] + len(caps[0][0])])
    _write_stl(folder / "condyles.stl", V, F)
    plate = flat_patch(0.07, 0.03, 0.5e-3)
    _write_stl(folder / "plate.stl", plate.vertices_B, plate.faces)
    (folder / "knee.yaml").write_text(f"""
openfdk: 1
units: {{length: mm, angle: deg}}
gravity: [0, 0, 0]
bodies:
  femur: {{mass: 1.0, inertia: [1.0e-3, 1.0e-3, 1.0e-3]}}
joints:
  hold: {{type: weld, parent: ground.origin, child: femur.origin}}
contacts:
  knee:
    vertices: {{body: femur, mesh: condyles.stl, units: mm}}
    surface: {{body: ground, mesh: plate.stl, units: mm}}
    pressure_modulus: {P_MOD}
    grid_spacing: 0.1
    max_depth: 1
    {regions}
""")
    return folder / "knee.yaml"


def test_each_half_is_its_condyles_closed_form_and_the_halves_add_up(tmp_path):
    model = load_model(_model(tmp_path))
    state = model.initial_state()
    _, out, _ = ForceElements(model).generalized_forces(state, 0.0)
    c = out["contacts"]["knee"]
    regions = c.region_force_W
    assert set(regions) == {"medial", "lateral"}
    np.testing.assert_allclose(regions["medial"] + regions["lateral"], c.force_W, rtol=1e-12, atol=1e-9)
    for side, delta in DEPTH.items():
        closed = np.pi * P_MOD * R * delta**2   # ∫ p (δ − r²/2R) 2πr dr over r ≤ √(2Rδ)
        F = regions[side]
        assert F[2] == pytest.approx(closed, rel=0.02)     # pushes the femur up (+z)
        assert np.hypot(F[0], F[1]) < 1e-6 * F[2]
    assert regions["medial"][2] / regions["lateral"][2] == pytest.approx(4.0, rel=0.05)  # (δ_m / δ_l)²


def test_region_forces_are_columns_of_forces_csv(tmp_path):
    model = _model(tmp_path)
    assert main(["run", str(model), "--out", str(tmp_path / "out"), "--no-progress", "--no-plots", "-q"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "out" / "forces.csv")))
    r = rows[0]
    total = float(r["knee.Fz_N"])
    assert float(r["knee.medial_N"]) + float(r["knee.lateral_N"]) == pytest.approx(total, rel=1e-6)
    assert float(r["knee.medial_N"]) > 3 * float(r["knee.lateral_N"]) > 0


@pytest.mark.parametrize("regions, expected", [
    ("regions: {medial: {axis: [0, 0, 0]}}", "contacts.knee.regions.medial.axis: expected a non-zero direction"),
    ("regions: {medial: {axis: [1, 0]}}", "contacts.knee.regions.medial.axis: expected 3 finite numbers"),
    ("regions: {medial: {axis: [1, 0, 0], centre: [0, 0, 0]}}", "contacts.knee.regions.medial"),
    ("regions: {a/b: {axis: [1, 0, 0]}}", "contacts.knee.regions.a/b: name 'a/b' contains '/'"),
])
def test_bad_regions_are_one_line_errors(tmp_path, regions, expected):
    with pytest.raises(ModelError) as err:
        load_model(_model(tmp_path, regions))
    assert expected in str(err.value)
