"""OpenSim-JAM's Smith2018ContactMesh / Smith2018ArticularContactForce imported as
openfdk's elastic foundation, against closed forms (issue 25: "a rigid sphere pressed
into a flat layer ... force, area and pressure given E and ν").

Elastic-foundation pressure of a layer (Bei & Fregly 2004; Smith et al. 2018):
linear p = K d / h, non-linear p = −K ln(1 − d/h), K = E (1 − ν)/((1 + ν)(1 − 2ν)); two
layers in series (a layer on each mesh, ``use_lumped_contact_model`` false) share the
pressure and add their depths, the lumped model (JAM's default) is one layer of mean E
and ν and thickness h₁ + h₂. A sphere of radius R whose vertices press δ into a plane
carries F = ∫₀^δ p(d) 2πR dd (the cap's area between depths d and d + dd is 2πR dd;
π p_mod R δ² for the linear law, docs/contact.md), on the cap area 2πRδ, with the peak
pressure p(δ) at the pole. The test integrates p over the cap with scipy and solves the
two layers' depths with brentq, independently of openfdk. The model (a ball on a slider above a plate) is built
with OpenSim's API; the JAM elements are added to its XML, as OpenSim-JAM writes them
(the standard OpenSim does not load them, and openfdk needs it not to).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from lxml import etree

opensim = pytest.importorskip("opensim")

from openfdk.contact.mesh import surface_mesh  # noqa: E402
from openfdk.contact.shapes import flat_patch, sphere_cap  # noqa: E402
from openfdk.io.modelfile import model_from_dict  # noqa: E402
from openfdk.io.opensim import OsimError, read_osim  # noqa: E402
from openfdk.kinematics.coordinate_pose import pose_from_coordinates  # noqa: E402

R, DELTA = 10e-3, 0.1e-3
LAYERS = {"ball_mesh": (12e6, 0.45, 4e-3), "plate_mesh": (30e6, 0.40, 6e-3)}  # E (Pa), ν, h (m)


def _stl(path, mesh):
    """A binary STL of a SurfaceMesh (m)."""
    tri = mesh.vertices_B[mesh.faces]
    with open(path, "wb") as f:
        f.write(b"openfdk test".ljust(80, b" ") + struct.pack("<I", len(tri)))
        for t in tri:
            n = np.cross(t[1] - t[0], t[2] - t[0])
            n /= np.linalg.norm(n)
            f.write(struct.pack("<12fH", *n, *t.ravel(), 0))


def _modulus(E, nu, h):
    return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu) * h)


def _model(folder, formulation="linear", lumped=False, layers=None, max_proximity=0.001):
    layers = layers or LAYERS
    m = opensim.Model()
    m.setName("ball_on_plate")
    ball = opensim.Body("ball", 1.0, opensim.Vec3(0), opensim.Inertia(1e-4, 1e-4, 1e-4))
    m.addBody(ball)
    turn = opensim.Vec3(0, -np.pi / 2, 0)  # the slider's x along the ground's z
    slider = opensim.SliderJoint("slide", m.getGround(), opensim.Vec3(0), turn, ball, opensim.Vec3(0), turn)
    slider.updCoordinate().setName("height")
    m.addJoint(slider)
    m.finalizeConnections()
    m.initSystem()
    m.printToXML(str(folder / "base.osim"))
    a = np.sqrt(2 * R * DELTA)
    _stl(folder / "ball.stl", sphere_cap(R, 1.5 * a / R, a / 5.0))   # pole −z, centre at the ball's origin
    _stl(folder / "plate.stl", flat_patch(0.012, 0.012, 1e-3))       # z = 0, normal +z
    tree = etree.parse(str(folder / "base.osim"))
    model = tree.getroot().find("Model")
    geometry = etree.SubElement(etree.SubElement(model, "ContactGeometrySet"), "objects")
    for name, frame, file in (("ball_mesh", "/bodyset/ball", "ball.stl"), ("plate_mesh", "/ground", "plate.stl")):
        E, nu, h = layers[name]
        etree.SubElement(geometry, "Smith2018ContactMesh", name=name).extend(
            [etree.fromstring(f"<socket_frame>{frame}</socket_frame>"),
             etree.fromstring(f"<mesh_file>{file}</mesh_file>"),
             etree.fromstring(f"<elastic_modulus>{E}</elastic_modulus>"),
             etree.fromstring(f"<poissons_ratio>{nu}</poissons_ratio>"),
             etree.fromstring(f"<thickness>{h}</thickness>")])
    forces = model.find("ForceSet/objects")
    force = etree.SubElement(forces, "Smith2018ArticularContactForce", name="ball_contact")
    for tag, text in (("socket_target_mesh", "/contactgeometryset/plate_mesh"),
                      ("socket_casting_mesh", "/contactgeometryset/ball_mesh"), ("min_proximity", "0"),
                      ("max_proximity", repr(max_proximity)), ("elastic_foundation_formulation", formulation),
                      ("use_lumped_contact_model", "true" if lumped else "false")):
        etree.SubElement(force, tag).text = text
    tree.write(str(folder / "ball.osim"))
    return folder / "ball.osim"


def test_sphere_on_layer_matches_the_elastic_foundation(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    data, _ = read_osim(_model(tmp_path))
    p_mod = 1.0 / sum(1.0 / _modulus(*layer) for layer in LAYERS.values())
    assert data["name"] == "ball_on_plate"  # (the ForceSet's readers once overwrote the model's name)
    spec = data["contacts"]["ball_contact"]
    assert spec["vertices"]["body"] == "ball" and spec["surface"]["body"] == "ground"
    assert spec["pressure_modulus"] == pytest.approx(p_mod, rel=1e-12) and spec["max_depth"] == 1e-3
    model = model_from_dict(data, source="ball.osim")
    state, _ = pose_from_coordinates(model, {"height": R - DELTA})
    contact = model.contacts[0]
    _, _, res = contact.generalized_forces(state, False)
    assert res.force_W[2] == pytest.approx(np.pi * p_mod * R * DELTA**2, rel=0.0035)
    np.testing.assert_allclose(res.force_W[:2], 0.0, atol=1e-9 * res.force_W[2])
    assert res.area == pytest.approx(2 * np.pi * R * DELTA, rel=0.05)
    # the pressure at the pole from E and ν: two layers in series, each compressed to
    # the same pressure, d₁ + d₂ = δ
    E1, nu1, h1 = LAYERS["ball_mesh"]
    E2, nu2, h2 = LAYERS["plate_mesh"]
    K1 = E1 * (1 - nu1) / ((1 + nu1) * (1 - 2 * nu1))
    K2 = E2 * (1 - nu2) / ((1 + nu2) * (1 - 2 * nu2))
    assert res.peak_pressure == pytest.approx(DELTA / (h1 / K1 + h2 / K2), rel=1e-5)  # (grid: φ in float32)
    # no contact above the plate
    state, _ = pose_from_coordinates(model, {"height": R + 1e-3})
    assert contact.generalized_forces(state, False)[2].n_contact == 0


def _K(E, nu):
    return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))


def _pressure(d, layers, formulation, lumped):
    """The pressure (Pa) at depth d (m), written from the formulas (module docstring)."""
    from scipy.optimize import brentq

    (E1, nu1, h1), (E2, nu2, h2) = layers["ball_mesh"], layers["plate_mesh"]
    if lumped:
        parts = [(_K((E1 + E2) / 2, (nu1 + nu2) / 2), h1 + h2)]
    else:
        parts = [(_K(E1, nu1), h1), (_K(E2, nu2), h2)]
    if formulation == "linear":
        return d / sum(h / K for K, h in parts)
    if len(parts) == 1:
        K, h = parts[0]
        return -K * np.log(1 - d / h)
    # each layer j at pressure p: p = −K_j ln(1 − d_j/h_j); the depths add up to d
    return brentq(lambda p: sum(h * (1 - np.exp(-p / K)) for K, h in parts) - d, 0.0, 1e12, xtol=1e-6, rtol=1e-15)


THIN = {"ball_mesh": (12e6, 0.45, 0.4e-3), "plate_mesh": (30e6, 0.40, 0.3e-3)}  # δ/h large: non-linear


@pytest.mark.parametrize("formulation,lumped,layers", [
    ("linear", True, LAYERS), ("nonlinear", True, THIN), ("nonlinear", False, THIN), ("nonlinear", False, LAYERS)])
def test_sphere_on_layer_matches_each_law(tmp_path, monkeypatch, formulation, lumped, layers):
    """Both formulations, lumped or two layers in series: the force equals the integral
    of the law over the cap (≤ 0.35 %, the mesh's discretisation, as the linear test
    above), the area 2πRδ (5 %), the pole pressure the law at δ from E and ν (1e-5). On
    the thin layers the non-linear law is far from its linearisation (the check below)."""
    from scipy.integrate import quad

    monkeypatch.chdir(tmp_path)
    data, _ = read_osim(_model(tmp_path, formulation, lumped, layers))
    spec = data["contacts"]["ball_contact"]
    assert ("layers" in spec) == (formulation == "nonlinear")
    model = model_from_dict(data, source="ball.osim")
    state, _ = pose_from_coordinates(model, {"height": R - DELTA})
    _, _, res = model.contacts[0].generalized_forces(state, False)
    force = quad(lambda d: _pressure(d, layers, formulation, lumped) * 2 * np.pi * R, 0.0, DELTA, epsabs=0,
                 epsrel=1e-12)[0]
    assert res.force_W[2] == pytest.approx(force, rel=0.0035)
    assert res.area == pytest.approx(2 * np.pi * R * DELTA, rel=0.05)
    pole = _pressure(DELTA, layers, formulation, lumped)
    assert res.peak_pressure == pytest.approx(pole, rel=1e-5)
    if layers is THIN:  # the linearised law is far off: the test tells them apart
        linear = DELTA / sum(h / K for K, h in ([(_K(*layers["ball_mesh"][:2]), layers["ball_mesh"][2]),
                                                  (_K(*layers["plate_mesh"][:2]), layers["plate_mesh"][2])]
                                                 if not lumped else [(_K((12e6 + 30e6) / 2, 0.425), 0.7e-3)]))
        assert pole > 1.05 * linear


def _place_mesh(folder, name, location, orientation):
    """The model's mesh ``name`` stored in a geometry frame G placed at ``location`` (m),
    ``orientation`` (body-fixed X-Y-Z Euler angles, rad) in its frame, as OpenSim
    4.0–4.4 write ContactGeometry: the STL's vertices become R_FGᵀ (v − p_FG), with R_FG
    from scipy (intrinsic 'XYZ'), so the placed mesh is the original one."""
    from scipy.spatial.transform import Rotation

    from openfdk.contact.stl import read_stl

    R_FG = Rotation.from_euler("XYZ", orientation).as_matrix()
    stl = folder / f"{name}.stl"
    vertices, faces = read_stl(stl)
    moved = type("M", (), {"vertices_B": (vertices - np.asarray(location)) @ R_FG, "faces": faces})
    _stl(folder / f"{name}_in_G.stl", moved)
    tree = etree.parse(str(folder / "ball.osim"))
    element = tree.getroot().find(f".//Smith2018ContactMesh[@name='{name}_mesh']")
    element.find("mesh_file").text = f"{name}_in_G.stl"
    etree.SubElement(element, "location").text = " ".join(repr(float(x)) for x in location)
    etree.SubElement(element, "orientation").text = " ".join(repr(float(x)) for x in orientation)
    tree.write(str(folder / "placed.osim"))
    return folder / "placed.osim"


@pytest.mark.parametrize("name", ["ball", "plate"])
def test_a_contact_mesh_placed_by_location_and_orientation_is_the_same_contact(tmp_path, monkeypatch, name):
    """ContactGeometry's location and orientation (the Lenhart 2015 knee's meshes carry
    them): the casting (ball) or target (plate) mesh written in a turned and shifted
    geometry frame, with that frame's pose in the file, gives the contact of the original
    model: the same force, area and pole pressure."""
    monkeypatch.chdir(tmp_path)
    reference = model_from_dict(read_osim(_model(tmp_path))[0], source="ball.osim")
    placed = model_from_dict(read_osim(_place_mesh(tmp_path, name, (0.002, -0.001, 0.003), (0.3, -0.4, 0.5)))[0],
                             source="placed.osim")
    results = []
    for model in (reference, placed):
        state, _ = pose_from_coordinates(model, {"height": R - DELTA})
        results.append(model.contacts[0].generalized_forces(state, False)[2])
    ref, got = results
    assert ref.force_W[2] > 0.1 and ref.n_contact > 10
    np.testing.assert_allclose(got.force_W, ref.force_W, rtol=0, atol=2e-6 * ref.force_W[2])
    assert got.area == pytest.approx(ref.area, rel=1e-6) and got.peak_pressure == pytest.approx(ref.peak_pressure,
                                                                                                 rel=1e-5)
    # the geometry frame's pose matters: the same moved mesh without it is another contact
    text = (tmp_path / "placed.osim").read_text()
    for tag in ("location", "orientation"):
        text = text.replace(text[text.index(f"<{tag}>"):text.index(f"</{tag}>") + len(tag) + 3], "")
    (tmp_path / "unplaced.osim").write_text(text)
    unplaced = model_from_dict(read_osim(tmp_path / "unplaced.osim")[0], source="unplaced.osim")
    state, _ = pose_from_coordinates(unplaced, {"height": R - DELTA})
    assert abs(unplaced.contacts[0].generalized_forces(state, False)[2].force_W[2] - ref.force_W[2]) > 0.01 * ref.force_W[2]


def _with_back_meshes(path, folder, lumped):
    """The ball-on-plate .osim with both meshes' thickness from bones behind them
    (use_variable_thickness): a sphere of radius R − h inside the ball's cap and the
    plane z = −h under the plate, h each mesh's uniform thickness of LAYERS; and
    ``lumped`` as given."""
    h_ball, h_plate = LAYERS["ball_mesh"][2], LAYERS["plate_mesh"][2]
    _stl(folder / "ball_bone.stl", sphere_cap(R - h_ball, 0.6, 0.4e-3))
    plane = flat_patch(0.03, 0.03, 2e-3)
    _stl(folder / "plate_bone.stl", surface_mesh(plane.vertices_B - [0.0, 0.0, h_plate], plane.faces, repair=False))
    text = path.read_text()
    for name, bone in (("ball_mesh", "ball_bone.stl"), ("plate_mesh", "plate_bone.stl")):
        h = LAYERS[name][2]
        old = f"<thickness>{h}</thickness>"
        i = text.index(f'<Smith2018ContactMesh name="{name}">')
        j = text.index(old, i)
        text = (text[:j] + f"<use_variable_thickness>true</use_variable_thickness><mesh_back_file>{bone}"
                "</mesh_back_file><min_thickness>0.001</min_thickness><max_thickness>0.01</max_thickness>"
                + text[j + len(old):])
    if lumped:
        text = text.replace("<use_lumped_contact_model>false", "<use_lumped_contact_model>true")
    out = folder / "ball_variable.osim"
    out.write_text(text)
    return out


@pytest.mark.parametrize("formulation,lumped", [("linear", False), ("linear", True), ("nonlinear", False)])
def test_variable_thickness_from_back_meshes_at_the_uniform_thickness_is_the_uniform_contact(
        tmp_path, monkeypatch, formulation, lumped):
    """use_variable_thickness with bones exactly h behind each cartilage: the import
    gives each surface a thickness field (rays from the triangles' centres to the bone,
    contact/thickness.py) and its layer ``thickness: vertices`` / ``surface`` (both added
    when lumped), and the contact's force and pole pressure equal the uniform contact's
    (the ball's flat triangles sit up to their sag, 1e-6 m, inside its sphere: 1e-3)."""
    monkeypatch.chdir(tmp_path)
    uniform_path = _model(tmp_path, formulation, lumped)
    variable_path = _with_back_meshes(uniform_path, tmp_path, lumped)
    results = {}
    for key, path in (("uniform", uniform_path), ("variable", variable_path)):
        data, _ = read_osim(path)
        spec = data["contacts"]["ball_contact"]
        if key == "variable":
            assert spec["vertices"]["thickness"]["back_mesh"].endswith("ball_bone.stl")
            assert spec["surface"]["thickness"] == {"back_mesh": str((tmp_path / "plate_bone.stl").resolve()),
                                                    "min": 0.001, "max": 0.01}
            want = [["vertices", "surface"]] if lumped else ["vertices", "surface"]
            assert [layer["thickness"] for layer in spec["layers"]] == want
        model = model_from_dict(data, source=path.name)
        state, _ = pose_from_coordinates(model, {"height": R - DELTA})
        results[key] = model.contacts[0].generalized_forces(state, False)[2]
        if key == "variable":
            pair = model.contacts[0].pair
            np.testing.assert_allclose(pair.variable.h_A, LAYERS["ball_mesh"][2], rtol=1e-3)
            np.testing.assert_allclose(pair.variable.h_B.h, LAYERS["plate_mesh"][2], rtol=1e-7)  # (STL: float32)
    u, v = results["uniform"], results["variable"]
    assert v.force_W[2] == pytest.approx(u.force_W[2], rel=1e-3)
    assert v.peak_pressure == pytest.approx(u.peak_pressure, rel=1e-3)
    assert v.n_contact == u.n_contact
    if formulation == "linear" and not lumped:
        # import-opensim copies the bones too, and its file loads to the same contact
        from openfdk.cli import main
        from openfdk.io.modelfile import load_model

        assert main(["import-opensim", str(variable_path), "--out", "imported", "-q"]) == 0
        assert sorted(p.name for p in (tmp_path / "imported" / "Geometry").iterdir()) == [
            "ball.stl", "ball_bone.stl", "plate.stl", "plate_bone.stl"]
        model = load_model(tmp_path / "imported" / "ball_on_plate.yaml")
        state, _ = pose_from_coordinates(model, {"height": R - DELTA})
        again = model.contacts[0].generalized_forces(state, False)[2]
        assert again.force_W[2] == pytest.approx(v.force_W[2], rel=1e-12)


def test_the_depth_band_stops_at_the_layers_thickness(tmp_path, monkeypatch):
    """max_proximity is how far JAM's rays search; openfdk's depth band (max_depth, the
    distance grid's extent) stops at the two layers' total thickness h₁ + h₂, beyond
    which the backing surfaces would pass through each other."""
    monkeypatch.chdir(tmp_path)
    total = sum(h for _, _, h in LAYERS.values())
    deep, _ = read_osim(_model(tmp_path, max_proximity=0.02))
    assert deep["contacts"]["ball_contact"]["max_depth"] == pytest.approx(total, rel=1e-15) and total < 0.02
    shallow, _ = read_osim(_model(tmp_path, max_proximity=0.5 * total))
    assert shallow["contacts"]["ball_contact"]["max_depth"] == pytest.approx(0.5 * total, rel=1e-15)


def test_unsupported_contact_options_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = _model(tmp_path, formulation="quadratic")
    with pytest.raises(OsimError) as exc:
        read_osim(path)
    msg = str(exc.value)
    assert "\n" not in msg and "ball.osim: line" in msg and "Smith2018ArticularContactForce 'ball_contact'" in msg
    assert "elastic_foundation_formulation 'quadratic'" in msg
    text = _model(tmp_path).read_text()
    for old, new, words in (("<poissons_ratio>0.45", "<poissons_ratio>0.5", "poissons_ratio 0.5 is out of range"),
                            ("/contactgeometryset/plate_mesh", "/contactgeometryset/nope", "no Smith2018ContactMesh 'nope'"),
                            ("<min_proximity>0", "<min_proximity>0.001", "min_proximity 0")):
        bad = tmp_path / "bad.osim"
        bad.write_text(text.replace(old, new, 1))
        with pytest.raises(OsimError) as exc:
            read_osim(bad)
        assert "\n" not in str(exc.value) and "bad.osim" in str(exc.value) and words in str(exc.value), exc.value


def test_import_opensim_copies_the_contact_meshes(tmp_path, monkeypatch, capsys):
    """``openfdk import-opensim`` writes the contact meshes beside the model file
    (Geometry/) like the display meshes, and the written file loads to the same contact."""
    from openfdk.cli import main
    from openfdk.io.modelfile import load_model

    monkeypatch.chdir(tmp_path)
    path = _model(tmp_path)
    assert main(["import-opensim", str(path), "--out", "out", "-q"]) == 0, capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "out" / "Geometry").iterdir()) == ["ball.stl", "plate.stl"]
    model = load_model(tmp_path / "out" / "ball_on_plate.yaml")
    p_mod = 1.0 / sum(1.0 / _modulus(*layer) for layer in LAYERS.values())
    assert len(model.contacts) == 1 and model.contacts[0].pair.pressure_modulus == pytest.approx(p_mod, rel=1e-12)


def test_a_missing_thickness_or_back_mesh_is_refused_in_one_line(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = _model(tmp_path).read_text()
    assert "<thickness>0.004</thickness>" in text
    for old, new, words in (("<thickness>0.004</thickness>", "", "<thickness> is missing"),
                            ("<thickness>0.004</thickness>", "<thickness>0.004</thickness><use_variable_thickness>true"
                             "</use_variable_thickness>", "use_variable_thickness without a mesh_back_file"),
                            ("<thickness>0.004</thickness>", "<use_variable_thickness>true</use_variable_thickness>"
                             "<mesh_back_file>b.stl</mesh_back_file><min_thickness>0.01</min_thickness>"
                             "<max_thickness>0.002</max_thickness>", "openfdk needs 0 < min < max")):
        bad = tmp_path / "bad.osim"
        bad.write_text(text.replace(old, new, 1))
        with pytest.raises(OsimError) as exc:
            read_osim(bad)
        msg = str(exc.value)
        assert "\n" not in msg and "bad.osim: line" in msg and "Smith2018ContactMesh 'ball_mesh'" in msg, msg
        assert words in msg, msg


def test_overlay_contact_regions_split_an_imported_contact(tmp_path, monkeypatch):
    """``contact_regions:`` in an overlay sets the regions of a contact the .osim defines:
    the ball pressed into the plate, halves by the plate's x axis, each carrying part of
    the load and adding up to the whole; an unknown contact is a one-line error with a
    did-you-mean."""
    from openfdk.forces.forceset import ForceElements
    from openfdk.io.modelfile import load_model_and_settings
    from openfdk.model.errors import ModelError

    monkeypatch.chdir(tmp_path)
    _model(tmp_path)
    (tmp_path / "with.yaml").write_text(
        "opensim: ball.osim\ncontact_regions:\n  ball_contact: {minus: {axis: [-1, 0, 0]}, plus: {axis: [1, 0, 0]}}\n")
    model, _ = load_model_and_settings(tmp_path / "with.yaml")
    state, _ = pose_from_coordinates(model, {"height": R - DELTA})
    c = ForceElements(model).generalized_forces(state, 0.0)[1]["contacts"]["ball_contact"]
    minus, plus = c.region_force_W["minus"], c.region_force_W["plus"]
    np.testing.assert_allclose(minus + plus, c.force_W, rtol=1e-12, atol=1e-12)
    assert np.linalg.norm(c.force_W) > 1.0
    assert min(minus[2], plus[2]) > 0.2 * c.force_W[2]  # the cap's mesh is not symmetric in x
    (tmp_path / "bad.yaml").write_text("opensim: ball.osim\ncontact_regions: {ball_contact2: {}}\n")
    with pytest.raises(ModelError, match=r"bad.yaml: contact_regions.ball_contact2: not a contact of the model; "
                                         r"did you mean 'ball_contact'\?"):
        load_model_and_settings(tmp_path / "bad.yaml")


def test_a_missing_contact_mesh_or_bone_names_the_contacts_ignore(tmp_path, monkeypatch):
    """A contact's mesh file (or the bone behind a cartilage) that is not found is one
    line naming the file, the folders looked in and how to leave the contacts out
    (``--ignore Mesh`` would not: it leaves out display meshes)."""
    monkeypatch.chdir(tmp_path)
    path = _with_back_meshes(_model(tmp_path), tmp_path, lumped=False)
    for missing in ("plate_bone.stl", "plate.stl"):
        (tmp_path / missing).unlink()
        with pytest.raises(OsimError) as exc:
            read_osim(path)
        msg = str(exc.value)
        assert "\n" not in msg and f"Smith2018ContactMesh '{missing}' not found (looked in" in msg, msg
        assert "--ignore Smith2018ContactMesh --ignore Smith2018ArticularContactForce" in msg, msg
