"""The virtual subject's skull and mandible display meshes (openfdk.mandible.bone_meshes):
written by ``create_subject``, closed, wound outward, the condyle heads on the model's
condyle points, and referenced as the bodies' ``visual`` meshes of the models."""

from __future__ import annotations

import numpy as np
import pytest

from openfdk.io.meshfiles import read_display_mesh
from openfdk.mandible.generator import create_subject
from openfdk.mandible.subject import load_subject


@pytest.fixture(scope="module")
def subject_dir(tmp_path_factory):
    return create_subject(tmp_path_factory.mktemp("bones") / "subject", resolution="coarse")


def _closed_parts(faces):
    """Every undirected edge is shared by exactly two triangles, traversed once in each
    direction (a closed, consistently wound surface)."""
    directed = np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    undirected, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert np.all(counts == 2)
    assert len(np.unique(directed, axis=0)) == len(directed)  # no edge twice the same way


def _signed_volume(v, f):
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0


@pytest.mark.parametrize("name", ["skull.stl", "mandible.stl"])
def test_bone_meshes_are_closed_and_wound_outward(subject_dir, name):
    v, f = read_display_mesh(subject_dir / name)   # (file units: mm)
    v = np.asarray(v, float)
    # STL stores triangles apart: weld coincident vertices to check the topology
    welded, inverse = np.unique(np.round(v, 6), axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[np.asarray(f)]
    _closed_parts(faces)
    # a closed surface encloses a positive volume with outward normals (each part does,
    # so does their sum); the volume is of the right order for a bone (cm³)
    vol = _signed_volume(welded, faces)
    assert vol > 0
    assert 1e4 < vol < 2e6  # mm³: 10 cm³ … 2 L


def test_condyle_heads_lie_on_the_condyle_points(subject_dir):
    subject = load_subject(subject_dir)
    v, _ = read_display_mesh(subject_dir / "mandible.stl")
    v = np.asarray(v, float) * 1e-3
    for side in ("r", "l"):
        top = subject.condyle_top(side)
        near = v[np.linalg.norm(v - top, axis=1) < 0.015]
        # the highest point of the mandible on that side is the condyle head's top
        assert np.linalg.norm(near[np.argmax(near[:, 2])] - top) < 2e-3
        same_side = v[np.sign(v[:, 1]) == np.sign(top[1])]
        assert abs(same_side[:, 2].max() - top[2]) < 1e-3


@pytest.mark.slow
def test_models_reference_the_meshes_as_visuals(subject_dir, tmp_path):
    from openfdk.io.modelfile import load_model
    from openfdk.mandible.models import write_models
    from openfdk.mandible.registration import register_braces
    from openfdk.mandible.experiment import record_experiment
    from openfdk.model.visuals import visual_mesh_B

    subject = load_subject(subject_dir)
    record_experiment(subject_dir, tasks=(), cycles=1)
    models = write_models(subject, register_braces(subject, subject_dir / "trials" / "reference.c3d"), tmp_path)
    for kind in ("pop", "fdk"):
        model = load_model(models[kind])
        by_body = {v.body: v for v in model.visuals}
        assert set(by_body) == {"skull", "mandible"}
        # in the mandible's body frame (origin at its centre of mass) the condyle heads
        # are at the model's condyle points
        v_B, _ = visual_mesh_B(by_body["mandible"])
        body = model.body("mandible")
        for side in ("r", "l"):
            p_B = model.frame(f"mandible.condyle_{side}").p_BF if kind == "fdk" else \
                subject.condyle_top(side) - body.p_WB0
            assert np.min(np.linalg.norm(v_B - p_B, axis=1)) < 1.5e-3
