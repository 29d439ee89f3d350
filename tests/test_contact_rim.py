"""Contact patch at an open mesh's rim: detected against the closed-form patch of a ball on
a plane, warned once per run, never for closed meshes."""

import warnings
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from openfdk.contact.mesh import MeshWarning, surface_mesh
from openfdk.contact.rim import RimCheck, contact_rim_frames, rim_edges, warn_contact_rims
from openfdk.contact.sections import add_contact
from openfdk.contact.shapes import flat_patch, sphere_cap
from openfdk.model.builder import ModelBuilder

R = 0.020  # ball radius, m
DELTA = 0.5e-3  # penetration of the ball into the plane, m
HALF = 0.010  # half side of the square floor patch, m
A_PATCH = np.sqrt(2 * R * DELTA - DELTA**2)  # closed-form patch radius on the plane, 4.44 mm


def _ball_model(half_angle=np.radians(60), floor=None, ball=None):
    """A ball (cap of radius R, centre = its centre of mass) above a floor patch z = 0 on ground."""
    b = ModelBuilder("ball on floor", gravity=(0, 0, -9.81))
    b.add_body("ball", 1.0, [1e-4] * 3, position=[0, 0, R])
    ball = ball if ball is not None else sphere_cap(R, half_angle, 0.5e-3, pole=(0, 0, -1), name="ball.stl")
    floor = floor if floor is not None else flat_patch(2 * HALF, 2 * HALF, 1e-3, name="floor.stl")
    add_contact(b, "foot", "ball", ball, "ground", floor, 1e9)
    return b.build()


def _q(x):
    """Ball centre at (x, 0, R − DELTA), identity orientation: q (7,)."""
    return np.array([x, 0.0, R - DELTA, 1.0, 0.0, 0.0, 0.0])


def test_rim_edges_of_a_grid_patch():
    mesh = flat_patch(0.004, 0.002, 1e-3)  # 5 × 3 nodes: perimeter 2·(4 + 2) edges
    e = rim_edges(mesh.faces)
    assert len(e) == 12
    on_rim = np.zeros(mesh.n_vertices, bool)
    on_rim[e.ravel()] = True
    v = mesh.vertices_B
    border = np.isclose(np.abs(v[:, 0]), 0.002) | np.isclose(np.abs(v[:, 1]), 0.001)
    np.testing.assert_array_equal(on_rim, border)


def test_patch_crossing_the_floor_rim_is_detected_as_the_closed_form_predicts():
    model = _ball_model()
    chk = RimCheck(model.contacts[0].pair)
    margin = chk.tol_B + 0.5e-3  # the detection band at the rim, plus one vertex spacing of A
    xs = np.array([0.0, 2e-3, HALF - A_PATCH - margin - 1e-3,  # patch inside the floor
                   HALF - A_PATCH + 1e-3, HALF - 1e-3, HALF + 1e-3])  # patch crosses the rim
    expected = xs + A_PATCH > HALF
    state = model.initial_state()
    got = []
    for x in xs:
        state.set_q(_q(x))
        res = model.contacts[0].evaluate(state)
        assert res.n_contact > 0  # loaded in every case, so the test is not vacuous
        got.append(chk.at_rim(state.p_WB[1], state.R_WB[1], state.p_WB[0], state.R_WB[0]))
    got = np.array(got)
    np.testing.assert_array_equal(got[:, 1], expected)  # floor (surface) rim
    assert not got[:, 0].any()  # the 60° cap's own rim (17 mm out) is never loaded
    # the floor truncates the force once its rim is reached: less than the full patch
    state.set_q(_q(0.0))
    full = np.linalg.norm(model.contacts[0].evaluate(state).force_W)
    state.set_q(_q(HALF))
    assert np.linalg.norm(model.contacts[0].evaluate(state).force_W) < 0.7 * full


def test_small_cap_loaded_at_its_own_rim():
    """A 10° cap (rim radius R sin 10° = 3.5 mm < 4.4 mm patch) is loaded at its rim."""
    model = _ball_model(half_angle=np.radians(10))
    q = np.stack([_q(0.0), _q(1e-3), _q(2e-3)])
    hits = contact_rim_frames(model, q)
    assert hits == [("foot", "vertices", "ball.stl", [0, 1, 2])]
    deep = np.stack([_q(0.0)])
    deep[0, 2] = R + 1e-3  # lifted clear of the floor: no load, no warning
    assert contact_rim_frames(model, deep) == []


def test_run_warns_once_naming_contact_file_frames_and_time():
    model = _ball_model()
    xs = [0.0, 0.0, HALF - 1e-3, HALF, 0.0]
    kin = SimpleNamespace(q=np.stack([_q(x) for x in xs]), time=np.array([0.0, 0.01, 0.02, 0.03, 0.04]))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_contact_rims(model, kin)
    msgs = [str(w.message) for w in caught if issubclass(w.category, MeshWarning)]
    assert msgs == ["contact 'foot': the contact patch reaches the border of mesh contacts.foot.surface "
                    "(file floor.stl) on 2 of 5 frames (first at t=0.020 s); forces there are truncated "
                    "(no load past an open mesh's rim): extend the mesh beyond the contact region"]


def test_closed_meshes_never_warn():
    ball = trimesh.creation.icosphere(subdivisions=4, radius=R)
    block = trimesh.creation.box(extents=[2 * HALF, 2 * HALF, 0.01])
    ball_mesh = surface_mesh(np.asarray(ball.vertices), np.asarray(ball.faces), name="ball_closed.stl")
    block_mesh = surface_mesh(np.asarray(block.vertices) - [0, 0, 0.005], np.asarray(block.faces),
                              name="block_closed.stl")
    model = _ball_model(floor=block_mesh, ball=ball_mesh)
    chk = RimCheck(model.contacts[0].pair)
    assert not chk.is_open
    xs = np.linspace(-HALF - 2e-3, HALF + 2e-3, 9)  # across the block's edges too
    state = model.initial_state()
    loaded = 0
    for x in xs:
        state.set_q(_q(x))
        loaded += model.contacts[0].evaluate(state).n_contact > 0
    assert loaded >= 7
    assert contact_rim_frames(model, np.stack([_q(x) for x in xs])) == []
