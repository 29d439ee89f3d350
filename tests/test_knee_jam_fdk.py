"""A small knee in OpenSim-JAM format, its secondary coordinates solved by FDK and by an
independent force balance written here (issue 27, "Tests that must exist").

The model (built with OpenSim's API, the JAM elements added to its XML as OpenSim-JAM
writes them):

* femur welded to the ground (y up, x anterior, z lateral); its two condyles are spheres
  of radius R centred at (0, 0, ±W), meshed as open caps (a square grid of spacing s
  projected onto the sphere, written here as binary STL);
* tibia on a CustomJoint ``knee``: knee_flex (about z), knee_add (x), knee_rot (y), each
  rotation about the axis turned by the ones before it, then knee_tx, knee_ty, knee_tz
  along the femur's axes (checked against OpenSim's own transform below); the joint's
  child frame sits R above the plateau, so all coordinates zero put the spheres on the
  plateau with zero depth;
* a flat tibial plateau (y = 0 in the tibia, normal +y), Smith2018ContactMesh layers on
  both meshes, lumped as JAM does (one layer of mean E and ν and thickness h₁ + h₂,
  linear law p = K/h · d, K = E (1 − ν)/((1 + ν)(1 − 2ν)));
* four Blankevoort1991Ligament strands (two collaterals, two crossing cruciates) with
  given stiffness, slack length and transition strain, no damping;
* a known external load on the tibia (compression, an anterior force, a varus and an
  internal-rotation moment), knee_flex held, the other five coordinates FDK DOFs
  (overlay ``fdk_dofs: [...]``, ``lock: [...]``).

The independent solve: the tibia pose from the five coordinates (the rotation sequence
above); each condyle presses δ = R − (distance of its centre above the plateau) and
carries F = π p R δ² along the plateau normal through the sphere's centre (the linear
elastic foundation integrated over the sphere's surface between depths 0 and δ: the cap
between d and d + dd has area 2πR dd, so F = ∫₀^δ p d 2πR dd, exactly); each strand
pulls with the Blankevoort law (ε = l/l₀ − 1; F = k ε²/(2ε_t) for 0 < ε < ε_t,
k (ε − ε_t/2) beyond; Blankevoort & Huiskes 1991, the form OpenSim's
Blankevoort1991Ligament documents); the generalized forces along the five coordinates
(virtual work, the tibia's angular velocity per unit coordinate rate from the rotation
matrix' derivative) are driven to zero by scipy's ``root``.

openfdk evaluates the contact on the meshes: the vertex sum Σ p a_i d_i over the sphere
cap's vertices (tributary areas a_i) approximates the integral. The discretisation error
is quantified by the same vertex sum written here over the STL's vertices
(``_vertex_contact``): with s = 0.2 mm it shifts the equilibrium from the closed form's by
1e-8 m and 3e-7 rad (measured), so the closed form is held to 1e-6 m and 1e-6 rad, and
the solve on the same vertices to 1e-8 (measured 1.5e-10). FDK runs with a residual
tolerance of 1e-9 N (N m); openfdk took 12 Newton iterations, 13 residual evaluations.
"""

from __future__ import annotations

import functools

import numpy as np

from openfdk.contact.stl import write_stl
import pytest
from lxml import etree

opensim = pytest.importorskip("opensim")

from opensim_models import six_dof_transform  # noqa: E402

from openfdk.fdk.analysis import run_fdk  # noqa: E402
from openfdk.io.modelfile import load_model_and_settings  # noqa: E402

R_CONDYLE, W_CONDYLE = 0.025, 0.022     # m: condyle sphere radius, half the condyles' spacing
CAP_HALF_WIDTH, CAP_SPACING = 0.0225, 0.2e-3
LAYERS = {"femur_cartilage": (8e6, 0.45, 2e-3), "tibia_cartilage": (12e6, 0.45, 4e-3)}  # E (Pa), ν, h (m)
LIGAMENTS = {  # name: femur point (m), tibia point (tibia frame, m), k (N/strain), slack length (m), ε_t
    "mcl": ((0.0, 0.0, -0.042), (-0.005, -0.035, -0.040), 2500.0, 0.057, 0.06),
    "lcl": ((0.0, 0.0, 0.042), (-0.010, -0.030, 0.045), 2000.0, 0.053, 0.06),
    "acl": ((-0.010, -0.005, 0.008), (0.015, -0.002, -0.003), 3000.0, 0.032, 0.06),
    "pcl": ((0.010, -0.005, -0.008), (-0.020, -0.008, 0.002), 3500.0, 0.039, 0.06),
}
COORDINATES = ("knee_flex", "knee_add", "knee_rot", "knee_tx", "knee_ty", "knee_tz")
SECONDARY = COORDINATES[1:]
CHILD_OFFSET = np.array([0.0, R_CONDYLE, 0.0])  # the joint's frame in the tibia (m)
LOAD_FORCE = np.array([10.0, 200.0, 0.0])       # N, world, at the joint's child frame origin
LOAD_MOMENT = np.array([2.0, 0.5, 0.0])         # N m, world: varus (x) and internal rotation (y)
FLEXION = 0.3                                   # rad, held
PATELLA = {  # the sixth body: a spherical button on a flat trochlea (m, N)
    "radius": 0.020, "cap_half_width": 0.017, "trochlea_x": 0.035,   # the trochlea: the plane x = 0.035 in the femur
    "quad_force": 300.0 * np.array([-0.2, 1.0, 0.0]) / np.hypot(0.2, 1.0),  # N, world
    # the patellar tendon: patella point, tibia point (m), k (N/strain), l₀ (m), ε_t
    "tendon": ((-0.010, -0.015, 0.0), (0.035, -0.045, 0.0), 20000.0, 0.056, 0.06),
}
PF_COORDINATES = ("pf_flex", "pf_rot", "pf_tilt", "pf_tx", "pf_ty", "pf_tz")
PF_PARENT = np.array([PATELLA["trochlea_x"] + PATELLA["radius"], 0.0, 0.0])  # the pf joint's frame in the femur


def _v3(x):
    return opensim.Vec3(*[float(a) for a in x])


def _grid_cap(radius, half_width, spacing):
    """An open spherical cap, pole −y, centre at the origin: the points of a square grid
    of ``spacing`` (m) in x and z, |x|, |z| ≤ half_width and within 0.9 radius of the
    axis, moved down onto the sphere;
    (vertices (n, 3) m, triangles (m, 3)) wound so the normals point away from the
    centre (out of the condyle)."""
    n = int(round(half_width / spacing))
    u = np.arange(-n, n + 1) * spacing
    x, z = np.meshgrid(u, u, indexing="ij")
    rho2 = np.minimum(x.ravel() ** 2 + z.ravel() ** 2, (0.9 * radius) ** 2)
    vertices = np.c_[x.ravel(), -np.sqrt(radius**2 - rho2), z.ravel()]
    idx = np.arange((2 * n + 1) ** 2).reshape(2 * n + 1, 2 * n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    triangles = np.r_[np.c_[a, b, c], np.c_[a, c, d]]   # (x, then z): e_x × e_z = −e_y
    # only the grid points within 0.9 R of the axis (the cap, not the equator)
    inside = x.ravel() ** 2 + z.ravel() ** 2 <= (0.9 * radius) ** 2
    triangles = triangles[inside[triangles].all(axis=1)]
    used = np.unique(triangles)
    renumber = np.zeros(len(vertices), int)
    renumber[used] = np.arange(len(used))
    return vertices[used], renumber[triangles]


def _flat(size_x, size_z, spacing):
    """A flat patch in y = 0, normal +y: (vertices (n, 3), triangles (m, 3))."""
    nx, nz = int(round(size_x / spacing)), int(round(size_z / spacing))
    x, z = np.meshgrid(np.linspace(-size_x / 2, size_x / 2, nx + 1), np.linspace(-size_z / 2, size_z / 2, nz + 1),
                       indexing="ij")
    vertices = np.c_[x.ravel(), np.zeros(x.size), z.ravel()]
    idx = np.arange(x.size).reshape(x.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return vertices, np.r_[np.c_[a, c, b], np.c_[a, d, c]]


def _jam_xml(root, meshes, contacts):
    """Add Smith2018ContactMesh ``meshes`` {name: (frame path, file, (E, ν, h))} and
    Smith2018ArticularContactForce ``contacts`` {name: (casting, target)} to an OpenSim
    document's Model element ``root``."""
    geometry = root.find("ContactGeometrySet/objects")
    if geometry is None:
        geometry = etree.SubElement(etree.SubElement(root, "ContactGeometrySet"), "objects")
    for name, (frame, file, (E, nu, h)) in meshes.items():
        mesh = etree.SubElement(geometry, "Smith2018ContactMesh", name=name)
        for tag, text in (("socket_frame", frame), ("mesh_file", file), ("elastic_modulus", E),
                          ("poissons_ratio", nu), ("thickness", h)):
            etree.SubElement(mesh, tag).text = str(text)
    forces = root.find("ForceSet/objects")
    for name, (casting, target) in contacts.items():
        force = etree.SubElement(forces, "Smith2018ArticularContactForce", name=name)
        for tag, text in (("socket_target_mesh", f"/contactgeometryset/{target}"),
                          ("socket_casting_mesh", f"/contactgeometryset/{casting}"), ("min_proximity", "0"),
                          ("max_proximity", "0.003"), ("elastic_foundation_formulation", "linear"),
                          ("use_lumped_contact_model", "true")):
            etree.SubElement(force, tag).text = text


def _knee_model(folder, patella=False):
    """The knee (module docstring) as ``folder``/knee.osim with its meshes, with the
    patella of :data:`PATELLA` if ``patella``; returns the OpenSim model (with the
    standard elements only) and the path."""
    m = opensim.Model()
    m.setName("jam_knee")
    m.setGravity(_v3([0, 0, 0]))
    femur = opensim.Body("femur", 1.0, _v3([0, 0, 0]), opensim.Inertia(1e-3, 1e-3, 1e-3))
    tibia = opensim.Body("tibia", 1e-6, _v3([0, 0, 0]), opensim.Inertia(1e-9, 1e-9, 1e-9))  # quasi-static
    m.addBody(femur)
    m.addBody(tibia)
    m.addJoint(opensim.WeldJoint("hip", m.getGround(), _v3([0, 0, 0]), _v3([0, 0, 0]), femur, _v3([0, 0, 0]),
                                 _v3([0, 0, 0])))
    transform = six_dof_transform(COORDINATES)
    m.addJoint(opensim.CustomJoint("knee", femur, _v3([0, 0, 0]), _v3([0, 0, 0]), tibia, _v3(CHILD_OFFSET),
                                   _v3([0, 0, 0]), transform))
    for name, (a, b, k, slack, eps_t) in LIGAMENTS.items():
        lig = opensim.Blankevoort1991Ligament(name, femur, _v3(a), tibia, _v3(b), k, slack)
        lig.set_transition_strain(eps_t)
        lig.set_damping_coefficient(0.0)
        m.addForce(lig)
    if patella:
        _add_patella(m, femur, tibia)
    m.finalizeConnections()
    m.initSystem()
    m.printToXML(str(folder / "base.osim"))
    vertices, triangles = _grid_cap(R_CONDYLE, CAP_HALF_WIDTH, CAP_SPACING)
    for side, z in (("medial", -W_CONDYLE), ("lateral", W_CONDYLE)):
        write_stl(folder / f"{side}_condyle.stl", vertices + [0.0, 0.0, z], triangles)
    write_stl(folder / "plateau.stl", *_flat(0.07, 0.10, 0.005))
    tree = etree.parse(str(folder / "base.osim"))
    meshes = {f"{side}_condyle": ("/bodyset/femur", f"{side}_condyle.stl", LAYERS["femur_cartilage"])
              for side in ("medial", "lateral")}
    meshes["plateau"] = ("/bodyset/tibia", "plateau.stl", LAYERS["tibia_cartilage"])
    contacts = {f"{side}_contact": (f"{side}_condyle", "plateau") for side in ("medial", "lateral")}
    if patella:
        vertices, triangles = _grid_cap(PATELLA["radius"], PATELLA["cap_half_width"], CAP_SPACING)
        turn = _rotation([0, 0, 1], -np.pi / 2)  # −y → −x: the button faces the trochlea
        write_stl(folder / "patella.stl", vertices @ turn.T, triangles)
        vertices, triangles = _flat(0.10, 0.06, 0.005)
        write_stl(folder / "trochlea.stl", vertices @ turn.T + [PATELLA["trochlea_x"], 0.0, 0.0], triangles)
        meshes["patella_button"] = ("/bodyset/patella", "patella.stl", LAYERS["femur_cartilage"])
        meshes["trochlea"] = ("/bodyset/femur", "trochlea.stl", LAYERS["tibia_cartilage"])
        contacts["pf_contact"] = ("patella_button", "trochlea")
    _jam_xml(tree.getroot().find("Model"), meshes, contacts)
    tree.write(str(folder / "knee.osim"))
    return m, folder / "knee.osim"


def _add_patella(m, femur, tibia):
    """The patella (:data:`PATELLA`) on a CustomJoint ``pf`` to the femur (its child frame
    is the patella's origin, the button's centre, where the quadriceps force is applied)
    and the patellar tendon to the tibia."""
    patella = opensim.Body("patella", 1e-6, _v3([0, 0, 0]), opensim.Inertia(1e-9, 1e-9, 1e-9))
    m.addBody(patella)
    transform = six_dof_transform(PF_COORDINATES)
    m.addJoint(opensim.CustomJoint("pf", femur, _v3(PF_PARENT), _v3([0, 0, 0]), patella, _v3([0, 0, 0]),
                                   _v3([0, 0, 0]), transform))
    a, b, k, slack, eps_t = PATELLA["tendon"]
    tendon = opensim.Blankevoort1991Ligament("patellar_tendon", patella, _v3(a), tibia, _v3(b), k, slack)
    tendon.set_transition_strain(eps_t)
    tendon.set_damping_coefficient(0.0)
    m.addForce(tendon)


# ----------------------------------------------------------------- the independent solve


def _pressure_modulus():
    """p (N/m³) of the lumped layer: K(Ē, ν̄)/(h₁ + h₂)."""
    (E1, nu1, h1), (E2, nu2, h2) = LAYERS.values()
    E, nu = (E1 + E2) / 2, (nu1 + nu2) / 2
    return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / (h1 + h2)


def _rotation(axis, angle):
    k = np.asarray(axis, float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def tibia_pose(q):
    """(R_FT (3, 3), p_FT (3,) m) of the tibia in the femur (= ground) for the six knee
    coordinates q (rad, m): R = R_z(flex) R_x(add) R_y(rot) (each axis turned by the
    rotations before it), the joint's child frame at (tx, ty, tz) along the femur's axes."""
    R = _rotation([0, 0, 1], q[0]) @ _rotation([1, 0, 0], q[1]) @ _rotation([0, 1, 0], q[2])
    return R, np.asarray(q[3:6], float) - R @ CHILD_OFFSET


def blankevoort(strain, k, eps_t):
    """Blankevoort & Huiskes (1991) strand force (N) at strain ε; k in N per unit strain."""
    if strain <= 0:
        return 0.0
    return k * strain**2 / (2 * eps_t) if strain < eps_t else k * (strain - eps_t / 2)


def _closed_form_contact(R_FT, p_FT):
    """[(force on the tibia (3,) N, a point of its line of action (3,) m)] of the two
    condyles: F = π p R δ² along −n through the sphere's centre."""
    n = R_FT[:, 1]
    out = []
    for z in (-W_CONDYLE, W_CONDYLE):
        centre = np.array([0.0, 0.0, z])
        depth = R_CONDYLE - (centre - p_FT) @ n
        out.append((-np.pi * _pressure_modulus() * R_CONDYLE * max(depth, 0.0) ** 2 * n, centre))
    return out


@functools.lru_cache(maxsize=None)
def _cap_vertex_areas(radius=R_CONDYLE, half_width=CAP_HALF_WIDTH):
    """The condyle cap's vertices (n, 3) m and their tributary areas (n,) m² (a third of
    each incident triangle's area)."""
    vertices, triangles = _grid_cap(radius, half_width, CAP_SPACING)
    corners = vertices[triangles]
    tri_area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    return vertices, np.bincount(triangles.ravel(), np.repeat(tri_area / 3, 3), len(vertices))


def _vertex_contact(R_FT, p_FT):
    """The same loads as openfdk's elastic foundation over the caps' vertices: f_i = −p
    a_i d_i n at each vertex i in contact (d_i its depth below the plateau); the forces
    are parallel, so each condyle's resultant acts through their f-weighted centroid."""
    vertices, area = _cap_vertex_areas()
    n = R_FT[:, 1]
    out = []
    for z in (-W_CONDYLE, W_CONDYLE):
        x = vertices + [0.0, 0.0, z]
        f = _pressure_modulus() * area * np.maximum(-((x - p_FT) @ n), 0.0)
        out.append((-f.sum() * n, f @ x / f.sum()))
    return out


def _wrench_on_tibia(q, contact):
    """Resultant force (3,) N and moment about the femur's origin (3,) N m on the tibia."""
    R_FT, p_FT = tibia_pose(q)
    loads = contact(R_FT, p_FT)
    for a, b, k, slack, eps_t in LIGAMENTS.values():
        b_F = p_FT + R_FT @ np.asarray(b)
        length = np.linalg.norm(np.asarray(a) - b_F)
        loads.append((blankevoort(length / slack - 1, k, eps_t) * (np.asarray(a) - b_F) / length, b_F))
    loads.append((LOAD_FORCE, p_FT + R_FT @ CHILD_OFFSET))
    points, forces = np.array([x for _, x in loads]), np.array([f for f, _ in loads])
    return forces.sum(axis=0), np.cross(points, forces).sum(axis=0) + LOAD_MOMENT


def generalized_forces(secondary, contact, flexion=FLEXION):
    """The generalized forces (5,) (N m, N) along the secondary coordinates: Q_j = F ·
    ∂o/∂q_j + M_o · ω_j, o the femur's origin as a tibia point, ω_j from ∂R/∂q_j Rᵀ (central
    differences of the pose, step 1e-6)."""
    q = np.r_[flexion, secondary]
    force, moment = _wrench_on_tibia(q, contact)
    R, p = tibia_pose(q)
    o_T = -R.T @ p  # the femur's origin in the tibia
    Q = []
    for j in range(1, 6):
        e = np.zeros(6)
        e[j] = 1e-6
        (Rp, pp), (Rm, pm) = tibia_pose(q + e), tibia_pose(q - e)
        W = (Rp - Rm) / 2e-6 @ R.T
        omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
        velocity = ((pp + Rp @ o_T) - (pm + Rm @ o_T)) / 2e-6
        Q.append(force @ velocity + moment @ omega)
    return np.array(Q)


def _solve(contact, start, flexion=FLEXION):
    from scipy.optimize import root

    sol = root(generalized_forces, start, args=(contact, flexion), method="hybr", options={"xtol": 1e-13})
    assert sol.success, sol.message
    assert np.abs(sol.fun).max() < 1e-7
    return sol.x


# ------------------------------------------------------------------------------ tests


@pytest.fixture(scope="module")
def knee(tmp_path_factory):
    folder = tmp_path_factory.mktemp("knee")
    model, path = _knee_model(folder)
    return folder, model, path


def test_the_independent_kinematics_are_opensims(knee):
    """The tibia pose written above equals OpenSim's for random coordinates (1e-12)."""
    _, model, _ = knee
    state = model.initSystem()
    rng = np.random.default_rng(27)
    coordinates = model.getCoordinateSet()
    tibia = model.getBodySet().get("tibia")
    for _ in range(5):
        q = np.r_[rng.uniform(-1, 1, 3), rng.uniform(-0.02, 0.02, 3)]
        for name, value in zip(COORDINATES, q):
            coordinates.get(name).setValue(state, float(value), False)
        model.realizePosition(state)
        X = tibia.getTransformInGround(state)
        R_theirs = np.array([[X.R().get(i, j) for j in range(3)] for i in range(3)])
        p_theirs = np.array([X.p().get(i) for i in range(3)])
        R, p = tibia_pose(q)
        np.testing.assert_allclose(R, R_theirs, atol=1e-12)
        np.testing.assert_allclose(p, p_theirs, atol=1e-12)


def _overlay(folder, text, name="fdk.yaml"):
    (folder / name).write_text("opensim: knee.osim\n" + text)
    return folder / name


@pytest.mark.slow
def test_secondary_coordinates_match_an_independent_force_balance(knee):
    folder, _, _ = knee
    overlay = _overlay(folder, f"""\
fdk_dofs: [knee_add, knee_rot, knee_tx, {{knee_ty: 0.0005}}, knee_tz]
lock: [{{knee_flex: {FLEXION}}}]
fdk: {{tolerance: 1.0e-9, max_iterations: 60}}
loads:
  tibia_load: {{point: tibia.knee_child, force: {LOAD_FORCE.tolist()}, moment: {LOAD_MOMENT.tolist()}, frame: world}}
""")
    model, settings = load_model_and_settings(overlay)
    res = run_fdk(model, None, np.array([0.0]), settings)
    assert res.converged.all(), res.messages
    ours = dict(zip(res.dof_names, res.alpha[0]))
    ours = np.array([ours[name] for name in SECONDARY])
    closed = _solve(_closed_form_contact, np.r_[0, 0, 0, 5e-4, 0])
    vertex = _solve(_vertex_contact, closed)
    # the solution moved every DOF (the test can tell a wrong equilibrium from the start)
    assert np.all(np.abs(closed) > [5e-4, 0.05, 1e-3, 1e-4, 1e-3])
    # openfdk against the closed form: translations (m) and rotations (rad) to 1e-6;
    # measured 1e-8 m and 3e-7 rad (the caps' discretisation, next line)
    np.testing.assert_allclose(ours, closed, rtol=0, atol=1e-6)
    # against the same force balance summed over the STL's vertices: the discretisation
    # is the whole difference (measured 1.5e-10)
    np.testing.assert_allclose(ours, vertex, rtol=0, atol=1e-8)
    # openfdk's reported loads at its equilibrium: each condyle's force π p R δ² (the
    # depth from the reported pose) and each strand's Blankevoort force
    R_FT, p_FT = tibia_pose(np.r_[FLEXION, ours])
    columns = res.forces.extra["columns"]
    for side, (force, _) in zip(("medial", "lateral"), _closed_form_contact(R_FT, p_FT)):
        reported = np.array([columns[f"{side}_contact.F{c}_N"][0] for c in "xyz"])
        np.testing.assert_allclose(reported, -force, rtol=2e-4, atol=0)  # (force on the condyle: −that on the tibia)
    for k, name in enumerate(res.forces.ligament_names):
        a, b, stiffness, slack, eps_t = LIGAMENTS[name]
        length = np.linalg.norm(np.asarray(a) - (p_FT + R_FT @ np.asarray(b)))
        assert res.forces.ligament_force[0, k] == pytest.approx(blankevoort(length / slack - 1, stiffness, eps_t),
                                                                rel=1e-9)


# ------------------------------------------------------------------- the patella as a sixth body

PF_FDK = ("pf_flex", "pf_tx", "pf_ty")  # the patella's FDK coordinates; pf_rot, pf_tilt, pf_tz held at 0
FLEXIONS = (-0.1, -0.3, -0.5)           # rad: knee_flex = −0.1 − 0.2 t at t = 0, 1, 2 s


def patella_pose(q):
    """(R (3, 3), p (3,) m) of the patella in the femur for its six coordinates (the
    same CustomJoint rotation sequence as the knee; the joint's child frame is the
    patella's origin)."""
    R = _rotation([0, 0, 1], q[0]) @ _rotation([1, 0, 0], q[1]) @ _rotation([0, 1, 0], q[2])
    return R, PF_PARENT + np.asarray(q[3:6], float)


def _body_generalized_forces(pose, q, indices, force, moment):
    """Q_j (len(indices),) of a body at coordinates q (6,) under a resultant ``force`` (3,)
    N and ``moment`` (3,) N m about the femur's origin o: Q_j = F · ∂o/∂q_j + M · ω_j (o
    taken as a point of the body; central differences of ``pose``, step 1e-6)."""
    R, p = pose(q)
    o_B = -R.T @ p
    Q = []
    for j in indices:
        e = np.zeros(6)
        e[j] = 1e-6
        (Rp, pp), (Rm, pm) = pose(q + e), pose(q - e)
        W = (Rp - Rm) / 2e-6 @ R.T
        Q.append(force @ (((pp + Rp @ o_B) - (pm + Rm @ o_B)) / 2e-6) + moment @ np.array([W[2, 1], W[0, 2], W[1, 0]]))
    return np.array(Q)


def _resultant(loads, moment=np.zeros(3)):
    points, forces = np.array([x for _, x in loads]), np.array([f for f, _ in loads])
    return forces.sum(axis=0), np.cross(points, forces).sum(axis=0) + moment


def patella_loads(q_knee, q_pf, vertices=False):
    """The loads [(force (3,) N, point (3,) m)] on the patella in closed form: the
    quadriceps force at its origin, the patellar tendon (Blankevoort) toward the tibia and
    the button's contact π p R δ² along the trochlea's normal +x through its centre (or,
    with ``vertices``, summed over the button mesh's vertices)."""
    R_FT, p_FT = tibia_pose(q_knee)
    R_FP, p_FP = patella_pose(q_pf)
    a, b, k, slack, eps_t = PATELLA["tendon"]
    a_F, b_F = p_FP + R_FP @ np.asarray(a), p_FT + R_FT @ np.asarray(b)
    length = np.linalg.norm(b_F - a_F)
    tendon = blankevoort(length / slack - 1, k, eps_t) * (b_F - a_F) / length
    if vertices:  # the same sum over the button's vertices as openfdk's (see _vertex_contact)
        cap, area = _cap_vertex_areas(PATELLA["radius"], PATELLA["cap_half_width"])
        x = p_FP + cap @ (R_FP @ _rotation([0, 0, 1], -np.pi / 2)).T
        f = _pressure_modulus() * area * np.maximum(PATELLA["trochlea_x"] - x[:, 0], 0.0)
        contact = (f.sum() * np.array([1.0, 0, 0]), f @ x / f.sum())
    else:
        depth = PATELLA["radius"] - (p_FP[0] - PATELLA["trochlea_x"])
        contact = (np.pi * _pressure_modulus() * PATELLA["radius"] * max(depth, 0.0) ** 2 * np.array([1.0, 0, 0]), p_FP)
    return [(PATELLA["quad_force"], p_FP), (tendon, a_F), contact], (tendon, b_F)


def knee_and_patella_forces(x, flexion, vertices=False):
    """The generalized forces (8,) along the knee's five secondary coordinates and the
    patella's three FDK coordinates ``x`` = [add, rot, tx, ty, tz, pf_flex, pf_tx, pf_ty]."""
    q_knee = np.r_[flexion, x[:5]]
    q_pf = np.array([x[5], 0.0, 0.0, x[6], x[7], 0.0])
    on_patella, (tendon, b_F) = patella_loads(q_knee, q_pf, vertices)
    R_FT, p_FT = tibia_pose(q_knee)
    on_tibia = (_vertex_contact if vertices else _closed_form_contact)(R_FT, p_FT)
    on_tibia += [(-tendon, b_F), (LOAD_FORCE, p_FT + R_FT @ CHILD_OFFSET)]
    for a, b, k, slack, eps_t in LIGAMENTS.values():
        b_F = p_FT + R_FT @ np.asarray(b)
        length = np.linalg.norm(np.asarray(a) - b_F)
        on_tibia.append((blankevoort(length / slack - 1, k, eps_t) * (np.asarray(a) - b_F) / length, b_F))
    return np.r_[_body_generalized_forces(tibia_pose, q_knee, range(1, 6), *_resultant(on_tibia, LOAD_MOMENT)),
                 _body_generalized_forces(patella_pose, q_pf, (0, 3, 4), *_resultant(on_patella))]


@pytest.mark.slow
def test_patella_in_equilibrium_at_three_flexion_angles(tmp_path):
    """The knee with the patella (a spherical button on a flat trochlea, the quadriceps a
    known 300 N force at the button's centre, a Blankevoort patellar tendon to the tibial
    tuberosity), knee_flex driven through three angles, eight FDK DOFs. At every angle:
    (1) the patella's loads as openfdk reports them — the tendon's force along the strand
    of the reported pose, the quadriceps force, the contact's force through its centre of
    pressure (exact for a plane target: all vertex forces are parallel) — balance along
    the patella's FDK directions (x, y force; z moment) to 1e-6 N and N m (measured
    4e-11); (2) all eight coordinates equal the independent closed-form solve's: the
    translations to 1e-6 m (measured 5e-8 m), the knee's rotations to 1e-6 rad (6e-7).
    The patella's rotation about the button's centre is soft (the quadriceps acts at the
    centre; only the tendon's lever turns it back), so the caps' discretisation (the
    centre of pressure a fraction of a µm off the closed form's line through the centre)
    turns it by up to 4e-6 rad: 8e-8 m as an arc on the 20 mm button, which is held to
    1e-6 m. On the meshes' own vertices (the same sums as openfdk's) all eight agree to
    1e-8 (measured 6e-9)."""
    from scipy.optimize import root

    _knee_model(tmp_path, patella=True)
    overlay = _overlay(tmp_path, f"""\
fdk_dofs: [knee_add, knee_rot, knee_tx, {{knee_ty: 0.0005}}, knee_tz, pf_flex, {{pf_tx: -0.0005}}, pf_ty]
lock: [pf_rot, pf_tilt, pf_tz]
drivers:
  flexion: {{measure: knee_flex, reaction: true, function: {{type: polynomial, coefficients: [{FLEXIONS[0]}, {FLEXIONS[1] - FLEXIONS[0]}]}}}}
fdk: {{tolerance: 1.0e-9, max_iterations: 60}}
loads:
  tibia_load: {{point: tibia.knee_child, force: {LOAD_FORCE.tolist()}, moment: {LOAD_MOMENT.tolist()}, frame: world}}
  quadriceps: {{point: patella.pf_child, force: {PATELLA["quad_force"].tolist()}, frame: world}}
""")
    model, settings = load_model_and_settings(overlay)
    res = run_fdk(model, None, np.arange(3.0), settings)
    assert res.converged.all(), res.messages
    names = SECONDARY + PF_FDK
    columns = res.forces.extra["columns"]
    tendon_k = res.forces.ligament_names.index("patellar_tendon")
    start = np.r_[0, 0, 0, 5e-4, 0, 0, -5e-4, 0]
    for i, flexion in enumerate(FLEXIONS):
        alpha = dict(zip(res.dof_names, res.alpha[i]))
        ours = np.array([alpha[n] for n in names])
        q_knee, q_pf = np.r_[flexion, ours[:5]], np.array([ours[5], 0, 0, ours[6], ours[7], 0])
        # (1) the patella's balance from openfdk's reported forces
        R_FT, p_FT = tibia_pose(q_knee)
        R_FP, p_FP = patella_pose(q_pf)
        a_F = p_FP + R_FP @ np.asarray(PATELLA["tendon"][0])
        b_F = p_FT + R_FT @ np.asarray(PATELLA["tendon"][1])
        tendon = res.forces.ligament_force[i, tendon_k] * (b_F - a_F) / np.linalg.norm(b_F - a_F)
        contact = np.array([columns[f"pf_contact.F{c}_N"][i] for c in "xyz"])
        cop = np.array([columns[f"pf_contact.cop_{c}_m"][i] for c in "xyz"])
        force, moment = _resultant([(PATELLA["quad_force"], p_FP), (tendon, a_F), (contact, cop)])
        assert np.linalg.norm(tendon) > 250 and contact[0] > 50  # the three forces are all there
        np.testing.assert_allclose([force[0], force[1], moment[2]], 0.0, atol=1e-6)
        # (2) the independent solve of all eight equations (closed-form contacts)
        sol = root(knee_and_patella_forces, start, args=(flexion,), method="hybr", options={"xtol": 1e-13})
        assert sol.success and np.abs(sol.fun).max() < 1e-7, sol.message
        assert np.abs(ours[5]) > 0.05 and np.abs(ours[6:]).max() > 5e-4  # the patella moved
        # translations to 1e-6 m, the knee's rotations to 1e-6 rad, the patella's rotation
        # about the button's centre as an arc on the button (R Δθ) to 1e-6 m (docstring)
        tolerance = np.r_[1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6 / PATELLA["radius"], 1e-6, 1e-6]
        assert np.all(np.abs(ours - sol.x) <= tolerance), ours - sol.x
        # on the meshes' own vertices the two agree to 1e-8 (measured 6e-9)
        fine = root(knee_and_patella_forces, sol.x, args=(flexion, True), method="hybr", options={"xtol": 1e-13})
        assert fine.success and np.abs(fine.fun).max() < 1e-7, fine.message
        np.testing.assert_allclose(ours, fine.x, rtol=0, atol=1e-8)
        start = sol.x


# ----------------------------------------------------- the Newton step with the contacts exact


@pytest.mark.slow
def test_the_contacts_exact_model_of_the_step(knee):
    """fdk/contact_step.py on the knee above, 3–6 mrad and 0.06–0.3 mm from the closed-form
    equilibrium (28 N off): the model g(Δα) = f + J_s Δα − R [Q_c(q̂ ⊕ U Δα) − Q_c(q̂)]
    starts at f with slope J (finite differences of g); R is the virtual work of a load
    on the contact bodies along U (no muscles: f^FDK balances the applied loads' virtual
    work, R = U_cᵀ); and after the Newton step, where the condyles' patches change, g
    misses f^FDK by 0.18 N where the linear model misses by 5.6 N (measured), and g's own
    root leaves 0.20 N where the linear step leaves 5.6 N. What g still misses is the
    tibia's rotation, which U linearises."""
    from openfdk.fdk.analysis import fdk_step
    from openfdk.fdk.jacobian import analytic_jacobian
    from openfdk.fdk.residual import FrameWorkspace

    folder, _, _ = knee
    overlay = _overlay(folder, f"""\
fdk_dofs: [knee_add, knee_rot, knee_tx, {{knee_ty: 0.0005}}, knee_tz]
lock: [{{knee_flex: {FLEXION}}}]
loads:
  tibia_load: {{point: tibia.knee_child, force: {LOAD_FORCE.tolist()}, moment: {LOAD_MOMENT.tolist()}, frame: world}}
""", "fdk_model.yaml")
    model, settings = load_model_and_settings(overlay)
    step = fdk_step(model, None, np.array([0.0]), settings)
    ctx, contacts = step.ctx, step.ctx.solver.forces.by_kind["contacts"]
    a0 = _solve(_closed_form_contact, np.r_[0, 0, 0, 5e-4, 0]) + np.array([3e-3, 6e-3, 3e-4, 6e-5, 3e-4])
    ev = ctx.evaluate(0, a0, FrameWorkspace({0: step.last_state}))
    J, _, _ = analytic_jacobian(ctx, 0, ev)
    split = ev.contact_split
    Q0, KU0 = split.terms(contacts, ev.state)
    split.split(J, KU0)
    # R against the virtual work of a load on the contact bodies' coordinates
    assert np.abs(split.R).max() > 1e-3
    np.testing.assert_allclose(split.R, split.U[split.cols].T, rtol=0, atol=1e-9 * np.abs(split.U).max())
    # g(0) = f, g'(0) = J
    g0, _ = split.model(contacts, ev.f_fdk, ev.state, Q0, np.zeros(5))
    np.testing.assert_array_equal(g0, ev.f_fdk)
    for j, h in enumerate((1e-7, 1e-7, 1e-9, 1e-9, 1e-9)):
        e = np.zeros(5)
        e[j] = h
        gp, _ = split.model(contacts, ev.f_fdk, ev.state, Q0, e)
        gm, _ = split.model(contacts, ev.f_fdk, ev.state, Q0, -e)
        assert np.max(np.abs(J[:, j])) > 1.0
        np.testing.assert_allclose((gp - gm) / (2 * h), J[:, j], rtol=0, atol=1e-5 * np.max(np.abs(J[:, j])))
    # after the Newton step
    step_N = -np.linalg.solve(J, ev.f_fdk)
    after = ctx.evaluate(0, a0 + step_N, FrameWorkspace({0: ev.state.copy()}))
    g, _ = split.model(contacts, ev.f_fdk, ev.state, Q0, step_N)
    linear_miss = np.max(np.abs(after.f_fdk - (ev.f_fdk + J @ step_N)))
    model_miss = np.max(np.abs(after.f_fdk - g))
    assert ev.norm > 20.0 and linear_miss > 1.0
    assert model_miss < 0.05 * linear_miss, (model_miss, linear_miss)
    # g's own root (Newton on the contacts alone)
    d, g_d = split.solve(contacts, ev.f_fdk, ev.state, Q0, step_N, 1e-6)
    assert np.max(np.abs(g_d)) < 1e-6
    at_d = ctx.evaluate(0, a0 + d, FrameWorkspace({0: ev.state.copy()}))
    assert at_d.norm < 0.05 * after.norm, (at_d.norm, after.norm)


@pytest.mark.slow
def test_with_and_without_the_contacts_exact_step_the_same_equilibria(knee):
    """The setting ``contact_step`` changes the path to the root, not the root: over six
    frames of flexion (0.3 → 0.4 rad, 0.02 rad per frame) both solves reach the vertex-sum
    force balance written above at every frame to 1e-8 m (rad). (On this knee the tibia's
    rotation bends f^FDK as much as the contacts do: the split measures that on its first
    large step, g's miss 0.58 of the linear model's, and sleeps; 21 evaluations either
    way.)"""
    folder, _, _ = knee
    times = np.arange(6) * 0.01
    rate = 2.0  # rad/s: 0.02 rad per frame
    alphas = {}
    for exact in (True, False):
        overlay = _overlay(folder, f"""\
fdk_dofs: [knee_add, knee_rot, knee_tx, {{knee_ty: 0.0005}}, knee_tz]
drivers:
  flexion: {{measure: knee_flex, reaction: true, function: {{type: polynomial, coefficients: [{FLEXION}, {rate}]}}}}
fdk: {{tolerance: 1.0e-9, max_iterations: 60, contact_step: {str(exact).lower()}}}
loads:
  tibia_load: {{point: tibia.knee_child, force: {LOAD_FORCE.tolist()}, moment: {LOAD_MOMENT.tolist()}, frame: world}}
""", f"fdk_{exact}.yaml")
        model, settings = load_model_and_settings(overlay)
        res = run_fdk(model, None, times, settings)
        assert res.converged.all(), res.messages
        alphas[exact] = np.array([[dict(zip(res.dof_names, a))[name] for name in SECONDARY] for a in res.alpha])
    start = np.r_[0, 0, 0, 5e-4, 0]
    for k, t in enumerate(times):
        flexion = FLEXION + rate * t
        start = _solve(_vertex_contact, _solve(_closed_form_contact, start, flexion), flexion)
        for exact in (True, False):
            np.testing.assert_allclose(alphas[exact][k], start, rtol=0, atol=1e-8)
    assert np.ptp(alphas[True][:, 1]) > 1e-4  # the frames differ (rotation: 0.27 mrad over the six)
