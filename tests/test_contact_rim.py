"""Contact patch at an open mesh's rim: detected against the closed-form patch of a ball on
a plane, warned once per run, never for closed meshes."""

import warnings
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from openfdk.contact.mesh import MeshWarning, surface_mesh
from openfdk.contact.rim import CUT_SHARE, RimCheck, contact_rim_frames, rim_edges, warn_contact_rims
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


def _closed_form_cut_share(x0, n=801):
    """Share of the ball's load beyond the floor's rim x = HALF: ∫ d dA over the patch part
    with x > HALF over ∫ d dA over the whole patch, d(ρ) = √(R² − ρ²) − (R − δ) (a plane
    continued past the rim), by quadrature on an n × n grid of the patch's square."""
    u = np.linspace(-A_PATCH, A_PATCH, n)
    X, Y = np.meshgrid(u, u, indexing="ij")
    d = np.sqrt(np.maximum(R**2 - X**2 - Y**2, 0.0)) - (R - DELTA)
    d = np.maximum(d, 0.0)
    return float(d[x0 + X > HALF].sum() / d.sum())


def test_load_cut_off_by_the_floor_rim_matches_the_closed_form_patch():
    model = _ball_model()
    chk = RimCheck(model.contacts[0].pair)
    # 1 mm (two vertex spacings of the ball) either side of the closed-form crossing x0 + a = HALF
    xs = np.array([0.0, 2e-3, HALF - A_PATCH - 1e-3,  # patch inside the floor
                   HALF - A_PATCH + 1e-3, HALF - 1e-3, HALF, HALF + 1e-3])  # patch crosses the rim
    state = model.initial_state()
    shares = []
    for x in xs:
        state.set_q(_q(x))
        res = model.contacts[0].evaluate(state)
        assert res.n_contact > 0  # loaded in every case, so the test is not vacuous
        on_A, share = chk.at_rim(state.p_WB[1], state.R_WB[1], state.p_WB[0], state.R_WB[0])
        assert not on_A  # the 60° cap's own rim (17 mm out) is never loaded
        shares.append(share)
    expected = np.array([_closed_form_cut_share(x) for x in xs])
    assert expected[2] == 0.0 and expected[3] > 0.01  # 1 mm inside / 1 mm past the rim
    np.testing.assert_array_equal(np.array(shares) == 0.0, expected == 0.0)
    # truncated load: the measured share is the closed form's to the mesh resolution
    np.testing.assert_allclose(shares, expected, atol=0.03, rtol=0.15)
    # and the floor does truncate the force once its rim is reached
    state.set_q(_q(0.0))
    full = np.linalg.norm(model.contacts[0].evaluate(state).force_W)
    state.set_q(_q(HALF))
    part = np.linalg.norm(model.contacts[0].evaluate(state).force_W)
    assert part < 0.7 * full
    np.testing.assert_allclose(part / full, 1 - expected[5], atol=0.05)


def test_frames_count_from_the_cut_share_on():
    """contact_rim_frames counts a frame when the cut-off share reaches CUT_SHARE."""
    model = _ball_model()
    xs = [0.0, HALF - A_PATCH + 1e-3, HALF - 1e-3, HALF]
    expected = [k for k, x in enumerate(xs) if _closed_form_cut_share(x) >= CUT_SHARE]
    assert expected == [2, 3]
    hits = contact_rim_frames(model, np.stack([_q(x) for x in xs]))
    assert [h[:4] for h in hits] == [("foot", "surface", "floor.stl", expected)]
    np.testing.assert_allclose(hits[0][4], _closed_form_cut_share(HALF), atol=0.03, rtol=0.15)


def test_small_cap_loaded_at_its_own_rim():
    """A 10° cap (rim radius R sin 10° = 3.5 mm < 4.4 mm patch) is loaded at its rim."""
    model = _ball_model(half_angle=np.radians(10))
    q = np.stack([_q(0.0), _q(1e-3), _q(2e-3)])
    hits = contact_rim_frames(model, q)
    assert len(hits) == 1 and hits[0][:4] == ("foot", "vertices", "ball.stl", [0, 1, 2])
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
    share = contact_rim_frames(model, kin.q)[0][4]
    assert 0.3 < share < 0.7  # the patch half past the rim at x = HALF
    assert msgs == ["contact 'foot': the contact patch reaches the border of mesh contacts.foot.surface "
                    "(file floor.stl) on 2 of 5 frames (first at t=0.020 s); forces there are truncated "
                    f"(no load past an open mesh's rim, up to {100 * share:.0f} % of the patch's load cut off): "
                    "extend the mesh beyond the contact region"]
    # `openfdk run` computes the hits in a figure worker and reports them here
    # (cli.commands._rim_check): the same warnings from the hits passed between processes
    import pickle

    from openfdk.cli.commands import _rim_check

    side = _rim_check(model, kin)
    side.take(pickle.loads(pickle.dumps(side.compute())))
    with warnings.catch_warnings(record=True) as again:
        warnings.simplefilter("always")
        side.finish()
    assert [str(w.message) for w in again if issubclass(w.category, MeshWarning)] == msgs


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


def test_the_nearest_rim_segment_is_the_closed_form_point_to_segment_distance_s_argmin():
    """``_nearest_segment`` (a compiled loop) against the distance of each point to each
    segment in closed form, |p − (a + t (b − a))| with t = clip((p − a)·(b − a) / |b − a|², 0, 1),
    written here per pair; segments of varied length and direction, points near and far,
    and one point at a shared end (the first of the equally near segments)."""
    from openfdk.contact.rim import _nearest_segment

    rng = np.random.default_rng(4)
    A = rng.uniform(-0.02, 0.02, (60, 3))
    B = A + rng.normal(0.0, 0.003, (60, 3))
    B[7] = A[8]  # segments 7 and 8 share an end
    P = np.vstack([rng.uniform(-0.03, 0.03, (200, 3)), A[8][None]])

    def distance(p, a, b):
        t = min(max(float(np.dot(p - a, b - a) / np.dot(b - a, b - a)), 0.0), 1.0)
        return float(np.linalg.norm(p - (a + t * (b - a))))

    expected = [int(np.argmin([distance(p, a, b) for a, b in zip(A, B)])) for p in P]
    assert _nearest_segment(P, A, B).tolist() == expected
    assert expected[-1] == 7  # distance 0 to segments 7 and 8: the first


def test_the_rim_check_s_share_equals_the_exact_query_of_every_vertex():
    """RimCheck.at_rim asks the exact distance only of A's vertices near B's rim and not
    nearer to a vertex of B than to the rim (k-d trees). The share it reports equals the
    one computed here from the exact query of every vertex of A, with the module
    docstring's formula written out (cut: closest point on B's rim, |φ| ≤ max_depth,
    depth e behind the nearest rim edge's triangle; share = Σ a e / (Σ a e + Σ a d)), for
    the ball on the floor at several places across the floor's rim; and it asks far
    fewer points."""
    from openfdk.contact.signed_distance import OpenSurfaceDistance

    model = _ball_model()
    pair = model.contacts[0].pair
    chk = RimCheck(pair)
    exact = OpenSurfaceDistance(pair.surface_B)
    rim, faces = rim_edges(pair.surface_B.faces, with_faces=True)
    V_B = pair.surface_B.vertices_B
    asked = []
    query = chk._distance_B.query
    chk._distance_B.query = lambda y: asked.append(len(y)) or query(y)
    state = model.initial_state()
    shares = []
    for x in (HALF - A_PATCH - 1e-3, HALF - 1e-3, HALF, HALF + 1.5e-3):
        state.set_q(_q(x))
        R_Wa, r_Wa, R_Wb, r_Wb = state.R_WB[1], state.p_WB[1], state.R_WB[0], state.p_WB[0]
        on_A, share = chk.at_rim(r_Wa, R_Wa, r_Wb, R_Wb)
        idx, depth = pair.penetration(r_Wa, R_Wa, r_Wb, R_Wb)[:2]
        y = (pair._s_A @ R_Wa.T + r_Wa - r_Wb) @ R_Wb
        phi, _, valid, c = exact.query(y)
        cut = np.flatnonzero(~valid & (np.abs(phi) <= pair.max_depth))
        missing = 0.0
        for i in cut:
            seg = [float(np.linalg.norm(c[i] - (V_B[u] + np.clip(np.dot(c[i] - V_B[u], V_B[v] - V_B[u])
                                                                   / np.dot(V_B[v] - V_B[u], V_B[v] - V_B[u]), 0, 1)
                                                   * (V_B[v] - V_B[u])))) for u, v in rim]
            n = pair.surface_B.face_normals_B[faces[int(np.argmin(seg))]]
            e = -float(np.dot(y[i] - c[i], n))
            missing += pair._a_A[i] * e if e > 0 else 0.0
        expected = missing / max(missing + float((pair._a_A[idx] * depth).sum()), 1e-300)
        assert share == pytest.approx(expected, rel=1e-12, abs=1e-15)
        shares.append(share)
    assert shares[0] == 0.0 and shares[-1] > CUT_SHARE  # inside the floor, then well past its rim
    assert max(asked) < 0.5 * len(pair._s_A)


def test_the_rim_check_asks_the_exact_distance_only_where_the_closest_point_can_be_on_the_rim():
    """RimCheck.at_rim asks the exact distance only of A's vertices within max_depth + half
    the longest rim edge of one of B's rim vertices (found here from all pairwise
    distances), and leaves out those of them that have a vertex of B nearer than their
    distance to the rim can be (nearest rim vertex − half an edge): their closest point
    on B is not on the rim. Every vertex it leaves out of that reach is certified so,
    and some are asked (the ball on the floor near the rim)."""
    model = _ball_model()
    pair = model.contacts[0].pair
    chk = RimCheck(pair)
    state = model.initial_state()
    state.set_q(_q(HALF - 1e-3))
    asked = []
    query = chk._distance_B.query
    chk._distance_B.query = lambda y: asked.append(np.array(y)) or query(y)
    on_A, share = chk.at_rim(state.p_WB[1], state.R_WB[1], state.p_WB[0], state.R_WB[0])
    assert share > 0.01
    R_Wa, r_Wa, R_Wb, r_Wb = state.R_WB[1], state.p_WB[1], state.R_WB[0], state.p_WB[0]
    y = (pair._s_A @ R_Wa.T + r_Wa - r_Wb) @ R_Wb
    gaps = np.linalg.norm(y[:, None, :] - chk._rim_V_B[None, :, :], axis=2).min(axis=1)
    to_B = np.linalg.norm(y[:, None, :] - pair.surface_B.vertices_B[None, :, :], axis=2).min(axis=1)
    half = 0.5 * max(float(np.linalg.norm(pair.surface_B.vertices_B[u] - pair.surface_B.vertices_B[v]))
                     for u, v in rim_edges(pair.surface_B.faces))
    within = gaps <= pair.max_depth + half
    asked_rows = {tuple(p) for p in asked[0]}
    rows = [tuple(p) for p in y]
    assert asked_rows <= {r for r, w in zip(rows, within) if w} and len(asked_rows) > 0
    left_out = [i for i, r in enumerate(rows) if within[i] and r not in asked_rows]
    assert left_out and all(to_B[i] < gaps[i] - half for i in left_out)
