"""Mesh loading, validation and derived quantities (openfdk.contact.mesh)."""

import warnings

import numpy as np
import pytest
import trimesh

from openfdk.contact import (
    MeshError,
    MeshWarning,
    check_scale,
    load_mesh,
    offset,
    surface_mesh,
)
from openfdk.contact.shapes import flat_patch, sphere_cap
from openfdk.numerics.spatial import rotation_matrix_xyz


def _sorted_rows(a, decimals=9):
    a = np.round(np.asarray(a), decimals)
    return a[np.lexsort(a.T[::-1])]


def _mean_normal(mesh):
    """Area-weighted mean unit normal from the raw triangles (independent of the class)."""
    V, F = mesh.vertices_B, mesh.faces
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n = cross.sum(axis=0)
    return n / np.linalg.norm(n)


@pytest.fixture
def cap_mm():
    """Open sphere cap, radius 10 (mm numbers), normals outward (away from the centre)."""
    return sphere_cap(10.0, 0.6, 1.0, pole=(0.0, 0.0, 1.0))


@pytest.mark.parametrize("file_type, suffix", [
    ("stl", ".stl"), ("stl_ascii", ".stl"), ("obj", ".obj"), ("ply", ".ply")])
def test_round_trip_formats_in_mm(tmp_path, cap_mm, file_type, suffix):
    path = tmp_path / f"cap_{file_type}{suffix}"
    tm = trimesh.Trimesh(cap_mm.vertices_B, cap_mm.faces, process=False)
    tm.export(path, file_type=file_type)
    if file_type == "stl_ascii":
        assert path.read_bytes()[:5] == b"solid"
    elif file_type == "stl":
        assert path.read_bytes()[:5] != b"solid"
    mesh = load_mesh(path, units="mm")
    assert mesh.name == path.name
    assert mesh.n_faces == cap_mm.n_faces
    # same vertex set, converted mm -> m (STL stores float32: compare to 1e-9 m)
    np.testing.assert_allclose(
        _sorted_rows(mesh.vertices_B, 7), _sorted_rows(cap_mm.vertices_B * 1e-3, 7), atol=1e-9
    )
    # area m² = area mm² · 1e-6, computed independently by trimesh from the original
    assert mesh.area == pytest.approx(tm.area * 1e-6, rel=1e-6)
    # orientation preserved: the cap's normals point away from the sphere centre (+z)
    np.testing.assert_allclose(_mean_normal(mesh), _mean_normal(cap_mm), atol=1e-9)
    assert _mean_normal(mesh)[2] > 0.9


def test_placement_matrix_and_tuple_agree(tmp_path, cap_mm):
    path = tmp_path / "cap.ply"
    trimesh.Trimesh(cap_mm.vertices_B, cap_mm.faces, process=False).export(path)
    R = rotation_matrix_xyz([0.3, -0.2, 1.1])
    t = np.array([0.01, -0.02, 0.03])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    a = load_mesh(path, units="mm", placement=T)
    b = load_mesh(path, units="mm", placement=(t, R))
    np.testing.assert_allclose(a.vertices_B, b.vertices_B, atol=1e-15)
    # v_B = R v_file·1e-3 + t, checked vertex by vertex (PLY keeps the vertex order)
    np.testing.assert_allclose(a.vertices_B, cap_mm.vertices_B * 1e-3 @ R.T + t, atol=1e-12)
    # normals rotate with the mesh
    np.testing.assert_allclose(_mean_normal(a), R @ _mean_normal(cap_mm), atol=1e-9)
    with pytest.raises(MeshError, match="proper rotation"):
        load_mesh(path, placement=(t, np.diag([1.0, 1.0, -1.0])))
    with pytest.raises(MeshError, match="4x4"):
        load_mesh(path, placement=np.eye(3))


def test_nonexistent_file_names_the_file(tmp_path):
    missing = tmp_path / "fossa_r.stl"
    with pytest.raises(MeshError, match="fossa_r.stl.*does not exist"):
        load_mesh(missing)


def test_unknown_unit(tmp_path, cap_mm):
    path = tmp_path / "cap.obj"
    trimesh.Trimesh(cap_mm.vertices_B, cap_mm.faces, process=False).export(path)
    with pytest.raises(MeshError, match="unknown length unit 'furlong'"):
        load_mesh(path, units="furlong")


def test_empty_and_garbage_files(tmp_path):
    empty = tmp_path / "empty.stl"
    empty.write_bytes(trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int)).export(file_type="stl"))
    with pytest.raises(MeshError, match="empty.stl.*no triangles"):
        load_mesh(empty)
    garbage = tmp_path / "garbage.stl"
    garbage.write_text("this is not a mesh")
    with pytest.raises(MeshError, match="garbage.stl"):
        load_mesh(garbage)
    with pytest.raises(MeshError, match="'arrays' contains no triangles"):
        surface_mesh(np.zeros((3, 3)), np.zeros((0, 3), int), name="arrays")


def test_degenerate_triangles_removed_with_warning(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 2, 0], [3, 3, 0.0]])
    F = np.array([[0, 1, 2], [1, 3, 2], [0, 3, 4], [3, 4, 5]])  # last two: collinear
    path = tmp_path / "degenerate.obj"
    trimesh.Trimesh(V, F, process=False).export(path)
    with pytest.warns(MeshWarning, match="degenerate.obj.*removed 2 degenerate"):
        mesh = load_mesh(path, units="mm")
    assert mesh.n_faces == 2
    assert mesh.n_vertices == 4  # unreferenced vertices dropped
    assert mesh.area == pytest.approx(1e-6)  # the unit square, in m²
    with pytest.raises(MeshError, match="all 2 triangles are degenerate"):
        surface_mesh(V, F[2:], name="line")


def test_partly_flipped_winding_is_fixed_with_warning(tmp_path):
    patch = flat_patch(10.0, 10.0, 1.0)  # normals +z
    F = patch.faces.copy()
    flipped = np.arange(7, 19)
    F[flipped] = F[flipped][:, ::-1]
    path = tmp_path / "patch.obj"
    trimesh.Trimesh(patch.vertices_B, F, process=False).export(path)
    with pytest.warns(MeshWarning, match=r"patch.obj.*12 triangle\(s\) had winding inconsistent"):
        mesh = load_mesh(path, units="mm")
    normals = mesh.face_normals_B
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, 1.0], (mesh.n_faces, 1)), atol=1e-12)
    # the majority (by area) decides: flipping most triangles makes −z the majority
    F2 = patch.faces[:, ::-1].copy()
    F2[flipped] = patch.faces[flipped]
    with pytest.warns(MeshWarning, match=r"12 triangle\(s\)"):
        mesh2 = surface_mesh(patch.vertices_B, F2, name="mostly down")
    assert np.all(mesh2.face_normals_B[:, 2] < -0.999)


def test_closed_mesh_with_inward_normals_is_turned_outward(tmp_path):
    ball = trimesh.creation.icosphere(subdivisions=2, radius=5.0)
    path = tmp_path / "ball_inward.stl"
    trimesh.Trimesh(ball.vertices, ball.faces[:, ::-1], process=False).export(path)
    with pytest.warns(MeshWarning, match="ball_inward.stl.*closed.*inward"):
        mesh = load_mesh(path, units="mm")
    centroids = mesh.vertices_B[mesh.faces].mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", mesh.face_normals_B, centroids) > 0.0)


def test_scale_check_warns_for_mm_declared_as_m(tmp_path):
    cap = sphere_cap(15.0, 1.2, 1.0, pole=(0, 0, 1))  # spans 25.0 (mm numbers)
    path = tmp_path / "fossa_r.stl"
    trimesh.Trimesh(cap.vertices_B, cap.faces, process=False).export(path)
    wrong = load_mesh(path, units="m")
    span = np.ptp(cap.vertices_B, axis=0).max()
    assert span == pytest.approx(28.0, abs=0.1)
    with pytest.warns(MeshWarning, match=r"mesh 'fossa_r.stl' spans 28.0 m; is it in mm\?"):
        assert check_scale(wrong, model_length_scale=0.03) is False
    right = load_mesh(path, units="mm")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_scale(right, model_length_scale=0.03) is True
    tiny = surface_mesh(cap.vertices_B * 1e-6, cap.faces, name="tiny.stl")
    with pytest.warns(MeshWarning, match="tiny.stl' spans 0.028 mm"):
        assert check_scale(tiny, model_length_scale=0.03) is False


def test_vertex_areas_are_one_third_of_incident_triangles():
    h = 0.5
    patch = flat_patch(4.0, 3.0, h)
    # closed form: interior vertices of a regular triangulated grid carry h², and the
    # total equals the rectangle area
    assert patch.area == pytest.approx(12.0, rel=1e-12)
    x, y = patch.vertices_B[:, 0], patch.vertices_B[:, 1]
    interior = (np.abs(x) < 2.0 - 1e-9) & (np.abs(y) < 1.5 - 1e-9)
    np.testing.assert_allclose(patch.vertex_areas[interior], h * h, rtol=1e-12)
    # area-weighted vertex centroid = area centroid (here the origin)
    np.testing.assert_allclose(patch.vertex_areas @ patch.vertices_B, 0.0, atol=1e-12)


def test_vertex_normals_of_sphere_cap_are_radial():
    R = 10e-3
    cap = sphere_cap(R, 0.8, 0.5e-3, pole=(1.0, 1.0, 0.0))
    radial = cap.vertices_B / np.linalg.norm(cap.vertices_B, axis=1)[:, None]
    cos = np.einsum("ij,ij->i", cap.vertex_normals_B, radial)
    # interior vertices: angle-weighted normals are radial to O(edge²/R²)
    assert np.median(cos) > 1.0 - 1e-6
    assert cos.min() > np.cos(0.5e-3 / R)  # rim vertices: within one facet angle


def test_offset_moves_vertices_along_normals():
    R = 10e-3
    cap = sphere_cap(R, 0.6, 0.4e-3)
    grown = offset(cap, 1e-3)
    r = np.linalg.norm(grown.vertices_B, axis=1)
    interior = np.linalg.norm(cap.vertices_B[:, :2], axis=1) < R * np.sin(0.55)
    np.testing.assert_allclose(r[interior], R + 1e-3, atol=1e-8)
    # area scales with (R + t)²/R² on a sphere; the rim vertices' normals see only the
    # triangles on one side (tilted by ≈ half a facet angle, edge/2R), which shrinks the
    # rim ring slightly: allow 1 %
    assert grown.area / cap.area == pytest.approx(((R + 1e-3) / R) ** 2, rel=1e-2)
    np.testing.assert_array_equal(grown.faces, cap.faces)


def test_surface_mesh_is_read_only():
    patch = flat_patch(1.0, 1.0, 0.5)
    with pytest.raises(AttributeError):
        patch.name = "other"
    with pytest.raises(ValueError):
        patch.vertices_B[0, 0] = 1.0
    with pytest.raises(MeshError, match="face indices"):
        surface_mesh(np.zeros((3, 3)), np.array([[0, 1, 3]]), name="bad")


def test_undirected_edge_keys_match_lexicographic_edge_rows():
    """Keys are equal for (a, b) and (b, a), and 1-D unique of the keys gives the same
    groups, in the same order, as np.unique(axis=0) of the sorted (lo, hi) rows."""
    from openfdk.contact.mesh import undirected_edge_keys

    rng = np.random.default_rng(1)
    ends = rng.integers(0, 50, size=(400, 2))
    np.testing.assert_array_equal(undirected_edge_keys(ends), undirected_edge_keys(ends[:, ::-1]))
    rows = np.sort(ends, axis=1)
    u_rows, inv_rows, cnt_rows = np.unique(rows, axis=0, return_inverse=True, return_counts=True)
    u_keys, inv_keys, cnt_keys = np.unique(undirected_edge_keys(ends), return_inverse=True, return_counts=True)
    np.testing.assert_array_equal(inv_keys.ravel(), inv_rows.ravel())
    np.testing.assert_array_equal(cnt_keys, cnt_rows)
    assert len(u_keys) == len(u_rows) < len(ends)


@pytest.mark.parametrize("file_type", ["stl", "stl_ascii"])
def test_stl_reader_gives_what_trimesh_gives(tmp_path, file_type):
    """openfdk.contact.stl reads STL without importing trimesh; trimesh's own reader (with
    its vertex merging) is the independent reference: same vertices in the same order,
    same faces."""
    from openfdk.contact.stl import read_stl

    ball = trimesh.creation.icosphere(subdivisions=3, radius=12.5)
    path = tmp_path / f"ball.{file_type}.stl"
    trimesh.Trimesh(ball.vertices + [1.0, -2.0, 30.0], ball.faces, process=False).export(path, file_type=file_type)
    reference = trimesh.load(path, force="mesh", process=True)
    vertices, faces = read_stl(path)
    assert vertices.dtype == np.float64 and faces.dtype == np.int64
    assert len(vertices) == len(ball.vertices) == len(reference.vertices)   # shared corners merged
    np.testing.assert_array_equal(vertices, reference.vertices)
    np.testing.assert_array_equal(faces, reference.faces)


def test_bad_stl_files_name_the_file(tmp_path):
    cases = {
        "binary_cut.stl": b"\0" * 80 + np.uint32(3).tobytes() + b"\0" * 100,    # 3 records announced, 2 present
        "latin1.stl": "solid é\nendsolid\n".encode("latin-1"),
        "quad.stl": b"solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\n"
                    b"vertex 0 1 0\nendloop\nendfacet\nendsolid q\n",
        "words.stl": b"solid w\nfacet normal 0 0 1\nouter loop\nvertex 0 0 zero\nvertex 1 0 0\nvertex 1 1 0\n"
                     b"endloop\nendfacet\nendsolid w\n",
    }
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(MeshError, match=f"could not read mesh file '.*{name}'"):
            load_mesh(tmp_path / name)
