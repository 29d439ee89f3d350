"""Subject folder format (load + validate) and the generated virtual subject's anatomy.

Reference numbers come from shared/reference/mandible-reference-data.md (typed here from
that document, not from the package's data files) and from closed-form geometry.
"""

import shutil

import igl
import numpy as np
import pytest
import trimesh
import yaml
from scipy.interpolate import griddata

from openfdk.mandible import SubjectError, create_subject, load_subject
from openfdk.mandible.generator import load_anatomy

MM = 1e-3
MIRROR = np.array([1.0, -1.0, 1.0])


@pytest.fixture(scope="module")
def subject_dir(tmp_path_factory):
    return create_subject(tmp_path_factory.mktemp("subject") / "virtual", resolution="coarse")


@pytest.fixture(scope="module")
def subject(subject_dir):
    return load_subject(subject_dir)


@pytest.fixture(scope="module")
def default_subject(tmp_path_factory):
    return load_subject(create_subject(tmp_path_factory.mktemp("default") / "virtual"))


def _copy(subject_dir, tmp_path):
    target = tmp_path / "copy"
    shutil.copytree(subject_dir, target)
    return target


def _edit_yaml(folder, edit):
    path = folder / "subject.yaml"
    data = yaml.safe_load(path.read_text())
    edit(data)
    path.write_text(yaml.safe_dump(data, sort_keys=False))


# --------------------------------------------------------------------------------------
# Contents and units
# --------------------------------------------------------------------------------------

def test_generated_folder_has_every_part_in_si(subject):
    assert len(subject.muscles) == 24 and len(subject.ligaments) == 6
    assert set(subject.surfaces) == {"condyle_r", "condyle_l", "fossa_r", "fossa_l"}
    assert subject.marker_labels == ("Upper_RS", "Upper_LS", "Upper_RI", "Upper_LI",
                                     "Lower_RS", "Lower_LS", "Lower_RI", "Lower_LI")
    # superficial masseter, reference table: F0 272.8 N, Lf0 0.0226 m, Lt0 0.0258 m,
    # origin (37.9, −52.3, −6.0) mm, insertion (19, −49, −49) mm; common Hill values
    m = subject.muscle("superficial_masseter_r")
    assert m.max_isometric_force == 272.8
    assert m.optimal_fibre_length == pytest.approx(0.0226, abs=1e-12)
    assert m.tendon_slack_length == pytest.approx(0.0258, abs=1e-12)
    np.testing.assert_allclose(m.origin, [0.0379, -0.0523, -0.006], atol=1e-12)
    np.testing.assert_allclose(m.insertion, [0.019, -0.049, -0.049], atol=1e-12)
    assert (m.tendon_strain_at_max_force, m.pennation_angle_at_optimal,
            m.fast_fibre_fraction, m.passive_shape_factor) == (0.053, 0.0, 0.4, 3.0)
    # left mirrors right in y, for every muscle
    for right in (mu for mu in subject.muscles if mu.name.endswith("_r")):
        left = subject.muscle(right.name[:-2] + "_l")
        np.testing.assert_allclose(left.origin, right.origin * MIRROR, atol=1e-15)
        np.testing.assert_allclose(left.insertion, right.insertion * MIRROR, atol=1e-15)
        assert left.max_isometric_force == right.max_isometric_force
    assert subject.mandible.mass == 0.44
    np.testing.assert_allclose(np.diag(subject.mandible.inertia), [8.6e-4, 2.9e-4, 6.1e-4])
    assert subject.cartilage_offset == pytest.approx(1e-3)


def test_landmarks_follow_the_frame_definition_and_bonwill(subject):
    r, l = subject.condyle_top("r"), subject.condyle_top("l")
    np.testing.assert_allclose(0.5 * (r + l), 0.0, atol=1e-12)            # origin midway
    assert 0.098 <= np.linalg.norm(l - r) <= 0.100                          # 98–100 mm
    incisor = subject.landmarks["incisal_point"]
    # the reference gives the incisal point as (88, 0, −54) mm "≈ 100 mm from each
    # condyle"; those coordinates are 103 mm from the origin and 114.5 mm from each
    # condyle top — the explicit coordinates are used
    np.testing.assert_allclose(incisor, [0.088, 0.0, -0.054])
    assert 0.095 <= np.linalg.norm(incisor) <= 0.105


def test_tmj_planes_are_30_degrees_down_anteriorly_and_5_medially(subject):
    for side, medial in (("r", 1.0), ("l", -1.0)):
        plane = subject.tmj_planes[side]
        n = plane.normal
        np.testing.assert_allclose(plane.point, subject.condyle_top(side))
        # the plane's trace in a sagittal plane is (n_z, 0, −n_x): slope atan(n_x / n_z)
        assert np.degrees(np.arctan2(n[0], n[2])) == pytest.approx(30.0, abs=1e-9)
        # trace in a frontal plane (0, n_z, −n_y): it descends toward medial by 5°
        assert np.degrees(np.arctan2(medial * n[1], n[2])) == pytest.approx(5.0, abs=1e-9)
        assert np.linalg.norm(n) == pytest.approx(1.0)


def test_ligaments_run_from_the_tubercle_to_the_condylar_neck(subject):
    for lig in subject.ligaments:
        side = lig.name.split("_")[2]
        lateral = -1.0 if side == "r" else 1.0
        top = subject.condyle_top(side)
        assert 0.012 <= lig.reference_length <= 0.024
        assert lig.reference_length == pytest.approx(np.linalg.norm(lig.insertion - lig.origin), abs=1e-9)
        below = top[2] - lig.insertion[2]
        assert 0.012 <= below <= 0.022                                       # neck 12–22 mm below
        assert lig.insertion[0] < top[0] and lateral * (lig.insertion[1] - top[1]) > 0   # lateral-posterior
        assert lig.origin[0] > top[0] and lig.origin[2] < top[2]             # anterior, inferior
        assert lateral * (lig.origin[1] - top[1]) > 0.005                    # lateral


def test_braces_are_50mm_plates_in_front_of_the_mouth(subject):
    incisor = subject.landmarks["incisal_point"]
    for brace in subject.braces.values():
        p = brace.positions
        assert brace.plate_size == pytest.approx(0.05) and brace.marker_diameter == pytest.approx(0.004)
        assert np.all(p[:, 0] > incisor[0] + 0.02)                            # in front of the mouth
        assert np.ptp(p[:, 1]) < 0.05 and np.ptp(p[:, 2]) < 0.05              # corners on the plate
        assert np.ptp(p[:, 0]) < 1e-12                                       # a frontal plate


# --------------------------------------------------------------------------------------
# Surfaces
# --------------------------------------------------------------------------------------

def _ellipsoid_residual(vertices, top, width, depth, height, angle_deg):
    """Σ (q_i / semi_i)² − 1 for the condyle ellipsoid written out independently."""
    a = np.radians(angle_deg)
    e1, e2 = np.array([np.cos(a), np.sin(a), 0.0]), np.array([-np.sin(a), np.cos(a), 0.0])
    q = vertices - (top - [0, 0, height])
    return (q @ e1 / (depth / 2)) ** 2 + (q @ e2 / (width / 2)) ** 2 + (q[:, 2] / height) ** 2 - 1


def test_condyle_meshes_are_20_by_9_mm_caps_rotated_medial_pole_posterior(subject):
    for side, sign in (("r", 1.0), ("l", -1.0)):
        c = subject.surfaces[f"condyle_{side}"]
        # on an ellipsoid 20 mm ML × 9 mm AP (height semi-axis 5 mm), long axis 20°
        residual = _ellipsoid_residual(c.vertices, subject.condyle_top(side), 0.020, 0.009, 0.005, sign * 20.0)
        assert np.max(np.abs(residual)) < 1e-5                             # float32 STL
        medial = sign * (c.vertices[:, 1] - subject.condyle_top(side)[1])
        assert c.vertices[np.argmax(medial), 0] < -0.002                   # medial pole posterior
        assert c.vertices[np.argmin(medial), 0] > 0.002                    # lateral pole anterior
        mesh = trimesh.Trimesh(c.vertices, c.faces, process=False)
        assert np.sum(mesh.area_faces * mesh.face_normals[:, 2]) > 0       # normals up/out
        radial = c.vertices - (subject.condyle_top(side) - [0.0, 0.0, 0.005])   # from the centre
        assert np.all(np.einsum("ij,ij->i", mesh.vertex_normals, radial) > 0)
        assert 400 <= len(c.vertices) <= 600                               # coarse ≈ 500


def test_default_resolution_sizes(default_subject):
    s = default_subject
    assert 3000 <= len(s.surfaces["condyle_r"].vertices) <= 5000
    assert 9000 <= len(s.surfaces["fossa_r"].faces) <= 11000
    assert len(s.surfaces["fossa_l"].faces) == len(s.surfaces["fossa_r"].faces)


def test_fossa_depth_slope_and_orientation(subject):
    for side in ("r", "l"):
        f = subject.surfaces[f"fossa_{side}"]
        mesh = trimesh.Trimesh(f.vertices, f.faces, process=False)
        assert np.sum(mesh.area_faces * mesh.face_normals[:, 2]) < 0       # normals down
        # sagittal profile through the condyle top, interpolated linearly on the mesh
        # vertices (the fossa is a height field over x, y)
        top = subject.condyle_top(side)
        x = np.linspace(-0.006, 0.016, 221)
        z = griddata(f.vertices[:, :2], f.vertices[:, 2], np.column_stack([x, np.full_like(x, top[1])]))
        roof, crest = np.nanargmax(z), np.nanargmin(z)
        depth = z[roof] - z[crest]
        slope = np.degrees(np.arctan2(depth, x[crest] - x[roof]))
        assert 0.006 <= depth <= 0.008, depth                               # 6–8 mm
        assert 30.0 <= slope <= 40.0, slope                                 # 30–40° to FH
        assert x[crest] > x[roof]                                           # eminence anterior


def test_condyle_sits_in_the_fossa_through_the_cartilage_layer(default_subject):
    """Reference pose: the condyle mesh offset by the 1 mm layer touches the fossa mesh.

    Tolerance from mesh precision: sagitta h²/(8R) of both meshes (h = longest edge,
    R = smallest radius of curvature: condyle b²/c = 4.05 mm, fossa 4w/k = 3.2 mm) plus
    the distance to the nearest vertex of the condyle, (h/2)²/(2R).
    """
    subject = default_subject
    for side in ("r", "l"):
        c, f = subject.surfaces[f"condyle_{side}"], subject.surfaces[f"fossa_{side}"]
        cm, fm = (trimesh.Trimesh(s.vertices, s.faces, process=False) for s in (c, f))
        offset = c.vertices + subject.cartilage_offset * cm.vertex_normals
        d = igl.signed_distance(offset, f.vertices, f.faces, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)[0]
        hc, hf = cm.edges_unique_length.max(), fm.edges_unique_length.max()
        tol = hc ** 2 / (8 * 4.05e-3) + hf ** 2 / (8 * 3.2e-3) + (hc / 2) ** 2 / (2 * 4.05e-3)
        assert abs(d.min()) < tol, (d.min(), tol)
        assert tol < 0.15e-3                                                # default mesh


def test_symmetric_and_asymmetric_subjects(tmp_path, subject):
    r, l = subject.surfaces["fossa_r"].vertices, subject.surfaces["fossa_l"].vertices
    np.testing.assert_allclose(np.sort(l * MIRROR, axis=0), np.sort(r, axis=0), atol=1e-8)
    folder = create_subject(tmp_path / "asym", resolution="coarse", symmetric=False, seed=3)
    asym = load_subject(folder)
    anatomy = load_anatomy(folder)
    assert not np.allclose(anatomy.condyles["r"].semi_axes, anatomy.condyles["l"].semi_axes)
    np.testing.assert_allclose(0.5 * (asym.condyle_top("r") + asym.condyle_top("l")), 0.0, atol=1e-12)
    # each side is still seated through the layer (generator property, mesh-independent)
    from openfdk.mandible.truth import TrueJoint, TruthOptions, min_gap

    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, anatomy.layer, TruthOptions.exact(),
                            np.random.default_rng(0))
    for side in ("r", "l"):
        gap = min_gap(joint, side, np.eye(3)[None], np.zeros((1, 3)))[0][0]
        assert abs(gap) < 1e-12


# --------------------------------------------------------------------------------------
# Errors name the file and the entry
# --------------------------------------------------------------------------------------

def test_missing_folder_and_subject_yaml(tmp_path):
    with pytest.raises(SubjectError, match="no such subject folder"):
        load_subject(tmp_path / "nope")
    with pytest.raises(SubjectError, match=r"subject\.yaml: missing"):
        load_subject(tmp_path)


def test_garbage_yaml(subject_dir, tmp_path):
    folder = _copy(subject_dir, tmp_path)
    (folder / "subject.yaml").write_text("landmarks: [1, 2\n  muscles: {{{\n")
    with pytest.raises(SubjectError, match=r"subject\.yaml: malformed YAML"):
        load_subject(folder)
    (folder / "subject.yaml").write_text("- just\n- a list\n")
    with pytest.raises(SubjectError, match="expected a mapping"):
        load_subject(folder)


def test_missing_empty_and_broken_stl(subject_dir, tmp_path):
    folder = _copy(subject_dir, tmp_path)
    (folder / "fossa_l.stl").unlink()
    with pytest.raises(SubjectError, match=r"surfaces\.fossa_l: mesh file 'fossa_l\.stl' not found"):
        load_subject(folder)
    (folder / "fossa_l.stl").write_bytes(b"")
    with pytest.raises(SubjectError, match=r"surfaces\.fossa_l: mesh file 'fossa_l\.stl' is empty"):
        load_subject(folder)
    (folder / "fossa_l.stl").write_bytes(b"solid broken\nthis is not an stl\nendsolid\n")
    with pytest.raises(SubjectError, match=r"surfaces\.fossa_l: mesh file 'fossa_l\.stl'"):
        load_subject(folder)


def test_muscle_without_max_isometric_force(subject_dir, tmp_path):
    folder = _copy(subject_dir, tmp_path)
    _edit_yaml(folder, lambda d: d["muscles"]["geniohyoid_l"].pop("max_isometric_force"))
    with pytest.raises(SubjectError, match=r"muscles\.geniohyoid_l: missing 'max_isometric_force' \(N\)"):
        load_subject(folder)


def test_unknown_keys_and_units(subject_dir, tmp_path):
    folder = _copy(subject_dir, tmp_path)
    _edit_yaml(folder, lambda d: d["muscles"]["geniohyoid_l"].update(optimal_fiber_length=1.0))
    with pytest.raises(SubjectError, match=r"muscles\.geniohyoid_l\.optimal_fiber_length: unknown key; "
                                           r"did you mean 'optimal_fibre_length'"):
        load_subject(folder)
    folder = _copy(subject_dir, tmp_path / "b")
    _edit_yaml(folder, lambda d: d.update(units={"length": "inch"}))
    with pytest.raises(SubjectError, match=r"units\.length: unknown length unit 'inch'"):
        load_subject(folder)
    folder = _copy(subject_dir, tmp_path / "c")
    _edit_yaml(folder, lambda d: d["surfaces"]["condyle_r"].update(units="m"))
    with pytest.raises(SubjectError, match=r"surfaces\.condyle_r: 'condyle_r\.stl' lies .* wrong units \(m\)"):
        load_subject(folder)


def test_bad_numbers_frames_and_normals(subject_dir, tmp_path):
    folder = _copy(subject_dir, tmp_path)
    _edit_yaml(folder, lambda d: d["muscles"]["geniohyoid_l"].update(max_isometric_force="strong"))
    with pytest.raises(SubjectError, match=r"muscles\.geniohyoid_l\.max_isometric_force: expected a number"):
        load_subject(folder)
    folder = _copy(subject_dir, tmp_path / "b")
    _edit_yaml(folder, lambda d: d["landmarks"].update(condyle_top_r=[10.0, -49.5, 0.0]))
    with pytest.raises(SubjectError, match=r"landmarks: the subject frame must have its origin midway"):
        load_subject(folder)
    folder = _copy(subject_dir, tmp_path / "c")
    _edit_yaml(folder, lambda d: d["surfaces"]["fossa_r"].update(flip_normals=True))
    with pytest.raises(SubjectError, match=r"surfaces\.fossa_r: the normals of 'fossa_r\.stl' point up"):
        load_subject(folder)
    folder = _copy(subject_dir, tmp_path / "d")

    def drop_two(d):
        for label in ("Lower_RS", "Lower_LS"):
            d["braces"]["mandible"]["markers"].pop(label)

    _edit_yaml(folder, drop_two)
    with pytest.raises(SubjectError, match=r"braces\.mandible\.markers: needs at least 3 markers"):
        load_subject(folder)


def test_user_folder_in_metres_with_defaults_and_placement(subject_dir, tmp_path):
    """A hand-written folder: metres, muscle defaults, an STL placed by a transform."""
    folder = _copy(subject_dir, tmp_path)
    data = yaml.safe_load((folder / "subject.yaml").read_text())

    def scale(v):
        return [x * MM for x in v]

    for key in list(data["landmarks"]):
        data["landmarks"][key] = scale(data["landmarks"][key])
    for plane in data["tmj_planes"].values():
        plane["point"] = scale(plane["point"])
    data["mandible"]["center_of_mass"] = scale(data["mandible"]["center_of_mass"])
    for m in data["muscles"].values():
        m["origin"], m["insertion"] = scale(m["origin"]), scale(m["insertion"])
        m["optimal_fibre_length"] *= MM
        m["tendon_slack_length"] *= MM
        for key in ("tendon_strain_at_max_force", "pennation_angle_at_optimal",
                    "fast_fibre_fraction", "passive_shape_factor"):
            m.pop(key)
    data["muscle_defaults"] = {"passive_shape_factor": 4.0}
    for lig in data["ligaments"].values():
        lig["origin"], lig["insertion"] = scale(lig["origin"]), scale(lig["insertion"])
        lig.pop("reference_length")
    for brace in data["braces"].values():
        brace["markers"] = {k: scale(v) for k, v in brace["markers"].items()}
        brace["plate_size"] *= MM
        brace["marker_diameter"] *= MM
    data["units"] = {"length": "m", "angle": "deg"}
    data["cartilage_offset"] = 0.001
    # condyle_r.stl stored shifted by +10 mm in x and rotated 90° about z; placement undoes it
    mesh = trimesh.load(folder / "condyle_r.stl")
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    mesh.vertices = (mesh.vertices + [10.0, 0.0, 0.0]) @ R.T
    mesh.export(folder / "condyle_r.stl")
    data["surfaces"]["condyle_r"]["placement"] = {"orientation": [0.0, 0.0, -90.0], "position": [-0.010, 0.0, 0.0]}
    (folder / "subject.yaml").write_text(yaml.safe_dump(data))
    loaded, original = load_subject(folder), load_subject(subject_dir)
    np.testing.assert_allclose(np.sort(loaded.surfaces["condyle_r"].vertices, axis=0),
                               np.sort(original.surfaces["condyle_r"].vertices, axis=0), atol=1e-8)
    assert loaded.muscle("geniohyoid_l").passive_shape_factor == 4.0
    assert loaded.muscle("geniohyoid_l").tendon_strain_at_max_force == 0.053
    for a, b in zip(loaded.ligaments, original.ligaments):
        assert a.reference_length == pytest.approx(b.reference_length, abs=1e-9)
    np.testing.assert_allclose(loaded.landmarks["incisal_point"], original.landmarks["incisal_point"])
