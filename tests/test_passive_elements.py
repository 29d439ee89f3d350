"""Ligaments, springs and contacts as model force elements: model-file sections,
generalised forces against closed forms, and stiffness ∂Q/∂q̂ against finite
differences on the manifold."""

import textwrap
import warnings

import numpy as np
import pytest
import trimesh

from openfdk.contact.mesh import MeshWarning
from openfdk.contact.shapes import flat_patch
from openfdk.forces.forceset import ForceElements
from openfdk.model.model import ModelError
from openfdk.io.modelfile import load_model
from openfdk.numerics.numdiff import manifold_jacobian


def _write_patch(path, size, edge, scale=1.0, flip=False):
    patch = flat_patch(size, size, edge)
    faces = patch.faces[:, ::-1] if flip else patch.faces
    trimesh.Trimesh(patch.vertices_B * scale, faces, process=False).export(path)


MODEL = """
openfdk: 1
units: {length: mm, angle: deg}
bodies:
  block:
    mass: 1.0
    inertia: [1.0e-3, 1.0e-3, 1.0e-3]
    position: [0, 0, 4.9]          # bottom face 5 mm below the centre of mass: 0.1 mm into the floor
    frames:
      hook: [0, 0, 10]
  ground:
    frames:
      anchor: [0, 0, 40]
contacts:
  floor:
    vertices: {body: block, mesh: bottom.stl, units: mm, placement: {position: [0, 0, -5], orientation: [180, 0, 0]}}
    surface: {body: ground, mesh: floor.stl, units: mm}
    pressure_modulus: 1.0e10
ligaments:
  sling:
    path: [ground.anchor, block.hook]
    stiffness: 500
    slack_length: 20
springs:
  level:
    measure: {type: vector, from: ground.origin, to: block.origin}
    component: 0
    stiffness: 100
    rest_value: 0
"""


#: drivers holding the block at its reference pose (with reactions), 3 frames
HELD = """
measures:
  where: {type: point, point: block.origin}
  how: {type: angles, frame: ground.origin, of: block.origin}
drivers:
  hold_position: {measure: where, function: {type: constant, value: [0, 0, 4.9]}, reaction: true}
  hold_angles: {measure: how, function: {type: constant, value: [0, 0, 0]}, reaction: true}
analysis: {start: 0, end: 0.1, frames: 3}
"""


@pytest.fixture
def block_model(tmp_path):
    _write_patch(tmp_path / "bottom.stl", 10.0, 0.5)   # 10 mm × 10 mm face, normals flipped down by the placement
    _write_patch(tmp_path / "floor.stl", 40.0, 1.0)    # floor at z = 0, normals up
    (tmp_path / "block.yaml").write_text(textwrap.dedent(MODEL))
    return load_model(tmp_path / "block.yaml")


def test_contact_ligament_spring_forces_closed_form(block_model):
    """Flat 10×10 mm face 0.1 mm into the floor: F = p A δ = 1e10·1e-4·1e-4 = 100 N up;
    ligament stretched from 20 mm to 40 − 14.9 = 25.1 mm: toe or linear branch of
    Blankevoort's law; spring at rest (x = 0): no force."""
    model = block_model
    state = model.initial_state()
    Q, out, _ = ForceElements(model).generalized_forces(state, 0.0)
    contact = out["contacts"]["floor"]
    assert contact.force_W[2] == pytest.approx(100.0, rel=1e-6)
    l0, k, eps_l = 0.020, 500.0, 0.03
    eps = (0.0251 - l0) / l0
    T = k * l0 * (eps - eps_l) if eps > 2 * eps_l else k * l0 * eps**2 / (4 * eps_l)
    assert out["ligaments"].force[0] == pytest.approx(T, rel=1e-9)
    assert out["springs"].force[0] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(Q[:3], [0.0, 0.0, 100.0 + T], rtol=1e-6, atol=1e-9)


def test_passive_stiffness_matches_manifold_finite_differences(block_model):
    model = block_model
    state = model.initial_state()
    # tilt and shift a little so every element and every block of K is active
    state.displace(np.r_[0.0005, -0.0003, 0.00002, 0.01, -0.02, 0.3])
    passive = ForceElements(model)
    _, _, K = passive.generalized_forces(state, 0.0, want_stiffness=True)
    K_fd = manifold_jacobian(lambda s: passive.generalized_forces(s, 0.0)[0], state, eps=1e-8)
    assert np.abs(K).max() > 1e5  # contact stiffness p A ≈ 1e6 N/m
    # rotations scaled by a 10 mm lever so that all blocks compare in N/m
    S = np.diag([1, 1, 1, 1e2, 1e2, 1e2])
    np.testing.assert_allclose(S @ K @ S, S @ K_fd @ S, atol=1e-3 * np.abs(S @ K @ S).max())
    # from the outputs the forces stage left (ligament/spring Jacobians not evaluated again)
    _, out, _ = passive.generalized_forces(state, 0.0)
    K_out = passive.stiffness(state, out)
    np.testing.assert_allclose(S @ K_out @ S, S @ K_fd @ S, atol=1e-3 * np.abs(S @ K @ S).max())
    np.testing.assert_allclose(K_out, K, rtol=0, atol=1e-9 * np.abs(K).max())


def test_contact_far_apart_and_unit_warnings(tmp_path):
    _write_patch(tmp_path / "bottom.stl", 10.0, 1.0)
    _write_patch(tmp_path / "floor.stl", 40.0, 2.0)
    text = textwrap.dedent(MODEL).replace("position: [0, 0, 4.9]", "position: [0, 0, 400]")
    (tmp_path / "far.yaml").write_text(text)
    with pytest.warns(MeshWarning, match="floor.*apart in the reference pose"):
        load_model(tmp_path / "far.yaml")
    text = textwrap.dedent(MODEL).replace("{body: ground, mesh: floor.stl, units: mm}", "{body: ground, mesh: floor.stl, units: m}")
    (tmp_path / "units.yaml").write_text(text)
    # a 40 mm floor read as metres: the scale warning comes first, then the distance
    # grid refuses the 40 m surface with a clear error
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(ModelError, match="units.yaml: contacts.floor: .*floor.stl.*larger spacing"):
            load_model(tmp_path / "units.yaml")
    assert any("floor.stl" in str(w.message) and "mm" in str(w.message) for w in caught)


def test_missing_mesh_is_named(tmp_path):
    (tmp_path / "m.yaml").write_text(textwrap.dedent(MODEL))
    with pytest.raises(ModelError, match=r"m.yaml: contacts.floor.vertices.mesh: .*bottom.stl"):
        load_model(tmp_path / "m.yaml")


def test_contact_outputs_in_forces_csv(tmp_path):
    """A block held in place by drivers (with reactions) resting 0.1 mm into the floor:
    forces.csv reports the contact force p A δ = 100 N, its centre of pressure under the
    block, the 1 cm² area and the pressure p δ = 1 MPa; the driver reactions carry the
    rest of the weight, ligament and contact (sum of vertical forces = m g)."""
    import csv

    from openfdk.cli import main

    _write_patch(tmp_path / "bottom.stl", 10.0, 0.5)
    _write_patch(tmp_path / "floor.stl", 40.0, 1.0)
    text = textwrap.dedent(MODEL) + textwrap.dedent(HELD)
    text = text.replace("springs:\n  level:", "springs_unused:\n  level:").replace("springs_unused:", "springs:")
    (tmp_path / "held.yaml").write_text(text)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "held.yaml"), "--out", str(out), "--no-progress"]) == 0
    rows = list(csv.DictReader(open(out / "forces.csv")))
    assert len(rows) == 3 and all(r["converged"] == "1" for r in rows)
    r = rows[0]
    assert float(r["floor.Fz_N"]) == pytest.approx(100.0, rel=1e-6)
    assert float(r["floor.area_m2"]) == pytest.approx(1e-4, rel=1e-6)
    assert float(r["floor.peak_pressure_Pa"]) == pytest.approx(1e10 * 1e-4, rel=1e-6)
    assert abs(float(r["floor.cop_x_m"])) < 1e-9 and abs(float(r["floor.cop_y_m"])) < 1e-9
    total = float(r["floor.Fz_N"]) + float(r["sling.force_N"]) + float(r["hold_position[2].reaction"])
    assert total == pytest.approx(1.0 * 9.81, abs=1e-6)  # CSV keeps 10 significant digits


def test_spring_forces_and_stiffness_batched_and_measure_by_measure():
    """Springs on relative-vector components (batched into one kernel call): Q against
    the closed form f = −k (m − m0), Q = Σ f M, K against
    manifold finite differences of Q (non-zero geometric part), and the batched path
    equal to the measure-by-measure one."""
    from openfdk.forces.elements import add_spring
    from openfdk.model.builder import ModelBuilder
    from openfdk.numerics.spatial import quat_from_rotvec

    b = ModelBuilder("springs")
    b.add_body("a", 1.0, [1e-3] * 3, position=[0.01, 0.02, -0.03], orientation=quat_from_rotvec([0.2, -0.1, 0.3]))
    b.add_frame("a", "p", [0.02, -0.01, 0.015])
    vec = b.vector("ground.origin", "a.p", expressed_in="a")
    add_spring(b, "x_in_a", b._select(vec, [0]), 300.0, rest_value=0.005)
    add_spring(b, "z_in_a", b._select(vec, [2]), 150.0, rest_value=-0.01)
    model = b.build()
    state = model.initial_state()
    passive = ForceElements(model)
    assert passive.by_kind["springs"].rows.batched is not None
    Q, out, K = passive.generalized_forces(state, 0.0, want_stiffness=True)
    expect = np.zeros(model.n_coords)
    for k, (spr, m0, stiff) in enumerate(zip(model.springs, [0.005, -0.01], [300.0, 150.0])):
        m, M, _ = spr.measure.evaluate(state, 1)
        assert out["springs"].force[k] == pytest.approx(-stiff * (m[0] - m0), rel=1e-12)  # restoring
        expect += M[0] * out["springs"].force[k]
    assert np.abs(out["springs"].force).min() > 1.0
    np.testing.assert_allclose(Q, expect, rtol=1e-12, atol=1e-12)
    K_fd = manifold_jacobian(lambda s: passive.generalized_forces(s, 0.0)[0], state, eps=1e-7)
    K_material = sum(np.outer(M, M) * k for M, k in
                     zip([s.measure.evaluate(state, 1)[1][0] for s in model.springs], [300.0, 150.0]))
    assert np.abs(K - K_material).max() > 1e-2  # the geometric part is exercised
    np.testing.assert_allclose(K, K_fd, atol=1e-5 * np.abs(K).max())
    slow = ForceElements(model)
    slow.by_kind["springs"].rows.batched = None  # measure by measure
    Q2, _, K2 = slow.generalized_forces(state, 0.0, want_stiffness=True)
    np.testing.assert_allclose(Q2, Q, rtol=0, atol=1e-13)
    # K's geometric part is a forward difference (ε = 1e-7): round-off of the two
    # evaluation orders (≈1e-16 relative) is amplified ≈1e7 times
    np.testing.assert_allclose(K2, K, rtol=0, atol=1e-7)


def test_ligaments_law_on_arrays_equals_each_law():
    """Three Blankevoort ligaments, one slack, one in the toe region and one in the
    linear region: the law evaluated on arrays equals each law object's own evaluation
    (lengths, strains, tensions, Q, K), and the tensions match the closed form."""
    from openfdk.forces.elements import add_ligament
    from openfdk.model.builder import ModelBuilder

    b = ModelBuilder("ligs")
    b.add_body("a", 1.0, [1e-3] * 3, position=[0.0, 0.0, -0.1])
    b.add_frame("a", "p", [0.01, 0.0, 0.0])
    b.add_frame("ground", "o", [0.0, 0.0, 0.0])
    # path length is |(0.01, 0, -0.1)| ≈ 0.1005 m; slack lengths put ε at -1 %, 2 %, 10 %
    length = float(np.hypot(0.01, 0.1))
    strains = [-0.01, 0.02, 0.10]
    for k, eps in enumerate(strains):
        add_ligament(b, f"lig{k}", ["ground.o", "a.p"], stiffness=1000.0 * (k + 1), slack_length=length / (1 + eps))
    model = b.build()
    state = model.initial_state()
    fast = ForceElements(model)
    slow = ForceElements(model)
    assert fast.by_kind["ligaments"].blankevoort is not None
    slow.by_kind["ligaments"].blankevoort = None  # law object by law object
    Q, out, K = fast.generalized_forces(state, 0.0, want_stiffness=True)
    Q2, out2, K2 = slow.generalized_forces(state, 0.0, want_stiffness=True)
    np.testing.assert_allclose(out["ligaments"].strain, strains, rtol=1e-12)
    k_l0 = np.array([1000.0 * (k + 1) * length / (1 + e) for k, e in enumerate(strains)])
    expect = [0.0, k_l0[1] * 0.02**2 / (4 * 0.03), k_l0[2] * (0.10 - 0.03)]
    np.testing.assert_allclose(out["ligaments"].force, expect, rtol=1e-12, atol=1e-12)
    for x, y in ((out["ligaments"].force, out2["ligaments"].force), (out["ligaments"].strain, out2["ligaments"].strain), (Q, Q2)):
        np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(K, K2, rtol=1e-12, atol=1e-9)


def test_coordinate_limit_law_slope_is_its_derivative():
    """The limit law's df/dq equals a central difference of f at points inside, in the
    transition bands and beyond both limits (non-zero there, zero inside)."""
    from openfdk.forces.limit_force import CoordinateLimitLaw

    law = CoordinateLimitLaw(1.0, 120.0, 0.5, 170.0, 0.09, 3.0)
    h = 1e-7
    for q in (0.3, 0.44, 0.47, 0.7, 1.04, 1.08, 1.3):
        fd = (law.force(q + h) - law.force(q - h)) / (2 * h)
        assert law.dforce_dmeasure(q) == pytest.approx(fd, rel=1e-6, abs=1e-6)
    assert law.force(0.7) == 0.0 and law.dforce_dmeasure(0.7) == 0.0
    assert law.force(1.3) == pytest.approx(-120.0 * 0.3) and law.force(0.3) == pytest.approx(170.0 * 0.2)
    assert law.damping_force(1.3, 2.0) == pytest.approx(-6.0) and law.damping_force(0.7, 2.0) == 0.0


def test_expression_law_is_parsed_safely_and_evaluates_like_python():
    """An expression of q and qdot (OpenSim's Lepton syntax, ^ for power) evaluates to
    the same numbers as the formula written in Python; its slope is its derivative; code
    is refused without being run."""
    from openfdk.forces.expression_force import ExpressionLaw
    from openfdk.forces.force_laws import ForceLawError

    law = ExpressionLaw("-3*(q-0.2)^2 + square(q)*exp(-q) - 0.5*qdot - max(q, 0.1)", name="e")
    for q, qd in ((0.0, 1.0), (0.7, -2.0), (-1.3, 0.4)):
        f = -3 * (q - 0.2) ** 2 + q * q * np.exp(-q) - 0.5 * qd - max(q, 0.1)
        assert law.force(q) + law.damping_force(q, qd) == pytest.approx(f, rel=1e-14)
        h = 1e-6
        slope = (law.force(q + h) - law.force(q - h)) / (2 * h)
        assert law.dforce_dmeasure(q) == pytest.approx(slope, rel=1e-6) and abs(slope) > 0.1
    for bad in ("__import__('os').system('true')", "q.real", "[q][0]", "lambda: q", "y + q", "sin(q, q)", ""):
        with pytest.raises(ForceLawError):
            ExpressionLaw(bad, name="e")
    with pytest.raises(FloatingPointError, match="spring 'e'"):
        ExpressionLaw("log(q)", name="e").force(-1.0)


def test_expression_parser_fuzz():
    """2 000 random mutations of an expression: each is refused with ForceLawError, or
    parses and then evaluates to a number or FloatingPointError naming the spring —
    never another exception."""
    from openfdk.forces.expression_force import ExpressionLaw
    from openfdk.forces.force_laws import ForceLawError

    rng = np.random.default_rng(11)
    base = "-2.5*(q-0.3)^3 - 0.4*qdot*abs(qdot) + 0.2*sin(q) / max(q, 1e-3)"
    alphabet = list("qdot+-*/^()., 0123456789eE_[]'\"") + ["sin", "__", "lambda", "import", "q.", "**"]
    for _ in range(2000):
        text = list(base)
        for _ in range(int(rng.integers(1, 5))):
            k = int(rng.integers(0, len(text) + 1))
            if rng.random() < 0.5 and text:
                del text[min(k, len(text) - 1)]
            else:
                text.insert(k, alphabet[int(rng.integers(len(alphabet)))])
        try:
            law = ExpressionLaw("".join(text), name="fuzz")
        except ForceLawError:
            continue
        try:
            value = law.force(0.4) + law.damping_force(0.4, -1.3)
        except FloatingPointError as exc:
            assert "spring 'fuzz'" in str(exc)
            continue
        assert np.isfinite(value)
