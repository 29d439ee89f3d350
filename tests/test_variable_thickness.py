"""Cartilage thickness from the bone behind it (contact/thickness.py,
contact/variable_layers.py; OpenSim-JAM's ``use_variable_thickness``), against closed
forms on flat layers whose bone is a tilted plane.

The cartilage is the plate z = 0 (normals +z), 40 × 20 mm; its bone is the plane
z = −(H0 + S x), so the ray from a point (x, y, 0) along −z meets it at h(x) = H0 + S x.
The opposite surface is the plane z = −δ facing it (normals −z), so every vertex is δ
behind it."""

import numpy as np
import pytest

from openfdk.contact.shapes import flat_patch
from openfdk.contact.stl import write_stl
from openfdk.contact.thickness import triangle_thickness, vertex_thickness
from openfdk.forces.forceset import ForceElements
from openfdk.io.modelfile import load_model
from openfdk.model.errors import ModelError

H0, S = 2.0e-3, 0.04     # m, m/m: h(x) = H0 + S x from 1.2 mm (x = −20 mm) to 2.8 mm (x = 20 mm)
DELTA = 0.1e-3           # m
K = 1.0e7                # Pa
SIZE = (0.04, 0.02)      # m


def h_of(x):
    return H0 + S * x


def _write(path, V, F):
    write_stl(path, 1e3 * np.asarray(V), F)  # mm


def _files(folder, side="vertices", h_max=4.0):
    """plate.stl (the cartilage, z = 0, +z), bone.stl (the tilted plane behind it) and
    cover.stl (the plane z = −δ, −z); the cartilage is the ``side`` surface."""
    plate = flat_patch(*SIZE, 0.5e-3)
    _write(folder / "plate.stl", plate.vertices_B, plate.faces)
    bone = flat_patch(0.06, 0.04, 2e-3)
    V = bone.vertices_B.copy()
    V[:, 2] = -h_of(V[:, 0])
    _write(folder / "bone.stl", V, bone.faces)
    cover = flat_patch(0.05, 0.03, 0.5e-3)
    V = cover.vertices_B.copy()
    V[:, 2] = -DELTA
    _write(folder / "cover.stl", V, cover.faces[:, ::-1])  # normals −z
    return plate


def _model(folder, law="linear", layers=None, side="vertices", h_max=4.0):
    _files(folder)
    thickness = f", thickness: {{back_mesh: bone.stl, min: 0.5, max: {h_max}}}"
    cart = f"{{body: tibia, mesh: plate.stl, units: mm{thickness}}}"
    other = "{body: femur, mesh: cover.stl, units: mm}"
    if side == "surface":  # the cartilage is the opposite surface: the cover presses from below
        cart, other = other, cart
    layers = layers or f"[{{modulus: {K}, thickness: {side}}}]"
    (folder / "m.yaml").write_text(f"""
openfdk: 1
units: {{length: mm, angle: deg}}
gravity: [0, 0, 0]
bodies:
  tibia: {{mass: 1.0, inertia: [1.0e-3, 1.0e-3, 1.0e-3]}}
  femur: {{mass: 1.0, inertia: [1.0e-3, 1.0e-3, 1.0e-3]}}
joints:
  a: {{type: weld, parent: ground.origin, child: tibia.origin}}
  b: {{type: weld, parent: ground.origin, child: femur.origin}}
contacts:
  knee:
    vertices: {cart}
    surface: {other}
    law: {law}
    layers: {layers}
    mode: exact                 # closest points exact: the depth is δ to rounding
    max_depth: 1
""")
    return folder / "m.yaml"


def test_the_rays_find_the_tilted_bone_and_jams_clamps():
    plate = flat_patch(*SIZE, 0.5e-3)
    bone = flat_patch(0.06, 0.04, 2e-3)
    V = bone.vertices_B.copy()
    V[:, 2] = -h_of(V[:, 0])
    F = plate.faces
    centres = plate.vertices_B[F].mean(axis=1)
    h, hit = triangle_thickness(plate.vertices_B, F, V, bone.faces, 1.0e-3, 4.0e-3)
    assert hit.all()
    np.testing.assert_allclose(h, h_of(centres[:, 0]), rtol=0, atol=1e-9)  # (libigl's ray hits)
    # below min: min; above max (and a ray that misses): min as well, as OpenSim-JAM sets it
    h, hit = triangle_thickness(plate.vertices_B, F, V, bone.faces, 1.5e-3, 2.5e-3)
    want = h_of(centres[:, 0])
    expected = np.where(want > 2.5e-3, 1.5e-3, np.maximum(want, 1.5e-3))
    np.testing.assert_allclose(h, expected, rtol=0, atol=1e-9)
    assert not hit[want > 2.5e-3].any() and hit[want <= 2.5e-3].all()
    h, hit = triangle_thickness(plate.vertices_B, F, V + [1.0, 0.0, 0.0], bone.faces, 1.5e-3, 2.5e-3)
    assert not hit.any() and np.all(h == 1.5e-3)
    # a vertex's thickness: its triangles' mean by area; exact for a linear field inside
    hv = vertex_thickness(plate, h_of(centres[:, 0]))
    inner = np.all(np.abs(plate.vertices_B[:, :2]) < np.array(SIZE) / 2 - 1e-6, axis=1)
    np.testing.assert_allclose(hv[inner], h_of(plate.vertices_B[inner, 0]), rtol=0, atol=1e-12)


def _contact(path):
    model = load_model(path)
    _, out, _ = ForceElements(model).generalized_forces(model.initial_state(), 0.0)
    return model, out["contacts"]["knee"]


def test_a_vertex_layer_of_varying_thickness_carries_k_delta_over_h(tmp_path):
    """Linear law: each vertex carries P_i = K δ / h_i; the total force is Σ a_i K δ/h_i,
    close to the integral K δ W/S ln(h(x₁)/h(x₀)), and 1.4 % off what a uniform layer of
    the mean thickness gives."""
    model, c = _contact(_model(tmp_path))
    pair = model.contacts[0].pair
    plate = pair.surface_A  # (as read from the STL: its vertices in the file's merged order)
    h_v = pair.variable.h_A
    a = plate.vertex_areas
    delta = -float(pair.surface_B.vertices_B[:, 2].mean())  # δ as the STL's float32 holds it
    assert delta == pytest.approx(DELTA, rel=1e-7)
    Fz = float(np.sum(a * K * delta / h_v))
    assert c.force_W[2] == pytest.approx(-Fz, rel=1e-9)  # the tibia is pressed down
    x0, x1 = -SIZE[0] / 2, SIZE[0] / 2
    integral = K * DELTA * SIZE[1] / S * np.log(h_of(x1) / h_of(x0))
    assert Fz == pytest.approx(integral, rel=2e-3)
    uniform = K * DELTA * SIZE[0] * SIZE[1] / H0
    assert abs(Fz / uniform - 1.0) > 0.01
    # the moment: the thin side (x < 0) pushes harder, so the resultant lies at x < 0
    x_c = float(np.sum(a * plate.vertices_B[:, 0] / h_v) / np.sum(a / h_v))
    assert x_c < -1e-4
    assert c.cop_W[0] == pytest.approx(x_c, abs=1e-9)


def test_the_non_linear_law_per_vertex(tmp_path):
    """P_i = −K ln(1 − δ/h_i) at every vertex in contact (Bei & Fregly 2004)."""
    model, c = _contact(_model(tmp_path, law="nonlinear"))
    plate = model.contacts[0].pair.surface_A
    h_v = model.contacts[0].pair.variable.h_A
    delta = -float(model.contacts[0].pair.surface_B.vertices_B[:, 2].mean())
    Fz = float(np.sum(plate.vertex_areas * -K * np.log1p(-delta / h_v)))
    assert c.force_W[2] == pytest.approx(-Fz, rel=1e-9)
    assert c.peak_pressure == pytest.approx(-K * np.log1p(-delta / h_v.min()), rel=1e-9)


def test_the_opposite_surfaces_thickness_is_that_of_its_nearest_triangle(tmp_path):
    """The cartilage as the opposite surface: a vertex of the cover takes the thickness
    of the cartilage triangle under it (nearest centre), piecewise constant per
    triangle as OpenSim-JAM's per-triangle thickness."""
    model, c = _contact(_model(tmp_path, side="surface"))
    pair = model.contacts[0].pair
    cover = pair.surface_A
    inside = np.all(np.abs(cover.vertices_B[:, :2]) <= np.array(SIZE) / 2, axis=1)
    # the cover's vertices are the cover's (z = −δ): their closest cartilage points are (x, y, 0)
    closest = cover.vertices_B[inside] * [1.0, 1.0, 0.0]
    h = pair.variable.h_B.at(closest)
    assert np.abs(h - h_of(closest[:, 0])).max() < S * 0.5e-3  # within the field's change over a triangle
    res = pair.evaluate(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3), want_vertex_pressure=True)
    p = res.vertex_pressure[inside]
    assert np.count_nonzero(p) > 0.9 * inside.sum()
    on = p > 0
    np.testing.assert_allclose(p[on], K * DELTA / h[on], rtol=1e-6)


def test_the_stiffness_is_the_derivative_of_the_loads(tmp_path):
    """K = ∂Q/∂q̂ with variable layers: central differences of Q along each of the 12
    coordinates (the thickness is fixed to the triangles, so it does not change within
    1e-7 m), and non-zero."""
    model, _ = _contact(_model(tmp_path, law="nonlinear"))
    pair = model.contacts[0].pair
    rot = np.eye(3)
    base = pair.evaluate(np.zeros(3), rot, np.zeros(3), rot, want_stiffness=True)
    assert np.abs(base.K).max() > 0.0
    from scipy.spatial.transform import Rotation

    cols = []
    for j in range(12):
        eps = 1e-8 if (j // 3) % 2 == 0 else 1e-6  # m, rad
        qs = []
        for sign in (1.0, -1.0):
            d = np.zeros(12)
            d[j] = sign * eps
            Ra = rot @ Rotation.from_rotvec(d[3:6]).as_matrix()  # δπ in the body's frame
            Rb = rot @ Rotation.from_rotvec(d[9:12]).as_matrix()
            qs.append(pair.evaluate(d[0:3], Ra, d[6:9], Rb).Q)
        cols.append((qs[0] - qs[1]) / (2 * eps))
    J = np.array(cols).T
    S = np.repeat([1.0, 1.0 / 0.02, 1.0, 1.0 / 0.02], 3)  # every block in N/m (lever 20 mm)
    Kn, Jn = S[:, None] * base.K * S[None, :], S[:, None] * J * S[None, :]
    np.testing.assert_allclose(Kn, Jn, rtol=0, atol=1e-4 * np.abs(Kn).max())


@pytest.mark.parametrize("layers, fragment", [
    ("[{modulus: 1.0e7, thickness: surface}]", "contacts.knee.layers[0].thickness: the surface surface has no"),
    ("[{modulus: 1.0e7, thickness: bone}]", "contacts.knee.layers[0].thickness: expected a number, 'vertices'"),
    ("[{modulus: 1.0e7, thickness: [vertices, vertices]}]", "each once"),
    ("[{modulus: 1.0e7, thickness: 2}]", "contacts.knee.vertices.thickness: no layer uses this thickness field"),
])
def test_bad_thickness_entries_are_one_line_errors(tmp_path, layers, fragment):
    with pytest.raises(ModelError) as err:
        load_model(_model(tmp_path, layers=layers))
    assert fragment in str(err.value) and "\n" not in str(err.value)


def test_a_back_mesh_the_rays_never_meet_is_an_error(tmp_path):
    path = _model(tmp_path)
    bone = flat_patch(0.06, 0.04, 2e-3)
    V = bone.vertices_B.copy()
    V[:, 2] = +0.01  # in front of the cartilage, not behind it
    _write(tmp_path / "bone.stl", V, bone.faces)
    with pytest.raises(ModelError) as err:
        load_model(path)
    assert "contacts.knee.vertices.thickness.back_mesh" in str(err.value) and "bone.stl" in str(err.value)


@pytest.mark.parametrize("old, new, fragment", [
    ("min: 0.5, max: 4.0", "min: 4.0, max: 0.5", "contacts.knee.vertices.thickness: min 4.0 must be below max 0.5"),
    ("min: 0.5, max: 4.0", "max: 4.0", "contacts.knee.vertices.thickness"),
    ("min: 0.5, max: 4.0", "min: 0.5, max: 4.0, scale: 2", "contacts.knee.vertices.thickness"),
    ("back_mesh: bone.stl", "back_mesh: nowhere.stl", "contacts.knee.vertices.thickness.back_mesh"),
    ("thickness: vertices}", "thickness: [vertices, 1, 2]}", "contacts.knee.layers[0].thickness"),
    ("thickness: vertices}", "thickness: -1}", "contacts.knee.layers[0].thickness"),
    ("law: linear", "law: linear\n    pressure_modulus: 1.0e10", "contacts.knee.pressure_modulus"),
])
def test_bad_thickness_fields_are_one_line_errors(tmp_path, old, new, fragment):
    path = _model(tmp_path)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ModelError) as err:
        load_model(path)
    assert fragment in str(err.value) and "\n" not in str(err.value), str(err.value)


@pytest.mark.parametrize("max_depth, warned", [(1, False), (3, True)])
def test_the_mesh_check_names_the_fields_and_a_band_deeper_than_the_thickest_layer(tmp_path, max_depth, warned):
    """``openfdk check``'s layer column gives each field's range (1.2–2.8 mm here), and
    the non-linear law's depth warning compares max_depth with the thickest the layers
    get: 2.79333 mm, the edge vertices' mean of their triangles' h at x = 19.83 mm (their
    centres), 2 + 0.04·19.833 mm. A 3 mm band is warned of, a 1 mm one is not."""
    from openfdk.contact.mesh_check import check_contacts

    path = _model(tmp_path, law="nonlinear")
    path.write_text(path.read_text().replace("max_depth: 1", f"max_depth: {max_depth}"))
    (check,) = check_contacts(load_model(path))
    assert "variable thickness (vertices 1.2–2.8 mm)" in check.layer, check.layer
    layer_warnings = [w for w in check.warnings if "layers' thickness" in w]
    assert bool(layer_warnings) == warned, check.warnings
    if warned:
        assert "max_depth 3 mm is not below the layers' thickness 2.79333 mm" in layer_warnings[0], layer_warnings
