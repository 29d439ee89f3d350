"""The contact-mesh check (openfdk.contact.mesh_check) on meshes written by the test.

A ball (sphere cap of radius R, pole down) on a welded body hangs a gap g above a plate
(z = 0, normal +z) on the ground. Figures are compared with closed forms: the plate's
triangle areas are half its cells (dx_i · dy / 2); its rim edges are the 4 (n − 1) edges of
its border, and the distance of a point m outside the ball to the ball is |m − c| − R.
"""

from __future__ import annotations


import numpy as np

from openfdk.contact.stl import write_stl
import pytest

from openfdk.cli import main
from openfdk.contact.mesh_check import ZONE_DISTANCE, check_contacts
from openfdk.contact.shapes import sphere_cap
from openfdk.io.modelfile import load_model

R, GAP = 10e-3, 0.5e-3  # ball radius and its gap above the plate, m
DY = 2e-3  # the plate's row spacing, m
XS = np.r_[0.0, np.cumsum(np.linspace(0.5e-3, 3e-3, 12))]  # graded columns, m (x from 0 to 21 mm)
XS = XS - XS[-1] / 2
YS = np.arange(-10e-3, 10.01e-3, DY)


def _write_stl(path, vertices, faces):
    """Binary STL of vertices (n, 3) m written in mm."""
    return write_stl(path, 1e3 * np.asarray(vertices), faces)


def _plate(flip=False):
    """Vertices (n, 3), faces (m, 3) of the graded plate z = 0, normals +z (−z if flip)."""
    X, Y = np.meshgrid(XS, YS, indexing="ij")
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    ny = len(YS)
    faces = []
    for i in range(len(XS) - 1):
        for j in range(ny - 1):
            a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
            faces += [(a, b, c), (a, c, d)]
    F = np.array(faces)
    return V, (F[:, ::-1] if flip else F)


def _model(tmp_path, ball_x=0.0, flip_plate=False, flip_ball=False, extra_surface="", law=None):
    ball = sphere_cap(R, np.radians(70), 0.6e-3)  # pole (0, 0, −R), normals outward
    F = ball.faces[:, ::-1] if flip_ball else ball.faces
    _write_stl(tmp_path / "ball.stl", ball.vertices_B, F)
    _write_stl(tmp_path / "plate.stl", *_plate(flip_plate))
    law = law or "pressure_modulus: 1.0e10"
    text = f"""
openfdk: 1
units: {{length: mm, angle: deg}}
gravity: [0, 0, 0]
bodies:
  ball: {{mass: 1.0, inertia: [1.0e-3, 1.0e-3, 1.0e-3], position: [{ball_x * 1e3}, 0, {(R + GAP) * 1e3}]}}
joints:
  hold: {{type: weld, parent: ground.origin, child: ball.origin}}
contacts:
  touch:
    vertices: {{body: ball, mesh: ball.stl, units: mm}}
    surface: {{body: ground, mesh: plate.stl, units: mm{extra_surface}}}
    {law}
"""
    path = tmp_path / "ball.yaml"
    path.write_text(text)
    return path


def test_area_spread_and_counts_match_the_cells(tmp_path):
    (check,) = check_contacts(load_model(_model(tmp_path)))
    plate = check.meshes[1]
    dx = np.diff(XS)
    cells = np.repeat(dx * DY / 2, 2 * (len(YS) - 1))  # two triangles per cell
    assert plate.role == "surface" and plate.n_triangles == cells.size
    assert plate.area_min == pytest.approx(cells.min(), rel=1e-5)
    assert plate.area_median == pytest.approx(np.median(cells), rel=1e-5)
    assert plate.area_max == pytest.approx(cells.max(), rel=1e-5)
    assert plate.area_ratio == pytest.approx(dx.max() / dx.min(), rel=1e-5)
    assert plate.n_open_edges == 2 * (len(XS) - 1) + 2 * (len(YS) - 1)
    assert plate.n_slivers == 0


def test_normals_facing_each_other_pass_and_rims_outside_the_zone_are_not_counted(tmp_path, capsys):
    path = _model(tmp_path)
    (check,) = check_contacts(load_model(path))
    assert not check.errors
    ball, plate = check.meshes
    for m in (ball, plate):
        assert m.away_fraction == 0.0 and m.aligned_fraction == 0.0 and m.n_zone >= 10
    # the ball's rim is R(1 − cos 70°) + g ≈ 7.1 mm above the plate, the plate's 10 mm from the ball
    assert ball.n_open_in_zone == 0 and plate.n_open_in_zone == 0
    assert ball.rim_distance == pytest.approx(R * (1 - np.cos(np.radians(70))) + GAP, rel=1e-3)
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "contact meshes at the reference pose" in out and "touch" in out and "plate.stl" in out


def test_a_plate_rim_under_the_ball_is_counted(tmp_path):
    """The ball moved over the plate's edge x = XS[-1]: the rim edges whose midpoint m
    lies within the zone of the ball, |m − c| − R ≤ zone, are counted."""
    x0 = XS[-1] - 1e-3
    (check,) = check_contacts(load_model(_model(tmp_path, ball_x=x0)))
    plate = check.meshes[1]
    V, F = _plate()
    V = V.astype(np.float32).astype(float)
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(edges, axis=0, return_counts=True)
    rim = keys[counts == 1]
    mid = 0.5 * (V[rim[:, 0]] + V[rim[:, 1]])
    centre = np.array([x0, 0.0, R + GAP])
    # the ball's closest point to m is on its cap (m is below the ball's equator): |m − c| − R
    expected = int(np.sum(np.linalg.norm(mid - centre, axis=1) - R <= min(ZONE_DISTANCE, 3e-3)))
    assert expected > 0
    assert plate.n_open_in_zone == expected
    # a figure (check's table, summary.json), not a printed warning: the run warns when
    # the contact does reach the rim (contact/rim.py)
    assert not any("open boundary edge" in w for w in check.warnings)
    assert check.as_dict()["meshes"][1]["open_edges_in_zone"] == expected


def test_an_inverted_plate_is_refused_naming_file_contact_mesh_and_fix(tmp_path, capsys):
    path = _model(tmp_path, flip_plate=True)
    (check,) = check_contacts(load_model(path))
    ball, plate = check.meshes
    assert plate.away_fraction == 1.0 and plate.aligned_fraction == 1.0 and ball.away_fraction == 0.0
    assert len(check.errors) == 1 and "contacts.touch.surface" in check.errors[0]
    assert main(["check", str(path)]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("openfdk: error")]
    assert len(err) == 1
    assert "ball.yaml" in err[0] and "contacts.touch.surface" in err[0] and "plate.stl" in err[0]
    assert "flip_normals: true" in err[0]
    # the fix the message names makes the model pass
    fixed = _model(tmp_path, flip_plate=True, extra_surface=", flip_normals: true")
    assert not check_contacts(load_model(fixed))[0].errors


def test_an_inverted_ball_is_the_one_named_and_run_refuses_it(tmp_path):
    from openfdk.analysis.jobs import contact_mesh_checks
    from openfdk.model.model import ModelError

    path = _model(tmp_path, flip_ball=True)
    (check,) = check_contacts(load_model(path))
    assert len(check.errors) == 1 and "contacts.touch.vertices" in check.errors[0] and "ball.stl" in check.errors[0]
    with pytest.raises(ModelError) as exc:
        contact_mesh_checks(load_model(path), str(path))
    assert "\n" not in str(exc.value) and "ball.yaml" in str(exc.value) and "flip_normals" in str(exc.value)
    # a chunked run makes the same check before any segment
    from openfdk.study.cli import run_chunked_job

    with pytest.raises(ModelError, match="flip_normals"):
        run_chunked_job(path, None, 2, workers=0, progress=False)


def test_a_missing_layer_thickness_is_refused_and_a_thin_layer_reported(tmp_path, capsys):
    path = _model(tmp_path, law="law: nonlinear\n    layers: [{modulus: 2.0e7}]")
    assert main(["check", str(path)]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("openfdk: error")]
    assert len(err) == 1 and "ball.yaml" in err[0] and "contacts.touch.layers[0]" in err[0] and "thickness" in err[0]
    # a layer thinner than the depth band (default max_depth 3 mm): a warning naming both
    thin = _model(tmp_path, law="law: nonlinear\n    layers: [{modulus: 2.0e7, thickness: 2}]")
    (check,) = check_contacts(load_model(thin))
    assert "h = 2 mm" in check.layer
    assert any("max_depth 3 mm" in w and "thickness 2 mm" in w for w in check.warnings)


def test_both_meshes_inverted_are_both_named(tmp_path):
    """Normals opposed (aligned 0) but both facing away from the other mesh: both named,
    as a warning, not a refusal — two open meshes that overlap at the reference pose look
    exactly the same (flipping both normals swaps inside and outside): the ball pushed
    into the correctly wound plate gives the same figures."""
    (check,) = check_contacts(load_model(_model(tmp_path, flip_plate=True, flip_ball=True)))
    ball, plate = check.meshes
    assert ball.aligned_fraction == 0.0 and plate.aligned_fraction == 0.0
    assert ball.away_fraction == 1.0 and plate.away_fraction == 1.0
    assert not check.errors
    named = [w for w in check.warnings if "face away" in w]
    assert len(named) == 2 and "ball.stl" in named[0] and "plate.stl" in named[1]
    assert all("overlap" in w and "flip_normals" in w for w in named)
